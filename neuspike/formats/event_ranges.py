"""Event files read by index range: what a recording opener streams events from.

:func:`open_event_source` opens an event file and returns a source with ``count``, ``width``,
``height``, ``time_of(i)``, ``index(t_s)`` (the first event at or after ``t_s``), ``read(i0, i1)``
and ``close()``. HDF5 files (the common and the PKU-Vidar-DVS layouts) are searched by bisection
over the timestamps and sliced; text, ``.npz`` and AEDAT4 files have no index and are read once,
whole, by :func:`neuspike.formats.event_readers.read_events`.

Every range read is validated by the same function as a whole-file read (:func:`read_events`): the
same layouts are accepted, with the same checks (1-D arrays of one length, sorted finite
timestamps, whole coordinates inside the sensor, polarities in {0, 1} or {-1, +1}), so that a range
of a file gives exactly the events a whole read would give, or refuses where it would refuse.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from neuspike.errors import FormatError
from neuspike.formats.event_readers import (
    DAVIS346_SIZE, H5_KEYS, PKU_FIELDS, check_side, events_from_arrays, read_events,
)
from neuspike.streams import EventStream

__all__ = ["open_event_source"]

_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


class WholeEvents:
    """An event file without an index: read once, sliced in memory."""

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        kwargs = {} if width is None else {"width": width, "height": height}
        self.stream = read_events(path, **kwargs)
        self.width, self.height = self.stream.width, self.stream.height
        self.count = len(self.stream)

    def time_of(self, i: int) -> float:
        return float(self.stream.t_s[i])

    def index(self, t_s: float) -> int:
        return int(np.searchsorted(self.stream.t_s, t_s, side="left"))

    def read(self, i0: int, i1: int) -> EventStream:
        s = self.stream
        return EventStream.trusted(s.t_s[i0:i1], s.x[i0:i1], s.y[i0:i1], s.p[i0:i1], s.width, s.height)

    def close(self) -> None:
        pass


class H5Events:
    """An HDF5 event file (common or PKU-Vidar-DVS layout) read by index range.

    The layout is checked when the file is opened (datasets or fields present, 1-D, of one length);
    the first index at or after a time is found by bisection over the timestamp dataset (a few dozen
    element reads); a range is read with one slice per dataset and validated as the whole file is.
    The common layout's polarity convention ({0, 1} or {-1, +1}) is decided by the values, as for a
    whole read: a file whose ranges show both a 0 and a -1 is refused.
    """

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        import h5py

        self.path = path
        try:
            self.file = h5py.File(path, "r")
        except OSError as exc:
            raise FormatError(f"{path}: not a readable HDF5 file ({exc})") from None
        try:
            self._open_layout(h5py, width, height)
        except BaseException:
            self.file.close()
            raise
        self._seen: set[int] = set()  # polarity values met so far (common layout)

    def _open_layout(self, h5py: Any, width: int | None, height: int | None) -> None:
        path, node = self.path, self.file.get("events")
        declared = None
        if isinstance(node, h5py.Group):
            missing = [k for k in H5_KEYS if not isinstance(node.get(k), h5py.Dataset)]
            if missing:
                raise FormatError(f"{path}: the group 'events' lacks dataset(s) "
                                  f"{', '.join('events/' + k for k in missing)}")
            self.layout = "common"
            self.xs, self.ys, self.ts, self.ps = (node[k] for k in H5_KEYS)
            shapes = {k: node[k].shape for k in H5_KEYS}
            if any(len(s) != 1 for s in shapes.values()) or len({s[0] for s in shapes.values()}) != 1:
                raise FormatError(f"{path}: expected events/xs, ys, ts, ps as 1-D arrays of one length, got "
                                  + ", ".join(f"{k} {s}" for k, s in shapes.items()))
            if "sensor_resolution" in self.file.attrs:
                res = np.asarray(self.file.attrs["sensor_resolution"]).ravel()
                if res.size != 2:
                    raise FormatError(f"{path}: attribute sensor_resolution should be (height, width), "
                                      f"got {res.tolist()!r}")
                declared = (check_side(path, res[1], "sensor_resolution width"),
                            check_side(path, res[0], "sensor_resolution height"))
            self.divisor = 1.0
            self.count = int(self.ts.shape[0])
        elif isinstance(node, h5py.Dataset) and node.dtype.names is not None:
            missing = [k for k in PKU_FIELDS if k not in node.dtype.names]
            if missing:
                raise FormatError(f"{path}: dataset 'events' lacks field(s) {missing}; the PKU-Vidar-DVS layout "
                                  f"has {', '.join(PKU_FIELDS)}, found {list(node.dtype.names)}")
            if node.ndim != 1:
                raise FormatError(f"{path}: expected the dataset 'events' to be 1-D, got shape {node.shape}")
            if node.dtype["timestamp"].kind not in "iuf":
                raise FormatError(f"{path}: expected numeric timestamps, got dtype {node.dtype['timestamp']}")
            self.layout = "pku"
            self.node = node
            declared = DAVIS346_SIZE
            self.divisor = 1e6  # microseconds, divided as the whole-file reader divides
            self.count = int(node.shape[0])
        else:
            raise FormatError(f"{path}: neither the common HDF5 event layout (events/xs, ys, ts, ps) nor the "
                              f"PKU-Vidar-DVS one (a compound dataset 'events' with {', '.join(PKU_FIELDS)})")
        if width is not None:
            self.width, self.height = int(width), int(height)
        elif declared is not None:
            self.width, self.height = declared
        else:
            raise FormatError(f"{path}: no sensor_resolution attribute (height, width) in the file; give the size")

    def time_of(self, i: int) -> float:
        if self.layout == "common":
            return float(self.ts[i])
        return float(self.node[i]["timestamp"]) / self.divisor

    def index(self, t_s: float) -> int:
        """The first event index with ``t >= t_s`` (``count`` when none)."""
        lo, hi = 0, self.count
        while lo < hi:
            mid = (lo + hi) // 2
            if self.time_of(mid) < t_s:
                lo = mid + 1
            else:
                hi = mid
        return lo

    def read(self, i0: int, i1: int) -> EventStream:
        meta = {"source": str(self.path)}
        try:
            if self.layout == "common":
                p = np.asarray(self.ps[i0:i1])
                self._seen.update(int(v) for v in np.unique(p[(p == 0) | (p == -1)]))
                if {0, -1} <= self._seen:
                    raise FormatError(f"{self.path}: polarities mix the {{0, 1}} and the {{-1, +1}} conventions")
                return events_from_arrays(self.path, self.ts[i0:i1], self.xs[i0:i1], self.ys[i0:i1], p,
                                           self.width, self.height, meta, polarity="01" if 0 in self._seen else "any")
            rec = self.node[i0:i1]
            t = rec["timestamp"].astype(np.float64) / self.divisor
            return events_from_arrays(self.path, t, rec["x"], rec["y"], rec["polarity"], self.width, self.height,
                                       meta, polarity="01")
        except FormatError as exc:
            raise FormatError(f"{exc} (counted from event {i0} of the file)") from None

    def close(self) -> None:
        self.file.close()


def open_event_source(path: Path, width: int | None, height: int | None) -> WholeEvents | H5Events:
    """The range reader of the event file ``path`` (HDF5 by range, any other format whole).

    ``width`` and ``height`` (both or neither) override the size the file declares.
    """
    is_h5 = path.suffix.lower() in (".h5", ".hdf5")
    if not is_h5:
        with open(path, "rb") as fh:
            is_h5 = fh.read(8) == _HDF5_MAGIC
    return (H5Events if is_h5 else WholeEvents)(path, width, height)
