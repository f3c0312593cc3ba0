"""Image quality measures: PSNR and SSIM with pinned settings, affine-aligned variants, and
no-reference measures for real recordings.

Full-reference metrics compare an image with its ground truth, both 2-D (H, W) arrays on
``[0, data_range]`` (``data_range = 1`` for the suite's float images). ``data_range`` is keyword-only
and required everywhere: inferring it from the dtype or the data moves PSNR by several dB.

SSIM settings
    Pinned to EVREAL's: Gaussian weights with ``sigma = 1.5`` (an 11x11 window, truncated at 3.5
    sigma), population (not sample) covariance, ``K1 = 0.01``, ``K2 = 0.03``; computed by
    scikit-image's ``structural_similarity`` with :data:`SSIM_SETTINGS`. :func:`describe_metrics`
    returns the line that the command line and the harness print.

Identical images
    PSNR is ``inf`` when the mean squared error is exactly zero (no finite cap: a cap would be a
    number nobody measured). ``inf`` survives a CSV round trip through pandas (written ``inf``,
    read back as ``float('inf')``); averages over rows that contain it are ``inf`` by design, so a
    perfect reconstruction is visible rather than hidden.

Affine alignment
    Methods without an absolute scale (e.g. robust normalisation on real data) are also scored after
    the least-squares gain and offset to the ground truth, ``aligned = gain * image + offset``, in
    closed form. :func:`evaluate` clips the aligned image to ``[0, data_range]`` before scoring (both
    metrics are defined on that range and the ground truth lies in it, so clipping can only move the
    aligned image closer to it); ``psnr_affine`` and ``ssim_affine`` are reported as separate metrics.

Isolated outliers (:func:`isolated_outliers`)
    Specks: pixels that lie beyond the range of all eight of their neighbours by more than
    :data:`SPECK_THRESHOLD` (a bright pixel above the brightest neighbour, or a dark one below the
    darkest), counted only where the ground truth has no such pixel, as a fraction of the interior
    pixels. Noise that spreads over neighbourhoods rarely does this; a network's isolated bright and
    dark pixels under sensor noise do, and PSNR hides them (one pixel in a thousand costs little).

No-reference measures (:func:`no_reference`), in the image's own units
    ``noise_sigma``
        Standard deviation of additive white Gaussian noise, estimated from the finest diagonal
        detail band of an orthonormal Haar wavelet transform by the robust median rule of Donoho and
        Johnstone: ``sigma = median(|HH|) / 0.6745``. (scikit-image's ``estimate_sigma`` applies the
        same rule with a Daubechies wavelet but needs PyWavelets, which is not a dependency.)
        Structure in the image inflates it a little; its value is meaningful for comparing methods on
        the same recording, and for pure noise it equals the noise's sigma. It is 0 when more than
        half of the 2x2 blocks are exactly flat (e.g. an event integration where most pixels saw no
        event): the rule measures noise where the image has it, not how much of the image is empty.
    ``laplacian_var``
        Sharpness: the variance of the 3x3 Laplacian (OpenCV ``Laplacian``, ``ksize=1``, float64)
        over the image interior (the one-pixel border, where OpenCV would extrapolate, is left out).
        Blur lowers it; noise raises it, so read it together with ``noise_sigma``.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from skimage.metrics import structural_similarity

from neuspike.utils.checks import check_positive
from neuspike.errors import InputError

#: The SSIM settings, pinned (EVREAL's): passed verbatim to ``skimage.metrics.structural_similarity``.
#: Read-only by convention: changing it changes every SSIM the suite reports.
SSIM_SETTINGS: dict[str, Any] = {
    "gaussian_weights": True,
    "sigma": 1.5,
    "use_sample_covariance": False,
    "K1": 0.01,
    "K2": 0.03,
}
#: Side of the Gaussian SSIM window for these settings (radius int(3.5 * 1.5 + 0.5) = 5); smaller
#: images have no valid SSIM.
SSIM_WINDOW_SIDE = 11
#: Names of the full-reference metrics :func:`evaluate` returns, in order.
FULL_REFERENCE_METRICS = ("psnr", "ssim", "psnr_affine", "ssim_affine")
#: Names of the no-reference measures :func:`no_reference` returns, in order.
NO_REFERENCE_MEASURES = ("noise_sigma", "laplacian_var")
#: median(|N(0, 1)|): turns a median absolute value into a Gaussian standard deviation.
_MAD_TO_SIGMA = 0.6744897501960817


def describe_metrics() -> str:
    """One line stating how PSNR, SSIM and their affine variants are computed.

    Returns
    -------
    str
        E.g. ``"SSIM: skimage structural_similarity, gaussian_weights=True, sigma=1.5, ..."``.
    """
    settings = ", ".join(f"{k}={v}" for k, v in SSIM_SETTINGS.items())
    return (
        f"metrics on [0, data_range] images; SSIM: skimage structural_similarity, {settings}; "
        "PSNR = 10 log10(data_range^2 / MSE), inf when MSE = 0; "
        "*_affine: least-squares gain and offset to the ground truth, clipped to [0, data_range]"
    )


def _as_image(name: str, image: Any) -> np.ndarray:
    """``image`` as a float64 2-D finite array; raise :class:`InputError` otherwise."""
    a = np.asarray(image)
    if a.dtype == np.bool_ or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise InputError(f"{name}: expected a real-valued image, got dtype {a.dtype}")
    if a.ndim != 2:
        raise InputError(f"{name}: expected a 2-D (H, W) image, got shape {a.shape}")
    if a.size == 0:
        raise InputError(f"{name}: expected a non-empty image, got shape {a.shape}")
    a = a.astype(np.float64, copy=False)
    if not np.isfinite(a).all():
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise InputError(f"{name}: expected finite values, got {bad} NaN or infinite entries")
    return a


def _check_pair(image: Any, reference: Any, data_range: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """Validate a full-reference input pair on ``[0, data_range]``."""
    dr = check_positive("data_range", data_range)
    a = _as_image("image", image)
    b = _as_image("reference", reference)
    if a.shape != b.shape:
        raise InputError(f"image and reference must have the same shape, got {a.shape} and {b.shape}")
    for name, arr in (("image", a), ("reference", b)):
        lo, hi = float(arr.min()), float(arr.max())
        if lo < 0.0 or hi > dr:
            raise InputError(
                f"{name}: expected values in [0, data_range] = [0, {dr}], got [{lo}, {hi}]"
            )
    return a, b, dr


def psnr(image: Any, reference: Any, *, data_range: float) -> float:
    """Peak signal-to-noise ratio in dB.

    Parameters
    ----------
    image, reference : array (H, W), real, values in [0, data_range]
    data_range : float, keyword-only, required
        The span of possible values (1.0 for the suite's float images).

    Returns
    -------
    float
        ``10 * log10(data_range**2 / MSE)``; ``inf`` when the images are identical (MSE = 0).

    Raises
    ------
    InputError
        Shapes differ, an array is not 2-D or not finite, a value lies outside [0, data_range],
        or ``data_range`` is not a positive number.
    """
    a, b, dr = _check_pair(image, reference, data_range)
    return _psnr(a, b, dr)


def _psnr(a: np.ndarray, b: np.ndarray, dr: float) -> float:
    mse = float(np.mean(np.square(a - b)))
    if mse == 0.0:
        return float("inf")
    return float(10.0 * np.log10(dr * dr / mse))


def ssim(image: Any, reference: Any, *, data_range: float) -> float:
    """Structural similarity with the pinned :data:`SSIM_SETTINGS`.

    Parameters
    ----------
    image, reference : array (H, W), real, values in [0, data_range]; H, W >= 11
    data_range : float, keyword-only, required

    Returns
    -------
    float
        Mean SSIM over the valid (window-inside-image) region, in [-1, 1]; 1 for identical images.

    Raises
    ------
    InputError
        As :func:`psnr`, and when a side is shorter than the 11-pixel Gaussian window.
    """
    a, b, dr = _check_pair(image, reference, data_range)
    return _ssim(a, b, dr)


def _ssim(a: np.ndarray, b: np.ndarray, dr: float) -> float:
    if min(a.shape) < SSIM_WINDOW_SIDE:
        raise InputError(
            f"ssim: images must be at least {SSIM_WINDOW_SIDE}x{SSIM_WINDOW_SIDE} for the pinned Gaussian "
            f"window, got {a.shape}"
        )
    return float(structural_similarity(a, b, data_range=dr, **SSIM_SETTINGS))


def affine_fit(image: Any, reference: Any) -> tuple[float, float]:
    """Least-squares gain and offset mapping ``image`` onto ``reference``.

    Minimises ``sum((gain * image + offset - reference)**2)``; closed form
    ``gain = cov(image, reference) / var(image)``, ``offset = mean(reference) - gain * mean(image)``.
    A constant ``image`` (zero variance) carries no scale information: then ``gain = 0`` and
    ``offset = mean(reference)``, the least-squares solution of minimum norm in ``gain``.

    Parameters
    ----------
    image, reference : array (H, W), real, finite

    Returns
    -------
    (gain, offset) : tuple of float
    """
    a = _as_image("image", image)
    b = _as_image("reference", reference)
    if a.shape != b.shape:
        raise InputError(f"image and reference must have the same shape, got {a.shape} and {b.shape}")
    return _affine_fit(a, b)


def _affine_fit(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    ma, mb = float(a.mean()), float(b.mean())
    if float(a.max()) == float(a.min()):  # constant: the mean's rounding must not fake a variance
        return 0.0, mb
    da = a - ma
    var = float(np.mean(da * da))
    gain = float(np.mean(da * (b - mb))) / var
    return gain, mb - gain * ma


def affine_align(
    image: Any, reference: Any, *, data_range: float | None = None
) -> tuple[np.ndarray, float, float]:
    """``image`` mapped onto ``reference`` by the least-squares gain and offset.

    Parameters
    ----------
    image, reference : array (H, W), real, finite
    data_range : float or None, keyword-only
        When given, the aligned image is clipped to ``[0, data_range]`` (the range the metrics are
        defined on); when ``None`` (the default) it is returned unclipped.

    Returns
    -------
    aligned : ndarray float64 (H, W)
        ``gain * image + offset`` (clipped when ``data_range`` is given).
    gain, offset : float
        From :func:`affine_fit`.
    """
    a = _as_image("image", image)
    b = _as_image("reference", reference)
    if a.shape != b.shape:
        raise InputError(f"image and reference must have the same shape, got {a.shape} and {b.shape}")
    gain, offset = _affine_fit(a, b)
    aligned = gain * a + offset
    if data_range is not None:
        dr = check_positive("data_range", data_range)
        aligned = np.clip(aligned, 0.0, dr)
    return aligned, gain, offset


def psnr_affine(image: Any, reference: Any, *, data_range: float) -> float:
    """PSNR after affine alignment to the reference (aligned image clipped to [0, data_range])."""
    a, b, dr = _check_pair(image, reference, data_range)
    aligned, _, _ = affine_align(a, b, data_range=dr)
    return _psnr(aligned, b, dr)


def ssim_affine(image: Any, reference: Any, *, data_range: float) -> float:
    """SSIM after affine alignment to the reference (aligned image clipped to [0, data_range])."""
    a, b, dr = _check_pair(image, reference, data_range)
    aligned, _, _ = affine_align(a, b, data_range=dr)
    return _ssim(aligned, b, dr)


def evaluate(image: Any, reference: Any, *, data_range: float) -> dict[str, float]:
    """Every full-reference metric of ``image`` against ``reference``.

    Parameters
    ----------
    image, reference : array (H, W), real, values in [0, data_range]; H, W >= 11
    data_range : float, keyword-only, required

    Returns
    -------
    dict
        ``{"psnr": dB, "ssim": ..., "psnr_affine": dB, "ssim_affine": ...}``
        (:data:`FULL_REFERENCE_METRICS`); PSNR values may be ``inf``.
    """
    a, b, dr = _check_pair(image, reference, data_range)
    aligned, _, _ = affine_align(a, b, data_range=dr)
    return {
        "psnr": _psnr(a, b, dr),
        "ssim": _ssim(a, b, dr),
        "psnr_affine": _psnr(aligned, b, dr),
        "ssim_affine": _ssim(aligned, b, dr),
    }


#: How far, in units of the data range, a pixel must lie beyond all eight neighbours to count as a speck.
SPECK_THRESHOLD = 0.1
_RING = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.uint8)


def _specks(a: np.ndarray, margin: float) -> np.ndarray:
    """Bool (H - 2, W - 2): interior pixels beyond all eight neighbours' range by more than ``margin``."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    high = cv2.dilate(a, _RING, borderType=cv2.BORDER_REPLICATE)
    low = cv2.erode(a, _RING, borderType=cv2.BORDER_REPLICATE)
    out = (a - high > margin) | (low - a > margin)
    return out[1:-1, 1:-1]


def isolated_outliers(image: Any, reference: Any, *, data_range: float,
                      threshold: float = SPECK_THRESHOLD) -> float:
    """The fraction of pixels that are specks in ``image`` but not in ``reference`` (module docstring).

    Parameters
    ----------
    image, reference : array (H, W), real, values in [0, data_range]; H, W >= 3
    data_range : float, keyword-only, required
    threshold : float
        The margin beyond the neighbours' range, as a fraction of ``data_range``.

    Returns
    -------
    float
        In [0, 1], over the ``(H - 2) (W - 2)`` interior pixels (the border has no full neighbourhood).
    """
    a, b, dr = _check_pair(image, reference, data_range)
    if min(a.shape) < 3:
        raise InputError(f"image: expected at least 3x3 pixels, got {a.shape}")
    margin = float(threshold) * dr
    extra = _specks(a, margin) & ~_specks(b, margin)
    return float(np.count_nonzero(extra)) / extra.size


#: Pixels trimmed from the edge of a static region before :func:`static_texture` measures it (the
#: 3x3 Sobel support and a moving edge's blur stay outside).
STATIC_ERODE_PX = 3
#: A static region (after trimming) smaller than this fraction of the view gets no value.
STATIC_MIN_FRACTION = 0.05


def static_texture(image: Any, reference: Any, static: Any, *, data_range: float) -> float:
    """How much of the texture of the static regions an image recovers.

    The Pearson correlation, over the pixels of ``static`` (trimmed by :data:`STATIC_ERODE_PX`),
    between the Sobel gradient magnitudes of ``image`` and ``reference``. Gain and offset do not
    matter (a correlation), so methods that normalise differently compare fairly. 1: the static
    texture is all there; about 0: none is; an image without any gradient there scores 0 (no
    texture recovered). PSNR and SSIM cannot tell this apart: a flat image can outscore a noisy
    textured one.

    Parameters
    ----------
    image, reference : array (H, W), real, values in [0, data_range]
    static : array (H, W) of bool
        Pixels that do not change during the recording (:func:`neuspike.simulation.window.static_region`).
    data_range : float, keyword-only, required

    Returns
    -------
    float
        In [-1, 1]; NaN when the trimmed region covers less than :data:`STATIC_MIN_FRACTION` of the
        view or the reference has no texture there.
    """
    a, b, _ = _check_pair(image, reference, data_range)
    mask = np.asarray(static)
    if mask.shape != a.shape or mask.dtype != np.bool_:
        raise InputError(f"static: expected a bool array of shape {a.shape}, got {mask.dtype} {mask.shape}")
    side = 2 * STATIC_ERODE_PX + 1
    inner = cv2.erode(mask.astype(np.uint8), np.ones((side, side), np.uint8), borderType=cv2.BORDER_CONSTANT,
                      borderValue=0).astype(bool)
    if inner.mean() < STATIC_MIN_FRACTION:
        return float("nan")

    def magnitude(x: np.ndarray) -> np.ndarray:
        x = x.astype(np.float64)
        return np.hypot(cv2.Sobel(x, cv2.CV_64F, 1, 0, ksize=3), cv2.Sobel(x, cv2.CV_64F, 0, 1, ksize=3))[inner]

    g_ref, g_img = magnitude(b), magnitude(a)
    if g_ref.std() <= 1e-12 * max(1.0, float(np.abs(g_ref).max())):
        return float("nan")
    if g_img.std() <= 1e-12 * max(1.0, float(np.abs(g_img).max())):
        return 0.0
    return float(np.corrcoef(g_img, g_ref)[0, 1])


def haar_noise_sigma(image: Any) -> float:
    """Robust estimate of the standard deviation of additive white Gaussian noise.

    The finest diagonal (HH) band of the orthonormal Haar transform over 2x2 blocks,
    ``(a - b - c + d) / 2``, carries noise of the same sigma as the image while flat and linearly
    varying regions contribute zero; ``sigma = median(|HH|) / 0.6745``.

    Parameters
    ----------
    image : array (H, W), real, finite; H, W >= 2 (a trailing odd row or column is not used)

    Returns
    -------
    float, >= 0, in the image's units.
    """
    a = _as_image("image", image)
    h, w = (a.shape[0] // 2) * 2, (a.shape[1] // 2) * 2
    if h == 0 or w == 0:
        raise InputError(f"image: expected at least 2x2 pixels, got {a.shape}")
    a = a[:h, :w]
    hh = (a[0::2, 0::2] - a[0::2, 1::2] - a[1::2, 0::2] + a[1::2, 1::2]) / 2.0
    return float(np.median(np.abs(hh)) / _MAD_TO_SIGMA)


def laplacian_variance(image: Any) -> float:
    """Sharpness: variance of the 3x3 Laplacian over the image interior.

    Parameters
    ----------
    image : array (H, W), real, finite; H, W >= 3

    Returns
    -------
    float, >= 0, in squared image units.
    """
    a = _as_image("image", image)
    if min(a.shape) < 3:
        raise InputError(f"image: expected at least 3x3 pixels, got {a.shape}")
    lap = cv2.Laplacian(a, cv2.CV_64F, ksize=1)
    return float(np.var(lap[1:-1, 1:-1]))


def no_reference(image: Any) -> dict[str, float]:
    """No-reference measures for images without ground truth (real recordings).

    Parameters
    ----------
    image : array (H, W), real, finite; H, W >= 3

    Returns
    -------
    dict
        ``{"noise_sigma": ..., "laplacian_var": ...}`` (:data:`NO_REFERENCE_MEASURES`), see the
        module docstring.
    """
    a = _as_image("image", image)
    return {"noise_sigma": haar_noise_sigma(a), "laplacian_var": laplacian_variance(a)}
