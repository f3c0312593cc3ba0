"""The representation modules T_spike and T_event: a sample's streams -> 32 channels each.

Both are pure NumPy functions of a :class:`~neuspike.sample.Sample` giving float32 (32, H, W).
Candidates (chosen by the ablation recorded in :mod:`neuspike.nets`):

T_spike
    ``"counts"``: the 256-plane window in 32 groups of 8 consecutive planes; each channel is the
    group's spike count divided by (8 * gain), i.e. a radiance estimate per 0.4 ms (TFP over 8 planes).
    ``"counts_interval"``: 16 groups of 16 planes as above (16 channels) plus 16 channels of the
    interval estimate ``1 / (ISI * gain)`` at the 16 group centres, where ISI is the distance from the
    last spike before the centre to the first one at or after it (TFI); a side without a spike in the
    window counts as a spike one window length away.
T_event
    ``"voxel"``: the E2VID voxel grid of the window's events, 32 bins, non-zero entries normalised to
    mean 0 / std 1 (:func:`neuspike.representations.voxel_grid`).
    ``"contrast"``: signed event counts in 32 equal time bins times the contrast threshold: the
    log-intensity change of each pixel in each bin (no normalisation, so its scale is physical).

The gain (expected spikes per plane per unit radiance) comes from ``sample.spikes.gain``; for a real
recording without a gain, :func:`spike_gain` takes the one that maps the 99.5th percentile of the
window's spike rate to radiance 1 and says so (``"estimated"``).
"""

from __future__ import annotations

import numpy as np

from neuspike.errors import InputError
from neuspike.representations import spike_bins, voxel_grid
from neuspike.sample import Sample

__all__ = ["CHANNELS", "EVENT_REPRESENTATIONS", "SPIKE_REPRESENTATIONS", "event_representation",
           "spike_gain", "spike_representation"]

#: Channels of either representation (the supplement's 32).
CHANNELS = 32
SPIKE_REPRESENTATIONS = ("counts", "counts_interval")
EVENT_REPRESENTATIONS = ("voxel", "contrast")
#: Contrast threshold assumed by ``"contrast"`` when neither the sample nor the caller gives one.
NOMINAL_EVENT_THRESHOLD = 0.2


def spike_gain(sample: Sample) -> tuple[float, str]:
    """(gain, how): the sample's gain (``"known"``) or an estimate from the data (``"estimated"``)."""
    spikes = sample.spikes
    if spikes is None:
        raise InputError("spike representation: the sample has no spikes")
    if spikes.gain is not None and spikes.gain > 0:
        return float(spikes.gain), "known"
    rate = spikes.planes.mean(axis=0, dtype=np.float32)
    top = float(np.percentile(rate, 99.5))
    return (top if top > 0 else 1.0 / spikes.num_planes), "estimated"


def _planes(sample: Sample) -> np.ndarray:
    if sample.spikes is None:
        raise InputError("spike representation: the sample has no spikes")
    planes = sample.spikes.planes
    if planes.shape[0] % CHANNELS:
        raise InputError(f"spike representation: {planes.shape[0]} planes is not a multiple of {CHANNELS}")
    return planes


# Index (0 = most significant) of the first and the last set bit of every byte value (0 for 0, unused).
_FIRST_BIT = np.array([next((j for j in range(8) if b >> (7 - j) & 1), 0) for b in range(256)], np.int32)
_LAST_BIT = np.array([next((j for j in range(7, -1, -1) if b >> (7 - j) & 1), 0) for b in range(256)], np.int32)


def interval_rate(planes: np.ndarray, centres: np.ndarray, *, group: int | None = None) -> np.ndarray:
    """``1 / ISI`` at each plane index of ``centres``: float32 (len(centres), H, W), spikes per plane.

    ISI at centre c is ``next(c) - prev(c)`` with ``prev`` the last spike plane < c and ``next`` the
    first spike plane >= c; missing sides count as a spike one window length (T) outside the window.
    The planes are scanned in groups of ``group`` planes (default: the greatest common divisor of the
    centres and T, so every centre lies on a group boundary): each group's first and last spike,
    then running extremes over the groups.
    """
    t, h, w = planes.shape
    centres = np.asarray(centres, dtype=np.int64)
    if group is None:
        group = int(np.gcd.reduce(np.concatenate([centres[centres > 0], [t]])))
    n = t // group
    u8 = np.ascontiguousarray(planes).view(np.uint8).reshape(n, group, h, w)
    offsets = (np.arange(n, dtype=np.int32) * group)[:, None, None]
    if group == 8:  # each group's 8 planes as one byte (plane 0 = most significant bit): table look-ups
        byte = np.zeros((n, h, w), np.uint8)
        for j in range(8):
            byte |= u8[:, j] << np.uint8(7 - j)
        has = byte != 0
        first = np.where(has, _FIRST_BIT[byte] + offsets, 2 * t)
        last = np.where(has, _LAST_BIT[byte] + offsets, -t)
    else:
        has = u8.any(axis=1)
        first = np.where(has, u8.argmax(axis=1).astype(np.int32) + offsets, 2 * t)
        last = np.where(has, group - 1 - u8[:, ::-1].argmax(axis=1).astype(np.int32) + offsets, -t)
    # prev_before[k]: last spike in groups < k; next_from[k]: first spike in groups >= k
    prev_before = np.concatenate([np.full((1, h, w), -t, np.int32), np.maximum.accumulate(last, axis=0)])
    next_from = np.concatenate([np.minimum.accumulate(first[::-1], axis=0)[::-1], np.full((1, h, w), 2 * t, np.int32)])
    k = centres // group
    return (1.0 / (next_from[k] - prev_before[k]).astype(np.float32)).astype(np.float32)


def spike_representation(sample: Sample, kind: str) -> np.ndarray:
    """T_spike of ``sample``: float32 (32, H, W), radiance units (module docstring)."""
    planes = _planes(sample)
    gain, _ = spike_gain(sample)
    t = planes.shape[0]
    if kind == "counts":
        return spike_bins(planes, CHANNELS) / np.float32(t / CHANNELS * gain)
    if kind == "counts_interval":
        half = CHANNELS // 2
        counts = spike_bins(planes, half) / np.float32(t / half * gain)
        centres = (np.arange(half) * (t // half) + t // half // 2).astype(np.int64)
        return np.concatenate([counts, interval_rate(planes, centres) / np.float32(gain)])
    raise InputError(f"spike representation: expected one of {SPIKE_REPRESENTATIONS}, got {kind!r}")


def event_representation(sample: Sample, kind: str, *, event_threshold: float | None = None) -> np.ndarray:
    """T_event of ``sample``'s window events: float32 (32, H, W) (module docstring)."""
    if sample.events is None:
        raise InputError("event representation: the sample has no events (this method needs events)")
    events = sample.window_events()
    t0, t1 = sample.window_start_s, sample.window_end_s
    h, w = sample.height, sample.width
    if kind == "voxel":
        return voxel_grid(events, bins=CHANNELS, t0_s=t0, t1_s=t1, height=h, width=w, normalize=True)
    if kind == "contrast":
        theta = event_threshold or sample.event_threshold or NOMINAL_EVENT_THRESHOLD
        if not len(events):
            return np.zeros((CHANNELS, h, w), np.float32)
        b = np.clip(((events.t_s - t0) / max(t1 - t0, 1e-12) * CHANNELS).astype(np.int64), 0, CHANNELS - 1)
        flat = (b * h + events.y.astype(np.int64)) * w + events.x.astype(np.int64)
        out = np.bincount(flat, weights=events.p.astype(np.float64), minlength=CHANNELS * h * w)
        return (out * theta).astype(np.float32).reshape(CHANNELS, h, w)
    raise InputError(f"event representation: expected one of {EVENT_REPRESENTATIONS}, got {kind!r}")
