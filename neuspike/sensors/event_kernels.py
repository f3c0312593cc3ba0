"""Compiled (numba) kernels of the event camera: the ideal pixel and every effect stage.

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
    order is the NumPy path's exactly. With a refractory period, each pixel's crossings pass its
    filter in time order (the NumPy path's level by level, or its closed form when the interval
    is shorter than the period).
:func:`noise_keys`
    the events of the pixels with shot noise in the interval (the draws themselves stay NumPy's,
    from the camera's generator): the segments between noise events, their crossings, the
    pixels' new memorised levels, and the keys through the refractory filter.
:func:`write_events`
    the ordered keys decoded straight into the output arrays (t, x, y, p).

Import this module only where numba is importable (see :func:`neuspike.utils.parallel.resolve_backend`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["interval_keys", "noise_keys", "pixel_update", "write_events"]

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
                  q_one, pix_bits, keys, exclude=None, last_emit=None, period=0.0, t_a=0.0, scale=0.0,
                  short=False):
    """The event keys of one interval into ``keys``; returns their number.

    ``active[:n_active]`` and ``c_max`` come from :func:`pixel_update`; ``mem`` (already leaked)
    moves by the emitted crossings. ``keys`` (int64) holds at least the interval's event count.
    Keys are ``(fraction << pix_bits) | (pixel << 1) | ON`` with the fraction of the interval in
    units of ``1 / q_one``, computed in float64 exactly as the NumPy path does (including its
    clamps and its float-to-int conversion of non-finite values).

    ``exclude``: ascending pixels left out (those with shot noise this interval, whose events
    :func:`noise_keys` builds); ``c_max`` is then recomputed over the others, as the NumPy path
    takes it. ``last_emit`` (float64 seconds per pixel, updated): the refractory period
    ``period``; an event at ``t_a + fraction * scale`` is dropped within ``period`` of its pixel's
    last emitted event. ``short`` (the interval is shorter than the period): each pixel emits at
    most its first allowed crossing, found by the NumPy path's closed form and settled the same way.
    """
    th = th_on[0]
    one = np.float32(1)
    n_ex = 0 if exclude is None else exclude.shape[0]
    if n_ex:
        # the largest count over the pixels that stay, as the NumPy path's crossing_keys sees it
        c_max = 0
        e = 0
        for a in range(n_active):
            i = active[a]
            while e < n_ex and exclude[e] < i:
                e += 1
            if e < n_ex and exclude[e] == i:
                continue
            d = d1[i]
            th_i = th if symmetric else (th_on[i] if d > 0 else th_off[i])
            c = np.int64(abs(np.trunc(d / th_i)))
            if c > c_max:
                c_max = c
    at = 0
    e = 0
    for a in range(n_active):
        i = active[a]
        if n_ex:
            while e < n_ex and exclude[e] < i:
                e += 1
            if e < n_ex and exclude[e] == i:
                continue
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
        c = np.int64(count)
        if last_emit is not None:
            at = _refractory_keys(k1, c, step, i, keys, at, pix_bits, last_emit, period, t_a, scale, short)
            continue
        keys[at] = k1
        at += 1
        if c > 1:
            kstep = _to_int64(step) << pix_bits
            k = k1
            for _ in range(1, c):
                k += kstep
                keys[at] = k
                at += 1
    return at


@njit(inline="always", error_model="numpy")
def _time_of(q, scale, t_a):
    return np.float64(q) * scale + t_a


@njit(inline="always", error_model="numpy")
def _refractory_keys(k1, c, step, i, keys, at, pix_bits, last_emit, period, t_a, scale, short):
    """Pixel ``i``'s crossings ``k1 + j * kstep`` (j < c) through the refractory filter; returns ``at``."""
    last = last_emit[i]
    q1 = k1 >> pix_bits
    t = _time_of(q1, scale, t_a)
    if not short:
        # every crossing in turn against the last emitted one (the NumPy path's level by level)
        kstep = _to_int64(step) << pix_bits if c > 1 else np.int64(0)
        k = k1
        for j in range(c):
            if j:
                k += kstep
                t = _time_of(k >> pix_bits, scale, t_a)
            if t - last >= period:
                keys[at] = k
                at += 1
                last = t
        last_emit[i] = last
        return at
    if t - last >= period:
        keys[at] = k1
        last_emit[i] = t
        return at + 1
    if c <= 1:
        return at
    # the first crossing is too early: the first allowed one in closed form, settled by comparisons
    qstep = _to_int64(step)
    jf = np.ceil(((last + period - t_a) / scale - np.float64(q1)) / np.float64(qstep))
    if jf != jf:
        j = _INT64_MIN
    else:
        jf = jf if jf > 1.0 else 1.0
        jf = jf if jf < c else np.float64(c)
        j = _to_int64(jf)
    tl = _time_of(q1 + j * qstep, scale, t_a)
    for _ in range(2):
        if j < c and (tl - last) < period:
            j += 1
        if j > 1 and (_time_of(q1 + (j - 1) * qstep, scale, t_a) - last) >= period:
            j -= 1
        tl = _time_of(q1 + j * qstep, scale, t_a)
    if j < c and (tl - last) >= period:
        keys[at] = k1 + ((j * qstep) << pix_bits)
        last_emit[i] = tl
        return at + 1
    return at


@njit(inline="always")
def _after(a, b):
    """``a`` sorts after ``b`` in NumPy's order (NaN last)."""
    return a > b or (a != a and b == b)


@njit(inline="always", error_model="numpy")
def _segment(k, r, e0, f_n, d_start, g, th_up, th_down):
    """Segment ``k`` of ``r + 1`` of a noise pixel: ``(f_a, d_a, d_b, rising, th, s)``."""
    f_a = 0.0 if k == 0 else f_n[e0 + k - 1]
    f_b = 1.0 if k == r else f_n[e0 + k]
    d_a = d_start if k == 0 else 0.0
    d_b = d_a + g * (f_b - f_a)
    rising = d_b > 0
    th = th_up if rising else th_down
    return f_a, d_a, d_b, rising, th, np.trunc(d_b / th)


@njit(cache=True, nogil=True, error_model="numpy")
def noise_keys(pix_n, f_n, on_n, sig, mem, d1, leak, dt, th_on, th_off, q_one, pix_bits,
               last_emit=None, period=0.0, t_a=0.0, scale=0.0):
    """All event keys of the pixels with shot noise in this interval; moves their memorised level.

    ``pix_n``, ``f_n``, ``on_n``: the interval's noise events sorted by pixel, then time. A noise
    event resets the pixel's memorised level to its signal, so each segment between noise events
    starts from a known difference (the first from the pixel's state, the others from zero) and
    ``d = sig - mem`` is linear within it. The NumPy path's ``noise_pixels`` and ``noise_keys``
    operation for operation (float64 segments, ``rint`` fractions, the same stable order per
    pixel, refractory in that order); returns ``(keys, the noise pixels ascending)``.
    """
    m = pix_n.shape[0]
    starts = np.empty(m + 1, np.int64)
    u = 0
    for e in range(m):
        if e == 0 or pix_n[e] != pix_n[e - 1]:
            starts[u] = e
            u += 1
    starts[u] = m
    pixels = np.empty(u, np.int64)
    d_starts = np.empty(u, np.float64)
    slopes = np.empty(u, np.float64)
    dt32 = np.float32(dt)
    most = 0  # the most events of one pixel
    total = 0
    for a in range(u):
        e0, e1 = starts[a], starts[a + 1]
        p = pix_n[e0]
        pixels[a] = p
        mem_start = np.float64(mem[p])
        if leak is not None:
            mem_start += np.float64(leak[p] * dt32)
        d_start = np.float64(sig[p]) - mem_start
        g = np.float64(d1[p]) - d_start
        d_starts[a], slopes[a] = d_start, g
        th_up, th_down = np.float64(th_on[p]), np.float64(th_off[p])
        n_ev = e1 - e0
        for k in range(e1 - e0 + 1):
            n_ev += _to_int64(abs(_segment(k, e1 - e0, e0, f_n, d_start, g, th_up, th_down)[5]))
        total += n_ev
        most = max(most, n_ev)
    keys = np.empty(total, np.int64)
    ev_f = np.empty(most, np.float64)
    ev_on = np.empty(most, np.bool_)
    sort_key = np.empty(most, np.float64)
    order = np.empty(most, np.int64)
    at = 0
    for a in range(u):
        e0, e1 = starts[a], starts[a + 1]
        r = e1 - e0
        p = pixels[a]
        d_start, g = d_starts[a], slopes[a]
        th_up, th_down = np.float64(th_on[p]), np.float64(th_off[p])
        # this pixel's events in the NumPy path's order: its segments' crossings, then its noise
        x = 0
        for k in range(r + 1):
            f_a, d_a, d_b, rising, th, s = _segment(k, r, e0, f_n, d_start, g, th_up, th_down)
            signed = th if rising else -th
            for j in range(1, _to_int64(abs(s)) + 1):
                ev_f[x] = f_a + (signed * np.float64(j) - d_a) / g
                ev_on[x] = rising
                x += 1
            if k == r:  # the last segment leaves the new memorised level
                mem[p] = (mem[p] + d1[p]) - np.float32(d_b - s * th)
        for e in range(e0, e1):
            ev_f[x] = f_n[e]
            ev_on[x] = on_n[e]
            x += 1
        base = np.float64(p)
        for e in range(x):
            f = ev_f[e]
            if f == f:  # np.clip(f, 0, 1); NaN stays NaN
                f = f if f > 0.0 else 0.0
                f = f if f < 1.0 else 1.0
                ev_f[e] = f
            sort_key[e] = base + f * 0.5
            # stable insertion by the NumPy path's key (pixel + fraction / 2; NaN last)
            y = e
            while y > 0 and _after(sort_key[order[y - 1]], sort_key[e]):
                order[y] = order[y - 1]
                y -= 1
            order[y] = e
        pix_on = np.int64(p) << 1
        last = 0.0 if last_emit is None else last_emit[p]
        for y in range(x):
            e = order[y]
            k = (_to_int64(np.rint(ev_f[e] * q_one)) << pix_bits) | pix_on | np.int64(ev_on[e])
            if last_emit is not None:
                t = _time_of(k >> pix_bits, scale, t_a)
                if not t - last >= period:
                    continue
                last = t
            keys[at] = k
            at += 1
        if last_emit is not None:
            last_emit[p] = last
    return keys[:at], pixels


@njit(cache=True, nogil=True, error_model="numpy")
def write_events(keys, pix_bits, width, t_a, scale, t_b, t_out, x_out, y_out, p_out):
    """Decode sorted keys into events: ``t = min(t_a + fraction * scale, t_b)`` (float64), x, y (uint16), p (int8 +-1).

    ``t_b`` is the interval's end as the caller holds it (the next interval's ``t_a``): a fraction
    near one can round above it, which would put the event after the next interval's first ones.
    """
    pix_mask = (np.int64(1) << pix_bits) - 1
    inv_width = 1.0 / width
    for e in range(keys.shape[0]):
        k = keys[e]
        low = k & pix_mask
        pix = low >> 1
        t = np.float64(k >> pix_bits) * scale + t_a
        t_out[e] = t if t < t_b else t_b
        # pix // width without an integer division: a float estimate, corrected by one either way
        y = np.int64(np.float64(pix) * inv_width)
        y = y + 1 if (y + 1) * width <= pix else y
        y = y - 1 if y * width > pix else y
        x_out[e] = np.uint16(pix - y * width)
        y_out[e] = np.uint16(y)
        p_out[e] = np.int8(2 * (low & 1) - 1)
