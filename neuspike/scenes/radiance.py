"""From luma to radiance: the dynamic-range mapping of a scene."""

from __future__ import annotations

import numpy as np

from neuspike.errors import InputError


def luma_to_radiance(luma: np.ndarray, *, dynamic_range: float | None, peak: float) -> np.ndarray:
    """Map luma to linear radiance (1.0 = reference white).

    Parameters
    ----------
    luma : ndarray, (..., H, W), values in [0, 1]
    dynamic_range : float or None
        ``None``: radiance = ``peak * v``. A number ``D >= 1``: radiance = ``peak * D ** (v - 1)``,
        so luma 1 maps to ``peak`` and luma 0 to ``peak / D``; the maximum-to-minimum ratio of a
        photograph spanning [0, 1] is exactly ``D``.
    peak : float
        Radiance of luma 1, > 0.

    Returns
    -------
    ndarray, float32, same shape, values >= 0 (> 0 when ``dynamic_range`` is a number)

    Raises
    ------
    InputError
        For luma outside [0, 1] or NaN, a ``dynamic_range`` below 1, or a ``peak`` <= 0.
    """
    v = np.asarray(luma, dtype=np.float64)
    if v.size and (not np.isfinite(v).all() or v.min() < 0 or v.max() > 1):
        raise InputError("luma: expected finite values in [0, 1]")
    if not np.isfinite(peak) or peak <= 0:
        raise InputError(f"peak: expected a positive radiance, got {peak!r}")
    if dynamic_range is None:
        return (peak * v).astype(np.float32)
    if not np.isfinite(dynamic_range) or dynamic_range < 1:
        raise InputError(f"dynamic_range: expected a ratio >= 1 or None, got {dynamic_range!r}")
    return (peak * np.power(float(dynamic_range), v - 1.0)).astype(np.float32)
