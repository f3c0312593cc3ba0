"""Tensor representations of sensor streams that networks and filters consume.

* :func:`voxel_grid` — the E2VID event voxel grid: ``B`` temporal bins, each event spread over the
  two nearest bins with bilinear weights in time, at its integer pixel position; optionally the
  non-zero entries are scaled to mean 0 and standard deviation 1 (the normalisation FireNet and
  E2VID expect).
* :func:`spike_bins` — spike planes summed in ``bins`` equal groups of consecutive planes (spike
  counts per bin).

Both are pure functions of their inputs (NumPy arrays in, NumPy arrays out).
"""

from __future__ import annotations

import numpy as np

from neuspike.utils.checks import check_positive_int
from neuspike.errors import InputError
from neuspike.streams import EventStream

__all__ = ["event_windows", "voxel_grid", "normalize_voxel_grid", "spike_bins", "spike_count"]


def normalize_voxel_grid(grid: np.ndarray) -> np.ndarray:
    """Scale the non-zero entries of a voxel grid to mean 0 and standard deviation 1.

    Zeros stay zero. The mean and the (population) standard deviation are taken over the non-zero
    entries only, as in E2VID. When fewer than two entries are non-zero, or when they are all
    equal (standard deviation 0), the non-zero entries are centred and not scaled, which makes
    them 0: such a grid carries no contrast to normalise, and no NaN or infinity can arise.

    Parameters
    ----------
    grid : ndarray, float, any shape (usually (B, H, W))

    Returns
    -------
    ndarray, float32, same shape as ``grid``.
    """
    g = np.asarray(grid, dtype=np.float32)
    nonzero = g != 0
    n = int(np.count_nonzero(nonzero))
    out = np.zeros_like(g)
    if n == 0:
        return out
    values = g[nonzero].astype(np.float64)
    mean = values.mean()
    std = values.std()
    if n < 2 or not std > 0:
        return out
    out[nonzero] = ((values - mean) / std).astype(np.float32)
    return out


def voxel_grid(
    events: EventStream,
    *,
    bins: int,
    t0_s: float,
    t1_s: float,
    height: int,
    width: int,
    normalize: bool,
) -> np.ndarray:
    """The E2VID voxel grid of the events in ``[t0_s, t1_s]``.

    Each event i at pixel (y_i, x_i) with polarity p_i in {-1, +1} and time t_i has the normalised
    time ``t*_i = (B - 1)(t_i - t0_s) / (t1_s - t0_s)`` in [0, B - 1] and adds
    ``p_i * max(0, 1 - |b - t*_i|)`` to bin ``b`` at its pixel, for every ``b`` in 0..B-1. The
    absolute weights of one event sum to 1.

    Parameters
    ----------
    events : EventStream
        The events to accumulate; every timestamp must lie in ``[t0_s, t1_s]`` (select them first,
        e.g. with ``EventStream.between``; events outside are an error, not silently dropped).
    bins : int
        Number of temporal bins B (>= 1). With B = 1 every event adds its full polarity to the
        single bin.
    t0_s, t1_s : float
        The time span in seconds mapped onto bins 0 .. B-1; ``t1_s > t0_s``.
    height, width : int
        Output size; must equal the event stream's sensor size.
    normalize : bool
        When ``True``, scale the non-zero entries to mean 0 and std 1 (:func:`normalize_voxel_grid`).
        Required because it changes the answer: FireNet expects it, FireNet+ does not.

    Returns
    -------
    ndarray, float32, shape (B, H, W). Without normalisation, entries are signed sums of event
    weights (units: events).

    Raises
    ------
    InputError
        On a non-positive bin count, a time span that is not finite and increasing, a size that does
        not match the stream, or events outside ``[t0_s, t1_s]``.
    """
    bins = check_positive_int("bins", bins)
    height = check_positive_int("height", height)
    width = check_positive_int("width", width)
    if not isinstance(events, EventStream):
        raise InputError(f"events: expected an EventStream, got {type(events).__name__}")
    if (events.height, events.width) != (height, width):
        raise InputError(
            f"voxel_grid: the events come from a {events.width}x{events.height} sensor, "
            f"the grid is {width}x{height}"
        )
    t0 = float(t0_s)
    t1 = float(t1_s)
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise InputError(f"voxel_grid: expected finite times with t1_s > t0_s, got t0_s={t0_s!r}, t1_s={t1_s!r}")
    n = len(events)
    flat = np.zeros(bins * height * width, dtype=np.float64)
    if n:
        t = events.t_s
        if t[0] < t0 or t[-1] > t1:
            raise InputError(
                f"voxel_grid: events span [{t[0]!r}, {t[-1]!r}] s, outside the grid's span [{t0!r}, {t1!r}] s"
            )
        pixel = events.y.astype(np.int64) * width + events.x.astype(np.int64)
        polarity = events.p.astype(np.float64)
        if bins == 1:
            flat += np.bincount(pixel, weights=polarity, minlength=height * width)
        else:
            tn = (bins - 1) * (t - t0) / (t1 - t0)
            lower = np.floor(tn).astype(np.int64)
            np.minimum(lower, bins - 2, out=lower)  # t* = B - 1 goes wholly to the last bin
            frac = tn - lower
            plane = height * width
            flat += np.bincount(lower * plane + pixel, weights=polarity * (1.0 - frac), minlength=flat.size)
            flat += np.bincount((lower + 1) * plane + pixel, weights=polarity * frac, minlength=flat.size)
    grid = flat.reshape(bins, height, width).astype(np.float32)
    if normalize:
        grid = normalize_voxel_grid(grid)
    return grid


def spike_bins(planes: np.ndarray, bins: int) -> np.ndarray:
    """Spike counts in ``bins`` equal groups of consecutive planes.

    Parameters
    ----------
    planes : ndarray of bool (or 0/1 integers), shape (T, H, W)
        Spike planes; T must be a multiple of ``bins`` (no planes are dropped silently).
    bins : int
        Number of groups (>= 1).

    Returns
    -------
    ndarray, float32, shape (bins, H, W): the number of spikes of each pixel in each group of
    T / bins planes (whole numbers in [0, T / bins]).

    Raises
    ------
    InputError
        When ``planes`` is not 3-D or T is not a multiple of ``bins``.
    """
    bins = check_positive_int("bins", bins)
    a = np.asarray(planes)
    if a.ndim != 3:
        raise InputError(f"spike_bins: expected planes of shape (T, H, W), got {a.shape}")
    t, h, w = a.shape
    if t == 0 or t % bins:
        raise InputError(f"spike_bins: {t} planes cannot be split into {bins} equal groups")
    if a.dtype == np.bool_:
        a = a.view(np.uint8)
    per = t // bins
    counts = np.empty((bins, h, w), dtype=np.float32)
    for b in range(bins):
        counts[b] = a[b * per:(b + 1) * per].sum(axis=0, dtype=np.uint32)
    return counts


# A uint8 accumulator holds the count of up to 255 planes.
_UINT8_PLANES = 255


def spike_count(planes: np.ndarray) -> np.ndarray:
    """Spikes per pixel over all planes of ``planes``.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)

    Returns
    -------
    ndarray of unsigned integers, shape (H, W): uint8 when T <= 255, else uint32.
    """
    n = planes.shape[0]
    u8 = planes.view(np.uint8)  # bool and uint8 share their layout: 0 or 1 per byte
    if n <= _UINT8_PLANES:
        hw = planes.shape[1] * planes.shape[2]
        if hw % 8 == 0 and planes.flags.c_contiguous:
            # Eight pixels per 64-bit word: each byte lane sums at most 255 ones, so no carry
            # crosses into the next pixel, and viewing the word sums as bytes gives the counts.
            words = u8.reshape(n, hw // 8 * 8).view(np.uint64)
            return np.add.reduce(words, axis=0).view(np.uint8).reshape(planes.shape[1:])
        return np.add.reduce(u8, axis=0, dtype=np.uint8)
    count = np.zeros(planes.shape[1:], dtype=np.uint32)
    for s in range(0, n, _UINT8_PLANES):
        count += np.add.reduce(u8[s : s + _UINT8_PLANES], axis=0, dtype=np.uint8)
    return count


def event_windows(t_s: np.ndarray, *, events_per_window: int, end_s: float,
                  max_windows: int) -> list[tuple[int, int, float, float]]:
    """Split sorted event times into fixed-count windows counted back from ``end_s``.

    Parameters
    ----------
    t_s : ndarray float64 (N,)
        Sorted event times, all ``< end_s``.
    events_per_window : int
        Events per window (the oldest window may hold fewer).
    end_s : float
        End of the last window, in seconds.
    max_windows : int
        Keep only the most recent windows.

    Returns
    -------
    list of ``(i0, i1, t0_s, t1_s)``, oldest first: events ``i0:i1`` fall in ``[t0_s, t1_s]``, with
    ``t0_s`` the first event's time and ``t1_s`` the next window's first event time (``end_s`` for
    the last). An empty input gives an empty list. When all of a window's events and its end share
    one timestamp, ``t1_s`` is the next representable float after ``t0_s``.
    """
    n = int(t_s.shape[0])
    if n == 0:
        return []
    ends = list(range(n, 0, -events_per_window))[:max_windows]
    windows = []
    next_start = float(end_s)
    for i1 in ends:
        i0 = max(0, i1 - events_per_window)
        t0 = float(t_s[i0])
        t1 = next_start if next_start > t0 else float(np.nextafter(t0, np.inf))
        windows.append((i0, i1, t0, t1))
        next_start = t0
    return windows[::-1]
