"""NeuSpike-Net's representations over a running video: each plane and event binned once.

Neighbouring frames of a video share most of their window (at 1,000 frames/s and 20,000 planes/s,
240 of 256 planes). :class:`SlidingRepresentation` keeps, over the planes of the current window,

* the spike count of every pixel before each plane (a ring of ``T + 1`` uint32 maps),
* the last spike of every pixel before each plane, and the first one at or after each plane among
  the planes that arrived with it (rings of ``T + 1`` int32 maps), and
* the signed event count of every pixel before each plane (a ring of ``T + 1`` int32 maps),

and advances them by the planes and events that are new since the previous frame, once each
(:mod:`neuspike.nets.representation_kernels`). A frame's representation is then assembled from
those shared bins: a group's count is the difference of two prefix maps, the interval at a centre
is read from the last-spike map at the centre and the first-spike maps of the centre's chunk of
planes and the later chunks, and an event bin is the difference of two event prefix maps. The result equals the per-frame representation
(:func:`neuspike.nets.representations.spike_representation` and ``event_representation``) exactly,
bit for bit; ``tests/neuspike/nets/test_sliding.py`` checks it frame by frame.

Event bins and plane boundaries. The per-frame ``"contrast"`` bin of an event is
``int((t - t0) / (t1 - t0) * 32)``, which in floating point need not agree with a comparison against
the plane boundary times for an event that lies on (or within rounding of) a boundary, as events
with microsecond stamps do every 50 us at 20 kHz. Each plane's events are therefore those before a
split time recorded with the plane, and at assembly the few events whose per-frame bin differs
from their plane's (found by walking from each split, the bin being monotone in time) are moved to
the per-frame bin.

The rings start afresh from a frame's whole window (every plane and event of it binned, as a
single frame would be) at the first frame, at a frame that starts before the previous one and at one
whose window does not overlap the previous one's. A frame is computed whole by the per-frame
kernels, without the rings, when the sample lacks its plane range in the file
(``meta["window_planes_in_file"]``, set by :func:`neuspike.formats.samples.stream_samples`) or numba
cannot run; the event bins alone are computed per frame for a window whose length is not a multiple
of 32 planes (bins that do not fall on plane boundaries) and for ``"voxel"``. ``last_mode`` says
which happened (``"sliding"`` or ``"whole"``).
"""

from __future__ import annotations

import numpy as np

from neuspike.errors import InputError
from neuspike.nets import representations as reps
from neuspike.sample import Sample
from neuspike.utils.parallel import KERNEL_LOCK

__all__ = ["SlidingRepresentation"]


class SlidingRepresentation:
    """The representations of consecutive frames of one recording (module docstring).

    Parameters
    ----------
    spike_kind : str
        T_spike (:data:`neuspike.nets.representations.SPIKE_REPRESENTATIONS`).
    event_kind : str or None
        T_event; ``None`` for the spike-only network. Only ``"contrast"`` slides; ``"voxel"`` (whose
        normalisation depends on the whole window) is computed per frame.
    event_threshold : float or None
        As for :func:`~neuspike.nets.representations.event_representation`.
    """

    def __init__(self, spike_kind: str, event_kind: str | None, *, event_threshold: float | None = None) -> None:
        if spike_kind not in reps.SPIKE_REPRESENTATIONS:
            raise InputError(f"spike representation: expected one of {reps.SPIKE_REPRESENTATIONS}, got {spike_kind!r}")
        if event_kind is not None and event_kind not in reps.EVENT_REPRESENTATIONS:
            raise InputError(f"event representation: expected one of {reps.EVENT_REPRESENTATIONS}, got {event_kind!r}")
        self.spike_kind = spike_kind
        self.event_kind = event_kind
        self.event_threshold = event_threshold
        #: ``"sliding"`` or ``"whole"``: how the last frame was computed
        self.last_mode: str | None = None
        #: How many times the rings started afresh from a whole window (once per run of frames)
        self.starts = 0
        self.reset()

    def reset(self) -> None:
        """Forget the rings (a new recording or a jump) and free them."""
        self._cnt = self._last = self._first = self._ev = None
        self._shape: tuple[int, int, int] | None = None
        self._hi = -1  # planes [.., hi) are binned
        self._ev_ok = False

    # ------------------------------------------------------------------ public
    def __call__(self, sample: Sample) -> tuple[np.ndarray, np.ndarray | None]:
        """``(x_t, x_m)``: the spike representation and the event one (``None`` without an event kind)."""
        planes = reps._planes(sample)
        gain = reps.spike_gain(sample)[0]
        kernels = reps._kernels_usable()
        span = sample.meta.get("window_planes_in_file")
        t = planes.shape[0]
        slide = kernels and span is not None and int(span[1]) - int(span[0]) == t
        ws = int(span[0]) if slide else 0
        if slide and not (self._shape == (t, sample.height, sample.width) and self._hi - t <= ws <= self._hi):
            self._start(sample, ws)  # the first frame, a step back or a jump: bin the whole window
        elif slide:
            self._advance(sample, ws)
        if not slide:
            self.reset()
            self.last_mode = "whole"
            x_t = reps.spike_representation(sample, self.spike_kind)
            x_m = None if self.event_kind is None else reps.event_representation(
                sample, self.event_kind, event_threshold=self.event_threshold)
            return x_t, x_m
        self.last_mode = "sliding"
        x_t = self._assemble_spikes(ws, t, gain)
        x_m = None
        if self.event_kind is not None:
            x_m = self._assemble_events(sample, ws, t) if self._ev_ok else reps.event_representation(
                sample, self.event_kind, event_threshold=self.event_threshold)
        return x_t, x_m

    # ------------------------------------------------------------------ rings
    def _start(self, sample: Sample, ws: int) -> None:
        """Start the rings at plane ``ws`` and bin the sample's whole window."""
        self.starts += 1
        planes = sample.spikes.planes
        t, h, w = planes.shape
        self._shape = (t, h, w)
        self._cnt = np.zeros((t + 1, h, w), np.uint32)
        self._last = np.zeros((t + 1, h, w), np.int32)
        self._first = np.zeros((t + 1, h, w), np.int32)
        self._running = np.zeros((h, w), np.int64)
        self._last_now = np.full((h, w), np.iinfo(np.int32).min + 1, np.int32)
        self._chunks: list[int] = []  # first plane of each chunk of planes binned together
        self._hi = ws
        self._split: dict[int, float] = {}
        self._ev_ok = (self.event_kind == "contrast" and sample.events is not None and t % reps.CHANNELS == 0)
        if self._ev_ok:
            self._ev = np.zeros((t + 1, h, w), np.int32)
            self._ev_running = np.zeros((h, w), np.int32)
            self._split[ws] = float(sample.window_start_s)
        self._cnt[ws % (t + 1)] = 0
        self._advance(sample, ws)

    def _advance(self, sample: Sample, ws: int) -> None:
        """Bin the planes (and events) of ``[hi, ws + T)``, each once."""
        from neuspike.nets import representation_kernels as k

        t = self._shape[0]
        we = ws + t
        if we <= self._hi:
            return
        new = sample.spikes.planes[self._hi - ws:]
        u8 = reps.as_u8(new)
        with KERNEL_LOCK:
            k.advance_spikes(np.ascontiguousarray(u8), self._hi, self._cnt, self._last, self._first, self._running,
                             self._last_now)
        self._chunks.append(self._hi)
        if self._ev_ok:
            rate = sample.spikes.plane_rate_hz
            splits_t = np.empty(we - self._hi + 1)
            splits_t[0] = self._split[self._hi]
            for j in range(1, we - self._hi):  # the plane boundaries, from this window's start
                splits_t[j] = sample.window_start_s + (self._hi + j - ws) / rate
            splits_t[-1] = sample.window_end_s  # the sample holds every event before its end
            np.maximum.accumulate(splits_t, out=splits_t)
            # the first split is the previous window's end (or this window's start), which lies in
            # this window: the sample holds every event after it
            ev = sample.events
            idx = np.searchsorted(ev.t_s, splits_t, side="left").astype(np.int64)
            with KERNEL_LOCK:
                k.advance_events(ev.t_s, ev.x, ev.y, ev.p, idx, self._hi, self._ev, self._ev_running)
            for j in range(1, we - self._hi + 1):
                self._split[self._hi + j] = float(splits_t[j])
            for key in [key for key in self._split if key < ws]:
                del self._split[key]
        live = [i for i, a in enumerate(self._chunks) if a > ws]  # chunks that still reach into the window
        self._chunks = self._chunks[max(0, live[0] - 1 if live else len(self._chunks) - 1):]
        self._hi = we

    # ------------------------------------------------------------------ assembly
    def _assemble_spikes(self, ws: int, t: int, gain: float) -> np.ndarray:
        from neuspike.nets import representation_kernels as k

        edges, centres = reps._edges_centres(t, self.spike_kind)
        starts = np.asarray(self._chunks, np.int64)
        centre_chunk = np.searchsorted(starts, ws + centres, side="right").astype(np.int64) - 1
        out = np.empty((reps.CHANNELS, *self._shape[1:]), np.float32)
        with KERNEL_LOCK:
            k.assemble_spikes(self._cnt, self._last, self._first, ws, edges, centres, starts % (t + 1), centre_chunk,
                              np.float32(gain), out)
        return out

    def _assemble_events(self, sample: Sample, ws: int, t: int) -> np.ndarray:
        from neuspike.nets import representation_kernels as k

        bins = reps.CHANNELS
        per = t // bins
        counts = np.empty((bins, *self._shape[1:]), np.int32)
        with KERNEL_LOCK:
            k.assemble_events(self._ev, ws, per, counts)
        _correct_boundaries(counts, sample, [self._split[ws + j * per] for j in range(bins + 1)])
        theta = self.event_threshold or sample.event_threshold or reps.NOMINAL_EVENT_THRESHOLD
        out = np.empty(counts.shape, np.float32)
        with KERNEL_LOCK:
            k.counts_to_contrast(counts, float(theta), out)
        return out


def _correct_boundaries(counts: np.ndarray, sample: Sample, split_times: list[float]) -> None:
    """Move the events whose per-frame bin differs from their plane's bin (module docstring), in place."""
    ev = sample.events
    t = ev.t_s
    bins = counts.shape[0]
    t0, t1 = sample.window_start_s, sample.window_end_s
    span = max(t1 - t0, 1e-12)
    f0, f_end = (int(i) for i in np.searchsorted(t, [t0, t1], side="left"))
    s = np.searchsorted(t, split_times, side="left").astype(np.int64)

    def bin_of(i: int) -> int:
        return min(max(int((t[i] - t0) / span * bins), 0), bins - 1)

    f = np.empty(bins + 1, np.int64)
    f[0], f[bins] = f0, f_end
    for j in range(1, bins):
        i = min(max(int(s[j]), f0), f_end)
        while i > f0 and bin_of(i - 1) >= j:
            i -= 1
        while i < f_end and bin_of(i) < j:
            i += 1
        f[j] = i
    if np.array_equal(f, s):
        return
    moved: set[int] = set()
    for j in range(bins + 1):
        moved.update(range(int(min(f[j], s[j])), int(max(f[j], s[j]))))
    for i in sorted(moved):
        slot = int(np.searchsorted(s, i, side="right")) - 1  # the bin the rings put it in
        own = int(np.searchsorted(f, i, side="right")) - 1  # the per-frame bin
        y, x, p = int(ev.y[i]), int(ev.x[i]), int(ev.p[i])
        if 0 <= slot < bins:
            counts[slot, y, x] -= p
        if 0 <= own < bins:
            counts[own, y, x] += p

