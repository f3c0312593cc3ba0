"""Read-out steps a method may apply to its image after the image is made.

:func:`despeckle` — a switching median: a pixel that lies beyond the range of all eight of its
neighbours by more than ``margin`` (a bright pixel above the brightest neighbour, or a dark one below
the darkest) is replaced by the median of its 3x3 neighbourhood; every other pixel is left exactly
as it was. Such an isolated pixel is what the suite counts as a speck
(:func:`neuspike.metrics.isolated_outliers`, :data:`neuspike.metrics.SPECK_THRESHOLD`): noise in a
real scene spreads over neighbourhoods, while a network under sensor noise makes single wrong pixels
that PSNR hides. The switching form (the median is taken only where a pixel is an impulse) is the
classic remedy for impulse noise; it leaves edges, ramps and texture untouched, unlike a plain
median filter. A pass replaces every outlier at once, from the image as it was; the passes repeat
until none remains (at most :data:`MAX_PASSES`), since a pixel beside a replaced speck can be left
beyond all of its neighbours (two specks side by side).

:func:`wiener` — the local linear minimum-mean-square-error estimate under additive noise (Lee's
filter, a local Wiener filter): with the local mean ``m`` and variance ``v`` of the image over a
``window`` x ``window`` box and the noise variance ``s2``, each pixel becomes ``m + max(v - s2, 0) / v
* (x - m)``. Where the neighbourhood varies no more than noise would, the pixel takes the local mean;
where it varies much more (an edge, texture), it keeps its value. ``s2`` is estimated from the image:
``scale`` times the ``quantile``-th percentile of the local variance over the image, the variance of
its flattest neighbourhoods, which is the noise's where the image has flat regions and near zero in a
clean one (where the filter leaves the image nearly as it was). A network trained for PSNR under
sensor noise leaves grain of about that size on flat, dim regions, which costs SSIM most (on a flat
truth SSIM's structure term is ``C2 / (var + C2)``, halved by a grain of 0.03 of the range).
"""

from __future__ import annotations

import cv2
import numpy as np

from neuspike.errors import InputError

__all__ = ["WIENER_QUANTILE", "WIENER_WINDOW", "despeckle", "wiener"]

_RING = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.uint8)
#: Passes at most: a pixel that stood beside a replaced one can be left beyond all its neighbours (a
#: pair of specks), so the filter runs again until no outlier remains; on the validation windows of the
#: training photographs one pass left 0.056 specks per mille, two 0.002, three none.
MAX_PASSES = 4
#: :func:`wiener`'s box (pixels a side) and the percentile of the local variance taken for the noise's.
WIENER_WINDOW = 5
WIENER_QUANTILE = 10.0


def despeckle(image: np.ndarray, margin: float) -> np.ndarray:
    """``image`` with its isolated outliers replaced by their 3x3 median (module docstring).

    Parameters
    ----------
    image : ndarray float32 (H, W)
        The image (any range; ``margin`` is in its units).
    margin : float
        How far beyond all eight neighbours' range a pixel must lie to be replaced, > 0.

    Returns
    -------
    ndarray float32 (H, W): a new array; pixels that are never isolated outliers keep their exact
    value. Border pixels compare against their replicated neighbours.
    """
    image = np.array(image, dtype=np.float32)  # a copy: the caller's image is never changed
    if image.ndim != 2:
        raise InputError(f"despeckle: expected an (H, W) image, got shape {image.shape}")
    if not (np.isfinite(margin) and margin > 0):
        raise InputError(f"despeckle: margin must be a positive number, got {margin!r}")
    if min(image.shape) < 3:
        return image
    for _ in range(MAX_PASSES):
        high = cv2.dilate(image, _RING, borderType=cv2.BORDER_REPLICATE)
        low = cv2.erode(image, _RING, borderType=cv2.BORDER_REPLICATE)
        speck = (image - high > margin) | (low - image > margin)
        if not speck.any():
            break
        image = np.where(speck, cv2.medianBlur(image, 3), image).astype(np.float32, copy=False)
    return image


def wiener(image: np.ndarray, scale: float, *, window: int = WIENER_WINDOW,
           quantile: float = WIENER_QUANTILE) -> np.ndarray:
    """``image`` smoothed where it varies no more than its noise (the local Wiener filter; module docstring).

    Parameters
    ----------
    image : ndarray float32 (H, W)
        The image (any range: the filter commutes with adding a constant and with scaling).
    scale : float
        The noise variance as a multiple of the ``quantile``-th percentile of the local variance, > 0.
    window : int
        Side of the box of the local mean and variance, odd, >= 3.
    quantile : float
        Percentile of the local variance over the image, in (0, 100).

    Returns
    -------
    ndarray float32 (H, W): a new array (the caller's image is never changed). Borders see their
    mirrored neighbours. The statistics are taken in float64, so that the variance of a nearly flat
    region is not lost to cancellation.
    """
    image = np.asarray(image)
    if image.ndim != 2:
        raise InputError(f"wiener: expected an (H, W) image, got shape {image.shape}")
    if isinstance(scale, bool) or not (isinstance(scale, (int, float)) and np.isfinite(scale) and scale > 0):
        raise InputError(f"wiener: scale must be a positive number, got {scale!r}")
    if isinstance(window, bool) or not isinstance(window, int) or window < 3 or window % 2 == 0:
        raise InputError(f"wiener: window must be an odd whole number >= 3, got {window!r}")
    if not (isinstance(quantile, (int, float)) and 0 < quantile < 100):
        raise InputError(f"wiener: quantile must lie in (0, 100), got {quantile!r}")
    x = image.astype(np.float64)
    if min(x.shape) < window:
        return x.astype(np.float32)
    mean = cv2.blur(x, (window, window), borderType=cv2.BORDER_REFLECT)
    var = np.maximum(cv2.blur(x * x, (window, window), borderType=cv2.BORDER_REFLECT) - mean * mean, 0.0)
    noise = scale * float(np.percentile(var, quantile))
    if noise <= 0.0:  # no flat neighbourhood varies at all: nothing to tell from noise
        return x.astype(np.float32)
    gain = np.maximum(var - noise, 0.0) / np.maximum(var, noise)
    return (mean + gain * (x - mean)).astype(np.float32)
