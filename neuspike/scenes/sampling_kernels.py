"""Compiled (numba) bilinear sampling of the scenes, one pass per frame, frames in parallel.

The arithmetic is that of the NumPy paths in :mod:`neuspike.scenes.sampling`, element by element in
the same float32 order (each product rounded, then the sum; no fused multiply-add), so both give the
same frames bit for bit; the NumPy paths stay as the reference and the fallback where numba cannot
be imported. Frames are independent and run in parallel (``prange``) on
``numba.get_num_threads()`` threads.

Import this module only where numba is importable.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["sample_separable_frames", "sample_translated_frames"]


_JIT = dict(cache=True, nogil=True, error_model="numpy")


@njit(**_JIT)
def _translated_row(upper, lower, b, one_x, wx, one_y, wy, row):
    """One output row from two rows of the extended plane (a separate function: its loop vectorises).

    The four inputs are taken as slices first: indexed by the loop counter alone, the loads carry
    no negative-index wraparound test, which with ``upper[b + j]`` kept the loop scalar (4x slower).
    """
    n = row.shape[0]
    u0, u1 = upper[b:b + n], upper[b + 1:b + n + 1]
    l0, l1 = lower[b:b + n], lower[b + 1:b + n + 1]
    for j in range(n):
        top = u0[j] * one_x + u1[j] * wx
        bottom = l0[j] * one_x + l1[j] * wx
        row[j] = top * one_y + bottom * wy


@njit(parallel=True, **_JIT)
def sample_translated_frames(extended, iy, ix, fy, fx, out):
    """``out[t]`` (float32 (T, H, W)): the view whose top-left is at ``(ix[t] + fx[t], iy[t] + fy[t])``
    of the mirror-extended plane ``extended``; ``iy``, ``ix`` int64, ``fy``, ``fx`` float32 in [0, 1)."""
    num, height, _ = out.shape
    for t in prange(num):
        a = iy[t]
        wx = fx[t]
        wy = fy[t]
        one_x = np.float32(1.0) - wx
        one_y = np.float32(1.0) - wy
        for i in range(height):
            _translated_row(extended[a + i], extended[a + i + 1], ix[t], one_x, wx, one_y, wy, out[t, i])


@njit(**_JIT)
def _separable_row(upper, lower, x0, x1, fx, one_y, wy, row):
    """One output row between two plane rows, gathered at columns ``x0``, ``x1``."""
    for j in range(row.shape[0]):
        wx = fx[j]
        left = upper[x0[j]] * one_y + lower[x0[j]] * wy
        right = upper[x1[j]] * one_y + lower[x1[j]] * wy
        row[j] = left * (np.float32(1.0) - wx) + right * wx


@njit(parallel=True, **_JIT)
def sample_separable_frames(plane, x0, x1, fx, y0, y1, fy, out):
    """``out[t, i, j]`` (float32 (T, H, W)): bilinear sample of ``plane`` between columns
    ``x0[t, j]``, ``x1[t, j]`` (weight ``fx[t, j]`` on the second) and rows ``y0[t, i]``, ``y1[t, i]``
    (weight ``fy[t, i]``); indices int64 within the plane, weights float32."""
    num, height, _ = out.shape
    for t in prange(num):
        for i in range(height):
            wy = fy[t, i]
            _separable_row(plane[y0[t, i]], plane[y1[t, i]], x0[t], x1[t], fx[t], np.float32(1.0) - wy, wy,
                           out[t, i])
