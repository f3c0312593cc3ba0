"""Compiled (numba) plane loops of the SNM-style baseline.

The same three layers as the torch reference in :mod:`baselines.snm` (``_integrate``), fused: for
each plane and each pixel of a row, the motion marks, refined current, cut and decay are computed and
accumulated in registers, instead of a few dozen full-frame tensor operations per plane. The float32
arithmetic follows the reference operation by operation (same formulas, same order, no fused
multiply-add) with one exception: the decay of an excited pixel, ``exp(-(1/tau + 1/(memory b)))``,
comes from a float32 Taylor series (:func:`_exp_near`) rather than torch's exp, so the two agree to
a few float32 roundings (the tests state the tolerance). The series covers ``motion_memory_isi`` of
about 0.91 ISI or more (:func:`fits_exp_range`); :mod:`baselines.snm` takes the reference path
otherwise.

Two passes over each band of rows, all bands in one parallel region (``prange``):

1. each pixel's motion marks per plane (a mark depends on the pixel's own spike train only), stored
   as bits of the band's own zero-padded uint8 array ``flags (T, rows + 2, W + 2)``: bit 0
   ``max(marked before, marked after)``, bit 1 ``marked after``; the rows just above and below the
   band are marked too (by both neighbouring bands), so no band waits for another;
2. the 3x3 motion excitation (the OR of bit 0 over each pixel's neighbourhood, read from the padded
   array, so the border needs no special case), the refined current, the cut and the reconstruction
   neuron.

Each row first tabulates, backwards in time, each plane's next spike and the ISI after it (the
reference's ``_next_spike_tables``), as float32 whole numbers in scratch of its own (exact up to
2**24 planes).

The inner loops run over the pixels of one row of one plane, load every operand unconditionally and
combine them with selects (no branch, no short-circuit, no array passed to an inlined helper, whose
reference counting would stop LLVM): that is what lets them vectorise (8 float32 lanes with AVX2).

Import this module only where numba is importable.
"""

from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, njit, prange

__all__ = ["EXP_HALF_RANGE", "fits_exp_range", "snm_integrate"]


_JIT = dict(cache=True, nogil=True, error_model="numpy")

@njit(**_JIT)
def _tables_row(s_row, np_in, ni_in, np_out, ni_out, j):
    """Plane ``j`` of the backward tables from plane ``j + 1`` (float32, whole numbers)."""
    fj = np.float32(j)
    zero = np.float32(0.0)
    for x in range(s_row.shape[0]):
        fired = s_row[x]
        nxt = np_in[x]
        isi = ni_in[x]
        opened = nxt - fj if nxt >= zero else zero
        ni_out[x] = opened if fired else isi
        np_out[x] = fj if fired else nxt


@njit(**_JIT)
def _next_tables(spikes, row, next_plane, next_isi):
    """Backward pass over one row: ``next_plane[j, x]``, the first spike at or after plane j (-1:
    none), and ``next_isi[j, x]``, the complete ISI that spike opens (0: none); float32."""
    num_planes = spikes.shape[0]
    next_plane[num_planes - 1, :] = -1.0
    next_isi[num_planes - 1, :] = 0.0
    _tables_row(spikes[num_planes - 1, row], next_plane[num_planes - 1], next_isi[num_planes - 1],
                next_plane[num_planes - 1], next_isi[num_planes - 1], num_planes - 1)
    for j in range(num_planes - 2, -1, -1):
        _tables_row(spikes[j, row], next_plane[j + 1], next_isi[j + 1], next_plane[j], next_isi[j], j)


@njit(**_JIT)
def _marks_row(s_row, np_row, ni_row, f_row, a, last, has_prev, cnt, thr, j):
    """Motion marks of one row on plane ``j`` into ``f_row[1:]`` (bit 0: either mark, bit 1: the
    mark after); the forward state (``a``, ``last``, ``has_prev``, spike count) advanced."""
    one = np.float32(1.0)
    zero = np.float32(0.0)
    fj = np.float32(j)
    for x in range(s_row.shape[0]):
        fired = s_row[x]
        n = np_row[x]
        c = ni_row[x]
        ax = a[x]
        lx = last[x]
        hp = has_prev[x]
        count = cnt[x]
        complete = (n >= zero) & (hp > zero)
        b = n - lx if complete else one
        m0 = complete & (ax > zero) & (abs(ax - b) - one > min(ax, b) * thr)
        m1 = complete & (c > zero) & (abs(b - c) - one > min(b, c) * thr)
        f_row[x + 1] = np.uint8(m0 | m1) | (np.uint8(m1) << np.uint8(1))
        offset = fj - lx
        a[x] = (offset if hp > zero else zero) if fired else ax
        last[x] = fj if fired else lx
        has_prev[x] = one if fired else hp
        cnt[x] = count + one if fired else count


@njit(**_JIT)
def _row_marks(spikes, row, thr, flags, frow, next_plane, next_isi, state):
    """The mark bits of image row ``row`` into ``flags[:, frow, 1:-1]``; returns nothing, leaves the
    row's spike count in ``state[3]`` and its next-spike tables in ``next_plane``, ``next_isi``."""
    _next_tables(spikes, row, next_plane, next_isi)
    state[0, :] = 0.0   # a: the ISI that ended at the last spike (0: unknown)
    state[1, :] = -1.0  # last: the last spike before plane j (-1: none)
    state[2, :] = 0.0   # has_prev: [last >= 0]
    state[3, :] = 0.0   # spikes so far
    for j in range(spikes.shape[0]):
        _marks_row(spikes[j, row], next_plane[j], next_isi[j], flags[j, frow], state[0], state[1], state[2],
                   state[3], thr, j)


#: Half-width of the argument range of :func:`_exp_near` (its accuracy holds within it).
EXP_HALF_RANGE = 0.55


@njit(inline="always", **_JIT)
def _exp_near(x, centre, exp_centre):
    """``exp(x)`` for float32 ``x`` within :data:`EXP_HALF_RANGE` of ``centre`` (``exp_centre`` =
    ``exp(centre)``), by a degree-9 Taylor series in float32 arithmetic (no call, so it vectorises):
    truncation below 4e-10, a few float32 roundings in all."""
    t = x - centre
    p = np.float32(1.0 / 362880.0)
    p = p * t + np.float32(1.0 / 40320.0)
    p = p * t + np.float32(1.0 / 5040.0)
    p = p * t + np.float32(1.0 / 720.0)
    p = p * t + np.float32(1.0 / 120.0)
    p = p * t + np.float32(1.0 / 24.0)
    p = p * t + np.float32(1.0 / 6.0)
    p = p * t + np.float32(0.5)
    p = p * t + np.float32(1.0)
    p = p * t + np.float32(1.0)
    return exp_centre * p


@njit(inline="always", **_JIT)
def _plane(fj, fired, n, c, ax, lx, hp, marks, centre, thr, dynamic, lost, kept_floor, decay_still,
           neg_motion_rate, static_rate, exp_arg_centre, exp_of_centre):
    """One pixel, one plane (scalars in and out, so no array reference is counted in the loops).

    ``n``, ``c``: the next spike and the ISI after it; ``ax``, ``lx``, ``hp``: the forward state
    (``a``, ``last``, ``[last >= 0]``); ``marks``: the OR of the 3x3 neighbourhood's mark bits;
    ``centre``: the pixel's own. Returns ``(current, mass_in, kept, decay, excited, a, last,
    has_prev)``: the refined current, 1 inside a complete ISI (else 0), the cut factor, the
    reconstruction neuron's decay on this plane, 1 where excited (else 0), and the forward state
    after the plane. Each line is the reference's tensor operation on one element, in its order.
    """
    one = np.float32(1.0)
    zero = np.float32(0.0)
    complete = (n >= zero) & (hp > zero)
    b = n - lx if complete else one
    # layer 1: the excitation (3x3 maximum of the marks) and this pixel's own "after" mark
    excite = (marks & np.uint8(1)) != np.uint8(0)
    after = (centre & np.uint8(2)) != np.uint8(0)
    # layer 2: spike refining, with the located change t_m where a > b > c or a < b < c
    mono = dynamic & complete & (ax > zero) & (c > zero) & ((ax - b) * (b - c) > zero)
    den = c - ax if mono else one
    t_m = ((c - b) * ax) / den
    t_m = t_m if mono else zero
    offset = fj - lx
    t1 = min(max((t_m - offset) + one, zero), one)
    t2 = (one - t1) / max(c, one)
    t1 = t1 / max(ax, one) + t2
    r = one / b
    current = (t1 - r) + r if mono else r
    current = current if complete else zero
    whole = np.float32(np.int32(t_m))  # t_m in (0, b) where mono: truncation, then ceil
    ceil_t_m = whole + one if whole < t_m else whole
    cut = ceil_t_m if mono else (b if after else zero)
    kept = min(abs(cut - offset) * lost + kept_floor, one)
    # layer 3: the decay of the reconstruction neuron, exp((1 / b) * (-1 / memory) - 1 / tau) where
    # excited inside a complete ISI, exp(-1 / tau) elsewhere
    moving = _exp_near(r * neg_motion_rate - static_rate, exp_arg_centre, exp_of_centre)
    decay = moving if excite & complete else decay_still
    mass_in = one if complete else zero
    # forward state: where the pixel fires, a <- j - last (if last exists), last <- j
    new_a = (offset if hp > zero else zero) if fired else ax
    new_last = fj if fired else lx
    new_hp = one if fired else hp
    return current, mass_in, kept, decay, one if excite else zero, new_a, new_last, new_hp


@njit(**_JIT)
def _before_row(j, at_key, s_row, np_row, ni_row, up, mid, down, a, last, has_prev, excited, charge, mass,
                kept_prev, thr, dynamic, lost, kept_floor, decay_still, neg_motion_rate, static_rate, exp_arg_centre,
                exp_of_centre):
    """Plane ``j <= key``: ``A <- (q A + x) * kept`` (no cut at the key plane itself)."""
    one = np.float32(1.0)
    fj = np.float32(j)
    for x in range(s_row.shape[0]):
        marks = (up[x] | up[x + 1] | up[x + 2] | mid[x] | mid[x + 1] | mid[x + 2]
                 | down[x] | down[x + 1] | down[x + 2])
        current, mass_in, kept, decay, excite, new_a, new_last, new_hp = _plane(
            fj, s_row[x], np_row[x], ni_row[x], a[x], last[x], has_prev[x], marks, mid[x + 1], thr, dynamic, lost,
            kept_floor, decay_still, neg_motion_rate, static_rate, exp_arg_centre, exp_of_centre)
        factor = one if at_key else kept
        cb = charge[x]
        mb = mass[x]
        ex = excited[x]
        charge[x] = (cb * decay + current) * factor
        mass[x] = (mb * decay + mass_in) * factor
        kept_prev[x] = kept
        excited[x] = ex + excite
        a[x] = new_a
        last[x] = new_last
        has_prev[x] = new_hp


@njit(**_JIT)
def _after_row(j, s_row, np_row, ni_row, up, mid, down, a, last, has_prev, excited, charge, mass, weight,
               kept_prev, thr, dynamic, lost, kept_floor, decay_still, neg_motion_rate, static_rate, exp_arg_centre,
               exp_of_centre, min_weight):
    """Plane ``j > key``, weighted by the product of the decays and cuts back to the key plane."""
    fj = np.float32(j)
    for x in range(s_row.shape[0]):
        marks = (up[x] | up[x + 1] | up[x + 2] | mid[x] | mid[x + 1] | mid[x + 2]
                 | down[x] | down[x + 1] | down[x + 2])
        current, mass_in, kept, decay, excite, new_a, new_last, new_hp = _plane(
            fj, s_row[x], np_row[x], ni_row[x], a[x], last[x], has_prev[x], marks, mid[x + 1], thr, dynamic, lost,
            kept_floor, decay_still, neg_motion_rate, static_rate, exp_arg_centre, exp_of_centre)
        w = max(weight[x] * kept_prev[x] * decay, min_weight)
        ca = charge[x]
        ma = mass[x]
        ex = excited[x]
        weight[x] = w
        charge[x] = ca + w * current
        mass[x] = ma + w * mass_in
        kept_prev[x] = kept
        excited[x] = ex + excite
        a[x] = new_a
        last[x] = new_last
        has_prev[x] = new_hp


@njit(**_JIT)
def _row_neurons(spikes, row, key_plane, flags, frow, thr, dynamic, lost, kept_floor, decay_still, neg_motion_rate,
                 static_rate, exp_arg_centre, exp_of_centre, min_weight, next_plane, next_isi, st, charge_out,
                 mass_out, excited_out):
    """Excitation, refined current, cut and the two reconstruction neurons of image row ``row``,
    whose marks are ``flags[:, frow]`` (the rows above and below at ``frow - 1``, ``frow + 1``)."""
    num_planes, _, width = spikes.shape
    _next_tables(spikes, row, next_plane, next_isi)
    # a, last, has_prev, excited planes; charge and mass up to the key plane; after it; the weight
    # of the plane after the key plane; the cut factor of the previous plane
    st[0:8, :] = 0.0
    st[1, :] = -1.0
    st[8:10, :] = 1.0
    for j in range(key_plane + 1):
        _before_row(j, j == key_plane, spikes[j, row], next_plane[j], next_isi[j], flags[j, frow - 1],
                    flags[j, frow], flags[j, frow + 1], st[0], st[1], st[2], st[3], st[4], st[5], st[9], thr,
                    dynamic, lost, kept_floor, decay_still, neg_motion_rate, static_rate, exp_arg_centre,
                    exp_of_centre)
    for j in range(key_plane + 1, num_planes):
        _after_row(j, spikes[j, row], next_plane[j], next_isi[j], flags[j, frow - 1], flags[j, frow],
                   flags[j, frow + 1], st[0], st[1], st[2], st[3], st[6], st[7], st[8], st[9], thr, dynamic, lost,
                   kept_floor, decay_still, neg_motion_rate, static_rate, exp_arg_centre, exp_of_centre, min_weight)
    for x in range(width):
        charge_out[row, x] = st[4, x] + st[6, x]
        mass_out[row, x] = st[5, x] + st[7, x]
        excited_out[row, x] = st[3, x]


@njit(parallel=True, **_JIT)
def _bands(spikes, key_plane, thr, dynamic, lost, kept_floor, decay_still, neg_motion_rate, static_rate,
           exp_arg_centre, exp_of_centre, min_weight, band_rows, count, first, charge, mass, excited):
    """Both passes, band by band in one parallel region: a band marks its rows and the row above
    and below it (recomputed by both neighbours, so bands need no barrier between the passes) into
    flags of its own, zero-padded, then runs the neurons of its rows."""
    num_planes, height, width = spikes.shape
    n_bands = (height + band_rows - 1) // band_rows
    for band in prange(n_bands):
        r0 = band * band_rows
        r1 = min(height, r0 + band_rows)
        flags = np.zeros((num_planes, r1 - r0 + 2, width + 2), dtype=np.uint8)
        next_plane = np.empty((num_planes, width), dtype=np.float32)
        next_isi = np.empty((num_planes, width), dtype=np.float32)
        st = np.empty((10, width), dtype=np.float32)
        for row in range(max(0, r0 - 1), min(height, r1 + 1)):
            _row_marks(spikes, row, thr, flags, row - r0 + 1, next_plane, next_isi, st)
            if r0 <= row < r1:
                for x in range(width):
                    count[row, x] = st[3, x]
                    first[row, x] = next_plane[0, x]
        for row in range(r0, r1):
            _row_neurons(spikes, row, key_plane, flags, row - r0 + 1, thr, dynamic, lost, kept_floor, decay_still,
                         neg_motion_rate, static_rate, exp_arg_centre, exp_of_centre, min_weight, next_plane,
                         next_isi, st, charge, mass, excited)


def fits_exp_range(motion_rate: float, num_planes: int) -> bool:
    """Whether the moving decay's argument over ISIs of 1 to ``num_planes`` planes lies within the
    range of :func:`_exp_near` (``motion_memory_isi`` of about 0.91 or more)."""
    return 0.5 * motion_rate * (1.0 - 1.0 / num_planes) <= EXP_HALF_RANGE


def snm_integrate(spikes: np.ndarray, key_plane: int, *, motion_threshold: float, dynamic_refining: bool,
                  lost_at_cut: float, static_rate: float, motion_rate: float, decay_still: np.float32,
                  min_weight: float) -> tuple[np.ndarray, ...]:
    """The plane loops of the SNM-style model, compiled.

    Parameters
    ----------
    spikes : ndarray bool (T, H, W), C-contiguous
    key_plane : int in [0, T)
    motion_threshold : float >= 0
    dynamic_refining : bool
    lost_at_cut : float in [0, 1)
        ``1 - exp(-step_forgetting)``.
    static_rate, motion_rate : float
        ``1 / tau`` (planes) and ``1 / motion_memory_isi``: the decay per plane is
        ``exp(-(static_rate + motion_rate / b))`` for an excited pixel inside a complete ISI of ``b``
        planes.
    decay_still : float32
        ``exp(-static_rate)``, the decay of every other pixel (as the reference computes it).
    min_weight : float
        Floor of the kernel weight of planes after the key plane.

    Returns
    -------
    charge, mass, count, first_spike, excited_planes : ndarray float32 (H, W)
        Refined charge (before the threshold step), running mass, spikes per pixel, plane of the
        first spike (-1 without one) and planes excited by motion.
    """
    num_planes, height, width = spikes.shape
    # the argument of the moving decay, (1 / b) * (-motion_rate) - static_rate for b in [1, T]
    lo, hi = -motion_rate - static_rate, -motion_rate / num_planes - static_rate
    if not fits_exp_range(motion_rate, num_planes):
        raise ValueError(f"motion_rate {motion_rate} spans more than the compiled exp's range")
    centre = 0.5 * (lo + hi)
    band_rows = max(1, -(-height // (4 * get_num_threads())))
    count = np.empty((height, width), dtype=np.float32)
    first = np.empty((height, width), dtype=np.float32)
    charge = np.empty((height, width), dtype=np.float32)
    mass = np.empty((height, width), dtype=np.float32)
    excited = np.empty((height, width), dtype=np.float32)
    _bands(spikes, int(key_plane), np.float32(motion_threshold), bool(dynamic_refining), np.float32(lost_at_cut),
           np.float32(1.0 - lost_at_cut), np.float32(decay_still), np.float32(-motion_rate), np.float32(static_rate),
           np.float32(centre), np.float32(math.exp(centre)), np.float32(min_weight), band_rows, count, first, charge,
           mass, excited)
    return charge, mass, count, first, excited
