"""What a reconstruction method receives: a :class:`Sample`.

A sample is one reconstruction target: the spike window around the key instant, the events of the
same interval plus earlier history (for recurrent methods to warm up on), and the sensor metadata.
The ground truth travels with it for the harness's evaluation only; methods must never read it
(a test feeds samples whose ground truth is poisoned).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from neuspike.errors import InputError
from neuspike.streams import EventStream, SpikeStream


@dataclass(frozen=True, eq=False)
class Sample:
    """One reconstruction target.

    Parameters
    ----------
    height, width : int
        Output size (H, W).
    key_time_s : float
        Sensor time of the instant to reconstruct (the window's centre for simulated data).
    window_start_s, window_end_s : float
        The reconstruction window in sensor time (the spike window's span when spikes are present).
    spikes : SpikeStream or None
        The spike planes of the window. ``spikes.gain`` is the expected spikes per plane per unit
        radiance when known (simulated data), ``None`` for real recordings.
    events : EventStream or None
        Events with ``t < window_end_s``: those of the window and, before ``window_start_s``, the
        history that recurrent methods warm up on.
    event_threshold : float or None
        The nominal contrast threshold (log units) of the event camera, when known.
    ground_truth : ndarray float32 (H, W) or None
        Radiance at ``key_time_s`` in [0, 1] units; for evaluation only.
    meta : dict
        Provenance (scene, condition, source files).
    """

    height: int
    width: int
    key_time_s: float
    window_start_s: float
    window_end_s: float
    spikes: SpikeStream | None = None
    events: EventStream | None = None
    event_threshold: float | None = None
    ground_truth: np.ndarray | None = field(default=None, repr=False)
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.spikes is None and self.events is None:
            raise InputError("Sample: needs spikes, events or both")
        for name, stream in (("spikes", self.spikes), ("events", self.events)):
            if stream is not None and (stream.height, stream.width) != (self.height, self.width):
                raise InputError(
                    f"Sample.{name}: sensor size {stream.width}x{stream.height} does not match "
                    f"the sample's {self.width}x{self.height}"
                )
        if not self.window_start_s <= self.key_time_s <= self.window_end_s:
            raise InputError(
                f"Sample: key time {self.key_time_s} s lies outside the window "
                f"[{self.window_start_s}, {self.window_end_s}] s"
            )
        if self.ground_truth is not None and np.shape(self.ground_truth) != (self.height, self.width):
            raise InputError(
                f"Sample.ground_truth: expected shape {(self.height, self.width)}, got {np.shape(self.ground_truth)}"
            )

    @property
    def modalities(self) -> frozenset[str]:
        """The inputs present: a subset of {"spikes", "events"}."""
        present = set()
        if self.spikes is not None:
            present.add("spikes")
        if self.events is not None:
            present.add("events")
        return frozenset(present)

    @property
    def key_plane(self) -> int:
        """Index, within ``spikes``, of the plane containing the key instant."""
        if self.spikes is None:
            raise InputError("Sample has no spikes")
        # a key time on a plane boundary belongs to the plane that starts there; the small
        # tolerance keeps float rounding (k / rate * rate = k - 1e-12) from moving it back
        j = int(np.floor((self.key_time_s - self.spikes.start_s) * self.spikes.plane_rate_hz + 1e-6))
        return min(max(j, 0), self.spikes.num_planes - 1)

    def window_events(self) -> EventStream:
        """The events of the reconstruction window only (no history)."""
        if self.events is None:
            raise InputError("Sample has no events")
        return self.events.between(self.window_start_s, self.window_end_s)

    def history_events(self) -> EventStream:
        """The events before the window (warm-up history)."""
        if self.events is None:
            raise InputError("Sample has no events")
        t0 = self.events.t_s[0] if len(self.events) else self.window_start_s
        return self.events.between(min(t0, self.window_start_s), self.window_start_s)

    def without_ground_truth(self) -> "Sample":
        """The same sample with the ground truth removed."""
        return replace(self, ground_truth=None)
