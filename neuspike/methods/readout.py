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
where it varies much more (an edge, texture), it keeps its value. ``s2`` is ``scale`` times the square
of a noise level measured on the image itself: the 3x3 Laplacian mask ``[[1, -2, 1], [-2, 4, -2], [1,
-2, 1]]`` cancels constants and ramps, its absolute response is averaged over 7x7 boxes, and the
``quantile``-th percentile of those averages over the image, divided by ``6 sqrt(2 / pi)`` (the mean
absolute response of the mask to white noise of unit deviation), is the deviation of the noise in the
image's least-varying neighbourhoods. On a clean image with flat regions that is zero and the filter
leaves the image as it was; over texture the least-varying neighbourhoods are still texture, so the
percentile of a fine-scale measure (rather than of the local variance, which smooth shading fills)
keeps the estimate low there. A network trained for PSNR under sensor noise leaves grain of a few
hundredths of the range on flat, dim regions, which costs SSIM most (on a flat truth SSIM's structure
term is ``C2 / (var + C2)``, halved by a grain of 0.03 of the range).
"""

from __future__ import annotations

import cv2
import numpy as np

from neuspike.errors import InputError

__all__ = ["WIENER_QUANTILE", "WIENER_WINDOW", "despeckle", "noise_level", "wiener"]

_RING = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.uint8)
#: Passes at most: a pixel that stood beside a replaced one can be left beyond all its neighbours (a
#: pair of specks), so the filter runs again until no outlier remains; on the validation windows of the
#: training photographs one pass left 0.056 specks per mille, two 0.002, three none.
MAX_PASSES = 4
#: :func:`wiener`'s box (pixels a side), and the percentile of the local mean absolute Laplacian taken for the
#: noise level, averaged over boxes of ``_NOISE_BOX`` a side.
WIENER_WINDOW = 7
WIENER_QUANTILE = 5.0
_NOISE_BOX = 7
_LAPLACIAN = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float64)
#: The mask's mean absolute response to white Gaussian noise of unit deviation: 6 sqrt(2 / pi).
_LAPLACIAN_MEAN_ABS = 6.0 * np.sqrt(2.0 / np.pi)


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


def noise_level(image: np.ndarray, quantile: float = WIENER_QUANTILE) -> float:
    """The deviation of white noise that the image's least-varying neighbourhoods hold (module docstring).

    Parameters
    ----------
    image : ndarray (H, W)
    quantile : float
        Percentile, in (0, 100), of the 7x7 local means of the absolute Laplacian over the image.

    Returns
    -------
    float >= 0, in the image's units: white noise of deviation s on a flat image reads about s at the median
    and about 0.65 s at the 5th percentile (the boxes that happen to vary least); a clean image with flat
    regions reads 0.
    """
    x = np.asarray(image, dtype=np.float64)
    response = np.abs(cv2.filter2D(x, -1, _LAPLACIAN, borderType=cv2.BORDER_REFLECT))
    local = cv2.blur(response, (_NOISE_BOX, _NOISE_BOX), borderType=cv2.BORDER_REFLECT)
    return float(np.percentile(local, quantile)) / _LAPLACIAN_MEAN_ABS


def wiener(image: np.ndarray, scale: float, *, window: int = WIENER_WINDOW,
           quantile: float = WIENER_QUANTILE) -> np.ndarray:
    """``image`` smoothed where it varies no more than its noise (the local Wiener filter; module docstring).

    Parameters
    ----------
    image : ndarray float32 (H, W)
        The image (any range: the filter commutes with adding a constant and with scaling).
    scale : float
        The noise variance as a multiple of the square of :func:`noise_level`, > 0.
    window : int
        Side of the box of the local mean and variance, odd, >= 3.
    quantile : float
        :func:`noise_level`'s percentile, in (0, 100).

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
    if min(x.shape) < max(window, _NOISE_BOX):
        return x.astype(np.float32)
    noise = scale * noise_level(x, quantile) ** 2
    if noise <= 0.0:  # the least-varying neighbourhoods hold no noise: nothing to smooth
        return x.astype(np.float32)
    mean = cv2.blur(x, (window, window), borderType=cv2.BORDER_REFLECT)
    var = np.maximum(cv2.blur(x * x, (window, window), borderType=cv2.BORDER_REFLECT) - mean * mean, 0.0)
    gain = np.maximum(var - noise, 0.0) / np.maximum(var, noise)
    return (mean + gain * (x - mean)).astype(np.float32)
