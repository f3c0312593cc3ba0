"""Compiled (numba) integrate-and-fire kernels of the spike camera.

One fused pass per band of rows: convert, scale, add the dark charge, integrate, compare, reset
and emit, with the float32 arithmetic in exactly the order given in
:mod:`neuspike.sensors.spike_camera` (so the planes equal the NumPy path's bit for bit). Bands are
independent and run in parallel (``prange``) on ``numba.get_num_threads()`` threads.

Validation happens in the same pass at the cost of one compare per value: each band counts the
radiance values below zero (after conversion to float32). NaN is not counted there but can never
leave the charge (``NaN + x`` is NaN and ``NaN >= phi`` is false), nor can +inf; so a caller that
finds no negative value and a finite final charge knows every value was finite and >= 0, and
otherwise looks for the offending frame in a slow path that runs only on bad input.

Import this module only where numba is importable (see :func:`neuspike.utils.parallel.resolve_backend`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["PACK_MAGIC", "fire_packed", "fire_planes"]

#: ``(x * PACK_MAGIC) >> 56`` turns eight 0/1 bytes of a little-endian uint64 ``x`` (byte i = pixel i)
#: into one byte whose bit i is pixel i: byte i lands on bit 56 + i, every other partial product
#: either leaves the 64 bits or stays below bit 56, and no two share a bit, so nothing carries.
PACK_MAGIC = np.uint64(0x0102040810204080)


@njit(inline="always", error_model="numpy")
def _fire_row(frame, light, threshold, charge, out):
    """One row of one plane, in the documented float32 order; returns the count of values < 0."""
    negative = 0
    for c in range(frame.shape[0]):
        f = np.float32(frame[c])
        negative += f < 0
        v = charge[c] + f * light
        s = v >= threshold
        charge[c] = v - threshold if s else v
        out[c] = s
    return negative


@njit(inline="always", error_model="numpy")
def _fire_row_dark(frame, light, threshold, charge, dark, out):
    """:func:`_fire_row` with a dark charge added to the drive."""
    negative = 0
    for c in range(frame.shape[0]):
        f = np.float32(frame[c])
        negative += f < 0
        v = charge[c] + (f * light + dark[c])
        s = v >= threshold
        charge[c] = v - threshold if s else v
        out[c] = s
    return negative


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def fire_planes(frames, hold, light, threshold, charge, dark, band_rows, out, negatives):
    """Bool planes ``out`` (K * hold, H, W); ``charge`` (H, W) float32 is updated in place.

    ``frames`` (K, H, W) float32; ``light`` and ``threshold`` float32; ``dark`` (H, W)
    float32 or ``None`` (a separate specialisation); ``negatives`` (number of bands,) int64 receives each band's
    count of radiance values < 0 (counted once per frame, on its first plane).
    """
    k_frames, h, w = frames.shape
    n_bands = (h + band_rows - 1) // band_rows
    for b in prange(n_bands):
        r0 = b * band_rows
        r1 = min(h, r0 + band_rows)
        negative = 0
        for k in range(k_frames):
            for i in range(hold):
                j = k * hold + i
                for r in range(r0, r1):
                    if dark is None:  # resolved at compile time: one specialisation each
                        n = _fire_row(frames[k, r], light, threshold, charge[r], out[j, r])
                    else:
                        n = _fire_row_dark(frames[k, r], light, threshold, charge[r], dark[r], out[j, r])
                    if i == 0:
                        negative += n
        negatives[b] = negative


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def fire_packed(frames, hold, light, threshold, charge, dark, band_rows, out, negatives):
    """As :func:`fire_planes`, writing the planes bit-packed in the Vidar ``.dat`` layout.

    ``out`` is uint8 (K * hold, H * W / 8): each plane is flipped vertically (stored row ``s`` is
    image row ``H - 1 - s``) and flattened, and stored pixel ``p`` is bit ``p % 8`` of byte
    ``p // 8``. Bands are counted in stored rows, and ``band_rows`` must be a multiple of 8 (every
    band then starts on a byte and its scratch row buffer is a whole number of uint64 words);
    ``H * W`` must be a multiple of 8.
    """
    k_frames, h, w = frames.shape
    n_bands = (h + band_rows - 1) // band_rows
    band_pixels = band_rows * w
    for b in prange(n_bands):
        s0 = b * band_rows
        s1 = min(h, s0 + band_rows)
        n_bytes = ((s1 - s0) * w) >> 3
        first_byte = (s0 * w) >> 3
        bits = np.zeros(band_pixels, np.bool_)  # the band's spikes, stored order, one byte each
        words = bits.view(np.uint64)
        negative = 0
        for k in range(k_frames):
            for i in range(hold):
                j = k * hold + i
                # image rows ascending (memory order: descending rows defeat the prefetcher),
                # each into its stored row of the scratch buffer
                for r in range(h - s1, h - s0):
                    a = (h - 1 - r - s0) * w
                    if dark is None:
                        n = _fire_row(frames[k, r], light, threshold, charge[r], bits[a:a + w])
                    else:
                        n = _fire_row_dark(frames[k, r], light, threshold, charge[r], dark[r], bits[a:a + w])
                    if i == 0:
                        negative += n
                plane = out[j]
                for q in range(n_bytes):
                    plane[first_byte + q] = np.uint8((words[q] * PACK_MAGIC) >> np.uint64(56))
        negatives[b] = negative
