"""The DVS pixel's response model (v2e's): the 8-bit intensity scale and the lin-log transfer.

Shared by :class:`neuspike.sensors.event_camera.EventCamera` and its capture engine
(:mod:`neuspike.sensors.event_capture`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.errors import InputError

__all__ = ["DARK_FLOOR_8BIT", "REFERENCE_WHITE_8BIT", "SHOT_NOISE_BRIGHT_FACTOR", "lin_log_into", "log_intensity"]

#: Intensity of the reference white (radiance 1.0 at light 1) on v2e's 8-bit scale.
REFERENCE_WHITE_8BIT = 255.0
#: Below this 8-bit value the log response is linear (v2e's lin-log): 20/255 of reference white.
DARK_FLOOR_8BIT = 20.0
#: Shot-noise rate at full intensity relative to the dark limit (v2e): rate ~ 1 - 0.75 * I01.
SHOT_NOISE_BRIGHT_FACTOR = 0.25
#: v2e's normalised intensity I01 = (I8 + offset) / scale, which sets the photoreceptor bandwidth and
#: the shot-noise rate.
I01_OFFSET = 20.0
I01_SCALE = 275.0

LIN_SLOPE = np.float32(np.log(DARK_FLOOR_8BIT) / DARK_FLOOR_8BIT)


def lin_log_into(x: np.ndarray, out: np.ndarray, tmp: np.ndarray, floor: np.float32,
                  slope: np.float32) -> np.ndarray:
    """``log(x)`` above ``floor``, ``slope * x`` below it (float32, into ``out``).

    Computed as ``log(max(x, floor)) + (min(x, floor) * slope - log(floor))`` with ``log(floor)``
    the float32 value of the same ``np.log``, so that ``f(0) == 0`` exactly.
    """
    np.maximum(x, floor, out=out)
    np.log(out, out=out)
    np.minimum(x, floor, out=tmp)
    tmp *= slope
    tmp -= np.log(floor)
    out += tmp
    return out


def log_intensity(intensity: Any) -> np.ndarray:
    """The DVS pixel's log response to intensity (v2e's lin-log on the 8-bit scale).

    With ``x = 255 * intensity`` (reference white, intensity 1.0, is 255)::

        f(x) = x * ln(20) / 20   for x <= 20
        f(x) = ln(x)             for x > 20

    The linear part is the *dark floor*: below 20/255 of reference white the response is linear
    rather than logarithmic, so a dark pixel needs a much larger relative change to cross a
    threshold and dark scenes give fewer events (and, with shot noise, relatively more noise).
    The function is continuous at the floor and ``f(0) = 0``.

    Parameters
    ----------
    intensity : array_like of float, any shape
        Linear intensity, >= 0 (1.0 = reference white; HDR values above 1 are fine).

    Returns
    -------
    ndarray of float32, same shape
        Log intensity in natural-log units.

    Raises
    ------
    InputError
        If ``intensity`` holds NaN, infinity or a negative value.
    """
    x = np.asarray(intensity, dtype=np.float32)
    if x.size:
        lo, hi = float(np.min(x)), float(np.max(x))
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise InputError("log_intensity: expected finite intensities, got NaN or infinity")
        if lo < 0:
            raise InputError(f"log_intensity: expected intensities >= 0, got a minimum of {lo!r}")
    x8 = np.multiply(x, np.float32(REFERENCE_WHITE_8BIT), dtype=np.float32)
    return lin_log_into(x8, np.empty_like(x8), np.empty_like(x8), np.float32(DARK_FLOOR_8BIT), LIN_SLOPE)
