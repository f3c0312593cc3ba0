"""How spike-rate estimates become images in [0, 1].

Two documented paths, and every method says which one it took (the label goes into each result row):

``"gain"``
    The stream's gain (expected spikes per plane per unit radiance) is known, as for simulated data:
    radiance = rate / gain. Radiance above 1 (brighter than reference white, HDR) saturates at 1,
    which is the output contract of every method; nothing else is altered.
``"robust-p99"``
    The gain is unknown (real recordings): the estimate is divided by its 99th percentile over the
    image (ignoring non-finite values), so 1 % of pixels saturate and the image's scale no longer
    depends on the light level. An all-zero estimate stays zero.
"""

from __future__ import annotations

import numpy as np

GAIN = "gain"
ROBUST = "robust-p99"
ROBUST_PERCENTILE = 99.0


def robust_scale(estimate: np.ndarray, *, percentile: float = ROBUST_PERCENTILE) -> float:
    """The ``percentile``-th value of ``estimate`` (> 0), or 1.0 when that value is not positive."""
    finite = estimate[np.isfinite(estimate)]
    if finite.size == 0:
        return 1.0
    scale = float(np.percentile(finite, percentile))
    return scale if scale > 0 else 1.0


def rate_to_image(rate: np.ndarray, gain: float | None) -> tuple[np.ndarray, str]:
    """Turn a rate estimate (spikes per plane, (H, W)) into a float32 image in [0, 1].

    Parameters
    ----------
    rate : ndarray (H, W)
        Non-negative rate estimate in spikes per plane (NaN/inf treated as 0).
    gain : float or None
        Expected spikes per plane per unit radiance, or ``None`` when unknown.

    Returns
    -------
    image : float32 (H, W) in [0, 1]
    label : ``"gain"`` or ``"robust-p99"``
    """
    rate = np.asarray(rate)
    if not np.isfinite(rate).all():
        rate = np.nan_to_num(rate.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if gain is not None:
        scale, label = float(gain), GAIN
    else:
        scale, label = robust_scale(rate), ROBUST
    # divide in float64, then clip the float32 image in place (one allocation each)
    image = np.divide(rate, scale, dtype=np.float64).astype(np.float32)
    return np.clip(image, 0.0, 1.0, out=image), label
