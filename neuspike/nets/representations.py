"""The representation modules T_spike and T_event: a sample's streams -> 32 channels each.

Both are pure NumPy functions of a :class:`~neuspike.sample.Sample` giving float32 (32, H, W).
Candidates (chosen by the ablation recorded in :mod:`neuspike.nets`):

T_spike
    ``"counts"``: the 256-plane window in 32 groups of 8 consecutive planes; each channel is the
    group's spike count divided by (8 * gain), i.e. a radiance estimate per 0.4 ms (TFP over 8 planes).
    Another window length T >= 32 is split into near-equal groups (rates per plane, so the scale is
    the same).
    ``"counts_interval"``: 16 groups of 16 planes as above (16 channels) plus 16 channels of the
    interval estimate ``1 / (ISI * gain)`` at the 16 group centres, where ISI is the distance from the
    last spike before the centre to the first one at or after it (TFI); a side without a spike in the
    window counts as a spike one window length away.
T_event
    ``"voxel"``: the E2VID voxel grid of the window's events, 32 bins, non-zero entries normalised to
    mean 0 / std 1 (:func:`neuspike.methods.representations.voxel_grid`).
    ``"contrast"``: signed event counts in 32 equal time bins times the contrast threshold: the
    log-intensity change of each pixel in each bin (no normalisation, so its scale is physical).

The gain (expected spikes per plane per unit radiance) comes from ``sample.spikes.gain``; for a real
recording without a gain, :func:`spike_gain` takes the one that maps the 99.5th percentile of the
window's spike rate to radiance 1 and says so (``"estimated"``).

Speed: ``backend="auto"`` (default) computes ``counts``, ``counts_interval`` and ``contrast`` with
compiled kernels (:mod:`neuspike.nets.representation_kernels`: one pass over the planes, rows in
parallel, and one over the events) where numba runs, ``"numpy"`` with the NumPy reference below;
both give the same arrays bit for bit. In a video, :class:`neuspike.nets.sliding.SlidingRepresentation`
bins each plane and event once and assembles every frame from bins shared with its neighbours.
"""

from __future__ import annotations

import numpy as np

from neuspike.errors import InputError
from neuspike.methods.representations import voxel_grid
from neuspike.sample import Sample
from neuspike.utils.parallel import KERNEL_LOCK, resolve_backend

try:  # numba is a dependency, but the representations must still work where it cannot be imported
    from neuspike.nets import representation_kernels as _kernels
except ImportError:  # pragma: no cover - exercised only without numba
    _kernels = None

__all__ = ["CHANNELS", "EVENT_REPRESENTATIONS", "KEY_CHANNELS", "KEY_ESTIMATES", "KEY_SIDE",
           "SPIKE_REPRESENTATIONS", "as_u8", "event_representation", "key_intervals", "key_representation",
           "spike_gain", "spike_quantum", "spike_representation"]

#: Channels of either representation (the supplement's 32).
CHANNELS = 32
SPIKE_REPRESENTATIONS = ("counts", "counts_interval")
EVENT_REPRESENTATIONS = ("voxel", "contrast")
#: Contrast threshold assumed by ``"contrast"`` when neither the sample nor the caller gives one.
NOMINAL_EVENT_THRESHOLD = 0.2
#: Accepted values of ``backend``: the compiled kernels where numba runs, or the NumPy reference.
BACKENDS = ("auto", "numba", "numpy")
#: Rows per parallel band of the spike kernel.
BAND_ROWS = 8
#: Intervals on each side of the one that holds the key instant (``2 * KEY_SIDE + 1`` channels).
KEY_SIDE = 2
#: Extra spike estimates at the key instant (:func:`key_representation`) and the channels each adds.
KEY_CHANNELS = {"none": 0, "isi-sequence": 2 * KEY_SIDE + 1}
KEY_ESTIMATES = tuple(KEY_CHANNELS)


def as_u8(planes: np.ndarray) -> np.ndarray:
    """Spike planes as uint8 0/1 (a view of a boolean array, no copy)."""
    return planes.view(np.uint8) if planes.dtype == np.bool_ else (planes != 0).view(np.uint8)


def _kernels_usable(backend: str = "auto") -> bool:
    return resolve_backend(backend, compiled=_kernels is not None) == "numba"


def _edges_centres(t: int, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Group edges (G + 1,) and interval centres (C,) of a ``t``-plane window, int64 plane indices."""
    if kind == "counts":
        return np.round(np.linspace(0, t, CHANNELS + 1)).astype(np.int64), np.zeros(0, np.int64)
    if kind == "counts_interval":
        edges = np.round(np.linspace(0, t, CHANNELS // 2 + 1)).astype(np.int64)
        return edges, (edges[:-1] + edges[1:]) // 2
    raise InputError(f"spike representation: expected one of {SPIKE_REPRESENTATIONS}, got {kind!r}")


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


def spike_quantum(sample: Sample) -> float:
    """The radiance of one spike in one of the 16 plane groups: ``16 / (T * gain)`` (T planes).

    The rates of the ``counts_interval`` representation are multiples of it; the ``"support-count"``
    head of :class:`~neuspike.nets.network.NeuSpikeNet` counts its correction in this unit.
    """
    planes = _planes(sample)
    return float(CHANNELS // 2) / (planes.shape[0] * spike_gain(sample)[0])


def _planes(sample: Sample) -> np.ndarray:
    if sample.spikes is None:
        raise InputError("spike representation: the sample has no spikes")
    planes = sample.spikes.planes
    if planes.shape[0] < CHANNELS:
        raise InputError(f"spike representation: needs at least {CHANNELS} planes, got {planes.shape[0]}")
    return planes


def _bin_rates(planes: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Spike rate (spikes per plane) in ``bins`` near-equal groups of planes, and the group edges.

    With T a multiple of ``bins`` (256 planes) every group has T / bins planes; otherwise the edges
    are ``round(k T / bins)`` (a real recording's 200 planes: groups of 12 or 13).
    """
    t = planes.shape[0]
    edges = np.round(np.linspace(0, t, bins + 1)).astype(np.int64)
    u8 = as_u8(planes)
    counts = np.add.reduceat(u8, edges[:-1], axis=0, dtype=np.uint16).astype(np.float32)
    return counts / np.diff(edges).astype(np.float32)[:, None, None], edges


# Index (0 = most significant) of the first and the last set bit of every byte value (0 for 0, unused).
_FIRST_BIT = np.array([next((j for j in range(8) if b >> (7 - j) & 1), 0) for b in range(256)], np.int32)
_LAST_BIT = np.array([next((j for j in range(7, -1, -1) if b >> (7 - j) & 1), 0) for b in range(256)], np.int32)


def interval_rate(planes: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """``1 / ISI`` at each plane index of ``centres``: float32 (len(centres), H, W), spikes per plane.

    ISI at centre c is ``next(c) - prev(c)`` with ``prev`` the last spike plane < c and ``next`` the
    first spike plane >= c; missing sides count as a spike one window length (T) outside the window.
    One pass forward and one backward over groups of 8 planes (each group's planes packed into one
    byte per pixel, its first and last spike read from a table) keep running extremes; the planes
    between group boundaries are scanned one by one only for centres that are not on a boundary.
    """
    t, h, w = planes.shape
    centres = np.asarray(centres, dtype=np.int64)
    u8 = as_u8(planes)
    idx = np.int16
    # prev(c): the last spike plane < c, for every centre, by a forward pass
    prev = np.full((h, w), -t, idx)
    prev_at: dict[int, np.ndarray] = {}
    wanted = set(int(c) for c in centres)
    plane = 0
    while plane <= t:
        if plane in wanted:
            prev_at[plane] = prev.copy()
        if plane == t:
            break
        if plane % 8 == 0 and plane + 8 <= t and not any(plane < c < plane + 8 for c in wanted):
            byte = _pack8(u8, plane)
            np.maximum(prev, np.where(byte != 0, _LAST_BIT[byte] + plane, -t).astype(idx), out=prev)
            plane += 8
        else:
            prev[u8[plane] != 0] = plane
            plane += 1
    # next(c): the first spike plane >= c, by a backward pass
    nxt = np.full((h, w), 2 * t, idx)
    next_at: dict[int, np.ndarray] = {}
    plane = t
    while plane >= 0:
        if plane in wanted:
            next_at[plane] = nxt.copy()
        if plane == 0:
            break
        if plane % 8 == 0 and plane - 8 >= 0 and not any(plane - 8 < c < plane for c in wanted):
            byte = _pack8(u8, plane - 8)
            np.minimum(nxt, np.where(byte != 0, _FIRST_BIT[byte] + plane - 8, 2 * t).astype(idx), out=nxt)
            plane -= 8
        else:
            plane -= 1
            nxt[u8[plane] != 0] = plane
    out = np.empty((len(centres), h, w), np.float32)
    for k, c in enumerate(centres):
        np.divide(1.0, (next_at[int(c)] - prev_at[int(c)]).astype(np.float32), out=out[k])
    return out


def _pack8(u8: np.ndarray, start: int) -> np.ndarray:
    """Planes ``start .. start + 7`` as one byte per pixel, plane ``start`` the most significant bit."""
    byte = u8[start] << np.uint8(7)
    for j in range(1, 8):
        byte |= u8[start + j] << np.uint8(7 - j)
    return byte


def spike_representation(sample: Sample, kind: str, *, backend: str = "auto") -> np.ndarray:
    """T_spike of ``sample``: float32 (32, H, W), radiance units (module docstring)."""
    planes = _planes(sample)
    edges, centres = _edges_centres(planes.shape[0], kind)
    gain, _ = spike_gain(sample)
    if _kernels_usable(backend):
        u8 = as_u8(planes)
        out = np.empty((CHANNELS, *planes.shape[1:]), np.float32)
        with KERNEL_LOCK:
            _kernels.spike_window(np.ascontiguousarray(u8), edges, centres, np.float32(gain), BAND_ROWS, out)
        return out
    if kind == "counts":
        return _bin_rates(planes, CHANNELS)[0] / np.float32(gain)
    if kind == "counts_interval":
        rates, edges = _bin_rates(planes, CHANNELS // 2)
        centres = (edges[:-1] + edges[1:]) // 2
        return np.concatenate([rates, interval_rate(planes, centres)]) / np.float32(gain)
    raise InputError(f"spike representation: expected one of {SPIKE_REPRESENTATIONS}, got {kind!r}")


def key_intervals(planes: np.ndarray, centre: int, side: int = KEY_SIDE) -> np.ndarray:
    """``1 / ISI`` of the ``2 * side + 1`` inter-spike intervals around plane index ``centre``:
    float32 (2 * side + 1, H, W), spikes per plane, earliest interval first.

    With ``p_1 > p_2 > ...`` the pixel's spike planes before ``centre`` (``< centre``) and ``n_1 < n_2 <
    ...`` those at or after it, interval 0 (channel ``side``) is ``n_1 - p_1``, the one that holds the
    key instant (:func:`interval_rate` at ``centre``, exactly); interval ``-k`` is ``p_k - p_(k+1)`` and
    ``+k`` is ``n_(k+1) - n_k``. The first missing spike on a side counts as one a window length (T)
    outside the window (``-T`` or ``2T``), as in :func:`interval_rate`; an interval beyond that one
    repeats its neighbour nearer the key instant, so every channel is a radiance estimate.
    """
    t, h, w = planes.shape
    if not 0 < centre < t:
        raise InputError(f"key intervals: the centre {centre} is not inside the {t}-plane window")
    u8 = as_u8(planes)

    def nth(stack: np.ndarray, first: int, step: int, virtual: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """The planes of the 1st .. (side + 1)-th spike of ``stack`` (ordered away from the centre)."""
        cs = np.cumsum(stack, axis=0, dtype=np.int16)
        total = cs[-1]
        where, have = [], []
        for j in range(1, side + 2):
            found = total >= j
            at = np.argmax(cs >= j, axis=0)
            where.append(np.where(found, first + step * at, virtual).astype(np.int32))
            have.append(found)
        return where, have

    before, have_b = nth(u8[:centre][::-1], centre - 1, -1, -t)
    after, have_a = nth(u8[centre:], centre, 1, 2 * t)
    out = np.empty((2 * side + 1, h, w), np.float32)
    out[side] = 1.0 / (after[0] - before[0]).astype(np.float32)
    for k in range(1, side + 1):  # p_k - p_(k+1); where p_k is already the virtual spike, the nearer interval
        with np.errstate(divide="ignore"):  # two virtual spikes: replaced by the neighbour below
            b = 1.0 / (before[k - 1] - before[k]).astype(np.float32)
            a = 1.0 / (after[k] - after[k - 1]).astype(np.float32)
        out[side - k] = np.where(have_b[k - 1], b, out[side - k + 1])
        out[side + k] = np.where(have_a[k - 1], a, out[side + k - 1])
    return out


def key_representation(sample: Sample, kind: str, *, backend: str = "auto") -> np.ndarray | None:
    """The extra spike estimates at the key instant: float32 (2 * KEY_SIDE + 1, H, W) in radiance units
    for ``"isi-sequence"`` (:func:`key_intervals` at the window's centre, divided by the gain), None for
    ``"none"``."""
    if kind == "none":
        return None
    if kind != "isi-sequence":
        raise InputError(f"key estimates: expected one of {KEY_ESTIMATES}, got {kind!r}")
    planes = _planes(sample)
    gain, _ = spike_gain(sample)
    centre = planes.shape[0] // 2
    if _kernels_usable(backend) and KEY_SIDE == 2:  # the kernel keeps three spikes a side
        u8 = as_u8(planes)
        out = np.empty((2 * KEY_SIDE + 1, *planes.shape[1:]), np.float32)
        with KERNEL_LOCK:
            _kernels.key_window(np.ascontiguousarray(u8), centre, np.float32(gain), out)
        return out
    return key_intervals(planes, centre) / np.float32(gain)


def event_representation(sample: Sample, kind: str, *, event_threshold: float | None = None,
                         backend: str = "auto") -> np.ndarray:
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
        if _kernels_usable(backend):
            out = np.empty((CHANNELS, h, w), np.float32)
            with KERNEL_LOCK:
                _kernels.contrast_window(events.t_s, events.x, events.y, events.p, float(t0),
                                         max(t1 - t0, 1e-12), float(theta), out)
            return out
        b = np.clip(((events.t_s - t0) / max(t1 - t0, 1e-12) * CHANNELS).astype(np.int64), 0, CHANNELS - 1)
        flat = (b * h + events.y.astype(np.int64)) * w + events.x.astype(np.int64)
        out = np.bincount(flat, weights=events.p.astype(np.float64), minlength=CHANNELS * h * w)
        return (out * theta).astype(np.float32).reshape(CHANNELS, h, w)
    raise InputError(f"event representation: expected one of {EVENT_REPRESENTATIONS}, got {kind!r}")
