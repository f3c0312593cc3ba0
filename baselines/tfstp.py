"""TFSTP, texture from short-term plasticity (Zheng et al., CVPR 2021).

Each pixel drives a short-term-plasticity synapse with two states, the available resources ``R`` and
the utilisation ``u``. Between spikes ``R`` recovers towards 1 with time constant ``D`` and ``u``
decays towards ``u0`` with time constant ``F``; a spike uses the fraction ``u`` of the resources and
raises ``u`` by ``f (1 - u)``. Applied at each spike with ``Δ`` the interval in planes since the
pixel's previous spike (both updates from the values before the spike):

    R <- 1 - [1 - R (1 - u)] exp(-Δ / D)
    u <- u0 + [u + f (1 - u) - u0] exp(-Δ / F)

Start ``R = 1``, ``u = u0``. Defaults ``u0 = 0.15``, ``D = 1``, ``F = 10``, ``f = 0.15`` (planes).

Steady state and read-out
-------------------------
Under a periodic train of interval ``Δ`` the states reach fixed points ``R*``, ``u*``. Solving each
update for ``exp(-Δ / time constant)`` at the fixed point gives

    exp(-Δ / D) = (1 - R*) / (1 - R* (1 - u*))
    exp(-Δ / F) = (u* - u0) / (u* (1 - f) + f - u0)

so each state inverts to a rate ``1 / Δ``:

    ρ_R = -1 / (D ln[(1 - R) / (1 - R (1 - u))])  =  1 / (D log1p(u R / (1 - R)))
    ρ_u = -1 / (F ln[(u - u0) / (u (1 - f) + f - u0)])  =  1 / (F log1p(f (1 - u) / (u - u0)))

(the second denominator has the facilitation step ``f``, not the time constant ``F``: only that form
is the inverse of the update). The read-out is exact: on a converged periodic train both return
``1 / Δ``. The method reports their mean, ``(ρ_R + ρ_u) / 2``, equal to ``1 / Δ`` at steady state;
``ρ_R`` follows the last interval closely (``D`` is one plane), ``ρ_u`` averages over about ``F``
planes. A variable at rest carries no interval (see below), so where only one of them has moved,
that one is the estimate. The radiance is then rate / gain (or the robust normalisation when the
gain is unknown).

Numerics
--------
With ``D = 1`` plane, ``1 - R`` falls to ``exp(-Δ)``: ``1e-14`` after 32 planes, below float64's
resolution of ``R`` itself after about 37. The states are therefore kept as their distances from rest,
``q = 1 - R`` and ``v = u - u0``, which obey the same updates without cancellation::

    q <- [u + q (1 - u)] exp(-Δ / D)
    v <- [v (1 - f) + f (1 - u0)] exp(-Δ / F)

and the read-out uses the ``log1p`` forms above (as ``log(a + b) - log(b)`` where ``b`` is so small
that ``a / b`` would overflow).

Degenerate pixels, handled explicitly
-------------------------------------
* A pixel's first spike has no interval: it only starts the clock (the states stay at rest). A pixel
  with fewer than two spikes up to the key plane is thus at rest, ``q = v = 0``, and the read-out of
  a state at rest is its limit, rate 0 (an infinitely long interval), not ``log(0)``.
* ``q`` underflows to 0 for intervals beyond about 745 ``D`` planes (``v`` beyond about 745 ``F``);
  the read-out of that variable is then 0, its limit, and the estimate is the other read-out alone.

Which planes: the state at the key plane ``k`` is the state after the pixel's last spike at or
before ``k`` (planes after ``k`` are not used: the model is causal). It is updated only where spikes
occur, plane by plane, over the pixels that fire in that plane.
"""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from neuspike.methods.normalisation import stream_rate_to_image
from neuspike.utils.checks import check_positive, check_spike_window
from neuspike.errors import InputError, NeuSpikeError
from neuspike.methods import Method
from neuspike.utils.parallel import KERNEL_LOCK, resolve_backend
from neuspike.sample import Sample

U0 = 0.15
RECOVERY_PLANES = 1.0  # D
FACILITATION_PLANES = 10.0  # F
FACILITATION = 0.15  # f

#: Accepted values of ``backend``: the compiled pass, the NumPy reference, or numba where available.
BACKENDS: tuple[str, ...] = ("auto", "numba", "numpy")

try:  # numba is a dependency, but the method must still run where it cannot be imported
    from baselines import tfstp_kernels as _kernels
except ImportError:  # pragma: no cover - exercised only without numba
    _kernels = None

#: Upper bound of the time constants (planes): keeps exp(-1 / tau) distinguishable from 1.
MAX_TIME_CONSTANT_PLANES = 1.0e4
# Below this, a / b (a <= 1) could overflow; the read-out switches to a difference of logarithms.
_TINY = 1.0e-290
_SATURATED = "TFSTP read-out: a state reached its saturation (u = 1 or R = 0); check the parameters"


@dataclass(frozen=True)
class STPParams:
    """The four parameters of the short-term-plasticity synapse, validated once.

    Parameters
    ----------
    u0 : float in (0, 1)
        Resting utilisation.
    recovery_planes : float in (0, MAX_TIME_CONSTANT_PLANES]
        ``D``, the resources' recovery time constant, in planes.
    facilitation_planes : float in (0, MAX_TIME_CONSTANT_PLANES]
        ``F``, the utilisation's decay time constant, in planes.
    facilitation : float in (0, 1)
        ``f``, the utilisation step per spike.

    Raises
    ------
    InputError
        For a value outside its range (stored as floats otherwise).
    """

    u0: float = U0
    recovery_planes: float = RECOVERY_PLANES
    facilitation_planes: float = FACILITATION_PLANES
    facilitation: float = FACILITATION

    def __post_init__(self) -> None:
        for name in ("u0", "facilitation"):
            value = getattr(self, name)
            v = check_positive(name, value)
            if v >= 1:
                raise InputError(f"{name}: expected a number in (0, 1), got {value!r}")
            object.__setattr__(self, name, v)
        for name in ("recovery_planes", "facilitation_planes"):
            value = getattr(self, name)
            v = check_positive(name, value)
            if v > MAX_TIME_CONSTANT_PLANES:
                raise InputError(
                    f"{name}: expected a time constant in (0, {MAX_TIME_CONSTANT_PLANES:g}] planes, got {value!r}"
                )
            object.__setattr__(self, name, v)


#: The published parameters (Zheng et al. 2021).
DEFAULT_PARAMS = STPParams()


def _check_params(params: Any) -> STPParams:
    if not isinstance(params, STPParams):
        raise InputError(f"params: expected an STPParams, got {type(params).__name__}")
    return params


def _resolve_backend(backend: Any) -> str:
    """``"numba"`` or ``"numpy"`` for a requested backend (see :data:`BACKENDS`)."""
    return resolve_backend(backend, compiled=_kernels is not None)


def _step_inplace(
    q: np.ndarray, v: np.ndarray, decay_r: np.ndarray, decay_u: np.ndarray, u0: float, f: float, scratch: np.ndarray
) -> None:
    """One spike's update of ``q = 1 - R`` and ``v = u - u0``, in place.

    ``q <- [q (1 - u) + u] decay_r`` and ``v <- [v (1 - f) + f (1 - u0)] decay_u``, where
    ``u = u0 + v`` before the spike, ``decay_r = exp(-Δ/D)`` and ``decay_u = exp(-Δ/F)``. Every term
    is non-negative, so nothing cancels. ``scratch`` is a float64 buffer of the same shape.
    """
    np.subtract(1.0 - u0, v, out=scratch)  # 1 - u
    q *= scratch
    q += u0
    q += v
    q *= decay_r
    v *= 1.0 - f
    v += f * (1.0 - u0)
    v *= decay_u


def stp_step(
    r_deficit: np.ndarray,
    u_excess: np.ndarray,
    isi_planes: np.ndarray | float,
    params: STPParams = DEFAULT_PARAMS,
) -> tuple[np.ndarray, np.ndarray]:
    """The update at one spike, on the states' distances from rest.

    Parameters
    ----------
    r_deficit : array float64, values in [0, 1)
        ``q = 1 - R`` before the spike.
    u_excess : array float64, values in [0, 1 - u0)
        ``v = u - u0`` before the spike.
    isi_planes : array or float, > 0
        Δ, the interval since the previous spike, in planes.
    params : STPParams
        ``u0``, ``D``, ``F`` and ``f`` of the model.

    Returns
    -------
    r_deficit, u_excess : float64 arrays, the states after the update (broadcast shape).
    """
    p = _check_params(params)
    isi = np.asarray(isi_planes, dtype=np.float64)
    if isi.size and not (np.isfinite(isi).all() and (isi > 0).all()):
        raise InputError("isi_planes: expected finite intervals > 0 planes")
    q, v, isi = np.broadcast_arrays(
        np.asarray(r_deficit, dtype=np.float64), np.asarray(u_excess, dtype=np.float64), isi
    )
    q, v = q.copy(), v.copy()
    _step_inplace(q, v, np.exp(-isi / p.recovery_planes), np.exp(-isi / p.facilitation_planes), p.u0,
                  p.facilitation, np.empty_like(q))
    return q, v


# The C library's scalar log1p and log, the functions the compiled read-out calls. NumPy's own
# ufuncs pick SIMD kernels by CPU (AVX-512 ones round differently from the C library in about one
# value in twenty), so the reference calls the same scalar functions to stay equal bit for bit.
_scalar_log1p = np.frompyfunc(math.log1p, 1, 1)
_scalar_log = np.frompyfunc(math.log, 1, 1)


def _log1p_ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``log1p(a / b)`` for ``0 < a <= 1`` and ``b > 0``, without overflow for tiny ``b``; the C
    library's scalar functions, as the compiled read-out (see ``_scalar_log1p``)."""
    out = np.empty_like(b)
    ok = b >= _TINY
    out[ok] = _scalar_log1p(a[ok] / b[ok])
    tiny = ~ok
    if tiny.any():
        out[tiny] = _scalar_log(a[tiny] + b[tiny]).astype(np.float64) - _scalar_log(b[tiny]).astype(np.float64)
    return out


def stp_rates(
    r_deficit: np.ndarray,
    u_excess: np.ndarray,
    params: STPParams = DEFAULT_PARAMS,
) -> tuple[np.ndarray, np.ndarray]:
    """Invert the steady state of each variable to a rate (spikes per plane).

    Parameters
    ----------
    r_deficit : array float64, values in [0, 1)
        ``q = 1 - R``.
    u_excess : array float64, values in [0, 1 - u0)
        ``v = u - u0``.
    params : STPParams
        ``u0``, ``D``, ``F`` and ``f``.

    Returns
    -------
    rate_r, rate_u : float64 arrays >= 0
        ``ρ_R = 1 / (D log1p(u R / (1 - R)))`` and ``ρ_u = 1 / (F log1p(f (1 - u) / (u - u0)))``;
        0 where the variable is at rest (``q = 0`` or ``v = 0``).

    Raises
    ------
    InputError
        If a state lies outside its range (the model cannot reach it).
    """
    p = _check_params(params)
    q = np.asarray(r_deficit, dtype=np.float64)
    v = np.asarray(u_excess, dtype=np.float64)
    q, v = np.broadcast_arrays(q, v)
    if q.size and not (np.isfinite(q).all() and (q >= 0).all() and (q < 1).all()):
        raise InputError("r_deficit: expected 1 - R in [0, 1)")
    if v.size and not (np.isfinite(v).all() and (v >= 0).all() and (v < 1 - p.u0).all()):
        raise InputError(f"u_excess: expected u - u0 in [0, {1 - p.u0})")
    return _rates(q, v, p)


def _inverse_interval(tau: float, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``1 / (tau log1p(a / b))``, the rate whose steady state gives the ratio ``b / (a + b)``."""
    log_term = _log1p_ratio(a, b)
    if not (log_term > 0).all():
        # a > 0 always holds for valid parameters (u >= u0 > 0, R > 0, and u < 1 since every
        # update decays by exp(-Δ/F) < 1); a zero here would mean an infinite rate.
        raise NeuSpikeError(_SATURATED)
    return 1.0 / (tau * log_term)


def _rates(q: np.ndarray, v: np.ndarray, p: STPParams) -> tuple[np.ndarray, np.ndarray]:
    """The two read-outs (see :func:`stp_rates`), 0 where a variable is at rest."""
    u0, d, big_f, f = p.u0, p.recovery_planes, p.facilitation_planes, p.facilitation
    rate_r = np.zeros(q.shape)
    rate_u = np.zeros(v.shape)
    moved = q > 0
    if moved.any():
        q_m = q[moved]
        rate_r[moved] = _inverse_interval(d, (u0 + v[moved]) * (1.0 - q_m), q_m)  # a = u R, b = 1 - R
    moved = v > 0
    if moved.any():
        v_m = v[moved]
        rate_u[moved] = _inverse_interval(big_f, f * ((1.0 - u0) - v_m), v_m)  # a = f (1 - u), b = u - u0
    return rate_r, rate_u


def _decay_tables(n: int, d: float, big_f: float) -> tuple[np.ndarray, np.ndarray]:
    """Decay factors ``exp(-lag / D)`` and ``exp(-lag / F)`` indexed by the lag in planes, for the
    states after planes ``0 .. n - 1``.

    A pixel that has not fired yet holds last = -(n + 1), so its first spike sees a lag in
    [n + 1, 2n], where the tables hold 0: the update then maps the resting state (q = v = 0) onto
    itself, and the first spike only starts the clock.
    """
    lags = np.arange(2 * n + 1, dtype=np.float64)
    decay_r, decay_u = np.exp(-lags / d), np.exp(-lags / big_f)
    decay_r[n + 1 :] = 0.0
    decay_u[n + 1 :] = 0.0
    return decay_r, decay_u


def tfstp_state(
    planes: np.ndarray,
    key_plane: int,
    params: STPParams = DEFAULT_PARAMS,
    *,
    backend: str = "auto",
) -> tuple[np.ndarray, np.ndarray]:
    """The STP states at the key plane, from the spikes of planes ``0 .. key_plane``.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
    key_plane : int in [0, T)
    params : STPParams
        ``u0``, ``D``, ``F`` and ``f``.
    backend : {"auto", "numba", "numpy"}
        ``"numba"``: the compiled per-pixel pass (:mod:`baselines.tfstp_kernels`); ``"numpy"``: the
        reference plane loop over the pixels that fire; ``"auto"``: numba where it can be imported.
        Both run the same float64 operations in the same order: the states are equal bit for bit.

    Returns
    -------
    r_deficit, u_excess : float64 (H, W)
        ``1 - R`` in [0, 1) and ``u - u0`` in [0, 1 - u0); both 0 for pixels with fewer than two
        spikes.
    """
    planes, key_plane = check_spike_window(planes, key_plane)
    p = _check_params(params)
    u0, f = p.u0, p.facilitation
    compiled = _resolve_backend(backend) == "numba"
    n = key_plane + 1
    h, w = planes.shape[1:]
    size = h * w
    flat = planes[:n].reshape(n, size)
    decay_r, decay_u = _decay_tables(n, p.recovery_planes, p.facilitation_planes)
    if compiled:
        with KERNEL_LOCK:
            return _kernels.stp_states(np.ascontiguousarray(planes), n, decay_r, decay_u, u0, f)
    last = np.full(size, -(n + 1), dtype=np.int64)  # plane of each pixel's last spike
    q = np.zeros(size)
    v = np.zeros(size)
    # Work buffers, reused plane after plane (fresh large arrays would cost a page fault per page).
    lag_buf = np.empty(size, dtype=np.int64)
    q_buf, v_buf, r_buf, u_buf, scratch = (np.empty(size) for _ in range(5))
    for j in range(n):
        fired = flat[j]
        m = np.count_nonzero(fired)
        if m == 0:
            continue
        if m == size:  # every pixel fired: no gathering needed
            np.subtract(j, last, out=lag_buf)
            np.take(decay_r, lag_buf, out=r_buf, mode="clip")
            np.take(decay_u, lag_buf, out=u_buf, mode="clip")
            _step_inplace(q, v, r_buf, u_buf, u0, f, scratch)
            last.fill(j)
            continue
        idx = np.flatnonzero(fired)
        lag, q_m, v_m, r_m, u_m = lag_buf[:m], q_buf[:m], v_buf[:m], r_buf[:m], u_buf[:m]
        np.take(last, idx, out=lag, mode="clip")
        np.subtract(j, lag, out=lag)
        np.take(decay_r, lag, out=r_m, mode="clip")
        np.take(decay_u, lag, out=u_m, mode="clip")
        np.take(q, idx, out=q_m, mode="clip")
        np.take(v, idx, out=v_m, mode="clip")
        _step_inplace(q_m, v_m, r_m, u_m, u0, f, scratch[:m])
        q[idx] = q_m
        v[idx] = v_m
        last[idx] = j
    return q.reshape(h, w), v.reshape(h, w)


def tfstp_rate(
    planes: np.ndarray,
    key_plane: int,
    params: STPParams = DEFAULT_PARAMS,
    *,
    backend: str = "auto",
) -> np.ndarray:
    """TFSTP's rate estimate at the key plane, from the two read-outs.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
    key_plane : int in [0, T)
    params : STPParams
        ``u0``, ``D``, ``F`` and ``f``.
    backend : {"auto", "numba", "numpy"}
        How the states are computed (see :func:`tfstp_state`; the same bits either way).

    Returns
    -------
    ndarray float64 (H, W) >= 0
        ``(ρ_R + ρ_u) / 2`` in spikes per plane, or the one read-out whose variable is not at rest
        (after an interval of more than ~745 D planes); 0 for pixels with fewer than two spikes up
        to the key plane.
    """
    p = _check_params(params)
    u0, d, big_f, f = p.u0, p.recovery_planes, p.facilitation_planes, p.facilitation
    if _resolve_backend(backend) == "numba":  # states and read-out in one compiled pass
        planes, key_plane = check_spike_window(planes, key_plane)
        decay_r, decay_u = _decay_tables(key_plane + 1, d, big_f)
        with KERNEL_LOCK:
            rate, saturated = _kernels.tfstp_rate_fused(np.ascontiguousarray(planes), key_plane + 1, decay_r,
                                                        decay_u, u0, d, big_f, f, _TINY)
        if saturated:
            raise NeuSpikeError(_SATURATED)
        return rate
    q, v = tfstp_state(planes, key_plane, p, backend=backend)
    rate_r, rate_u = _rates(q, v, p)
    rate = rate_r + rate_u
    rate[(rate_r > 0) & (rate_u > 0)] *= 0.5  # the mean where both moved, else the one that did
    return rate


class TFSTP(Method):
    """Texture from short-term plasticity (see the module docstring).

    Parameters
    ----------
    name : str, optional
    u0 : float
        Resting utilisation, in (0, 1).
    recovery_planes : float
        ``D``, the resources' recovery time constant, in planes.
    facilitation_planes : float
        ``F``, the utilisation's decay time constant, in planes.
    facilitation : float
        ``f``, the utilisation step per spike, in (0, 1).
    """

    inputs = frozenset({"spikes"})

    def __init__(
        self,
        name: str | None = None,
        *,
        u0: float = U0,
        recovery_planes: float = RECOVERY_PLANES,
        facilitation_planes: float = FACILITATION_PLANES,
        facilitation: float = FACILITATION,
    ) -> None:
        self.stp = STPParams(u0, recovery_planes, facilitation_planes, facilitation)
        super().__init__(name, **dataclasses.asdict(self.stp))

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        stream = sample.spikes
        return stream_rate_to_image(tfstp_rate(stream.planes, sample.key_plane, self.stp), stream)


def register_methods(register) -> None:
    """Register ``tfstp`` with the published parameters."""
    register(
        "tfstp",
        TFSTP,
        params=dataclasses.asdict(DEFAULT_PARAMS),
        description="texture from short-term plasticity (Zheng et al. 2021), exact steady-state read-out",
    )
