"""Event files: the writers (HDF5 in the common layout, E2VID text, NumPy ``.npz``; see
:mod:`neuspike.formats.event_readers` for each layout). All are atomic: they write a temporary file
in the target folder and move it into place only when complete.
"""

from __future__ import annotations

import gzip
import os
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.utils.atomic import publish, replacing, temp_beside
from neuspike.utils.checks import check_positive_int
from neuspike.errors import InputError, SourceError
from neuspike.streams import T_DTYPE, XY_DTYPE, EventStream

__all__ = ["EventsH5Writer", "write_events_h5", "write_events_npz", "write_events_txt"]


def _check_stream(stream: Any, where: str) -> EventStream:
    if not isinstance(stream, EventStream):
        raise InputError(f"{where}: expected an EventStream, got {type(stream).__name__}")
    return stream


def _atomic(path: str | os.PathLike, write) -> Path:
    """Run ``write(temp_path)`` then move the temporary file onto ``path``; no partial files."""
    target = Path(path)
    if not target.parent.is_dir():
        raise SourceError(f"cannot write {target}: folder {target.parent} does not exist")
    with replacing(target) as tmp:
        write(Path(tmp))
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
        fd, tmp = temp_beside(self.path)
        os.close(fd)
        self._tmp = Path(tmp)
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
