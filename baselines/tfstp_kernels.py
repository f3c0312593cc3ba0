"""Compiled (numba) state update of TFSTP.

The plane loop of :func:`baselines.tfstp.tfstp_state` fused into one pass per band of rows: each
pixel visits its own spikes and updates its two states, in float64 with the operations of the NumPy
reference (:func:`baselines.tfstp._step_inplace`) in the same order, so the states are equal bit for
bit; :func:`tfstp_rate_fused` reads the rate out in the same pass (``math.log1p``, the C library's, as the reference).
Bands are independent and run in parallel (``prange``) on ``numba.get_num_threads()`` threads.

Import this module only where numba is importable.
"""

from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, njit, prange
from numba.cpython.unsafe.numbers import trailing_zeros

__all__ = ["stp_states", "tfstp_rate_fused"]


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def _states(planes, num_planes, decay_r, decay_u, u0, f, band_rows, q, v):
    """``q = 1 - R`` and ``v = u - u0`` (H, W) float64 after the spikes of planes ``0 .. num_planes - 1``.

    ``decay_r[lag]`` and ``decay_u[lag]`` are ``exp(-lag / D)`` and ``exp(-lag / F)`` for lags up to
    ``num_planes`` and 0 beyond (a first spike sees a lag above ``num_planes`` and leaves the resting
    state at rest).

    Per row, the spike trains are first packed into one bit mask per pixel and 64 planes (a
    vectorised pass over the planes); each pixel then visits only its own spikes, in time order,
    with its states in registers (``trailing_zeros`` finds the next spike), instead of testing
    every plane of every pixel.
    """
    height, width = planes.shape[1], planes.shape[2]
    n_bands = (height + band_rows - 1) // band_rows
    n_words = (num_planes + 63) // 64
    for band in prange(n_bands):
        masks = np.empty((n_words, width), dtype=np.uint64)
        for row in range(band * band_rows, min(height, (band + 1) * band_rows)):
            masks[:] = 0
            for j in range(num_planes):
                _pack_plane(planes[j, row], masks[j >> 6], np.uint64(j & 63))
            for x in range(width):
                q[row, x], v[row, x] = _pixel_states(masks, x, num_planes, decay_r, decay_u, u0, f)


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def _rate_fused(planes, num_planes, decay_r, decay_u, u0, d, big_f, f, tiny, band_rows, out):
    """The states (as :func:`_states`) and the read-out of each band in one parallel region (one
    launch, one barrier: on a shared machine every barrier waits for a descheduled thread). Returns
    the number of saturated read-outs."""
    height, width = planes.shape[1], planes.shape[2]
    n_bands = (height + band_rows - 1) // band_rows
    n_words = (num_planes + 63) // 64
    bad = 0
    for band in prange(n_bands):
        masks = np.empty((n_words, width), dtype=np.uint64)
        for row in range(band * band_rows, min(height, (band + 1) * band_rows)):
            masks[:] = 0
            for j in range(num_planes):
                _pack_plane(planes[j, row], masks[j >> 6], np.uint64(j & 63))
            for x in range(width):
                qx, vx = _pixel_states(masks, x, num_planes, decay_r, decay_u, u0, f)
                rate, saturated = _pixel_rate(qx, vx, u0, d, big_f, f, tiny)
                out[row, x] = rate
                bad += saturated
    return bad


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _pixel_states(masks, x, num_planes, decay_r, decay_u, u0, f):
    """One pixel's ``(q, v)`` after its spikes (bit masks ``masks[:, x]``), as in :func:`_states`."""
    one_minus_u0 = 1.0 - u0
    keep_v = 1.0 - f
    step_v = f * (1.0 - u0)
    last = -(num_planes + 1)
    qx = 0.0
    vx = 0.0
    for w in range(masks.shape[0]):
        bits = masks[w, x]
        while bits:
            j = w * 64 + np.int64(trailing_zeros(bits))
            bits &= bits - np.uint64(1)
            lag = j - last
            last = j
            qx *= one_minus_u0 - vx
            qx += u0
            qx += vx
            qx *= decay_r[lag]
            vx *= keep_v
            vx += step_v
            vx *= decay_u[lag]
    return qx, vx


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _pixel_rate(qx, vx, u0, d, big_f, f, tiny):
    """One pixel's read-out as in :func:`baselines.tfstp.tfstp_rate`: ``(rate, saturated read-outs)``."""
    rate_r = 0.0
    rate_u = 0.0
    bad = 0
    if qx > 0:
        rate_r = _inverse_interval(d, (u0 + vx) * (1.0 - qx), qx, tiny)
        if rate_r < 0:
            bad += 1
    if vx > 0:
        rate_u = _inverse_interval(big_f, f * ((1.0 - u0) - vx), vx, tiny)
        if rate_u < 0:
            bad += 1
    rate = rate_r + rate_u
    return (rate * 0.5 if rate_r > 0 and rate_u > 0 else rate), bad


@njit(cache=True, nogil=True, error_model="numpy")
def _pack_plane(s_row, mask_row, bit):
    """Set bit ``bit`` of ``mask_row[x]`` where ``s_row[x]`` (one plane of one row)."""
    for x in range(s_row.shape[0]):
        mask_row[x] |= np.uint64(s_row[x]) << bit


def stp_states(planes: np.ndarray, num_planes: int, decay_r: np.ndarray, decay_u: np.ndarray, u0: float,
               f: float) -> tuple[np.ndarray, np.ndarray]:
    """The states after the spikes of planes ``0 .. num_planes - 1`` of ``planes`` (bool (T, H, W)).

    Returns ``q = 1 - R`` and ``v = u - u0``, float64 (H, W).
    """
    height, width = planes.shape[1], planes.shape[2]
    q = np.empty((height, width))
    v = np.empty((height, width))
    band_rows = max(1, -(-height // (4 * get_num_threads())))
    _states(planes, int(num_planes), decay_r, decay_u, float(u0), float(f), band_rows, q, v)
    return q, v


@njit(cache=True, nogil=True, error_model="numpy")
def _inverse_interval(tau, a, b, tiny):
    """``1 / (tau log1p(a / b))`` as in the reference (a difference of logarithms below ``tiny``);
    -1 where the logarithm is not positive (a saturated state)."""
    log_term = math.log1p(a / b) if b >= tiny else math.log(a + b) - math.log(b)
    return 1.0 / (tau * log_term) if log_term > 0 else -1.0


def tfstp_rate_fused(planes: np.ndarray, num_planes: int, decay_r: np.ndarray, decay_u: np.ndarray, u0: float,
                     d: float, big_f: float, f: float, tiny: float) -> tuple[np.ndarray, int]:
    """The TFSTP rate (float64 (H, W)) after the spikes of planes ``0 .. num_planes - 1`` and the
    number of saturated read-outs (the caller raises if any): states and read-out in one pass."""
    height, width = planes.shape[1], planes.shape[2]
    out = np.empty((height, width))
    band_rows = max(1, -(-height // (4 * get_num_threads())))
    bad = _rate_fused(planes, int(num_planes), decay_r, decay_u, float(u0), float(d), float(big_f), float(f),
                      float(tiny), band_rows, out)
    return out, int(bad)
