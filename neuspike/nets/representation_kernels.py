"""Compiled (numba) kernels of NeuSpike-Net's representations, one window or a sliding run of them.

Per window (:func:`spike_window`, :func:`contrast_window`): one pass over the planes (rows in
parallel bands; each band keeps, per pixel, the running group count, the last spike and the centres
still waiting for their next spike) and one pass over the window's events; :func:`key_window`, the
interval sequence at the key instant, one more pass over the planes (rows in parallel). The float arithmetic is
the NumPy reference's, operation for operation (:mod:`neuspike.nets.representations`), so the
results are equal bit for bit.

Sliding (:func:`advance_spikes`, :func:`assemble_spikes`, :func:`advance_events`,
:func:`assemble_events`): each new plane and each new event is binned once into per-plane maps held
in rings of ``T + 1`` planes (spike count before plane k; last spike before plane k; first spike at
or after plane k within the chunk of planes it arrived with; signed event count before plane k); a
frame's representation is differences of the count maps at its group edges and, at each centre,
the last-spike map and the first-spike maps of its chunk and the later ones (:mod:`neuspike.nets.sliding`).
Every read is a whole row of a map, so the assembly streams through memory.

Import this module only where numba is importable (see :func:`neuspike.utils.parallel.resolve_backend`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["advance_events", "advance_spikes", "assemble_events", "assemble_spikes", "contrast_window",
           "counts_to_contrast", "key_window", "spike_window"]

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@njit(parallel=True, **_JIT)
def spike_window(u8, edges, centres, gain, band_rows, out):
    """Group rates then interval rates of a window, divided by ``gain``, into ``out``.

    ``u8`` (T, H, W) uint8 0/1 planes; ``edges`` (G + 1,) int64 group edges; ``centres`` (C,) int64
    increasing plane indices (empty for counts only); ``gain`` float32; ``out`` (G + C, H, W) float32.
    Channel g < G: ``(count_g / len_g) / gain``; channel G + k: ``(1 / (next - prev)) / gain`` with
    ``prev`` the last spike < centre (else -T) and ``next`` the first spike >= centre (else 2T).
    Per row, a forward pass over the planes counts and keeps the last spike, a backward pass keeps
    the next one; both are branch-free selects over a row that stays in cache between them.
    """
    t_len, h, w = u8.shape
    n_groups = edges.shape[0] - 1
    n_centres = centres.shape[0]
    n_bands = (h + band_rows - 1) // band_rows
    for b in prange(n_bands):
        counts = np.zeros(w, np.int32)
        last = np.empty(w, np.int32)
        nxt = np.empty(w, np.int32)
        prevs = np.empty((max(n_centres, 1), w), np.int32)
        for r in range(b * band_rows, min(h, (b + 1) * band_rows)):
            counts[:] = 0
            last[:] = -t_len
            g = 0
            ci = 0
            for t in range(t_len):
                if ci < n_centres and centres[ci] == t:
                    prevs[ci, :] = last
                    ci += 1
                row = u8[t, r]
                for x in range(w):
                    s = row[x]
                    counts[x] += s
                    last[x] = t if s else last[x]
                if t + 1 == edges[g + 1]:
                    length = np.float32(edges[g + 1] - edges[g])
                    for x in range(w):
                        out[g, r, x] = (np.float32(counts[x]) / length) / gain
                        counts[x] = 0
                    g += 1
            if n_centres == 0:
                continue
            nxt[:] = 2 * t_len
            ci = n_centres - 1
            for t in range(t_len - 1, centres[0] - 1, -1):
                row = u8[t, r]
                for x in range(w):
                    nxt[x] = t if row[x] else nxt[x]
                if centres[ci] == t:
                    for x in range(w):
                        out[n_groups + ci, r, x] = (np.float32(1.0) / np.float32(nxt[x] - prevs[ci, x])) / gain
                    ci -= 1


@njit(parallel=True, **_JIT)
def key_window(u8, centre, gain, out):
    """The interval sequence around plane ``centre`` divided by ``gain`` into ``out`` (5, H, W) float32
    (:func:`neuspike.nets.representations.key_intervals` with two intervals a side, bit for bit).

    Per row, a forward pass over the planes before the centre keeps each pixel's last three spikes
    (a shift register updated by products with the 0/1 plane, which vectorise) and a backward pass
    over the planes from the end down to the centre keeps the first three at or after it; both
    stream whole rows.
    """
    t_len, h, w = u8.shape
    for r in prange(h):
        p1 = np.full(w, -t_len, np.int32)
        p2 = np.full(w, -t_len, np.int32)
        p3 = np.full(w, -t_len, np.int32)
        n_b = np.zeros(w, np.int32)
        for t in range(centre):
            row = u8[t, r]
            for x in range(w):
                s = np.int32(row[x])  # 0 or 1: the selects as products, which vectorise
                p3[x] += s * (p2[x] - p3[x])
                p2[x] += s * (p1[x] - p2[x])
                p1[x] += s * (t - p1[x])
                n_b[x] += s
        a1 = np.full(w, 2 * t_len, np.int32)
        a2 = np.full(w, 2 * t_len, np.int32)
        a3 = np.full(w, 2 * t_len, np.int32)
        n_a = np.zeros(w, np.int32)
        for t in range(t_len - 1, centre - 1, -1):
            row = u8[t, r]
            for x in range(w):
                s = np.int32(row[x])
                a3[x] += s * (a2[x] - a3[x])
                a2[x] += s * (a1[x] - a2[x])
                a1[x] += s * (t - a1[x])
                n_a[x] += s
        for x in range(w):
            mid = np.float32(1.0) / np.float32(a1[x] - p1[x])
            out[2, r, x] = mid / gain
            one = np.float32(1.0) / np.float32(p1[x] - p2[x]) if n_b[x] >= 1 else mid
            out[1, r, x] = one / gain
            out[0, r, x] = (np.float32(1.0) / np.float32(p2[x] - p3[x]) if n_b[x] >= 2 else one) / gain
            one = np.float32(1.0) / np.float32(a2[x] - a1[x]) if n_a[x] >= 1 else mid
            out[3, r, x] = one / gain
            out[4, r, x] = (np.float32(1.0) / np.float32(a3[x] - a2[x]) if n_a[x] >= 2 else one) / gain


@njit(**_JIT)
def _bin_of(t, t0, span, bins):
    """``int((t - t0) / span * bins)`` clipped to ``[0, bins - 1]`` (float64, the reference's order)."""
    b = np.int64((t - t0) / span * bins)
    if b < 0:
        return 0
    if b > bins - 1:
        return bins - 1
    return b


@njit(parallel=True, **_JIT)
def contrast_window(t_s, x, y, p, t0, span, theta, out):
    """Signed event counts per time bin times ``theta``: ``out`` (bins, H, W) float32.

    The bin of an event is :func:`_bin_of`; it never decreases along the sorted events, so each bin's
    events are one run, found first, and the bins are filled in parallel, each in a count plane of its
    own that stays in cache, then written as ``float32(float64(count) * theta)`` (the reference's rounding).
    """
    bins, h, w = out.shape
    n = t_s.shape[0]
    starts = np.empty(bins + 1, np.int64)
    b = 0
    starts[0] = 0
    for i in range(n):
        bi = _bin_of(t_s[i], t0, span, bins)
        while b < bi:
            b += 1
            starts[b] = i
    while b < bins:
        b += 1
        starts[b] = n
    for k in prange(bins):
        plane = np.zeros((h, w), np.int32)
        for i in range(starts[k], starts[k + 1]):
            plane[y[i], x[i]] += p[i]
        for r in range(h):
            for c in range(w):
                out[k, r, c] = np.float32(np.float64(plane[r, c]) * theta)


@njit(parallel=True, **_JIT)
def counts_to_contrast(counts, theta, out):
    """``out = float32(float64(counts) * theta)`` (the reference's rounding), rows in parallel."""
    n, h, w = counts.shape
    for r in prange(h):
        for b in range(n):
            for c in range(w):
                out[b, r, c] = np.float32(np.float64(counts[b, r, c]) * theta)


#: "No spike known yet" in the first-spike ring.
NONE = np.int32(2**31 - 1)


@njit(parallel=True, **_JIT)
def advance_spikes(u8, k0, cnt_ring, last_ring, first_ring, running, last):
    """Bin the new planes ``k0 .. k0 + n - 1`` (``u8`` (n, H, W) uint8) once, as one chunk.

    Rings of R maps, plane k in slot ``k % R``: ``cnt_ring`` (uint32) the spikes before plane k;
    ``last_ring`` (int32) the last spike plane before k (from ``last``, the running one, -2**31 + 1
    for none); ``first_ring`` (int32) the first spike plane at or after k *within this chunk*
    (:data:`NONE` if none): a forward pass writes the first two, a backward pass the third.
    ``running`` (H, W) int64 and ``last`` (H, W) int32 carry on to the next chunk.
    """
    n_new, h, w = u8.shape
    ring = cnt_ring.shape[0]
    for r in prange(h):
        for j in range(n_new):
            k = k0 + j
            row = u8[j, r]
            cnt = cnt_ring[(k + 1) % ring, r]
            lst = last_ring[(k + 1) % ring, r]
            for c in range(w):
                s = row[c]
                running[r, c] += s
                last[r, c] = np.int32(k) if s else last[r, c]
                cnt[c] = np.uint32(running[r, c] & 0xFFFFFFFF)
                lst[c] = last[r, c]
        for j in range(n_new - 1, -1, -1):
            k = k0 + j
            row = u8[j, r]
            dst = first_ring[k % ring, r]
            if j == n_new - 1:
                for c in range(w):
                    dst[c] = np.int32(k) if row[c] else NONE
            else:
                nxt = first_ring[(k + 1) % ring, r]
                for c in range(w):
                    dst[c] = np.int32(k) if row[c] else nxt[c]


@njit(parallel=True, **_JIT)
def assemble_spikes(cnt_ring, last_ring, first_ring, ws, edges, centres, chunk_slots, centre_chunk, gain, out):
    """The window ``[ws, ws + T)`` (T = edges[-1]) from the rings: as :func:`spike_window`.

    ``chunk_slots`` (M,) int64: the ring slots of the starts of the chunks that cover the window, in
    time order; ``centre_chunk`` (C,) int64: the chunk of each centre. The next spike at or after a
    centre is its chunk's first-spike entry, else the first spike of the earliest later chunk that has one.
    """
    ring = cnt_ring.shape[0]
    n_groups = edges.shape[0] - 1
    n_centres = centres.shape[0]
    n_chunks = chunk_slots.shape[0]
    t_len = edges[n_groups]
    _, h, w = cnt_ring.shape
    edge_slot = (ws + edges) % ring  # ring slots, once per frame
    centre_slot = (ws + centres) % ring
    for r in prange(h):
        for g in range(n_groups):
            a = cnt_ring[edge_slot[g], r]
            z = cnt_ring[edge_slot[g + 1], r]
            length = np.float32(edges[g + 1] - edges[g])
            for c in range(w):
                out[g, r, c] = (np.float32(np.uint32(z[c] - a[c])) / length) / gain
        for k in range(n_centres):
            lst = last_ring[centre_slot[k], r]
            fst = first_ring[centre_slot[k], r]
            for c in range(w):
                prev = np.int64(lst[c]) - ws
                if prev < 0:  # no spike in [ws, centre)
                    prev = -t_len
                v = fst[c]
                j = centre_chunk[k] + 1
                while v == NONE and j < n_chunks:
                    v = first_ring[chunk_slots[j], r, c]
                    j += 1
                nxt = 2 * t_len if v == NONE else np.int64(v) - ws
                out[n_groups + k, r, c] = (np.float32(1.0) / np.float32(nxt - prev)) / gain


@njit(**_JIT)
def advance_events(t_s, x, y, p, splits, k0, ev_ring, running):
    """Bin new events once: events ``splits[j]:splits[j + 1]`` fall in plane ``k0 + j``; after plane
    k, ``ev_ring[(k + 1) % R]`` holds ``running`` (signed counts of every event binned so far, int32)."""
    ring = ev_ring.shape[0]
    for j in range(splits.shape[0] - 1):
        for i in range(splits[j], splits[j + 1]):
            running[y[i], x[i]] += p[i]
        ev_ring[(k0 + j + 1) % ring] = running


@njit(parallel=True, **_JIT)
def assemble_events(ev_ring, ws, bin_planes, counts):
    """Signed counts of ``counts.shape[0]`` bins of ``bin_planes`` planes from plane ``ws``: ring differences."""
    ring = ev_ring.shape[0]
    n, h, w = counts.shape
    slot = (ws + np.arange(n + 1) * bin_planes) % ring
    for r in prange(h):
        for b in range(n):
            a = ev_ring[slot[b], r]
            z = ev_ring[slot[b + 1], r]
            for c in range(w):
                counts[b, r, c] = z[c] - a[c]
