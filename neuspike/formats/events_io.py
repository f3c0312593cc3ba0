"""Event files: read and write the formats the field uses.

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

Reading validates every file: a missing dataset or key raises :class:`FormatError` naming what
was expected; coordinates outside the sensor, timestamps that go back in time, non-finite times
and unknown polarity values raise :class:`FormatError` naming the first offending event.
Nothing is sorted, clipped or dropped silently. All writers are atomic: they write a temporary
file in the target folder and move it into place only when complete.
"""

from __future__ import annotations

import gzip
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.atomic import publish
from neuspike.checks import check_positive_int
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.streams import P_DTYPE, T_DTYPE, XY_DTYPE, EventStream

__all__ = [
    "DAVIS346_SIZE",
    "EventsH5Writer",
    "read_events",
    "write_events_h5",
    "write_events_npz",
    "write_events_txt",
]

#: Sensor size (width, height) assumed for PKU-Vidar-DVS files, which do not store it.
DAVIS346_SIZE = (346, 260)

_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_ZIP_MAGIC = b"PK\x03\x04"
_AEDAT4_MAGIC = b"#!AER-DAT4.0"
_H5_KEYS = ("xs", "ys", "ts", "ps")
_NPZ_KEYS = ("t_s", "x", "y", "p", "width", "height")
_PKU_FIELDS = ("timestamp", "x", "y", "polarity")


# --------------------------------------------------------------------------- validation
def _first_true(mask: np.ndarray) -> int:
    return int(np.argmax(mask))


def _events_from_arrays(
    path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray,
    width: int, height: int, meta: dict[str, Any], *, polarity: str,
) -> EventStream:
    """Validate raw arrays read from ``path`` and build the stream.

    ``polarity`` is ``"01"`` ({0, 1}), ``"pm1"`` ({-1, +1}) or ``"any"`` (either convention,
    decided by the values: any 0 means {0, 1}).
    """
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
    return EventStream(t, x.astype(XY_DTYPE), y.astype(XY_DTYPE), np.asarray(p, dtype=P_DTYPE),
                       width, height, meta)


def _size(path: Path, declared: tuple[int, int] | None, width: Any, height: Any, what: str) -> tuple[int, int]:
    """Sensor size: explicit ``width``/``height`` win over the file's declared size."""
    if (width is None) != (height is None):
        raise InputError(f"read_events: give both width and height or neither, got {width!r}, {height!r}")
    if width is not None:
        return check_positive_int("width", width), check_positive_int("height", height)
    if declared is None:
        raise FormatError(f"{path}: {what}; pass width= and height=")
    return declared


# --------------------------------------------------------------------------- readers
def _read_h5(path: Path, width: Any, height: Any) -> EventStream:
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise FormatError(f"{path}: not a readable HDF5 file ({exc})") from None
    with f:
        node = f.get("events")
        if isinstance(node, h5py.Group):
            missing = [k for k in _H5_KEYS if not isinstance(node.get(k), h5py.Dataset)]
            if missing:
                raise FormatError(
                    f"{path}: the group 'events' lacks dataset(s) {', '.join('events/' + k for k in missing)}; "
                    f"the common layout has events/xs, events/ys, events/ts (s) and events/ps"
                )
            declared = None
            if "sensor_resolution" in f.attrs:
                res = np.asarray(f.attrs["sensor_resolution"]).ravel()
                if res.size < 2 or not (res[:2] > 0).all():
                    raise FormatError(
                        f"{path}: attribute sensor_resolution should be (height, width), got {res.tolist()}"
                    )
                declared = (int(res[1]), int(res[0]))
            w, h = _size(path, declared, width, height,
                         "no sensor_resolution attribute (height, width) in the file")
            arrays = [node[k][()] for k in _H5_KEYS]
            return _events_from_arrays(path, arrays[2], arrays[0], arrays[1], arrays[3], w, h,
                                       {"source": str(path), "format": "hdf5"}, polarity="any")
        if isinstance(node, h5py.Dataset) and node.dtype.names is not None:
            missing = [k for k in _PKU_FIELDS if k not in node.dtype.names]
            if missing:
                raise FormatError(
                    f"{path}: dataset 'events' lacks field(s) {missing}; the PKU-Vidar-DVS layout has "
                    f"{', '.join(_PKU_FIELDS)}, found {list(node.dtype.names)}"
                )
            rec = node[()]
            w, h = _size(path, DAVIS346_SIZE, width, height, "")
            t = rec["timestamp"].astype(np.float64) / 1e6
            meta = {"source": str(path), "format": "pku-vidar-dvs-hdf5",
                    "t_first_s": float(t[0]) if t.size else None}
            return _events_from_arrays(path, t, rec["x"], rec["y"], rec["polarity"], w, h, meta,
                                       polarity="01")
        found = sorted(f.keys())
        raise FormatError(
            f"{path}: expected the group 'events' with datasets xs, ys, ts, ps (common layout) or a "
            f"compound dataset 'events' with fields {', '.join(_PKU_FIELDS)} (PKU-Vidar-DVS); "
            f"found {found}"
        )


def _read_txt(path: Path, width: Any, height: Any) -> EventStream:
    import pandas as pd

    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as fh:
        header = fh.readline().split()
        try:
            declared = (int(header[0]), int(header[1])) if len(header) == 2 else None
        except ValueError:
            declared = None
        if declared is None or min(declared) < 1:
            raise FormatError(
                f"{path}: the first line must be 'width height' (E2VID text format), got {' '.join(header)!r}"
            )
        w, h = _size(path, declared, width, height, "")
        try:
            table = pd.read_csv(fh, sep=r"\s+", header=None, names=["t", "x", "y", "p"],
                                dtype={"t": np.float64}, engine="c")
        except pd.errors.EmptyDataError:
            table = pd.DataFrame({"t": [], "x": [], "y": [], "p": []})
        except (ValueError, pd.errors.ParserError) as exc:
            raise FormatError(f"{path}: cannot parse the 't x y p' event lines ({exc})") from None
    missing = table[["x", "y", "p"]].isna().to_numpy().any(axis=1)
    if missing.any():
        i = int(np.argmax(missing))
        raise FormatError(f"{path}: event {i} (line {i + 2}) does not have four numbers 't x y p'")
    cols = [table[c].to_numpy() for c in ("t", "x", "y", "p")]
    return _events_from_arrays(path, cols[0], cols[1], cols[2], cols[3], w, h,
                               {"source": str(path), "format": "e2vid-txt"}, polarity="any")


def _read_npz(path: Path, width: Any, height: Any) -> EventStream:
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{path}: not a readable .npz file ({exc})") from None
    with data:
        missing = [k for k in _NPZ_KEYS if k not in data.files]
        if missing:
            raise FormatError(f"{path}: missing array(s) {missing}; expected {', '.join(_NPZ_KEYS)}")
        declared = (int(data["width"]), int(data["height"]))
        w, h = _size(path, declared, width, height, "")
        return _events_from_arrays(path, data["t_s"], data["x"], data["y"], data["p"], w, h,
                                   {"source": str(path), "format": "npz"}, polarity="pm1")


def _read_aedat4(path: Path, width: Any, height: Any) -> EventStream:
    try:
        import aedat
    except ImportError:
        raise SourceError(
            f"{path}: reading AEDAT4 needs the optional 'aedat' package; install the extra with "
            f"pip install 'neuspike-bench[aedat]'"
        ) from None
    try:
        decoder = aedat.Decoder(str(path))
        streams = decoder.id_to_stream()
    except Exception as exc:  # the Rust decoder raises plain exceptions
        raise FormatError(f"{path}: not a readable AEDAT4 file ({exc})") from None
    event_ids = sorted(i for i, s in streams.items() if s.get("type") == "events")
    if not event_ids:
        raise FormatError(f"{path}: no event stream in the file (streams: {streams})")
    sid = event_ids[0]
    declared = (int(streams[sid]["width"]), int(streams[sid]["height"]))
    w, h = _size(path, declared, width, height, "")
    parts = []
    try:
        for packet in decoder:
            if packet.get("stream_id") == sid and "events" in packet:
                parts.append(packet["events"])
    except Exception as exc:
        raise FormatError(f"{path}: corrupt AEDAT4 packet ({exc})") from None
    if parts:
        ev = np.concatenate(parts)
        t, x, y, p = ev["t"].astype(np.float64) / 1e6, ev["x"], ev["y"], ev["on"].astype(np.int8)
    else:
        t, x, y, p = np.zeros(0), np.zeros(0, np.uint16), np.zeros(0, np.uint16), np.zeros(0, np.int8)
    meta = {"source": str(path), "format": "aedat4", "t_first_s": float(t[0]) if t.size else None}
    return _events_from_arrays(path, t, x, y, p, w, h, meta, polarity="01")


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


# --------------------------------------------------------------------------- writers
def _check_stream(stream: Any, where: str) -> EventStream:
    if not isinstance(stream, EventStream):
        raise InputError(f"{where}: expected an EventStream, got {type(stream).__name__}")
    return stream


def _temp_path(path: Path) -> Path:
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    return Path(name)


def _atomic(path: str | os.PathLike, write) -> Path:
    """Run ``write(temp_path)`` then move the temporary file onto ``path``; no partial files."""
    target = Path(path)
    if not target.parent.is_dir():
        raise SourceError(f"cannot write {target}: folder {target.parent} does not exist")
    tmp = _temp_path(target)
    try:
        write(tmp)
        publish(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return target


def _h5_attrs(f, width: int, height: int, t: np.ndarray, num_pos: int, num_neg: int) -> None:
    f.attrs["sensor_resolution"] = np.array([height, width], dtype=np.int64)
    f.attrs["num_events"] = int(num_pos + num_neg)
    f.attrs["num_pos"] = int(num_pos)
    f.attrs["num_neg"] = int(num_neg)
    t0 = float(t[0]) if t.size else 0.0
    tk = float(t[-1]) if t.size else 0.0
    f.attrs["t0"] = t0
    f.attrs["tk"] = tk
    f.attrs["duration"] = tk - t0


def write_events_h5(path: str | os.PathLike, stream: EventStream) -> Path:
    """Write events in the common HDF5 layout (atomic).

    ``events/xs``, ``events/ys`` (uint16), ``events/ts`` (float64 s), ``events/ps`` (uint8,
    {0, 1}), attribute ``sensor_resolution = (height, width)``.
    """
    stream = _check_stream(stream, "write_events_h5")

    def write(tmp: Path) -> None:
        import h5py

        with h5py.File(tmp, "w") as f:
            g = f.create_group("events")
            g.create_dataset("xs", data=stream.x)
            g.create_dataset("ys", data=stream.y)
            g.create_dataset("ts", data=stream.t_s)
            g.create_dataset("ps", data=(stream.p > 0).astype(np.uint8))
            num_pos = int(np.count_nonzero(stream.p > 0))
            _h5_attrs(f, stream.width, stream.height, stream.t_s, num_pos, len(stream) - num_pos)

    return _atomic(path, write)


def write_events_txt(path: str | os.PathLike, stream: EventStream) -> Path:
    """Write events in the E2VID text format (atomic; gzip-compressed for a ``.gz`` name).

    Timestamps are written with 17 significant digits, so a float64 time reads back exactly.
    """
    stream = _check_stream(stream, "write_events_txt")
    import pandas as pd

    target = Path(path)

    def write(tmp: Path) -> None:
        opener = gzip.open if target.suffix == ".gz" else open
        with opener(tmp, "wt", newline="\n") as fh:
            fh.write(f"{stream.width} {stream.height}\n")
            table = pd.DataFrame({"t": stream.t_s, "x": stream.x, "y": stream.y,
                                  "p": (stream.p > 0).astype(np.uint8)})
            table.to_csv(fh, sep=" ", header=False, index=False, float_format="%.17g",
                         lineterminator="\n")

    return _atomic(target, write)


def write_events_npz(path: str | os.PathLike, stream: EventStream) -> Path:
    """Write events as ``.npz`` with arrays t_s, x, y, p, width, height (atomic, uncompressed)."""
    stream = _check_stream(stream, "write_events_npz")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez(fh, t_s=stream.t_s, x=stream.x, y=stream.y, p=stream.p,
                     width=np.int64(stream.width), height=np.int64(stream.height))

    return _atomic(path, write)


class EventsH5Writer:
    """Append event streams to a common-layout HDF5 file, for simulations too long for memory.

    The file is written under a temporary name beside ``path`` and moved into place by
    :meth:`close`; if the writer is discarded after an error (or used as a context manager that
    exits with an exception) the temporary file is removed and nothing appears at ``path``.

    Parameters
    ----------
    path : str or PathLike
        Target file.
    width, height : int
        Sensor size; every appended stream must have it.
    chunk_events : int
        HDF5 chunk length of the resizable datasets.

    Examples
    --------
    >>> with EventsH5Writer("events.h5", 400, 250) as out:   # doctest: +SKIP
    ...     for frames, times in chunks:
    ...         out.write(camera.capture(frames, times))
    """

    def __init__(self, path: str | os.PathLike, width: int, height: int, *, chunk_events: int = 1 << 16) -> None:
        import h5py

        self.path = Path(path)
        self.width = check_positive_int("EventsH5Writer width", width)
        self.height = check_positive_int("EventsH5Writer height", height)
        chunk = check_positive_int("chunk_events", chunk_events)
        if not self.path.parent.is_dir():
            raise SourceError(f"cannot write {self.path}: folder {self.path.parent} does not exist")
        self._tmp = _temp_path(self.path)
        self._file = h5py.File(self._tmp, "w")
        g = self._file.create_group("events")
        self._sets = {
            name: g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(chunk,))
            for name, dtype in (("xs", XY_DTYPE), ("ys", XY_DTYPE), ("ts", T_DTYPE), ("ps", np.uint8))
        }
        self.count = 0
        self._num_pos = 0
        self._t_first: float | None = None
        self._t_last: float | None = None

    def write(self, stream: EventStream) -> None:
        """Append ``stream``; its events must not precede those already written."""
        if self._file is None:
            raise InputError(f"EventsH5Writer({self.path}): write after close")
        stream = _check_stream(stream, "EventsH5Writer.write")
        if (stream.width, stream.height) != (self.width, self.height):
            raise InputError(
                f"EventsH5Writer.write: stream is {stream.width}x{stream.height}, the file is "
                f"{self.width}x{self.height}"
            )
        n = len(stream)
        if n == 0:
            return
        if self._t_last is not None and stream.t_s[0] < self._t_last:
            raise InputError(
                f"EventsH5Writer.write: the stream's first event at {stream.t_s[0]!r} s precedes the "
                f"last written event at {self._t_last!r} s (event {self.count - 1})"
            )
        start = self.count
        values = {"xs": stream.x, "ys": stream.y, "ts": stream.t_s, "ps": (stream.p > 0).astype(np.uint8)}
        for name, ds in self._sets.items():
            ds.resize((start + n,))
            ds[start:] = values[name]
        self.count = start + n
        self._num_pos += int(np.count_nonzero(stream.p > 0))
        if self._t_first is None:
            self._t_first = float(stream.t_s[0])
        self._t_last = float(stream.t_s[-1])

    def close(self) -> Path:
        """Finish the file and move it to ``path``."""
        if self._file is None:
            return self.path
        try:
            t = np.array([] if self._t_first is None else [self._t_first, self._t_last])
            _h5_attrs(self._file, self.width, self.height, t, self._num_pos, self.count - self._num_pos)
            self._file.close()
            self._file = None
            publish(self._tmp, self.path)
        except BaseException:
            self.abort()
            raise
        return self.path

    def abort(self) -> None:
        """Discard everything written; nothing appears at ``path``."""
        if self._file is not None:
            try:
                self._file.close()
            finally:
                self._file = None
        self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> "EventsH5Writer":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:  # an unclosed writer leaves no partial file behind
        try:
            if getattr(self, "_file", None) is not None:
                self.abort()
        except Exception:
            pass
