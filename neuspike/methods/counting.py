"""How many spikes a pixel fires in a window: the sensor model behind a counted level.

Over a window of ``T`` planes a pixel of radiance ``x`` integrates ``mu = T (gain x + d)`` thresholds
of charge (``d`` the dark rate) on top of the charge it held when the window began, ``I0`` in units
of the threshold. It fires ``max(0, floor(I0 + mu))`` spikes (reset by subtraction; a pixel that
starts below zero first climbs back). The expected count ``f(mu)`` therefore depends on how the
window began, :func:`initial_state`:

``"normal"``   the sensor started with the window, charge ``I0 ~ Normal(0, 1)`` (Algorithm 1's
               random initial charge): ``f(mu) = sum_{k >= 1} Phi(mu - k)``. A dark pixel
               (``mu`` near 0) still fires 0.18 spikes on average, from the charge it started with;
               ``f(mu) -> mu - 1/2`` once ``mu`` is a few spikes.
``"rest"``     the sensor started with the window at zero charge: ``f(mu) = floor(mu)``, taken as
               ``max(0, mu - 1/2)`` (its mean over the fractional part) for a smooth model.
``"running"``  the window is cut from a running sensor (a real recording, a continuous simulation
               after its first window): the charge at the window's start is the remainder of
               earlier spikes, spread evenly over ``[0, 1)``, so ``f(mu) = mu``.

A counted level that assumed ``mu - 1/2`` everywhere (the linear rule) put a dim scene's level about
``0.68 / (T gain)`` too high under ``"normal"`` (0.085 at ``L = 1/32``, ``T = 256``: a night street
lost 6.7 dB) and ``0.5 / (T gain)`` too low under ``"running"``. :func:`level_shift` instead finds
the shift of an image whose expected count under the right model equals the observed count.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.special import ndtr

if TYPE_CHECKING:
    from neuspike.streams import SpikeStream

__all__ = ["INITIAL_STATES", "expected_count", "initial_state", "level_shift"]

INITIAL_STATES = ("normal", "rest", "running")

#: Beyond this many thresholds of charge, ``f(mu) = mu - 1/2`` under ``"normal"`` to within 1e-8.
_NORMAL_ASYMPTOTE = 8.0
_K = np.arange(1, int(_NORMAL_ASYMPTOTE) + 10, dtype=np.float64)
_TABLE_MU = np.linspace(0.0, _NORMAL_ASYMPTOTE, 4097)
_TABLE_F = ndtr(_TABLE_MU[:, None] - _K).sum(axis=1)
_BINS = 8192


def expected_count(mu: np.ndarray, state: str) -> np.ndarray:
    """The expected spike count of pixels that integrate ``mu`` thresholds of charge (module docstring).

    Parameters
    ----------
    mu : ndarray, float, >= 0
        Charge integrated over the window, in thresholds.
    state : {"normal", "rest", "running"}

    Returns
    -------
    ndarray, float64, the shape of ``mu``; increasing in ``mu``.
    """
    mu = np.asarray(mu, dtype=np.float64)
    if state == "normal":
        return np.where(mu < _NORMAL_ASYMPTOTE, np.interp(mu, _TABLE_MU, _TABLE_F), mu - 0.5)
    if state == "rest":
        return np.maximum(mu - 0.5, 0.0)
    if state == "running":
        return mu
    raise ValueError(f"state: expected one of {INITIAL_STATES}, got {state!r}")


def initial_state(stream: "SpikeStream") -> str:
    """How the stream's window began: ``"normal"`` or ``"rest"`` where it is a simulation's first
    window (start time 0 and its stages recorded, with or without ``initial_charge``), ``"running"``
    otherwise (a window cut from a running sensor, or a recording that does not say)."""
    stages = (stream.meta or {}).get("stages")
    if stream.start_s != 0.0 or not isinstance(stages, list):
        return "running"
    names = {s.get("name") for s in stages if isinstance(s, dict)}
    if "integrate_and_fire" not in names:
        return "running"
    return "normal" if "initial_charge" in names else "rest"


def level_shift(image: np.ndarray, counts: np.ndarray, *, planes: int, gain: float, dark_rate: float,
                state: str, tolerance: float = 1e-5) -> float:
    """The shift ``s`` for which ``clip(image + s, 0, 1)`` predicts the observed number of spikes.

    Solves ``sum f(T (gain clip(x + s, 0, 1) + d)) = sum counts`` for ``s`` (:func:`expected_count`),
    by bisection on a bracket that always holds the answer where one exists.

    Parameters
    ----------
    image : ndarray (H, W), float, in [0, 1]
        The image whose level is set (radiance units).
    counts : ndarray (H, W)
        Each pixel's spike count over the window.
    planes : int
        The window's length T.
    gain, dark_rate : float
        Spikes per plane per unit radiance; spikes per plane in darkness.
    state : {"normal", "rest", "running"}
    tolerance : float
        Width of the final bracket, in radiance.

    Returns
    -------
    float
        The shift, in radiance; ``-1`` or ``+1`` where even an all-black or all-white image could
        not explain the count (a saturated or empty window).
    """
    x = np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0)
    target = float(np.sum(counts, dtype=np.float64))
    t_gain, t_dark = planes * gain, planes * dark_rate
    # the image's values binned finely (bins of 1/8192 of white): each trial shift costs 8192
    # evaluations, not one per pixel, and moves the predicted count by far less than one spike
    weights, edges = np.histogram(x, bins=_BINS, range=(0.0, 1.0))
    centres = 0.5 * (edges[:-1] + edges[1:])
    sums, _ = np.histogram(x, bins=_BINS, range=(0.0, 1.0), weights=x)
    filled = weights > 0
    centres[filled] = sums[filled] / weights[filled]  # each bin at the mean of its pixels
    weights = weights.astype(np.float64)

    def predicted(shift: float) -> float:
        return float(weights @ expected_count(t_gain * np.clip(centres + shift, 0.0, 1.0) + t_dark, state))

    lo, hi = -1.0, 1.0
    if predicted(lo) >= target:
        return lo
    if predicted(hi) <= target:
        return hi
    # start from the linear rule's shift, bracketed by a small step each way
    mean_mu = target / x.size
    guess = (mean_mu + 0.5 - t_dark) / t_gain - float(x.mean())
    step = 0.5 / t_gain
    a, b = max(lo, guess - step), min(hi, guess + step)
    lo = a if predicted(a) < target else lo
    hi = b if predicted(b) > target else hi
    while hi - lo > tolerance:
        mid = 0.5 * (lo + hi)
        if predicted(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
