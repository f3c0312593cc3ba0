"""Compiled (numba) kernels of the event camera's ideal pixel, with bandwidth and leak.

They repeat the NumPy path of :mod:`neuspike.sensors.event_camera` operation for operation, in
the same precision (float32 pixel state, float64 crossing times), so the events are the same bytes:

:func:`pixel_update`
    one pass over the pixels per sample interval: finish the lin-log (the ``log`` itself stays in
    NumPy, whose float32 ``log`` is not the C library's), the bandwidth low-pass, the leak, the
    difference ``d1 = sig_new - mem`` and the list of pixels that cross a threshold, with their
    number of events and the largest crossing count.
:func:`interval_keys`
    the crossings of those pixels as int64 keys ``(time fraction << P) | (pixel << 1) | ON`` (as
    in the NumPy path), their memorised levels moved. The caller orders the keys with NumPy's
    sort (vectorised, faster than any sort compiled here); the keys are a set of integers, so the
    order is the NumPy path's exactly.
:func:`write_events`
    the ordered keys decoded straight into the output arrays (t, x, y, p).

Import this module only where numba is importable (see :mod:`neuspike.sensors.backends`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["interval_keys", "pixel_update", "write_events"]

_INT64_MIN = np.int64(-(2 ** 63))
_TWO_63 = 9.223372036854775808e18


@njit(inline="always", error_model="numpy")
def _to_int64(x):
    """float64 -> int64 as NumPy's ``astype`` does on x86: NaN, inf and out-of-range give INT64_MIN."""
    if x < _TWO_63 and x > -_TWO_63:
        return np.int64(x)
    return _INT64_MIN


@njit(inline="always", error_model="numpy")
def _fmin(a, b):
    """NumPy's ``fmin``: the smaller, ignoring a NaN operand."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a <= b else b


@njit(cache=True, nogil=True, error_model="numpy")
def pixel_update(log_max, radiance, sig, mem, sig_new, d1, floor, slope, log_floor,
                 bandwidth, bw_gain, bw_offset, bw_clip, leak, leak_dt,
                 symmetric, th_on, th_off, active):
    """One interval's pixel state; returns ``(number of active pixels, their events, largest count)``.

    Parameters (n pixels; float32 unless said otherwise)
    ----------
    log_max : (n,) ``log(max(radiance, floor))`` computed by NumPy.
    radiance : (n,) the interval's end sample.
    sig : (n,) the (filtered) log at the interval start; not modified.
    mem : (n,) memorised level, leaked in place when ``leak`` is given.
    sig_new, d1 : (n,) outputs: the new (filtered) log, and ``sig_new - mem``.
    floor, slope, log_floor : the lin-log constants.
    bandwidth : bool; ``bw_gain``, ``bw_offset`` (float32) and ``bw_clip`` (bool) its eps terms.
    leak : (n,) leak per second or None; ``leak_dt`` float32 interval length.
    symmetric : bool, one threshold ``th_on[0]`` for both polarities; else per pixel
        ``th_on``, ``th_off``.
    active : (n,) int64 output: the pixels with ``|d1|`` at or past a threshold, ascending.
    """
    n = radiance.shape[0]
    one = np.float32(1)
    # first a branch-free pass the compiler vectorises: the new log, the leak, d1
    for i in range(n):
        x = radiance[i]
        lin = (x if x < floor else floor) * slope
        lin = lin - log_floor
        log_k = log_max[i] + lin
        if bandwidth:
            eps = x * bw_gain
            eps = eps + bw_offset
            if bw_clip:
                eps = one if eps > one else eps
            s_new = sig[i] + (log_k - sig[i]) * eps
        else:
            s_new = log_k
        sig_new[i] = s_new
        m = mem[i]
        if leak is not None:
            m = m - leak[i] * leak_dt
            mem[i] = m
        d1[i] = s_new - m
    # then the crossing pixels, their events and the largest count
    n_active = 0
    events = 0
    c_max = np.float32(0)
    th = th_on[0]
    for i in range(n):
        d = d1[i]
        if symmetric:
            if not abs(d) >= th:
                continue
            th_i = th
        else:
            # both compares, no short circuit: one branch per pixel, rarely taken
            if not ((d >= th_on[i]) | (d <= -th_off[i])):
                continue
            th_i = th_on[i] if d > 0 else th_off[i]
        active[n_active] = i
        n_active += 1
        c = abs(np.trunc(d / th_i))
        events += np.int64(c)
        if c > c_max:
            c_max = c
    return n_active, events, np.int64(c_max)


@njit(cache=True, nogil=True, error_model="numpy")
def interval_keys(active, n_active, c_max, d1, sig, mem, leak, leak_dt, symmetric, th_on, th_off,
                  q_one, pix_bits, keys):
    """The event keys of one interval into ``keys``; returns their number.

    ``active[:n_active]`` and ``c_max`` come from :func:`pixel_update`; ``mem`` (already leaked)
    moves by the emitted crossings. ``keys`` (int64) holds at least the interval's event count.
    Keys are ``(fraction << pix_bits) | (pixel << 1) | ON`` with the fraction of the interval in
    units of ``1 / q_one``, computed in float64 exactly as the NumPy path does (including its
    clamps and its float-to-int conversion of non-finite values).
    """
    th = th_on[0]
    one = np.float32(1)
    at = 0
    for a in range(n_active):
        i = active[a]
        d = d1[i]
        on = d > 0
        th_i = th if symmetric else (th_on[i] if on else th_off[i])
        s = np.trunc(d / th_i)
        m = mem[i]
        mem[i] = m + s * th_i
        if leak is not None:
            m = m + leak[i] * leak_dt
        d0 = np.float64(sig[i]) - np.float64(m)
        inv = q_one / (np.float64(d) - d0)
        signed_th = th_i if on else -th_i
        f1 = (np.float64(signed_th) - d0) * inv
        count = abs(s)
        if c_max > 1:
            step = abs(inv) * np.float64(th_i)
            f1 = _fmin(f1, q_one - np.float64(count - one) * step)
        else:
            step = 0.0
            f1 = _fmin(f1, q_one)
        if not f1 >= 0.0:  # fmax(f1, 0): NaN and negatives become 0
            f1 = 0.0
        k1 = (_to_int64(f1) << pix_bits) | ((np.int64(i) << 1) | np.int64(on))
        keys[at] = k1
        at += 1
        c = np.int64(count)
        if c > 1:
            kstep = _to_int64(step) << pix_bits
            k = k1
            for _ in range(1, c):
                k += kstep
                keys[at] = k
                at += 1
    return at


@njit(cache=True, nogil=True, error_model="numpy")
def write_events(keys, pix_bits, width, t_a, scale, t_out, x_out, y_out, p_out):
    """Decode sorted keys into events: ``t = t_a + fraction * scale`` (float64), x, y (uint16), p (int8 +-1)."""
    pix_mask = (np.int64(1) << pix_bits) - 1
    inv_width = 1.0 / width
    for e in range(keys.shape[0]):
        k = keys[e]
        low = k & pix_mask
        pix = low >> 1
        t_out[e] = np.float64(k >> pix_bits) * scale + t_a
        # pix // width without an integer division: a float estimate, corrected by one either way
        y = np.int64(np.float64(pix) * inv_width)
        y = y + 1 if (y + 1) * width <= pix else y
        y = y - 1 if y * width > pix else y
        x_out[e] = np.uint16(pix - y * width)
        y_out[e] = np.uint16(y)
        p_out[e] = np.int8(2 * (low & 1) - 1)
