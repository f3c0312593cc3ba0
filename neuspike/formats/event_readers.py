"""Event files: the readers (:func:`read_events`) and the validation every event file goes through.

Formats (:func:`read_events` picks one from the extension, or from the content when the extension
says nothing):

HDF5, common layout (``.h5``, ``.hdf5``; written by :func:`write_events_h5` and
:class:`EventsH5Writer`)
    datasets ``events/xs``, ``events/ys`` (pixel column and row), ``events/ts`` (seconds, float64),
    ``events/ps`` (polarity, {0, 1} or {-1, +1}), and the root attribute ``sensor_resolution``
    holding **(height, width)**, the order of the field's HDF5 tools (the event_cnn_minimal /
    EVREAL packagers set ``sensor_resolution = [height, width]`` from a text header
    ``width height``, and their readers unpack it as ``h, w``). The writer also sets the usual
    ``num_events``, ``num_pos``, ``num_neg``, ``t0``, ``tk`` and ``duration`` attributes.
HDF5, PKU-Vidar-DVS layout
    one compound dataset ``events`` with fields ``timestamp`` (microseconds, integer), ``x``,
    ``y`` and ``polarity`` ({0, 1}). The files carry no sensor size; they come from a DAVIS346,
    so 346 x 260 is assumed unless ``width``/``height`` are given. Timestamps stay absolute (the
    recordings start seconds after the sensor's zero); ``meta["t_first_s"]`` notes the start.
E2VID text (``.txt``, optionally ``.txt.gz``)
    first line ``width height``, then one event per line: ``t x y p`` with ``t`` in seconds and
    ``p`` in {0, 1} ({-1, 1} is accepted when reading).
NumPy (``.npz``)
    arrays ``t_s`` (float64 s), ``x``, ``y`` (uint16), ``p`` (int8, {-1, +1}), and scalars
    ``width``, ``height``.
AEDAT 4 (``.aedat4``)
    read through the optional ``aedat`` package (``pip install neuspike-bench[aedat]``); the
    first event stream is read, timestamps converted from microseconds to seconds (absolute).
    That decoder panics on some damaged headers, and some panics abort the interpreter, so the
    preamble, the header (its flatbuffer offsets and the XML stream description) and the packet
    framing are checked here first, and the decoding runs in a child process (about 0.1 s more
    per file): no file can take the caller down.

Reading validates every file: a missing dataset or key raises :class:`FormatError` naming what
was expected; coordinates outside the sensor, timestamps that go back in time, non-finite times
and unknown polarity values raise :class:`FormatError` naming the first offending event. Damaged
files (corrupt archives, HDF5 objects, gzip streams, undecodable text) raise :class:`FormatError`
naming the file, never the underlying library's exception; a sensor side above
:data:`MAX_SENSOR_SIDE` or a dataset declaring more data than its stored bytes can hold is refused
before anything is allocated. Nothing is sorted, clipped or dropped silently. The writers are in :mod:`neuspike.formats.event_writers`.
"""

from __future__ import annotations

import gzip
import math
import os
import struct
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.utils.checks import check_positive_int
from neuspike.errors import FormatError, InputError, NeuSpikeError, SourceError
from neuspike.formats._npz import NpzArchive
from neuspike.streams import P_DTYPE, T_DTYPE, XY_DTYPE, EventStream

__all__ = ["DAVIS346_SIZE", "H5_KEYS", "MAX_SENSOR_SIDE", "PKU_FIELDS", "check_side", "events_from_arrays",
           "read_events"]

#: Sensor size (width, height) assumed for PKU-Vidar-DVS files, which do not store it.
DAVIS346_SIZE = (346, 260)
#: Largest sensor side accepted from a file or an argument (coordinates are stored as uint16).
MAX_SENSOR_SIDE = 16384
#: A dataset may expand at most this many times its stored bytes (beyond deflate's ~1032:1).
_MAX_EXPANSION = 1100

_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_ZIP_MAGIC = b"PK\x03\x04"
_AEDAT4_MAGIC = b"#!AER-DAT4.0"
H5_KEYS = ("xs", "ys", "ts", "ps")
_NPZ_KEYS = ("t_s", "x", "y", "p", "width", "height")
PKU_FIELDS = ("timestamp", "x", "y", "polarity")


# --------------------------------------------------------------------------- validation
def _first_true(mask: np.ndarray) -> int:
    return int(np.argmax(mask))


def events_from_arrays(
    path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray,
    width: int, height: int, meta: dict[str, Any], *, polarity: str,
) -> EventStream:
    """Validate raw arrays read from ``path`` and build the stream.

    ``polarity`` is ``"01"`` ({0, 1}), ``"pm1"`` ({-1, +1}) or ``"any"`` (either convention,
    decided by the values: any 0 means {0, 1}).
    """
    arrays = {}
    for name, a in (("t", t), ("x", x), ("y", y), ("p", p)):
        a = np.asarray(a)
        if a.ndim != 1:
            raise FormatError(f"{path}: expected the event {name} values as a 1-D array, got shape {a.shape}")
        if a.dtype.kind not in "biuf":
            raise FormatError(f"{path}: expected numbers for the event {name} values, got dtype {a.dtype}")
        arrays[name] = a
    t, x, y, p = arrays["t"], arrays["x"], arrays["y"], arrays["p"]
    n = t.shape[0]
    if not (x.shape[0] == y.shape[0] == p.shape[0] == n):
        raise FormatError(
            f"{path}: event arrays differ in length: t {n}, x {x.shape[0]}, y {y.shape[0]}, p {p.shape[0]}"
        )
    t = np.asarray(t, dtype=T_DTYPE)
    if n:
        finite = np.isfinite(t)
        if not finite.all():
            i = _first_true(~finite)
            raise FormatError(f"{path}: event {i} has a non-finite timestamp {float(t[i])!r}")
        back = t[1:] < t[:-1]
        if back.any():
            i = _first_true(back) + 1
            raise FormatError(
                f"{path}: timestamps must not decrease; event {i} at {float(t[i])!r} s comes after "
                f"event {i - 1} at {float(t[i - 1])!r} s"
            )
        for name, a, size in (("x", x, width), ("y", y, height)):
            if not np.issubdtype(a.dtype, np.integer):
                whole = a == np.round(a)
                if not whole.all():
                    i = _first_true(~whole)
                    raise FormatError(f"{path}: event {i} has a non-integer {name} coordinate {a[i].item()!r}")
            outside = (a < 0) | (a >= size)
            if outside.any():
                i = _first_true(outside)
                raise FormatError(
                    f"{path}: event {i} at (x={x[i].item()}, y={y[i].item()}) lies outside the "
                    f"{width}x{height} sensor ({name} must be in [0, {size}))"
                )
        p = np.asarray(p)
        if polarity == "any":
            polarity = "01" if (p == 0).any() else "pm1"
        allowed = (0, 1) if polarity == "01" else (-1, 1)
        bad = (p != allowed[0]) & (p != allowed[1])
        if bad.any():
            i = _first_true(bad)
            raise FormatError(
                f"{path}: event {i} has polarity {p[i].item()!r}; expected values in {sorted(allowed)}"
            )
        p = (p.astype(np.int8) * 2 - 1) if polarity == "01" else p
    try:
        return EventStream(t, x.astype(XY_DTYPE), y.astype(XY_DTYPE), np.asarray(p, dtype=P_DTYPE),
                           width, height, meta)
    except InputError as exc:  # checked above; kept so that no file can surface an untyped error
        raise FormatError(f"{path}: {exc}") from None


def check_side(path: Path, value: Any, what: str) -> int:
    """A sensor side read from a file: a whole number in [1, MAX_SENSOR_SIDE]."""
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise FormatError(f"{path}: {what} must be a whole number, got {value!r}") from None
    if not (math.isfinite(v) and v == int(v) and 1 <= v <= MAX_SENSOR_SIDE):
        raise FormatError(f"{path}: {what} must be a whole number in [1, {MAX_SENSOR_SIDE}], got {value!r}")
    return int(v)


def _size(path: Path, declared: tuple[int, int] | None, width: Any, height: Any, what: str) -> tuple[int, int]:
    """Sensor size: explicit ``width``/``height`` win over the file's declared size."""
    if (width is None) != (height is None):
        raise InputError(f"read_events: give both width and height or neither, got {width!r}, {height!r}")
    if width is not None:
        w, h = check_positive_int("width", width), check_positive_int("height", height)
        if max(w, h) > MAX_SENSOR_SIDE:
            raise InputError(f"read_events: width and height must be at most {MAX_SENSOR_SIDE}, got {w}x{h}")
        return w, h
    if declared is None:
        raise FormatError(f"{path}: {what}; pass width= and height=")
    return declared


# --------------------------------------------------------------------------- readers
#: What h5py, zlib and the parsers raise on damaged bytes; readers turn these into FormatError.
_DAMAGE = (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError, OverflowError, EOFError,
           zlib.error, struct.error, UnicodeDecodeError, AttributeError)


def _h5_array(path: Path, ds: Any, what: str) -> np.ndarray:
    """Read an HDF5 dataset whose declared size its stored bytes can justify."""
    nbytes = int(ds.size or 0) * int(ds.dtype.itemsize)
    stored = int(ds.id.get_storage_size())
    if nbytes > stored * _MAX_EXPANSION + 4096:
        raise FormatError(
            f"{path}: dataset {what} declares {ds.shape} x {ds.dtype} ({nbytes} bytes) but stores only "
            f"{stored} bytes"
        )
    return np.asarray(ds[()])


def _read_h5(path: Path, width: Any, height: Any) -> EventStream:
    import h5py

    try:
        f = h5py.File(path, "r")
    except _DAMAGE as exc:
        raise FormatError(f"{path}: not a readable HDF5 file ({exc})") from None
    try:
        with f:
            return _read_h5_open(path, f, width, height)
    except NeuSpikeError:
        raise
    except _DAMAGE as exc:  # h5py surfaces corrupt object headers and chunks in many ways
        raise FormatError(f"{path}: damaged HDF5 file ({type(exc).__name__}: {exc})") from None


def _read_h5_open(path: Path, f: Any, width: Any, height: Any) -> EventStream:
    import h5py

    node = f.get("events")
    if isinstance(node, h5py.Group):
        missing = [k for k in H5_KEYS if not isinstance(node.get(k), h5py.Dataset)]
        if missing:
            raise FormatError(
                f"{path}: the group 'events' lacks dataset(s) {', '.join('events/' + k for k in missing)}; "
                f"the common layout has events/xs, events/ys, events/ts (s) and events/ps"
            )
        declared = None
        if "sensor_resolution" in f.attrs:
            res = np.asarray(f.attrs["sensor_resolution"]).ravel()
            if res.size != 2:
                raise FormatError(
                    f"{path}: attribute sensor_resolution should be (height, width), got {res.tolist()!r}"
                )
            declared = (check_side(path, res[1], "sensor_resolution width"),
                        check_side(path, res[0], "sensor_resolution height"))
        w, h = _size(path, declared, width, height,
                     "no sensor_resolution attribute (height, width) in the file")
        arrays = [_h5_array(path, node[k], f"events/{k}") for k in H5_KEYS]
        return events_from_arrays(path, arrays[2], arrays[0], arrays[1], arrays[3], w, h,
                                   {"source": str(path), "format": "hdf5"}, polarity="any")
    if isinstance(node, h5py.Dataset) and node.dtype.names is not None:
        missing = [k for k in PKU_FIELDS if k not in node.dtype.names]
        if missing:
            raise FormatError(
                f"{path}: dataset 'events' lacks field(s) {missing}; the PKU-Vidar-DVS layout has "
                f"{', '.join(PKU_FIELDS)}, found {list(node.dtype.names)}"
            )
        rec = _h5_array(path, node, "events")
        if rec.ndim != 1:
            raise FormatError(f"{path}: expected the dataset 'events' to be 1-D, got shape {rec.shape}")
        w, h = _size(path, DAVIS346_SIZE, width, height, "")
        stamp = rec["timestamp"]
        if stamp.dtype.kind not in "iuf":
            raise FormatError(f"{path}: expected numeric timestamps, got dtype {stamp.dtype}")
        t = stamp.astype(np.float64) / 1e6
        meta = {"source": str(path), "format": "pku-vidar-dvs-hdf5"}
        stream = events_from_arrays(path, t, rec["x"], rec["y"], rec["polarity"], w, h, meta, polarity="01")
        stream.meta["t_first_s"] = float(stream.t_s[0]) if len(stream) else None
        return stream
    found = sorted(f.keys())
    raise FormatError(
        f"{path}: expected the group 'events' with datasets xs, ys, ts, ps (common layout) or a "
        f"compound dataset 'events' with fields {', '.join(PKU_FIELDS)} (PKU-Vidar-DVS); "
        f"found {found}"
    )


def _read_txt(path: Path, width: Any, height: Any) -> EventStream:
    try:
        return _read_txt_open(path, width, height)
    except NeuSpikeError:
        raise
    except _DAMAGE as exc:  # gzip, decoding and parser errors on damaged bytes
        raise FormatError(f"{path}: not a readable E2VID text file ({type(exc).__name__}: {exc!r})") from None


def _read_txt_open(path: Path, width: Any, height: Any) -> EventStream:
    import pandas as pd

    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8", errors="strict", newline="") as fh:
        line = fh.readline(256)
        header = line.split()
        declared = None
        if len(header) == 2 and line.endswith("\n") and all(v.isascii() and v.isdigit() for v in header):
            declared = (check_side(path, header[0], "the header's width"), check_side(path, header[1], "the header's height"))
        if declared is None:
            raise FormatError(
                f"{path}: the first line must be 'width height' (E2VID text format), got a line of "
                f"{len(line.rstrip())} characters that is not two whole numbers"
            )
        w, h = _size(path, declared, width, height, "")
        try:
            table = pd.read_csv(fh, sep=r"\s+", header=None, names=["t", "x", "y", "p"],
                                dtype={"t": np.float64}, engine="c")
        except pd.errors.EmptyDataError:
            table = pd.DataFrame({"t": [], "x": [], "y": [], "p": []})
        except (ValueError, pd.errors.ParserError) as exc:
            raise FormatError(f"{path}: cannot parse the 't x y p' event lines ({str(exc)[:200]!r})") from None
    if table.shape[1] != 4:
        raise FormatError(f"{path}: expected four columns 't x y p', got {table.shape[1]}")
    missing = table[["x", "y", "p"]].isna().to_numpy().any(axis=1)
    if missing.any():
        i = int(np.argmax(missing))
        raise FormatError(f"{path}: event {i} (line {i + 2}) does not have four numbers 't x y p'")
    cols = [table[c].to_numpy() if len(table) else np.zeros(0) for c in ("t", "x", "y", "p")]
    return events_from_arrays(path, cols[0], cols[1], cols[2], cols[3], w, h,
                               {"source": str(path), "format": "e2vid-txt"}, polarity="any")


def _npz_number(archive: NpzArchive, key: str) -> Any:
    a = archive[key]
    if a.shape not in ((), (1,)) or a.dtype.kind not in "iuf":
        raise FormatError(f"{archive.path}: expected {key!r} to be a single number, got shape {a.shape} "
                          f"dtype {a.dtype}")
    return a.reshape(()).item()


def _read_npz(path: Path, width: Any, height: Any) -> EventStream:
    with NpzArchive(path) as data:
        missing = [k for k in _NPZ_KEYS if k not in data.files]
        if missing:
            raise FormatError(f"{path}: missing array(s) {missing}; expected {', '.join(_NPZ_KEYS)}")
        declared = (check_side(path, _npz_number(data, "width"), "width"),
                    check_side(path, _npz_number(data, "height"), "height"))
        w, h = _size(path, declared, width, height, "")
        return events_from_arrays(path, data["t_s"], data["x"], data["y"], data["p"], w, h,
                                   {"source": str(path), "format": "npz"}, polarity="pm1")


# AEDAT4: the decoder (the Rust ``aedat`` package) panics on some damaged headers, and some of
# those panics abort the whole interpreter. The file's header and packet framing are checked here
# first, and the decoding itself runs in a child process, so no file can take the caller down.
_AEDAT4_PREAMBLE = _AEDAT4_MAGIC + b"\r\n"
_AEDAT4_COMPRESSION = {0: "none", 1: "LZ4", 2: "LZ4 high", 3: "Zstd", 4: "Zstd high"}
_AEDAT4_CHILD = r"""
import json, sys
import numpy as np
try:
    import aedat
    decoder = aedat.Decoder(sys.argv[1])
    streams = {int(k): dict(v) for k, v in decoder.id_to_stream().items()}
    sid = int(sys.argv[3])
    parts = [np.asarray(p["events"]) for p in decoder if p.get("stream_id") == sid and "events" in p]
except BaseException as exc:  # the decoder's panics are BaseExceptions
    sys.stderr.write(type(exc).__name__ + ": " + str(exc)[:300])
    sys.exit(3)
ev = np.concatenate(parts) if parts else np.zeros(0, [("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("on", "?")])
out = np.empty(len(ev), [("t", "<i8"), ("x", "<i4"), ("y", "<i4"), ("on", "i1")])
for k in ("t", "x", "y", "on"):
    out[k] = ev[k]
np.save(sys.argv[2], out, allow_pickle=False)
"""


def _aedat4_header(path: Path, blob: bytes) -> tuple[int, int, dict[int, dict[str, Any]]]:
    """Check the preamble, the IOHeader flatbuffer and the stream description.

    Returns ``(data_start, data_end, streams)`` with ``streams`` mapping ids to their attributes.
    """
    import xml.etree.ElementTree as ET

    def bad(why: str) -> FormatError:
        return FormatError(f"{path}: not a valid AEDAT4 file: {why}")

    def u32(buf: bytes, at: int) -> int:
        if not 0 <= at <= len(buf) - 4:
            raise bad(f"an offset points outside the header (byte {at})")
        return struct.unpack_from("<I", buf, at)[0]

    if not blob.startswith(_AEDAT4_PREAMBLE):
        raise bad("it does not start with '#!AER-DAT4.0\\r\\n'")
    at = len(_AEDAT4_PREAMBLE)
    if len(blob) < at + 4:
        raise bad("the header size is missing")
    size = struct.unpack_from("<i", blob, at)[0]
    if not 8 <= size <= len(blob) - at - 4:
        raise bad(f"header size {size} does not fit in the file's {len(blob)} bytes")
    hdr = blob[at + 4:at + 4 + size]
    data_start = at + 4 + size
    root = u32(hdr, 0)
    if hdr[4:8] != b"IOHE":
        raise bad("the header lacks the IOHE identifier")
    if not 8 <= root <= size - 4:
        raise bad(f"the header's root offset {root} is outside its {size} bytes")
    vtable = root - struct.unpack_from("<i", hdr, root)[0]
    if not 0 <= vtable <= size - 4:
        raise bad(f"the header's vtable offset {vtable} is outside its {size} bytes")
    vt_size, table_size = struct.unpack_from("<HH", hdr, vtable)
    if vt_size < 4 or vt_size % 2 or vtable + vt_size > size or root + table_size > size:
        raise bad("the header's vtable is inconsistent")
    fields = [struct.unpack_from("<H", hdr, vtable + 4 + 2 * i)[0] for i in range((vt_size - 4) // 2)]
    fields += [0] * (3 - len(fields))
    for off, width_ in zip(fields[:3], (4, 8, 4)):
        if off and not 4 <= off <= table_size - width_:
            raise bad("a header field lies outside its table")
    compression = struct.unpack_from("<i", hdr, root + fields[0])[0] if fields[0] else 0
    if compression not in _AEDAT4_COMPRESSION:
        raise bad(f"unknown compression {compression}")
    table_pos = struct.unpack_from("<q", hdr, root + fields[1])[0] if fields[1] else -1
    if table_pos != -1 and not data_start <= table_pos <= len(blob):
        raise bad(f"the data table position {table_pos} is outside the file")
    if not fields[2]:
        raise bad("the header has no stream description")
    s_at = root + fields[2] + u32(hdr, root + fields[2])
    s_len = u32(hdr, s_at)
    if s_at + 4 + s_len > size:
        raise bad("the stream description runs past the header")
    try:
        text = hdr[s_at + 4:s_at + 4 + s_len].decode("utf-8")
    except UnicodeDecodeError as exc:
        raise bad(f"the stream description is not UTF-8 ({exc})") from None
    if "<!DOCTYPE" in text.upper() or "<!ENTITY" in text.upper() or "\0" in text:
        raise bad("the stream description holds a DOCTYPE, an entity or a NUL")
    try:
        tree = ET.fromstring(text)
    except ET.ParseError as exc:
        raise bad(f"the stream description is not XML ({exc})") from None
    streams: dict[int, dict[str, Any]] = {}
    for node in tree.iter("node"):
        name = node.get("name", "")
        attrs = {a.get("key"): (a.text or "") for a in node.findall("attr")}
        if name.isascii() and name.isdigit() and "typeIdentifier" in attrs:
            info: dict[str, Any] = {"type": attrs["typeIdentifier"]}
            for child in node.iter("node"):
                if child.get("name") == "info":
                    for a in child.findall("attr"):
                        info[a.get("key")] = a.text or ""
            streams[int(name)] = info
    if not streams:
        raise bad("the stream description names no stream")
    return data_start, (len(blob) if table_pos == -1 else table_pos), streams


def _aedat4_packets(path: Path, blob: bytes, start: int, end: int, streams: dict[int, Any]) -> int:
    """Walk the packet framing (stream id, size) from ``start`` to ``end``; return the packet count."""
    at, count = start, 0
    while at < end:
        if at + 8 > end:
            raise FormatError(f"{path}: a truncated AEDAT4 packet header at byte {at}")
        sid, size = struct.unpack_from("<ii", blob, at)
        if sid not in streams:
            raise FormatError(f"{path}: packet at byte {at} names stream {sid}, which the header does not declare")
        if not 0 < size <= end - at - 8:
            raise FormatError(f"{path}: packet at byte {at} declares {size} bytes; {end - at - 8} remain")
        at += 8 + size
        count += 1
    return count


def _read_aedat4(path: Path, width: Any, height: Any) -> EventStream:
    try:
        import aedat  # noqa: F401  (needed by the child process)
    except ImportError:
        raise SourceError(
            f"{path}: reading AEDAT4 needs the optional 'aedat' package; install the extra with "
            f"pip install 'neuspike-bench[aedat]'"
        ) from None
    blob = path.read_bytes()
    start, end, streams = _aedat4_header(path, blob)
    _aedat4_packets(path, blob, start, end, streams)
    event_ids = sorted(i for i, s in streams.items() if s.get("type") == "EVTS")
    if not event_ids:
        kinds = {i: s.get("type") for i, s in streams.items()}
        raise FormatError(f"{path}: no event stream (EVTS) in the file (streams: {kinds})")
    sid = event_ids[0]
    info = streams[sid]
    declared = None
    if "sizeX" in info and "sizeY" in info:
        declared = (check_side(path, info["sizeX"], "the event stream's sizeX"),
                    check_side(path, info["sizeY"], "the event stream's sizeY"))
    w, h = _size(path, declared, width, height, "the event stream states no sizeX/sizeY")
    ev = _aedat4_decode(path, sid)
    t = ev["t"].astype(np.float64) / 1e6
    meta = {"source": str(path), "format": "aedat4", "t_first_s": float(t[0]) if t.size else None}
    return events_from_arrays(path, t, ev["x"], ev["y"], ev["on"], w, h, meta, polarity="01")


def _aedat4_decode(path: Path, stream_id: int) -> np.ndarray:
    """Decode one event stream with the ``aedat`` package in a child process (t, x, y, on)."""
    with tempfile.TemporaryDirectory(prefix="neuspike-aedat4-") as tmp:
        out = Path(tmp) / "events.npy"
        timeout_s = 60.0 + path.stat().st_size / 1e6
        try:
            done = subprocess.run([sys.executable, "-c", _AEDAT4_CHILD, str(path), str(out), str(stream_id)],
                                  capture_output=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise FormatError(f"{path}: the AEDAT4 decoder did not finish in {timeout_s:.0f} s") from None
        if done.returncode != 0 or not out.is_file():
            why = done.stderr.decode("utf-8", "replace").strip().splitlines()
            detail = why[-1][:300] if why else f"the decoder process ended with status {done.returncode}"
            if done.returncode < 0:
                detail = f"the decoder crashed (signal {-done.returncode})"
            raise FormatError(f"{path}: not a readable AEDAT4 file ({detail})")
        return np.load(out, allow_pickle=False)


_READERS = {".h5": _read_h5, ".hdf5": _read_h5, ".hdf": _read_h5, ".txt": _read_txt,
            ".npz": _read_npz, ".aedat4": _read_aedat4}


def _sniff(path: Path):
    with open(path, "rb") as fh:
        head = fh.read(16)
    if head.startswith(_HDF5_MAGIC):
        return _read_h5
    if head.startswith(_ZIP_MAGIC):
        return _read_npz
    if head.startswith(_AEDAT4_MAGIC):
        return _read_aedat4
    return _read_txt


def read_events(path: str | os.PathLike, *, width: int | None = None, height: int | None = None) -> EventStream:
    """Read an event file (HDF5 common or PKU-Vidar-DVS layout, E2VID text, .npz, AEDAT4).

    Parameters
    ----------
    path : str or PathLike
        The file. The format comes from the extension (``.h5``/``.hdf5``, ``.txt``/``.txt.gz``,
        ``.npz``, ``.aedat4``), or from the content for other names.
    width, height : int, optional
        Sensor size; needed when the file does not store it (an HDF5 file without
        ``sensor_resolution``) and otherwise overriding the stored size. Give both or neither.

    Returns
    -------
    EventStream
        Events in file order (the file must be sorted by time), polarity converted to {-1, +1},
        ``meta`` naming the source file and format.

    Raises
    ------
    SourceError
        If the file does not exist, or AEDAT4 is read without the ``aedat`` package.
    FormatError
        For a malformed file: missing datasets, keys or header; coordinates outside the sensor;
        timestamps that decrease; unknown polarity values (naming the first offending event).
    """
    p = Path(path)
    if not p.is_file():
        raise SourceError(f"read_events: no such file {p}")
    suffixes = [s.lower() for s in p.suffixes]
    if suffixes[-2:] == [".txt", ".gz"]:
        reader = _read_txt
    else:
        reader = _READERS.get(p.suffix.lower()) or _sniff(p)
    return reader(p, width, height)
