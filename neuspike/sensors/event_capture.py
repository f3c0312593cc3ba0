"""The capture engine of :class:`neuspike.sensors.event_camera.EventCamera`: pixel state, stages, events.

The camera holds what persists and the order of things; this module holds the work, over explicit
values only (it never sees the camera):

* :class:`PixelArray` — the sensor's frozen per-pixel parameters (thresholds, leak rates, shot-noise
  rates) and the layout of its event keys, drawn once at construction by the stage functions
  :func:`threshold_mismatch`, :func:`leak_rates` and :func:`shot_noise_rates`;
* :class:`PixelState` — what a capture carries to the next: the last sample's time, each pixel's
  (filtered) log intensity and memorised level, and with ``refractory`` each pixel's last emitted event;
* the per-interval stages as functions of those values: :func:`leak_step`, :func:`bandwidth_step`,
  :func:`draw_shot_noise`, :func:`noise_pixel_events`, :func:`refractory_filter`;
* :class:`Capture` — one ``EventCamera.capture`` call: per sample interval it updates every pixel (the
  compiled pass of :mod:`neuspike.sensors.event_kernels`, in which ``bandwidth``, ``leak`` and
  ``refractory`` are fused, or the stage functions in NumPy on the reference path), turns each
  threshold crossing into an int64 key whose order is the output order, and decodes the sorted keys
  into the output stream, optionally on a worker thread. It starts from a copy of the state and
  returns the new one, so a rejected or failed call leaves the camera as it was.
"""

from __future__ import annotations

import functools
import math
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from neuspike.conditions import Effect
from neuspike.sensors.dvs_pixel import (DARK_FLOOR_8BIT, I01_OFFSET, I01_SCALE, REFERENCE_WHITE_8BIT,
                                        SHOT_NOISE_BRIGHT_FACTOR, lin_log_into)
from neuspike.streams import EventStream

#: Order in which declared stages are listed in a recording's metadata.
STAGE_ORDER = ("threshold_mismatch", "bandwidth", "leak", "shot_noise", "refractory")
#: Crossing levels handled one by one per interval before switching to a cumulative expansion.
MAX_LEVEL_LOOP = 48
#: Smallest per-pixel contrast threshold after mismatch (log units).
THRESHOLD_FLOOR = 0.01
#: Log-normal spread of the per-pixel leak rate, in decades (v2e).
LEAK_SPREAD_DECADES = 0.1
#: Finest resolution of a crossing time, as a power of two of the sample interval.
MAX_FRACTION_BITS = 44


# ---------------------------------------------------------------------- frozen per-pixel parameters
@dataclass(frozen=True, eq=False)
class ShotNoiseRates:
    """Frozen shot-noise rates: ``gain`` (2, n) float64 is ``theta_nominal / theta_pixel`` for OFF and ON,
    ``half_rate_hz`` half the declared rate, ``bound_hz`` a bound of one pixel's ON + OFF rate (for thinning)."""

    gain: np.ndarray
    half_rate_hz: float
    bound_hz: float


@dataclass(frozen=True, eq=False)
class PixelArray:
    """A sensor's frozen per-pixel parameters and the layout of its event keys.

    ``th_on``, ``th_off``: float32 (n,) thresholds in use; ``leak_per_s``: float32 (n,) drift of the
    memorised level (``leak``) or ``None``; ``noise``: :class:`ShotNoiseRates` or ``None``. An event is
    an int64 key ``(time fraction << pix_bits) | (pixel << 1) | ON`` whose numeric order is the output
    order (time, then pixel ``y * W + x``, then OFF before ON).
    """

    width: int
    height: int
    light: float
    threshold_on: float
    threshold_off: float
    th_on: np.ndarray
    th_off: np.ndarray
    leak_per_s: np.ndarray | None = None
    noise: ShotNoiseRates | None = None
    #: Whether every pixel has one threshold for both polarities (no mismatch, ``theta_on == theta_off``).
    symmetric: bool = False

    @property
    def n(self) -> int:
        return self.width * self.height

    @functools.cached_property
    def pix_bits(self) -> int:
        """Bits of the key's ``(pixel << 1) | ON`` part."""
        return (2 * self.n - 1).bit_length()

    @property
    def fraction_bits(self) -> int:
        """Bits of the key's time fraction at the finest."""
        return min(MAX_FRACTION_BITS, 62 - self.pix_bits)

    @property
    def pix_mask(self) -> int:
        return (1 << self.pix_bits) - 1

    @functools.cached_property
    def neg_th_off(self) -> np.ndarray:
        return -self.th_off

    @functools.cached_property
    def th_pair(self) -> np.ndarray:
        """Interleaved ``[off, on]`` per pixel: the threshold of pixel ``i`` for polarity ``p`` is ``th_pair[2 i + p]``."""
        return np.stack([self.th_off, self.th_on], axis=1).ravel()

    @functools.cached_property
    def luts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y (uint16) and polarity (int8) of each event key ``2 * pixel + ON``."""
        key = np.arange(2 * self.n)
        pix = key >> 1
        return ((pix % self.width).astype(np.uint16), (pix // self.width).astype(np.uint16),
                np.where(key & 1, 1, -1).astype(np.int8))


def threshold_mismatch(rng: np.random.Generator, n: int, theta_on: float, theta_off: float,
                       sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel thresholds ``N(theta, sigma**2)``, ON drawn first, floored at :data:`THRESHOLD_FLOOR` (float32)."""
    on = rng.normal(theta_on, sigma, n)
    off = rng.normal(theta_off, sigma, n)
    return np.maximum(on, THRESHOLD_FLOOR).astype(np.float32), np.maximum(off, THRESHOLD_FLOOR).astype(np.float32)


def leak_rates(rng: np.random.Generator, th_on: np.ndarray, rate_hz: float) -> np.ndarray:
    """Per-pixel drift of the memorised level, ``rate_pixel * theta_on_pixel`` per second (float32), with
    ``rate_pixel = rate_hz * 10**(0.1 N(0, 1))``."""
    rates = rate_hz * 10.0 ** (LEAK_SPREAD_DECADES * rng.standard_normal(th_on.shape[0]))
    return (rates * th_on).astype(np.float32)


def shot_noise_rates(th_on: np.ndarray, th_off: np.ndarray, theta_on: float, theta_off: float,
                     rate_hz: float) -> ShotNoiseRates:
    """The frozen part of shot noise: each pixel's rate scales as the nominal threshold over its own."""
    gain = np.stack([theta_off / th_off.astype(np.float64), theta_on / th_on.astype(np.float64)])  # OFF, ON
    dark = 1.0 - (1.0 - SHOT_NOISE_BRIGHT_FACTOR) * (I01_OFFSET / I01_SCALE)
    return ShotNoiseRates(gain=gain, half_rate_hz=0.5 * rate_hz, bound_hz=rate_hz * dark * float(gain.max()))


# ---------------------------------------------------------------------- what a capture carries on
@dataclass
class PixelState:
    """What persists between captures: ``t_last`` (time of the last sample, ``None`` before the first),
    ``sig`` (each pixel's log intensity, filtered with ``bandwidth``), ``mem`` (its memorised level),
    ``last_emit_s`` (with ``refractory``: the time of its last emitted event)."""

    t_last: float | None = None
    sig: np.ndarray | None = None
    mem: np.ndarray | None = None
    last_emit_s: np.ndarray | None = None

    def copy(self) -> "PixelState":
        return replace(self, **{k: None if v is None else v.copy()
                                for k, v in (("sig", self.sig), ("mem", self.mem), ("last_emit_s", self.last_emit_s))})


# ---------------------------------------------------------------------- per-interval stages
def leak_step(mem: np.ndarray, leak_per_s: np.ndarray, dt: float, tmp: np.ndarray) -> None:
    """``leak``: the memorised level drifts down by ``leak_per_s * dt`` (in place; ``tmp`` a float32 buffer)."""
    np.multiply(leak_per_s, np.float32(dt), out=tmp)
    mem -= tmp


def bandwidth_step(sig: np.ndarray, log_k: np.ndarray, radiance: np.ndarray, dt: float, cutoff_hz: float,
                   scale8: float, max_radiance: float, out: np.ndarray) -> np.ndarray:
    """``bandwidth``: ``out = sig + eps * (log_k - sig)``, ``eps = min(1, (I8 + 20) / 275 * dt * 2 pi cutoff_hz)``
    with ``I8 = scale8 * radiance`` of the new sample (``log_k`` is overwritten)."""
    a = dt * 2.0 * np.pi * cutoff_hz / I01_SCALE
    eps = np.multiply(radiance, np.float32(scale8 * a), out=out)
    eps += np.float32(I01_OFFSET * a)
    if (max_radiance * scale8 + I01_OFFSET) * a > 1.0:
        np.minimum(eps, np.float32(1.0), out=eps)
    log_k -= sig
    log_k *= eps
    return np.add(sig, log_k, out=out)


def draw_shot_noise(pixels: PixelArray, rng: np.random.Generator, radiance: np.ndarray, dt: float,
                    scale8: float):
    """``shot_noise``: the noise events of one interval by Poisson thinning, ``(pixel, fraction, ON)`` or ``None``.

    The rate of each pixel is taken from the interval's end sample ``radiance`` (as v2e does);
    ``scale8 = 255 * light``.
    """
    rates = pixels.noise
    n = pixels.n
    count = int(rng.poisson(rates.bound_hz * n * dt))
    if count == 0:
        return None
    u = rng.random((3, count))
    pix = np.minimum((u[0] * n).astype(np.int64), n - 1)
    i01 = radiance[pix].astype(np.float64)
    i01 *= scale8
    i01 += I01_OFFSET
    i01 /= I01_SCALE
    np.clip(i01, 0.0, 1.0, out=i01)
    base = rates.half_rate_hz * (1.0 - (1.0 - SHOT_NOISE_BRIGHT_FACTOR) * i01)
    rate_on = base * rates.gain[1, pix]
    level = u[2] * rates.bound_hz
    keep = level < rate_on + base * rates.gain[0, pix]
    if not keep.any():
        return None
    return pix[keep], u[1][keep], (level < rate_on)[keep]


def noise_pixel_events(pixels: PixelArray, noise, sig: np.ndarray, mem: np.ndarray, d1: np.ndarray,
                       dt: float):
    """All events of the pixels that have a noise event in this interval (the NumPy path).

    A noise event resets the memorised level to the current signal, so each segment between noise
    events starts from a known level: the first from the pixel's state, the others from zero.
    ``d1 = sig_new - mem`` for every pixel. Returns ``(pixels, events)`` with the events
    ``(pixel, fraction, ON)`` sorted by pixel then time, and sets those pixels' memorised level at
    the end of the interval (in ``mem``).
    """
    pix_n, f_n, on_n = noise
    order = np.argsort(pix_n + f_n)  # pixel, then time (f_n < 1)
    pix_n, f_n, on_n = pix_n[order], f_n[order], on_n[order]
    m = pix_n.size
    first = np.empty(m, np.bool_)
    first[0] = True
    np.not_equal(pix_n[1:], pix_n[:-1], out=first[1:])
    noisy = pix_n[first]
    # leak moves mem linearly in time, so d = sig - mem is linear over the interval
    mem_end = mem[noisy]
    mem_start = mem_end.astype(np.float64)
    if pixels.leak_per_s is not None:
        mem_start += pixels.leak_per_s[noisy] * dt
    d1 = d1[noisy]
    d_start = sig[noisy] - mem_start
    slope = d1 - d_start
    # segments: one ending at each noise event, and a final one after the pixel's last
    u = noisy.size
    seg = np.empty(m + u, np.int64)  # segment -> index into noisy
    seg[:m] = np.cumsum(first) - 1
    seg[m:] = np.arange(u)
    f_a = np.empty(m + u)
    f_a[0] = 0.0
    f_a[1:m] = f_n[:-1]
    f_a[:m][first] = 0.0
    f_a[m:-1] = f_n[:-1][first[1:]]
    f_a[-1] = f_n[-1]
    f_b = np.ones(m + u)
    f_b[:m] = f_n
    d_a = np.zeros(m + u)
    d_a[:m][first] = d_start
    g = slope[seg]
    d_b = d_a + g * (f_b - f_a)
    rising = d_b > 0
    seg_pix = noisy[seg]
    th = np.where(rising, pixels.th_on[seg_pix], pixels.th_off[seg_pix]).astype(np.float64)
    s = np.trunc(d_b / th)
    c = np.abs(s).astype(np.int64)
    total = int(c.sum())
    ev_pix = np.empty(total + m, np.int64)
    ev_f = np.empty(total + m)
    ev_on = np.empty(total + m, np.bool_)
    if total:
        rep = np.repeat(np.arange(m + u), c)
        j = np.arange(1, total + 1) - (np.cumsum(c) - c)[rep]
        level = np.where(rising[rep], th[rep], -th[rep]) * j
        ev_f[:total] = f_a[rep] + (level - d_a[rep]) / g[rep]
        ev_pix[:total] = seg_pix[rep]
        ev_on[:total] = rising[rep]
    ev_pix[total:] = pix_n
    ev_f[total:] = f_n
    ev_on[total:] = on_n
    np.clip(ev_f, 0.0, 1.0, out=ev_f)
    # new memorised level = sig_new - d_end, with sig_new = d1 + mem_end
    d_end = d_b[m:] - s[m:] * th[m:]
    mem[noisy] = (mem_end + d1) - d_end.astype(np.float32)
    order = np.argsort(ev_pix + ev_f * 0.5, kind="stable")  # pixel, then time
    return noisy, (ev_pix[order], ev_f[order], ev_on[order])


def refractory_filter(keys: np.ndarray, pix: np.ndarray, t_a: float, scale: float, pix_bits: int,
                      last_emit_s: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``refractory``: drop the events within ``period_s`` of their pixel's last emitted event.

    ``keys`` of one interval starting at ``t_a`` (time ``t_a + fraction * scale``), ``pix`` their pixels,
    each at most once, whose earlier events have been seen; ``last_emit_s`` is updated in place.
    """
    t = (keys >> pix_bits).astype(np.float64)
    t *= scale
    t += t_a
    keep = (t - last_emit_s[pix]) >= period_s
    if not keep.all():
        keys, pix, t = keys[keep], pix[keep], t[keep]
    last_emit_s[pix] = t
    return keys, pix


class EventBuffer:
    """Output arrays (t, x, y, p) filled interval by interval.

    Capacity is reserved at twice the count projected from the running event rate: ``np.empty``
    touches no memory, so the slack costs only address space, while growing (a copy of everything
    so far into fresh memory) is expensive. The arrays are trimmed in place at the end.
    """

    def __init__(self, intervals: int) -> None:
        self.intervals = max(intervals, 1)
        self.done = 0
        self.size = 0
        self.arrays = [np.empty(0, np.float64), np.empty(0, np.uint16), np.empty(0, np.uint16),
                       np.empty(0, np.int8)]

    def would_grow(self, count: int) -> bool:
        return self.size + count > self.arrays[0].shape[0]

    def extend(self, count: int) -> list[np.ndarray]:
        """Views of the next ``count`` slots of each array."""
        self.done += 1
        need = self.size + count
        if need > self.arrays[0].shape[0]:
            expected = need * self.intervals / self.done
            capacity = int(max(min(2.0 * expected, need + max(need, 1 << 25)), 2 * need, 1 << 16))
            grown = []
            for a in self.arrays:
                b = np.empty(capacity, a.dtype)
                b[:self.size] = a[:self.size]
                grown.append(b)
            self.arrays = grown
        start, self.size = self.size, need
        return [a[start:need] for a in self.arrays]

    def finish(self) -> list[np.ndarray]:
        for i, a in enumerate(self.arrays):
            if a.shape[0] != self.size:
                try:
                    a.resize(self.size, refcheck=False)  # shrinking: no copy
                except ValueError:
                    self.arrays[i] = a[:self.size].copy()
        return self.arrays


class Capture:
    """The work of one ``EventCamera.capture`` call, over explicit values.

    ``pixels``: the sensor's frozen parameters; ``effects``: the declared stages by name; ``rng``: the
    generator of the random stages; ``state``: what the previous capture left (not modified: the run
    starts from a copy and :meth:`run` returns the new state); ``backend``: ``"numba"`` (the compiled
    passes, every stage) or ``"numpy"``; ``setup_seconds``: the time of the frozen draws, charged to the
    capture that initialises the pixels.

    Per sample interval: update ``sig`` and ``mem`` (``bandwidth``, ``leak``), find the pixels whose
    ``sig - mem`` crosses a threshold and how often, then build the interval's events as int64 keys
    ``(time fraction << P) | (pixel << 1) | ON``, sort them and append them to the output. Sorting the
    keys orders events by time, then pixel index.
    """

    def __init__(self, pixels: PixelArray, effects: Mapping[str, Effect], rng: np.random.Generator | None,
                 state: PixelState, *, max_radiance: float, threads: int, backend: str,
                 setup_seconds: Mapping[str, float]) -> None:
        self.px = pixels
        self.effects = effects
        self.rng = rng
        self.state = state
        self.threads = threads
        self.backend = backend
        self.setup_seconds = setup_seconds
        self.pool: ThreadPoolExecutor | None = None
        self.pending: list[Future] = []
        eff = effects
        self.bandwidth_hz = eff["bandwidth"].param("cutoff_hz") if "bandwidth" in eff else None
        self.refractory_s = eff["refractory"].param("period_s") if "refractory" in eff else None
        self.shot_noise = "shot_noise" in eff
        self.leak = pixels.leak_per_s
        self.seconds = dict.fromkeys(["dvs_pixel", *(name for name in STAGE_ORDER if name in eff)], 0.0)
        # "numba": the compiled pixel pass and event building, every stage
        self.pixel_kernel = backend == "numba"
        # stages that run inside the compiled passes: their time is part of dvs_pixel's
        self.fused = frozenset({"bandwidth", "leak", "refractory"} & set(eff)) if self.pixel_kernel else frozenset()
        self.stage = "dvs_pixel"
        self.stage_t0 = time.perf_counter()
        self.luts = pixels.luts
        self.max_radiance = max_radiance
        n = pixels.n
        self.tmp = np.empty(n, np.float32)
        self.d1 = np.empty(n, np.float32)
        self.act = np.empty(n, np.bool_)
        self.act2 = np.empty(n, np.bool_)
        if self.pixel_kernel:
            self.log_max = np.empty(n, np.float32)
            self.active = np.empty(n, np.int64)
        # internal log: v2e's lin-log of 255 * light * radiance minus the constant ln(255 * light)
        # (only differences of the log matter), so the radiance needs no scaling per frame
        self.scale8 = pixels.light * REFERENCE_WHITE_8BIT
        self.floor = np.float32(DARK_FLOOR_8BIT / self.scale8)
        self.slope = np.float32(np.log(DARK_FLOOR_8BIT) / (DARK_FLOOR_8BIT / self.scale8))
        self.log_floor = np.log(self.floor)

    def switch(self, stage: str) -> str:
        """Charge the time since the last switch to the current stage; return that stage."""
        now = time.perf_counter()
        self.seconds[self.stage] += now - self.stage_t0
        self.stage_t0 = now
        previous, self.stage = self.stage, stage
        return previous

    def log_into(self, radiance: np.ndarray, out: np.ndarray) -> np.ndarray:
        return lin_log_into(radiance, out, self.tmp, self.floor, self.slope)

    # ------------------------------------------------------------------ loop
    def run(self, frames: np.ndarray, times: np.ndarray) -> PixelState:
        """Capture ``frames`` (K, n) float32 at ``times`` (K,); return the pixel state after the last sample."""
        n = self.px.n
        state = self.state
        if state.t_last is None:  # the first frame only initialises the pixels
            sig = self.log_into(frames[0], np.empty(n, np.float32))
            mem = sig.copy()
            last_emit = np.full(n, -np.inf) if self.refractory_s is not None else None
            t_prev = float(times[0])
            k0 = 1
            for name in ("threshold_mismatch", "leak"):
                if name in self.seconds:  # the frozen per-pixel draws made at construction
                    self.seconds[name] += self.setup_seconds.get(name, 0.0)
        else:
            # work on copies: the camera's state changes only when the call completes
            state = state.copy()
            sig, mem, last_emit, t_prev = state.sig, state.mem, state.last_emit_s, state.t_last
            k0 = 0
        self.last_emit = last_emit
        self.out = EventBuffer(frames.shape[0] - k0)
        if self.threads > 1 and frames.shape[0] - k0 > 1:
            self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="neuspike-events")
        try:
            if self.pixel_kernel:
                self.loop_compiled(frames, times, k0, sig, mem, t_prev)
            else:
                self.loop(frames, times, k0, sig, mem, t_prev)
            self.drain()
        finally:
            if self.pool is not None:
                self.pool.shutdown(wait=True, cancel_futures=True)
                self.pool = None
        sig, mem, t_prev = self.final_state
        return PixelState(t_last=t_prev, sig=sig, mem=mem, last_emit_s=last_emit)

    def loop_compiled(self, frames, times, k0, sig, mem, t_prev) -> None:
        """:meth:`loop` for the compiled backend (every stage; the same events)."""
        from neuspike.sensors import event_kernels

        px = self.px
        spare = np.empty(px.n, np.float32)
        # key buffers used in turn: with a worker thread, one is sorted while the next is filled
        buffers = [np.empty(0, np.int64), np.empty(0, np.int64)]
        jobs = 0
        last_emit, period = self.last_emit, self.refractory_s or 0.0
        no_noise = np.empty(0, np.int64)
        # the log of the next sample is taken by the worker thread (NumPy releases the GIL) while
        # this one runs the compiled passes of the current interval: two buffers in turn
        logs = [self.log_max, np.empty_like(self.log_max)] if self.pool is not None else [self.log_max]
        k_end = frames.shape[0]
        next_log = self.pool.submit(self.log_of, frames[k0], logs[k0 & 1]) if self.pool is not None else None
        for k in range(k0, k_end):
            t_k = float(times[k])
            dt = t_k - t_prev
            if next_log is not None:
                log_max = next_log.result()
                # the other buffer's last reader was the previous interval's pixel pass, finished
                next_log = self.pool.submit(self.log_of, frames[k + 1], logs[(k + 1) & 1]) if k + 1 < k_end else None
            else:
                log_max = self.log_of(frames[k], logs[0])
            n_active, n_events, c_max = self.pixel_pass(frames[k], dt, sig, mem, spare, log_max)
            q_one = self.fraction_unit(t_prev, dt)
            from_noise, noisy = None, no_noise
            if self.shot_noise:
                self.switch("shot_noise")
                drawn = draw_shot_noise(self.px, self.rng, frames[k], dt, self.scale8)
                if drawn is not None:
                    pix_n, f_n, on_n = drawn
                    order = np.argsort(pix_n + f_n)  # pixel, then time (f_n < 1), as noise_pixels
                    from_noise, noisy = event_kernels.noise_keys(
                        pix_n[order], f_n[order], on_n[order], sig, mem, self.d1, self.leak, dt, px.th_on,
                        px.th_off, q_one, px.pix_bits, last_emit, period, t_prev, dt / q_one)
                    n_events += from_noise.shape[0]
                self.switch("dvs_pixel")
            if n_events:
                slot = jobs & 1
                while len(self.pending) > 1:  # the job two back read this slot's buffer
                    self.pending.pop(0).result()
                if buffers[slot].shape[0] < n_events:
                    buffers[slot] = np.empty(2 * n_events, np.int64)
                keys = buffers[slot][:n_events]
                # an upper bound: noise pixels' crossings and refractory drops are not in the key set
                count = event_kernels.interval_keys(
                    self.active, n_active, c_max, self.d1, sig, mem, self.leak, np.float32(dt), px.symmetric,
                    px.th_on, px.th_off, q_one, px.pix_bits, keys, noisy, last_emit, period, t_prev,
                    dt / q_one, last_emit is not None and dt < period)
                if from_noise is not None:
                    keys[count:count + from_noise.shape[0]] = from_noise
                    count += from_noise.shape[0]
                keys = keys[:count]
                n_events = count
            if n_events:
                if self.out.would_grow(n_events):
                    self.drain()  # no write may be pending into arrays about to be replaced
                outputs = self.out.extend(n_events)
                if self.pool is None:
                    self.finish_interval(keys, t_prev, dt / q_one, t_k, outputs)
                else:
                    # fresh output memory costs a page fault per 4 KiB on first touch: fault the
                    # times in here, so that the two threads carry about the same load
                    outputs[0].fill(0.0)
                    self.pending.append(self.pool.submit(self.finish_interval, keys, t_prev, dt / q_one, t_k, outputs))
                jobs += 1
            sig, spare = spare, sig
            t_prev = t_k
        self.final_state = sig, mem, t_prev

    def finish_interval(self, keys: np.ndarray, t_a: float, scale: float, t_b: float,
                        outputs: list[np.ndarray]) -> None:
        """Order one interval's keys (NumPy's vectorised sort) and decode them into the output."""
        from neuspike.sensors import event_kernels

        keys.sort()  # the keys are distinct integers up to duplicates: the NumPy path's order exactly
        event_kernels.write_events(keys, self.px.pix_bits, self.px.width, t_a, scale, t_b, *outputs)

    def log_of(self, radiance: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``log(max(radiance, floor))`` into ``out``: NumPy's float32 log (not the C library's)."""
        np.maximum(radiance, self.floor, out=out)
        return np.log(out, out=out)

    def pixel_pass(self, radiance, dt, sig, mem, sig_new, log_max=None):
        """Compiled pixel update of one interval (lin-log, bandwidth, leak, ``d1``, crossing pixels).

        ``log_max``: :meth:`log_of` the radiance, when already taken. Fills ``sig_new``, ``self.d1``
        and ``self.active``, leaks ``mem``; returns ``(number of crossing pixels, their events,
        largest crossing count)``.
        """
        from neuspike.sensors import event_kernels

        px = self.px
        # the log stays in NumPy (its float32 log is not the C library's); the rest is compiled
        if log_max is None:
            log_max = self.log_of(radiance, self.log_max)
        gain = offset = np.float32(0.0)
        clip = False
        bandwidth = self.bandwidth_hz is not None
        if bandwidth:
            a = dt * 2.0 * np.pi * self.bandwidth_hz / I01_SCALE
            gain, offset = np.float32(self.scale8 * a), np.float32(I01_OFFSET * a)
            clip = (self.max_radiance * self.scale8 + I01_OFFSET) * a > 1.0
        return event_kernels.pixel_update(
            log_max, radiance, sig, mem, sig_new, self.d1, self.floor, self.slope, self.log_floor,
            bandwidth, gain, offset, clip, self.leak, np.float32(dt), px.symmetric, px.th_on, px.th_off,
            self.active,
        )

    def fraction_unit(self, t_a: float, dt: float) -> float:
        """``2**q_bits``: crossing fractions are counted in units of ``2**-q_bits`` of the interval.

        ``2**-44`` of the interval, or coarser where two float64 ulps of the timestamp are coarser
        (then distinct fractions stay distinct times).
        """
        t_max = max(abs(t_a), abs(t_a + dt))
        q_bits = min(self.px.fraction_bits, int(math.floor(math.log2(dt / (2.0 * math.ulp(t_max))))))
        return float(2 ** max(q_bits, 0))

    def loop(self, frames, times, k0, sig, mem, t_prev) -> None:
        px = self.px
        spare = np.empty(px.n, np.float32)
        tmp, d1 = self.tmp, self.d1
        for k in range(k0, frames.shape[0]):
            t_k = float(times[k])
            dt = t_k - t_prev
            radiance = frames[k]
            nz = None
            if self.pixel_kernel:  # the compiled pixel pass, then shot noise and refractory here
                n_active, _, _ = self.pixel_pass(radiance, dt, sig, mem, spare)
                sig_new = spare
                nz = self.active[:n_active]
            elif self.bandwidth_hz is not None:
                log_k = self.log_into(radiance, d1)
                self.switch("bandwidth")
                sig_new = bandwidth_step(sig, log_k, radiance, dt, self.bandwidth_hz, self.scale8, self.max_radiance,
                                         spare)
                self.switch("dvs_pixel")
            else:
                sig_new = self.log_into(radiance, spare)
            if nz is None:
                if self.leak is not None:
                    self.switch("leak")
                    leak_step(mem, self.leak, dt, tmp)
                    self.switch("dvs_pixel")
                np.subtract(sig_new, mem, out=d1)
            noise = None
            if self.shot_noise:
                self.switch("shot_noise")
                noise = draw_shot_noise(self.px, self.rng, radiance, dt, self.scale8)
                if noise is not None:
                    noise = noise_pixel_events(self.px, noise, sig, mem, self.d1, dt)
                self.switch("dvs_pixel")
            self.interval(sig, mem, t_prev, dt, noise, nz, t_k)
            sig, spare = sig_new, sig
            t_prev = t_k
        self.final_state = sig, mem, t_prev

    # ------------------------------------------------------------------ events
    def interval(self, sig: np.ndarray, mem: np.ndarray, t_a: float, dt: float, noise,
                 nz: np.ndarray | None, t_b: float) -> None:
        """The events of one interval ``[t_a, t_b]`` (``dt = t_b - t_a``). On entry ``self.d1 = sig_new - mem`` for every pixel.

        ``nz``: the crossing pixels (ascending) when the compiled pixel pass found them already.
        """
        px = self.px
        d1, act = self.d1, self.act
        q_one = self.fraction_unit(t_a, dt)
        if nz is not None:
            if noise is not None:  # these pixels' events come from noise_pixels
                nz = nz[~np.isin(nz, noise[0], assume_unique=True)]
        else:
            if px.symmetric:
                np.abs(d1, out=self.tmp)
                np.greater_equal(self.tmp, px.th_on[0], out=act)
            else:
                np.greater_equal(d1, px.th_on, out=act)
                np.less_equal(d1, px.neg_th_off, out=self.act2)
                np.logical_or(act, self.act2, out=act)
            if noise is not None:
                act[noise[0]] = False  # these pixels' events come from noise_pixels
            nz = np.flatnonzero(act)
        parts = []
        if nz.size:
            parts.append(self.crossing_keys(nz, sig, mem, t_a, dt, q_one))
        if noise is not None:
            self.switch("shot_noise")
            parts.append(self.noise_keys(noise[1], t_a, dt, q_one))
            self.switch("dvs_pixel")
        if not parts:
            return
        keys = parts[0] if len(parts) == 1 else np.concatenate(parts)
        if keys.size == 0:
            return
        if self.out.would_grow(keys.size):
            self.drain()  # no write may be pending into arrays about to be replaced
        outputs = self.out.extend(keys.size)
        if self.pool is None:
            self.write_events(keys, t_a, dt / q_one, t_b, outputs)
        else:
            self.pending.append(self.pool.submit(self.write_events, keys, t_a, dt / q_one, t_b, outputs))

    def write_events(self, keys: np.ndarray, t_a: float, scale: float, t_b: float, outputs: list[np.ndarray]) -> None:
        """Sort one interval's keys and write the events into their slots of the output.

        Times are ``t_a + fraction * scale``, at most ``t_b`` (the interval's end as the loop holds
        it): a fraction near one can round above it, out of order with the next interval's events.
        """
        t, x, y, p = outputs
        keys.sort()
        pix_pol = keys & self.px.pix_mask
        for table, out in zip(self.luts, (x, y, p)):
            np.take(table, pix_pol, out=out, mode="clip")
        keys >>= self.px.pix_bits
        np.multiply(keys, scale, out=t)
        t += t_a
        np.minimum(t, t_b, out=t)

    def drain(self) -> None:
        """Wait for the pending writes (and raise their errors)."""
        pending, self.pending = self.pending, []
        for job in pending:
            job.result()

    def crossing_keys(self, nz, sig, mem, t_a, dt, q_one) -> np.ndarray:
        """Keys of the threshold crossings of the pixels ``nz``; moves their memorised level."""
        px = self.px
        d1a = self.d1[nz]
        on = d1a > 0
        pix_on = nz << 1
        pix_on |= on  # the key's low bits, and the index into _th_pair
        th = px.th_on[0] if px.symmetric else px.th_pair[pix_on]
        s = d1a / th
        np.trunc(s, out=s)
        mem_a = mem[nz]
        mem[nz] = mem_a + s * th
        # d = sig - mem at the interval start, in float64 (leak moved mem by leak * dt)
        if self.leak is not None:
            mem_a = mem_a + self.leak[nz] * np.float32(dt)
        d0 = np.subtract(sig[nz], mem_a, dtype=np.float64)
        # the first crossing is at fraction (sign * theta - d0) / (d1 - d0), the next ones follow
        # every theta / |d1 - d0|; in units of 2**-q_bits
        inv = np.subtract(d1a, d0)
        np.divide(q_one, inv, out=inv)
        f1 = np.subtract(np.copysign(th, d1a), d0, out=d0)
        f1 *= inv
        counts = np.abs(s, out=s)
        c_max = int(counts.max())
        # d1 == d0 meets a crossing pixel only through float32 rounding at a threshold; the
        # clamps (fmin/fmax drop NaN) keep such a crossing inside the interval
        if c_max > 1:
            step = np.abs(inv, out=inv)
            step *= th  # infinite only where d1 == d0, i.e. for single crossings
            np.fmin(f1, q_one - (counts - 1) * step, out=f1)
        else:
            np.fmin(f1, q_one, out=f1)
        np.fmax(f1, 0.0, out=f1)
        k1 = f1.astype(np.int64)
        k1 <<= px.pix_bits
        k1 |= pix_on
        if self.last_emit is not None and dt < self.refractory_s:
            return self.refractory_short(k1, step if c_max > 1 else None, counts, nz, t_a, dt, q_one)
        if self.last_emit is not None:
            level0, _ = self.refractory(k1, nz, t_a, dt, q_one)
        else:
            level0 = k1
        if c_max == 1:
            return level0
        return self.more_levels(level0, k1, step, counts, c_max, nz, t_a, dt, q_one)

    def refractory_short(self, k1, step, counts, nz, t_a, dt, q_one) -> np.ndarray:
        """Refractory filter for an interval shorter than the period.

        Each pixel can then emit at most one event in the interval: its first crossing at least
        ``period_s`` after its last emitted event. Crossing ``j`` of pixel ``i`` is at
        ``t_a + (q1[i] + j * qstep[i]) * dt / q_one``; ``j`` is found in closed form and then
        settled with the same float64 comparison as :meth:`refractory`.
        """
        outer = self.switch("refractory")
        P = self.px.pix_bits
        scale = dt / q_one
        period = self.refractory_s
        last = self.last_emit[nz]
        q1 = k1 >> P
        t = q1.astype(np.float64)
        t *= scale
        t += t_a
        ok = (t - last) >= period
        if step is None:  # one crossing per pixel
            emit = np.flatnonzero(ok)
            keys = k1[emit]
        else:
            late = np.flatnonzero(~ok & (counts > 1))  # pixels whose first crossing is too early
            emit = [np.flatnonzero(ok)]
            keys = [k1[emit[0]]]
            if late.size:
                qstep = step[late].astype(np.int64)
                q1l, lastl, cl = q1[late], last[late], counts[late].astype(np.int64)
                j = np.ceil(((lastl + period - t_a) / scale - q1l) / qstep)
                j = np.clip(j, 1, cl).astype(np.int64)
                q = q1l + j * qstep
                tl = q.astype(np.float64) * scale + t_a
                for _ in range(2):  # settle rounding of the closed form: forward, then back
                    early = (j < cl) & ((tl - lastl) < period)
                    j += early
                    back = (j > 1) & ((((q1l + (j - 1) * qstep) * scale + t_a) - lastl) >= period)
                    j -= back
                    q = q1l + j * qstep
                    tl = q.astype(np.float64) * scale + t_a
                sel = np.flatnonzero((j < cl) & ((tl - lastl) >= period))
                emit.append(late[sel])
                keys.append(k1[late[sel]] + ((j[sel] * qstep[sel]) << P))
                t[late[sel]] = tl[sel]
            emit = np.concatenate(emit)
            keys = np.concatenate(keys)
        self.last_emit[nz[emit]] = t[emit]
        self.switch(outer)
        return keys

    def more_levels(self, level0, k1, step, counts, c_max, nz, t_a, dt, q_one) -> np.ndarray:
        """Append the 2nd, 3rd, ... crossings: pixel i's j-th has key ``k1[i] + j * kstep[i]``."""
        multi = np.flatnonzero(counts > 1)
        c_multi = counts[multi].astype(np.int64)
        n_events = level0.size + int(c_multi.sum()) - multi.size
        refractory = self.last_emit is not None
        if c_max > MAX_LEVEL_LOOP and not refractory:
            # many levels: expand all at once with a cumulative sum
            kstep = step[multi].astype(np.int64)
            kstep <<= self.px.pix_bits
            c = c_multi - 1
            more = np.repeat(kstep, c)
            start = k1[multi] + kstep
            first = start.copy()
            first[1:] -= (start + (c - 1) * kstep)[:-1]
            more[np.cumsum(c) - c] = first
            np.cumsum(more, out=more)
            return np.concatenate([level0, more])
        # level by level, pixels with more crossings first so that level j is a prefix
        key_dtype = np.uint8 if c_max < 256 else (np.uint16 if c_max < 65536 else np.int64)
        order = multi[np.argsort((c_max - c_multi).astype(key_dtype), kind="stable")]
        kstep = step[order].astype(np.int64)
        kstep <<= self.px.pix_bits
        cur = k1[order]
        cur += kstep
        pix = nz[order] if refractory else None
        n_more = multi.size - np.cumsum(np.bincount(c_multi, minlength=c_max + 1))
        keys = np.empty(n_events, np.int64)
        keys[:level0.size] = level0
        at = level0.size
        for j in range(1, c_max):
            m = int(n_more[j])
            level = cur[:m]
            if refractory:
                level, _ = self.refractory(level, pix[:m], t_a, dt, q_one)
            keys[at:at + level.size] = level
            at += level.size
            if j + 1 < c_max:
                m2 = int(n_more[j + 1])
                cur[:m2] += kstep[:m2]
        return keys[:at]

    def noise_keys(self, events, t_a, dt, q_one) -> np.ndarray:
        pix_e, f_e, on_e = events
        keys = np.rint(f_e * q_one).astype(np.int64)
        keys <<= self.px.pix_bits
        keys |= pix_e << 1
        keys |= on_e
        if self.last_emit is None:
            return keys
        rank = np.arange(pix_e.size) - np.searchsorted(pix_e, pix_e, side="left")
        kept = []
        for j in range(int(rank.max()) + 1):
            sel = np.flatnonzero(rank == j)
            k_j, _ = self.refractory(keys[sel], pix_e[sel], t_a, dt, q_one)
            kept.append(k_j)
        return np.concatenate(kept)

    def refractory(self, keys, pix, t_a, dt, q_one):
        """:func:`refractory_filter` on this interval's keys, its time charged to the stage."""
        outer = self.switch("refractory")
        keys, pix = refractory_filter(keys, pix, t_a, dt / q_one, self.px.pix_bits, self.last_emit, self.refractory_s)
        self.switch(outer)
        return keys, pix

    # ------------------------------------------------------------------ output
    def result(self) -> EventStream:
        px = self.px
        t, x, y, p = self.out.finish()
        self.switch("dvs_pixel")
        stages = []
        for name, seconds in self.seconds.items():
            if name == "dvs_pixel":
                params = {"light": px.light, "threshold_on": px.threshold_on,
                          "threshold_off": px.threshold_off, "backend": self.backend}
            else:
                params = dict(self.effects[name].params)
            stage = {"name": name, "params": params, "seconds": seconds}
            if name in self.fused:
                stage["fused_into"] = "dvs_pixel"
            stages.append(stage)
        meta = {"stages": stages, "event_count": int(t.shape[0])}
        return EventStream.trusted(t, x, y, p, px.width, px.height, meta)
