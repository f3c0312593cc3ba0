"""A minimal AEDAT4 writer for tests: uncompressed event packets, built byte by byte.

The layout follows the published AEDAT 4.0 description: the preamble ``#!AER-DAT4.0\\r\\n``, an
int32 header size, an ``IOHE`` flatbuffer (compression, data-table position, the XML stream
description), then packets of (int32 stream id, int32 size, size-prefixed ``EVTS`` flatbuffer
holding 16-byte events: int64 t in us, int16 x, int16 y, bool on, 3 bytes padding).
"""

from __future__ import annotations

import struct

import numpy as np

EVENT_DTYPE = np.dtype({"names": ["t", "x", "y", "on"], "formats": ["<i8", "<i2", "<i2", "?"],
                        "offsets": [0, 8, 10, 12], "itemsize": 16})


def _xml(width: int, height: int) -> bytes:
    return (
        '<dv version="2.0">\n'
        '    <node name="outInfo" path="/mainloop/Recorder/outInfo/">\n'
        '        <node name="0" path="/mainloop/Recorder/outInfo/0/">\n'
        '            <attr key="compression" type="string">NONE</attr>\n'
        '            <attr key="originalModuleName" type="string">capture</attr>\n'
        '            <attr key="originalOutputName" type="string">events</attr>\n'
        '            <attr key="typeDescription" type="string">Array of events (polarity ON/OFF).</attr>\n'
        '            <attr key="typeIdentifier" type="string">EVTS</attr>\n'
        '            <node name="info" path="/mainloop/Recorder/outInfo/0/info/">\n'
        f'                <attr key="sizeX" type="int">{width}</attr>\n'
        f'                <attr key="sizeY" type="int">{height}</attr>\n'
        '                <attr key="source" type="string">test</attr>\n'
        '                <attr key="tsOffset" type="long">0</attr>\n'
        '            </node>\n'
        '        </node>\n'
        '    </node>\n'
        '</dv>\n'
    ).encode()


def _header(width: int, height: int) -> bytes:
    xml = _xml(width, height)
    out = bytearray()
    out += struct.pack("<I", 24) + b"IOHE" + bytes(6)              # root offset, identifier, padding
    out += struct.pack("<HHHHH", 10, 20, 4, 12, 8)                  # vtable at 14: compression, dtp, info
    assert len(out) == 24
    out += struct.pack("<iiIq", 10, 0, 12, -1)                      # table: soffset, NONE, info ->, dtp
    out += struct.pack("<I", len(xml)) + xml + b"\0"
    out += bytes(-len(out) % 4)
    return bytes(out)


def _packet(events: np.ndarray) -> bytes:
    body = bytearray()
    body += struct.pack("<I", 16) + b"EVTS"                         # root offset, identifier
    body += struct.pack("<HHH", 6, 8, 4) + bytes(2)                 # vtable at 8
    body += struct.pack("<iI", 8, 8) + bytes(4)                     # table at 16: soffset, vector ->
    body += struct.pack("<I", len(events))                          # vector at 28, elements from 32
    body += np.ascontiguousarray(events, dtype=EVENT_DTYPE).tobytes()
    return struct.pack("<I", len(body)) + bytes(body)


def encode_aedat4(t_us, x, y, on, *, width: int, height: int, per_packet: int = 64) -> bytes:
    """Bytes of an uncompressed AEDAT4 file with one event stream (id 0)."""
    ev = np.zeros(len(t_us), EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["on"] = t_us, x, y, on
    header = _header(width, height)
    out = bytearray(b"#!AER-DAT4.0\r\n" + struct.pack("<i", len(header)) + header)
    for i in range(0, len(ev), per_packet):
        pkt = _packet(ev[i:i + per_packet])
        out += struct.pack("<ii", 0, len(pkt)) + pkt
    return bytes(out)
