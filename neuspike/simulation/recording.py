"""What a simulation gives: the sensor configuration and the recording of one window."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np

from neuspike.utils.checks import check_positive, check_positive_int
from neuspike.conditions import EVENTS, SPIKES
from neuspike.errors import InputError
from neuspike.sample import Sample
from neuspike.streams import VIDAR_PLANE_RATE_HZ, EventStream, SpikeStream

#: Bump when a change alters simulated bytes for the same inputs (part of every cache key).
SIMULATOR_VERSION = "1"
#: Event history simulated before a window for recurrent methods to warm up on, in window durations
#: (the default of the sweeps and the timing benchmark alike).
DEFAULT_HISTORY_WINDOWS = 5.0
MODALITIES = (SPIKES, EVENTS)


def check_modalities(modalities: Iterable[str]) -> frozenset[str]:
    """``modalities`` as a set, checked to be a non-empty subset of :data:`MODALITIES`."""
    mods = frozenset(modalities)
    if not mods or not mods <= set(MODALITIES):
        raise InputError(f"modalities must be a non-empty subset of {MODALITIES}, got {sorted(mods)}")
    return mods


@dataclass(frozen=True)
class SensorConfig:
    """Sensor and timing parameters shared by both cameras.

    Parameters
    ----------
    planes : int
        Spike planes per window (T).
    plane_rate_hz : float
        Spike planes per second of sensor time (Vidar: 20,000).
    upsampled_rate_hz : float
        Scene frames per second of the upsampled source (the paper: 22,500).
    spike_threshold : float
        Integrate-and-fire threshold phi (radiance 1 at L = 1 adds 1 per plane).
    event_threshold : float
        Nominal DVS contrast threshold, ON and OFF, in log units.
    """

    planes: int = 256
    plane_rate_hz: float = VIDAR_PLANE_RATE_HZ
    upsampled_rate_hz: float = 22_500.0
    spike_threshold: float = 1.0
    event_threshold: float = 0.2

    def __post_init__(self) -> None:
        check_positive_int("planes", self.planes)
        for name in ("plane_rate_hz", "upsampled_rate_hz", "spike_threshold", "event_threshold"):
            check_positive(name, getattr(self, name))

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True, eq=False)
class Recording:
    """What one simulated window gives.

    ``ground_truth`` is the radiance at the key instant, float32 (H, W) (may exceed 1 in HDR
    scenes); ``key_time_s`` and the window are in sensor time. ``events`` includes the warm-up
    history (``t < window_start_s``) when one was simulated. ``static_masks`` maps each simulated
    modality to a bool (H, W) mask of the pixels whose radiance was the same at every instant that
    camera saw (the spike camera: the window's frames; the event camera: its history too); it is
    empty for recordings cached before masks were kept.
    """

    spikes: SpikeStream | None
    events: EventStream | None
    ground_truth: np.ndarray
    key_time_s: float
    window_start_s: float
    window_end_s: float
    meta: dict[str, Any] = field(default_factory=dict)
    static_masks: Mapping[str, np.ndarray] = field(default_factory=dict)

    def static_region(self) -> np.ndarray | None:
        """Pixels static at every instant any of the recording's cameras saw: bool (H, W), or None when unknown.

        The same mask as :func:`neuspike.simulation.window.static_region` for the recording's
        modalities and history, without rendering the scene again.
        """
        present = [m for m in MODALITIES if getattr(self, m) is not None]
        if not present or any(m not in self.static_masks for m in present):
            return None
        mask = np.ones(self.ground_truth.shape, dtype=bool)
        for m in present:
            mask &= np.asarray(self.static_masks[m], dtype=bool)
        return mask

    def to_sample(self) -> Sample:
        """The recording as a method's :class:`~neuspike.sample.Sample` (ground truth clipped to [0, 1])."""
        h, w = self.ground_truth.shape
        return Sample(
            height=h,
            width=w,
            key_time_s=self.key_time_s,
            window_start_s=self.window_start_s,
            window_end_s=self.window_end_s,
            spikes=self.spikes,
            events=self.events,
            event_threshold=self.meta.get("event_threshold"),
            ground_truth=np.clip(self.ground_truth, 0.0, 1.0).astype(np.float32),
            meta=dict(self.meta),
        )
