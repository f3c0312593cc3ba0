"""TFI, texture from interval: the inverse of the inter-spike interval around the key plane.

For the key plane ``k`` of a window of ``T`` planes, ``t_prev`` is the last plane at or before ``k``
in which the pixel fired and ``t_next`` the first plane after ``k``; the interval is
``ISI = t_next - t_prev`` planes (>= 1), the rate ``1 / ISI`` spikes per plane and the radiance
``(1 / ISI - d) / gain`` with ``d`` the sensor's dark rate (known, or estimated from the window:
:func:`neuspike.methods.normalisation.dark_level`). An ideal integrate-and-fire pixel with constant rate ``a`` has intervals of
``floor(1 / a)`` or ``ceil(1 / a)`` planes, so the estimate lies in ``[1 / ceil(1/a), 1 / floor(1/a)]``.

Pixels without a spike on one side
----------------------------------
The window shows no spike in ``[0, k]`` (or in ``(k, T)``), so the missing spike lies outside it:
``t_prev <= -1`` (or ``t_next >= T``). The interval is then only known to be *at least* the
distance to the window's far edge, and the estimate uses that bound: a *virtual spike just outside the
window*, ``t_prev = -1`` and ``t_next = T``. Thus

* spike before only:  ``ISI = T - t_prev``;
* spike after only:   ``ISI = t_next + 1``;
* no spike at all:    ``ISI = T + 1``, the rate ``1 / (T + 1)``.

One rule covers every case, and for these pixels the estimate is the largest rate consistent with
what the window shows (an upper bound); ``1 / (T + 1)`` is the detection floor of a ``T``-plane
window. The estimate also stays continuous: a pixel with one spike at the window's edge reads
``1 / T``, a silent one ``1 / (T + 1)``, where a rate of 0 for the silent pixel would set them
infinitely far apart. No constant enters but the window's length (the field's tools put an interval
of 40 planes there).

Below the window's detection floor
-----------------------------------
Where the gain is known and so small that the floor ``1 / (T + 1)`` maps above white
(``gain * (T + 1) < 1``: a very dark scene or a short window), the bound would turn every pixel
that lacks a spike on a side white, the darkest brightest. There the pixels without a spike on a
side take the window's count instead, ``n / T`` (0 for a silent pixel), and the label says so.

TFI searches every plane of the sample's spike window; a sample with a shorter window searches fewer.
"""

from __future__ import annotations

import numpy as np

from neuspike.utils.checks import check_spike_window
from neuspike.methods.normalisation import stream_rate_to_image
from neuspike.errors import InputError
from neuspike.methods import Method
from neuspike.sample import Sample

# Weights 1..255 fit a uint8; each chunk of this many planes is searched with one uint8 accumulator.
_UINT8_PLANES = 255


def planes_to_first_spike(planes: np.ndarray) -> np.ndarray:
    """Per pixel, the index of the first plane (along axis 0) in which the pixel fired.

    Parameters
    ----------
    planes : ndarray of bool, shape (N, H, W)
        Planes ordered nearest first (any stride along axis 0, e.g. a reversed view).

    Returns
    -------
    ndarray (H, W) of integers in [0, N]
        The index of the first spike, ``N`` where the pixel never fired; uint8 when N <= 255,
        int32 otherwise.
    """
    if not isinstance(planes, np.ndarray) or planes.ndim != 3 or planes.dtype != np.bool_:
        raise InputError(
            f"planes: expected a bool array (N, H, W), got {getattr(planes, 'dtype', type(planes).__name__)} "
            f"of shape {np.shape(planes)}"
        )
    n, h, w = planes.shape
    if n == 0:
        return np.zeros((h, w), dtype=np.uint8)
    u8 = planes.view(np.uint8)  # 0 or 1 per byte
    acc = np.empty((h, w), dtype=np.uint8)
    tmp = np.empty((h, w), dtype=np.uint8)
    dist = None
    for start in range(0, n, _UINT8_PLANES):
        m = min(_UINT8_PLANES, n - start)
        # Plane i of the chunk gets the weight 255 - i, so the largest weight among the planes in
        # which the pixel fired names its first spike: i = 255 - max (and max = 0: no spike).
        acc.fill(0)
        for i in range(m):
            np.multiply(u8[start + i], np.uint8(_UINT8_PLANES - i), out=tmp)
            np.maximum(acc, tmp, out=acc)
        first = np.subtract(np.uint8(_UINT8_PLANES), acc)  # 255 where no spike in the chunk
        np.minimum(first, np.uint8(m), out=first)  # ... now m; found indices are < m
        if dist is None:
            if m == n:
                return first
            dist = first.astype(np.int32)
        else:
            # Pixels not found in nearer chunks hold dist == start; add this chunk's answer to them.
            np.add(dist, first, out=dist, where=dist == start)
        if start + m < n and not (dist == start + m).any():
            break
    return dist


def tfi_isi_planes(planes: np.ndarray, key_plane: int) -> np.ndarray:
    """The inter-spike interval around the key plane, in planes.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
        The spike window.
    key_plane : int
        Index of the key plane, in [0, T).

    Returns
    -------
    ndarray int32 (H, W) in [1, T + 1]
        ``t_next - t_prev``, with a virtual spike at plane ``-1`` (``T``) where the pixel has no spike
        at or before (after) the key plane; see the module docstring.
    """
    planes, key_plane = check_spike_window(planes, key_plane)
    # t_prev = k - d_prev (d_prev = k + 1 gives the virtual spike at -1);
    # t_next = k + 1 + d_next (d_next = T - k - 1 gives the virtual spike at T).
    d_prev = planes_to_first_spike(planes[key_plane::-1])
    d_next = planes_to_first_spike(planes[key_plane + 1 :])
    isi = np.add(d_prev, d_next, dtype=np.int32)
    isi += 1
    return isi


def tfi_rate(planes: np.ndarray, key_plane: int) -> np.ndarray:
    """Spike rate ``1 / ISI`` around the key plane (see :func:`tfi_isi_planes`).

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
    key_plane : int in [0, T)

    Returns
    -------
    ndarray float64 (H, W) in [1 / (T + 1), 1]
        Spikes per plane.
    """
    return 1.0 / tfi_isi_planes(planes, key_plane)


class TFI(Method):
    """Texture from interval (see the module docstring). It has no parameters."""

    inputs = frozenset({"spikes"})

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        stream = sample.spikes
        planes, key = stream.planes, sample.key_plane
        rate = tfi_rate(planes, key)
        t = planes.shape[0]
        gain = stream.gain
        if gain is not None and gain * (t + 1) < 1:  # the bound of a silent side maps above white
            one_sided = ~(planes[: key + 1].any(axis=0) & planes[key + 1:].any(axis=0))
            rate[one_sided] = np.count_nonzero(planes[:, one_sided], axis=0) / t
            image, label = stream_rate_to_image(rate, stream)
            return image, label + "; a side without a spike counted (the window's floor is above white at this gain)"
        return stream_rate_to_image(rate, stream)


def register_methods(register) -> None:
    """Register ``tfi``."""
    register(
        "tfi",
        TFI,
        params={},
        description="texture from interval: 1 / (ISI * gain) around the key plane; a side without a "
        "spike is bounded by the window's edge",
    )
