"""The two stream types every part of the suite exchanges.

``SpikeStream`` holds binary planes of a spike camera; ``EventStream`` holds the events of an event
camera. Both validate at construction, so code that receives one can rely on its invariants:

* spikes: ``planes`` is a C-contiguous ``bool`` array (T, H, W); plane ``j`` integrates the sensor
  time interval ``[start_s + j / plane_rate_hz, start_s + (j + 1) / plane_rate_hz)``.
* events: ``t_s`` float64 seconds, sorted non-decreasing; ``x`` in ``[0, width)``, ``y`` in
  ``[0, height)`` (uint16); ``p`` in {-1, +1} (int8). Row 0 is the top row of the image.

The event dtypes are defined once here (``T_DTYPE``, ``XY_DTYPE``, ``P_DTYPE``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from neuspike.utils.checks import check_nonnegative, check_positive, check_positive_int
from neuspike.errors import InputError

T_DTYPE = np.float64
XY_DTYPE = np.uint16
P_DTYPE = np.int8

#: Vidar spike camera plane rate (planes per second).
VIDAR_PLANE_RATE_HZ = 20_000.0
#: Vidar sensor size as (width, height).
VIDAR_SIZE = (400, 250)


@dataclass(frozen=True, eq=False)
class SpikeStream:
    """Binary spike planes of an integrate-and-fire camera.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
        ``True`` where the pixel fired during that plane. uint8/int arrays of 0 and 1 are accepted
        and converted; any other value raises.
    plane_rate_hz : float
        Planes per second (20,000 for Vidar).
    start_s : float
        Sensor time at the start of plane 0, in seconds.
    gain : float or None
        Expected spikes per plane per unit radiance (``L / threshold`` for simulated data);
        ``None`` when unknown (real recordings).
    threshold : float or None
        The integrate-and-fire threshold, when known.
    dark_rate : float or None
        The sensor's dark level: spikes per plane that a pixel fires in total darkness, averaged
        over the pixels (what a capped calibration measures; 0 for a simulated camera without dark
        current). ``None`` when unknown (real recordings unless given).
    meta : dict
        Free-form provenance (stages that ran, source file, ...).
    """

    planes: np.ndarray
    plane_rate_hz: float = VIDAR_PLANE_RATE_HZ
    start_s: float = 0.0
    gain: float | None = None
    threshold: float | None = None
    dark_rate: float | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        planes = np.asarray(self.planes)
        if planes.ndim != 3:
            raise InputError(f"SpikeStream.planes: expected shape (T, H, W), got {planes.shape}")
        if planes.dtype != np.bool_:
            if not (np.issubdtype(planes.dtype, np.integer) or np.issubdtype(planes.dtype, np.floating)):
                raise InputError(f"SpikeStream.planes: expected bool or 0/1 integers, got dtype {planes.dtype}")
            if planes.size and not np.isin(planes, (0, 1)).all():
                raise InputError("SpikeStream.planes: expected only 0 and 1 values")
            planes = planes.astype(np.bool_)
        object.__setattr__(self, "planes", np.ascontiguousarray(planes))
        object.__setattr__(self, "plane_rate_hz", check_positive("plane_rate_hz", self.plane_rate_hz))
        start = float(self.start_s)
        if not np.isfinite(start):
            raise InputError(f"start_s: expected a finite time, got {self.start_s!r}")
        object.__setattr__(self, "start_s", start)
        if self.gain is not None:
            object.__setattr__(self, "gain", check_positive("gain", self.gain))
        if self.threshold is not None:
            object.__setattr__(self, "threshold", check_positive("threshold", self.threshold))
        if self.dark_rate is not None:
            object.__setattr__(self, "dark_rate", check_nonnegative("dark_rate", self.dark_rate))

    @property
    def shape(self) -> tuple[int, int, int]:
        """(T, H, W)."""
        return self.planes.shape  # type: ignore[return-value]

    @property
    def num_planes(self) -> int:
        return self.planes.shape[0]

    @property
    def height(self) -> int:
        return self.planes.shape[1]

    @property
    def width(self) -> int:
        return self.planes.shape[2]

    @property
    def duration_s(self) -> float:
        return self.num_planes / self.plane_rate_hz

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def plane_centres_s(self) -> np.ndarray:
        """Sensor time of the centre of each plane's integration interval, float64 (T,)."""
        return self.start_s + (np.arange(self.num_planes, dtype=np.float64) + 0.5) / self.plane_rate_hz

    def plane_at(self, time_s: float) -> int:
        """Index of the plane whose integration interval contains ``time_s``."""
        j = int(np.floor((float(time_s) - self.start_s) * self.plane_rate_hz))
        if not 0 <= j < self.num_planes:
            raise InputError(
                f"time {time_s!r} s lies outside the stream [{self.start_s}, {self.end_s}) s"
            )
        return j

    def window(self, start: int, stop: int) -> "SpikeStream":
        """Planes ``[start, stop)`` as a new stream with its start time shifted accordingly."""
        if not 0 <= start < stop <= self.num_planes:
            raise InputError(f"window [{start}, {stop}) is outside the stream's 0..{self.num_planes} planes")
        return SpikeStream(
            self.planes[start:stop],
            plane_rate_hz=self.plane_rate_hz,
            start_s=self.start_s + start / self.plane_rate_hz,
            gain=self.gain,
            threshold=self.threshold,
            dark_rate=self.dark_rate,
            meta=dict(self.meta),
        )


def _as_1d(name: str, value: Any, dtype: Any) -> np.ndarray:
    a = np.asarray(value)
    if a.ndim != 1:
        raise InputError(f"EventStream.{name}: expected a 1-D array, got shape {a.shape}")
    return a


@dataclass(frozen=True, eq=False)
class EventStream:
    """Events of a DVS-style camera, sorted by time.

    Parameters
    ----------
    t_s : array (N,)
        Timestamps in seconds (stored as float64), sorted non-decreasing.
    x, y : array (N,)
        Pixel column and row (stored as uint16); row 0 is the top row.
    p : array (N,)
        Polarity, -1 (OFF) or +1 (ON) (stored as int8). {0, 1} input must be converted by the
        reader that knows the convention; this constructor rejects 0.
    width, height : int
        Sensor size.
    meta : dict
        Free-form provenance.
    """

    t_s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    width: int
    height: int
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        width = check_positive_int("EventStream.width", self.width)
        height = check_positive_int("EventStream.height", self.height)
        t = _as_1d("t_s", self.t_s, T_DTYPE)
        x = _as_1d("x", self.x, XY_DTYPE)
        y = _as_1d("y", self.y, XY_DTYPE)
        p = _as_1d("p", self.p, P_DTYPE)
        n = t.shape[0]
        if not (x.shape[0] == y.shape[0] == p.shape[0] == n):
            raise InputError(
                f"EventStream: t_s, x, y, p must have equal lengths, got {n}, {x.shape[0]}, {y.shape[0]}, {p.shape[0]}"
            )
        if n:
            t = t.astype(T_DTYPE, copy=False)
            if not np.isfinite(t).all():
                raise InputError("EventStream.t_s: expected finite timestamps, found NaN or infinity")
            if (np.diff(t) < 0).any():
                first = int(np.argmax(np.diff(t) < 0))
                raise InputError(
                    f"EventStream.t_s: timestamps must be sorted; event {first + 1} at {t[first + 1]!r} s "
                    f"comes after {t[first]!r} s"
                )
            for name, arr, hi in (("x", x, width), ("y", y, height)):
                if not (np.issubdtype(arr.dtype, np.integer) or (arr == np.round(arr)).all()):
                    raise InputError(f"EventStream.{name}: expected integer pixel coordinates")
                lo_v, hi_v = arr.min(), arr.max()
                if lo_v < 0 or hi_v >= hi:
                    raise InputError(
                        f"EventStream.{name}: coordinates must lie in [0, {hi}), got range [{lo_v}, {hi_v}]"
                    )
            if not np.isin(p, (-1, 1)).all():
                raise InputError(
                    f"EventStream.p: polarity must be -1 or +1, got values {np.unique(p)[:5].tolist()}"
                )
        object.__setattr__(self, "t_s", np.ascontiguousarray(t, dtype=T_DTYPE))
        object.__setattr__(self, "x", np.ascontiguousarray(x, dtype=XY_DTYPE))
        object.__setattr__(self, "y", np.ascontiguousarray(y, dtype=XY_DTYPE))
        object.__setattr__(self, "p", np.ascontiguousarray(p, dtype=P_DTYPE))
        object.__setattr__(self, "width", width)
        object.__setattr__(self, "height", height)

    @classmethod
    def trusted(cls, t_s: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int,
                meta: dict[str, Any] | None = None) -> "EventStream":
        """Build a stream from arrays whose producer guarantees the invariants (sorted, in range).

        Skips the O(N) value checks of the constructor (a large share of a simulator's time on
        millions of events); dtypes and lengths are still enforced. Readers of user files must use
        the validating constructor.
        """
        arrays = (np.ascontiguousarray(t_s, dtype=T_DTYPE), np.ascontiguousarray(x, dtype=XY_DTYPE),
                  np.ascontiguousarray(y, dtype=XY_DTYPE), np.ascontiguousarray(p, dtype=P_DTYPE))
        if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1:
            raise InputError(f"EventStream.trusted: arrays must be 1-D of equal length, got {[a.shape for a in arrays]}")
        stream = object.__new__(cls)
        for name, value in zip(("t_s", "x", "y", "p"), arrays):
            object.__setattr__(stream, name, value)
        object.__setattr__(stream, "width", check_positive_int("EventStream.width", width))
        object.__setattr__(stream, "height", check_positive_int("EventStream.height", height))
        object.__setattr__(stream, "meta", dict(meta or {}))
        return stream

    @classmethod
    def empty(cls, width: int, height: int, meta: dict[str, Any] | None = None) -> "EventStream":
        """A stream with no events."""
        z = np.zeros(0)
        return cls(z, z, z, z, width, height, dict(meta or {}))

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return self.width, self.height

    def between(self, t0_s: float, t1_s: float) -> "EventStream":
        """Events with ``t0_s <= t < t1_s`` (a view, found by binary search; a slice of a valid stream is
        valid, so it is not checked again: O(log N), not O(N), however long the stream)."""
        check_nonnegative("duration", float(t1_s) - float(t0_s))
        i0, i1 = np.searchsorted(self.t_s, [t0_s, t1_s], side="left")
        return EventStream.trusted(
            self.t_s[i0:i1], self.x[i0:i1], self.y[i0:i1], self.p[i0:i1],
            self.width, self.height, dict(self.meta),
        )

    @staticmethod
    def concatenate(streams: "list[EventStream]") -> "EventStream":
        """Join streams of the same sensor that follow each other in time."""
        if not streams:
            raise InputError("EventStream.concatenate: expected at least one stream")
        w, h = streams[0].width, streams[0].height
        for s in streams:
            if (s.width, s.height) != (w, h):
                raise InputError(f"EventStream.concatenate: sizes differ, {(w, h)} vs {(s.width, s.height)}")
        return EventStream(
            np.concatenate([s.t_s for s in streams]),
            np.concatenate([s.x for s in streams]),
            np.concatenate([s.y for s in streams]),
            np.concatenate([s.p for s in streams]),
            w, h, dict(streams[0].meta),
        )
