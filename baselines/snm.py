"""SNM-style reconstruction: a spiking neural model with motion excitation and adaptive thresholds.

After Zhu, Dong, Li, Huang and Tian, "Retina-like visual image reconstruction via spiking neural
model" (CVPR 2020). Three layers of per-pixel neurons, vectorised over all pixels with torch and
stepped plane by plane (float32 states of shape (H, W); no loop over pixels):

1. **Motion local excitation.** A pixel whose successive inter-spike intervals (ISIs) change
   markedly is changing (moving); a static pixel's ISIs are stable. Two consecutive complete ISIs
   ``u`` and ``v`` (in planes) mark a change when ``|u - v| - 1 > motion_threshold * min(u, v)``:
   one plane of difference is always allowed, because an integrate-and-fire pixel with constant
   input fires at ISIs ``floor(1 / rate)`` and ``ceil(1 / rate)`` alternately. An interval is
   flagged when it differs so from the interval before or after it, and the flag excites the
   pixel and its 3x3 neighbourhood (the *local* excitation) for the planes of that interval.
2. **Spike refining.** Each raw spike's unit of charge is spread evenly over the ISI it closes, a
   per-plane *refined current* ``x`` (spikes per plane). In moving-camera mode (``dynamic_refining``)
   an ISI ``b`` between neighbours ``a`` and ``c`` with ``a > b > c`` or ``a < b < c`` straddles a
   change of input: it is split at ``t_m = a (c - b) / (c - a)`` planes after its opening spike,
   with current ``1 / a`` before ``t_m`` and ``1 / c`` after. ``t_m`` is exactly the instant at
   which a unit-threshold integrator charging at ``1 / a`` and then at ``1 / c`` reaches threshold
   after ``b`` planes (``t_m / a + (b - t_m) / c = 1``), so both rules conserve charge: every
   interval carries exactly one spike.
3. **Visual reconstruction.** A neuron per pixel whose adaptive threshold ``theta`` (mV) rises by
   ``THRESHOLD_STEP_MV`` per unit of synaptic charge and relaxes to rest with the threshold time
   constant (``threshold_time_constant_ms``, 20 ms = 400 planes at 20 kHz); theta is read out as
   intensity. Motion excitation shortens the time constant of an excited pixel to
   ``motion_memory_isi`` of its own ISIs, and a detected change (at ``t_m``, or at the spike between
   two markedly different ISIs) discounts everything before it by ``exp(-step_forgetting)``: moving
   pixels adapt within a few ISIs (edges do not smear) while static pixels average over the whole
   window (less noise). The neuron is driven through 3x3 synapses with weights
   ``exp(-10 d / 15)`` (``d`` the distance in pixel pitches: 1, 0.51 and 0.39 for the centre, edge
   and corner neighbours; ``coupling_length_px = 1.5``) scaled by a symmetric STDP-style timing
   factor ``exp(-|dt| / stdp_time_constant_ms)``, ``dt`` the timing drift between the two pixels'
   spike trains (below).

Calibration (the read-out in the ground truth's units)
------------------------------------------------------
With decay factor ``q = exp(-1 / tau)`` per plane, the threshold excess ``A = theta - theta_rest``
follows ``A <- q A + step * x``; its fixed point for a constant current ``r`` (spikes per plane) is
``A* = step * r / (1 - q)`` (:func:`threshold_steady_state_mv`), so ``r = A* (1 - q) / step``. The
factor ``1 / (1 - q)`` is the steady state of the *mass* ``M <- q M + m`` (``m = 1`` on every plane
with a known current), and the read-out ``r = A / (step * M)`` (:func:`rate_from_threshold`) inverts
the steady state exactly once converged and is unbiased from a cold start, for any time course of
``q``: it is a normalised weighted mean of the refined current. Because the refined current
conserves charge, a perfectly periodic spike train of period ``P`` gives ``x = 1 / P`` on every
plane and the read-out ``1 / P`` exactly. The rate becomes an image through
:func:`neuspike.methods.normalisation.stream_rate_to_image`: the stream's dark rate subtracted (known, or
estimated from the window), then divided by the stream's gain when known (radiance), the robust
99th-percentile scale when not (real recordings).

Speed
-----
Two implementations of the plane loops, chosen by ``backend``: the compiled kernel of
:mod:`baselines.snm_kernels` (numba, every pixel's layers fused into one vectorised pass per row and
plane, row bands in parallel on ``numba.get_num_threads()`` threads; the default where numba can be
imported) and the reference, two plane loops of in-place torch operations on (H, W) float32 buffers
(a backward one that tabulates each plane's next spike and the ISI after it, a forward one that runs
the three layers) on one torch intra-op thread (:func:`_one_intra_op_thread`: per-operation thread
barriers cost more than they gain on planes this small). The two agree to a few float32 roundings
(``tests/baselines/test_snm.py`` states the tolerance); ``python -m bench.method_speed`` times both.

Simplifications of the authors' model (each one deliberate)
-----------------------------------------------------------
* **Discrete time.** Every dynamic runs in steps of one plane; times in ms become planes through
  the stream's ``plane_rate_hz`` (20,000 planes/s: 1 ms = 20 planes).
* **Two-sided, cold-started window.** The authors' network runs causally on an endless stream.
  A sample holds only its spike window (256 planes = 12.8 ms, shorter than the 20 ms threshold time
  constant), so the neuron cannot converge causally. The reconstruction neuron therefore integrates
  the planes after the key plane too (a second copy running backwards in time; the weight of a plane
  is the product of the decays between it and the key plane), and its read-out is normalised by the
  running mass instead of the converged one. No state carries over between samples.
* **Refining neuron.** The authors' refining layer is a leaky integrate-and-fire neuron (tau = 10 ms)
  with an adaptive threshold. Its leak makes the refined rate a non-linear function of the input,
  with a dead zone below about one spike per tau (every pixel darker than 0.16 at L = 1/32) and
  a light-dependent loss the read-out would have to undo. It is replaced by its leak-free limit, the
  charge-conserving refined current above; the 10 ms constant survives as the STDP time constant.
  Dynamic refining (the authors' moving-camera mode) is on by default and can be switched off.
* **Fluid threshold.** theta rises in proportion to the synaptic charge as it arrives (the
  expectation of the spiking update that adds one step per output spike), which removes the firing
  phase ripple of theta (relative size period / tau) from the read-out. ``THRESHOLD_STEP_MV`` and the
  resting threshold cancel from the read-out; they only set theta's scale in mV.
* **Motion excitation** is a binary flag per interval (no excitation neuron with its own dynamics);
  its effect is the shortened time constant and the discount across a located change. Intervals are
  compared whole; a pixel's first and last partial intervals in the window (before its first spike,
  after its last) carry no known charge and are left out of the read-out (mass 0).
* **Synapses.** The STDP rule is not learned: over one window, pair-based STDP on regular,
  rate-coded trains has no net drift of the weights (potentiation and depression balance) and its
  10 ms traces span most of the window. Each synapse keeps its distance weight times the pair-based
  STDP kernel ``exp(-|dt| / tau_stdp)`` evaluated at the timing drift of the two trains: regular
  trains of ISIs ``P_i`` and ``P_k`` released together drift apart by ``|P_i - P_k|`` per spike, so
  over the ``D`` planes both neurons integrated ``dt = D |P_i - P_k| / mean(P_i, P_k)
  = D * 2 |r_i - r_k| / (r_i + r_k)``, with ``D = min(M_i, M_k)``. Similar neighbours couple fully,
  dissimilar ones (an edge) hardly: an edge-preserving term. The coupling is applied once, at the key
  plane, to each pixel's read-out (neighbour ``k`` of pixel ``i`` weighs
  ``w * exp(-|dt| / tau_stdp) * min(M_i, M_k)``), not plane by plane; the two agree where the pixels
  share a time course, as static regions do. The length scale "15 um" of the weights is read as 1.5
  pixel pitches after the factor 10 (``d`` in pixel pitches); ``coupling_length_px = 0`` switches the
  coupling off. Even so, the coupling averages fine texture with its neighbours: on a static
  photograph it caps the PSNR well below that of the uncoupled read-out, which is the price of the
  authors' noise-reducing synapses.
* **Pixels without a complete ISI** in the window (an ISI longer than about ``T / 2``) have no
  interval to decode. Without a spike the read-out is 0. A single threshold crossing at time ``t``
  (in planes from the window's start) leaves two spans without spikes, the longer one
  ``G = max(t, T - t)``, and the read-out is ``T / (2 G^2)`` spikes per plane, averaged over the
  plane ``[t1, t1 + 1)`` in which the crossing happened. For an ISI ``P > T / 2`` and a uniformly
  random firing phase this makes the pixel's expected read-out exactly ``1 / P``: pixels with two
  spikes are read exactly, those with none read 0, and given one spike ``G`` is uniform on
  ``[T / 2, P]`` (on ``[T / 2, T]`` when ``P > T``), over which ``T / (2 G^2)`` averages to what is
  missing. Neither the plain count ``1 / T`` (biased low by up to about 17 % for ``T / 2 < P < T``,
  because exactly the pixels with fewer spikes than average land here) nor the bound ``1 / G``
  (biased high by up to about 39 %) has that property; the price is a larger spread per pixel.
"""

from __future__ import annotations

import contextlib
import math
import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from neuspike.methods.normalisation import stream_rate_to_image
from neuspike.utils.checks import check_nonnegative, check_positive, check_spike_window
from neuspike.errors import InputError
from neuspike.methods import Method
from neuspike.utils.parallel import KERNEL_LOCK, resolve_backend
from neuspike.sample import Sample

__all__ = [
    "COUPLING_LENGTH_PX",
    "MOTION_MEMORY_ISI",
    "MOTION_THRESHOLD",
    "SNM",
    "SNMState",
    "STDP_TIME_CONSTANT_MS",
    "STEP_FORGETTING",
    "THRESHOLD_STEP_MV",
    "THRESHOLD_TIME_CONSTANT_MS",
    "coupling_weights",
    "isi_changed",
    "ms_to_planes",
    "rate_from_threshold",
    "register_methods",
    "snm_rate",
    "snm_state",
    "steady_state_mass",
    "step_instant",
    "threshold_steady_state_mv",
]

#: Time constant of the reconstruction neuron's adaptive threshold (the authors' 20 ms).
THRESHOLD_TIME_CONSTANT_MS = 20.0
#: STDP time constant (the authors' 10 ms, pre and post alike).
STDP_TIME_CONSTANT_MS = 10.0
#: Rise of the adaptive threshold per unit of synaptic charge (the authors' 3 mV step).
THRESHOLD_STEP_MV = 3.0
#: e-folding length of the synaptic weights exp(-10 d / 15), in pixel pitches.
COUPLING_LENGTH_PX = 1.5
#: Relative ISI change (beyond one plane) that marks a pixel as changing.
MOTION_THRESHOLD = 0.25
#: Memory of an excited (moving) pixel, in its own ISIs.
MOTION_MEMORY_ISI = 1.0
#: Discount exp(-STEP_FORGETTING) of everything before a located change of a pixel's input.
STEP_FORGETTING = 4.0

#: Accepted values of ``backend``: the compiled kernel, the torch reference, or numba where available.
BACKENDS: tuple[str, ...] = ("auto", "numba", "torch")

try:  # numba is a dependency, but the method must still run where it cannot be imported
    from baselines import snm_kernels as _kernels
except ImportError:  # pragma: no cover - exercised only without numba
    _kernels = None

# Floor of the kernel weight of planes after the key plane: keeps float32 away from denormals (slow)
# and underflow; a plane this far from the key plane in decays contributes nothing measurable.
_MIN_WEIGHT = 1e-30


# --- small pure pieces ------------------------------------------------------------------------

def ms_to_planes(time_ms: float, plane_rate_hz: float) -> float:
    """A duration in milliseconds of sensor time as a number of planes (``ms * rate / 1000``)."""
    return check_positive("time_ms", time_ms) * check_positive("plane_rate_hz", plane_rate_hz) / 1000.0


def coupling_weights(coupling_length_px: float) -> np.ndarray:
    """Distance weights of the 3x3 synapses onto a reconstruction neuron.

    Parameters
    ----------
    coupling_length_px : float >= 0
        e-folding length in pixel pitches: ``w = exp(-d / coupling_length_px)`` with ``d`` the
        distance to the centre (0, 1 or sqrt(2)). ``0`` gives the centre alone.

    Returns
    -------
    ndarray float32 (3, 3), centre 1.
    """
    length = check_nonnegative("coupling_length_px", coupling_length_px)
    if length == 0:
        w = np.zeros((3, 3), dtype=np.float32)
        w[1, 1] = 1.0
        return w
    dy, dx = np.mgrid[-1:2, -1:2]
    return np.exp(-np.hypot(dy, dx) / length).astype(np.float32)


def isi_changed(
    u: torch.Tensor,
    v: torch.Tensor,
    motion_threshold: float,
    *,
    out: torch.Tensor | None = None,
    scratch: torch.Tensor | None = None,
) -> torch.Tensor:
    """Whether two consecutive ISIs differ markedly: ``|u - v| - 1 > motion_threshold * min(u, v)``.

    Parameters
    ----------
    u, v : float tensors, same shape
        ISIs in planes (>= 1 where known; the result is meaningless elsewhere and must be masked).
    motion_threshold : float >= 0
        Relative change beyond the one plane of quantisation that an integrate-and-fire pixel with
        constant input shows anyway.
    out, scratch : float tensors of the same shape, optional
        Buffers for the result and an intermediate (the plane loop reuses its own).

    Returns
    -------
    float tensor of 0.0 and 1.0, same shape (``out`` when given).
    """
    out = torch.empty_like(u) if out is None else out
    scratch = torch.empty_like(u) if scratch is None else scratch
    torch.sub(u, v, out=out)
    return _marked_change(out, torch.minimum(u, v, out=scratch), motion_threshold, out=out)


def _marked_change(
    diff: torch.Tensor, shorter: torch.Tensor, motion_threshold: float, *, out: torch.Tensor
) -> torch.Tensor:
    """``[|diff| - 1 > motion_threshold * shorter]`` as 0.0/1.0 into ``out`` (which may be ``diff``).

    ``diff`` is ``u - v`` and ``shorter`` is ``min(u, v)`` (scaled in place).
    """
    shorter.mul_(motion_threshold)
    return torch.abs(diff, out=out).sub_(1.0).sub_(shorter).sign_().clamp_(min=0.0)


def step_instant(
    a: torch.Tensor,
    b: torch.Tensor,
    c: torch.Tensor,
    *,
    mask: torch.Tensor | None = None,
    out: torch.Tensor | None = None,
    scratch: torch.Tensor | None = None,
) -> torch.Tensor:
    """Dynamic spike refining: where a change of input lies inside the ISI ``b``.

    For ISIs ``a, b, c`` in a row with ``a > b > c`` or ``a < b < c``, a unit-threshold integrator that
    charges at ``1 / a`` until ``t_m`` and at ``1 / c`` after reaches threshold after ``b`` planes when
    ``t_m = a (c - b) / (c - a)``, which lies in ``(0, b)``.

    Parameters
    ----------
    a, b, c : float tensors, same shape
        ISIs in planes, strictly monotonic element-wise where ``mask`` is 1.
    mask : float tensor of 0.0 and 1.0, optional
        Where to compute ``t_m``; the result is 0 elsewhere (no division by ``c - a = 0`` there).
        Without it every element must be monotonic.
    out, scratch : float tensors of the same shape, optional
        Buffers for the result and an intermediate.

    Returns
    -------
    float tensor, planes after the spike that opens ``b`` (``out`` when given).
    """
    out = torch.empty_like(a) if out is None else out
    scratch = torch.empty_like(a) if scratch is None else scratch
    torch.sub(c, a, out=scratch)
    torch.sub(c, b, out=out).mul_(a)
    if mask is not None:
        scratch.sub_(1.0).mul_(mask).add_(1.0)   # c - a where mask, 1 elsewhere
        out.mul_(mask)
    return out.div_(scratch)


def threshold_steady_state_mv(rate: Any, *, time_constant_planes: float, step_mv: float = THRESHOLD_STEP_MV) -> Any:
    """Threshold excess ``theta - theta_rest`` (mV) at the fixed point of ``A <- q A + step * rate``.

    Parameters
    ----------
    rate : float or array
        Constant refined current, spikes per plane.
    time_constant_planes : float > 0
        Threshold time constant ``tau`` in planes (``q = exp(-1 / tau)``).
    step_mv : float > 0
        Threshold rise per unit of charge.

    Returns
    -------
    ``step * rate * steady_state_mass(tau)``, same type as ``rate``.
    """
    return check_positive("step_mv", step_mv) * rate * steady_state_mass(time_constant_planes)


def steady_state_mass(time_constant_planes: float) -> float:
    """Fixed point ``1 / (1 - exp(-1 / tau))`` of the mass ``M <- exp(-1 / tau) M + 1``."""
    tau = check_positive("time_constant_planes", time_constant_planes)
    return -1.0 / math.expm1(-1.0 / tau)


def rate_from_threshold(threshold_excess_mv: Any, mass: Any, *, step_mv: float = THRESHOLD_STEP_MV) -> Any:
    """Invert the threshold's steady state: rate (spikes per plane) = excess / (step * mass).

    ``mass`` is :func:`steady_state_mass` for a converged one-sided neuron and the running mass of
    :func:`snm_state` in general. Entries with zero mass have no defined rate; the caller masks them.
    """
    return threshold_excess_mv / (check_positive("step_mv", step_mv) * mass)


@contextlib.contextmanager
def _one_intra_op_thread():
    """Run torch on one intra-op thread inside the block; restore the previous count after.

    The plane loops issue thousands of small (H, W) operations. Threads gain little on them, and on
    a shared machine every operation's thread barrier waits for a core that someone else holds:
    runs with two threads were seen to take from 0.3 s to tens of seconds per frame, with one
    thread 0.5 to 0.9 s. The results do not depend on the thread count (element-wise arithmetic).
    """
    previous = torch.get_num_threads()
    if previous == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


# --- the model --------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Params:
    """Validated parameters of the model, time constants already in planes."""

    threshold_tau_planes: float
    stdp_tau_planes: float
    coupling_length_px: float
    motion_threshold: float
    motion_memory_isi: float
    step_forgetting: float
    dynamic_refining: bool


@dataclass(frozen=True)
class SNMParams:
    """The model's parameters in their physical units, validated once (see :class:`SNM` for each).

    Raises
    ------
    InputError
        For a value outside its range (stored as float, or bool for ``dynamic_refining``, otherwise).
    """

    threshold_time_constant_ms: float = THRESHOLD_TIME_CONSTANT_MS
    stdp_time_constant_ms: float = STDP_TIME_CONSTANT_MS
    coupling_length_px: float = COUPLING_LENGTH_PX
    motion_threshold: float = MOTION_THRESHOLD
    motion_memory_isi: float = MOTION_MEMORY_ISI
    step_forgetting: float = STEP_FORGETTING
    dynamic_refining: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.dynamic_refining, (bool, np.bool_)):
            raise InputError(f"dynamic_refining: expected True or False, got {self.dynamic_refining!r}")
        checked = {
            "threshold_time_constant_ms": check_positive("threshold_time_constant_ms", self.threshold_time_constant_ms),
            "stdp_time_constant_ms": check_positive("stdp_time_constant_ms", self.stdp_time_constant_ms),
            "coupling_length_px": check_nonnegative("coupling_length_px", self.coupling_length_px),
            "motion_threshold": check_nonnegative("motion_threshold", self.motion_threshold),
            "motion_memory_isi": check_positive("motion_memory_isi", self.motion_memory_isi),
            "step_forgetting": check_nonnegative("step_forgetting", self.step_forgetting),
            "dynamic_refining": bool(self.dynamic_refining),
        }
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    def in_planes(self, plane_rate_hz: float) -> _Params:
        """The parameters with their time constants in planes of a sensor at ``plane_rate_hz``."""
        return _Params(
            threshold_tau_planes=ms_to_planes(self.threshold_time_constant_ms, plane_rate_hz),
            stdp_tau_planes=ms_to_planes(self.stdp_time_constant_ms, plane_rate_hz),
            coupling_length_px=self.coupling_length_px,
            motion_threshold=self.motion_threshold,
            motion_memory_isi=self.motion_memory_isi,
            step_forgetting=self.step_forgetting,
            dynamic_refining=self.dynamic_refining,
        )


#: The model's default parameters.
DEFAULT_PARAMS = SNMParams()


def _params(params: Any, plane_rate_hz: float) -> _Params:
    if not isinstance(params, SNMParams):
        raise InputError(f"params: expected an SNMParams, got {type(params).__name__}")
    return params.in_planes(plane_rate_hz)


def _check_planes(planes: Any, key_plane: Any) -> tuple[np.ndarray, int]:
    planes, key_plane = check_spike_window(planes, key_plane)
    if min(planes.shape) < 1:
        raise InputError(f"planes: expected at least one plane of at least 1x1 pixels, got shape {planes.shape}")
    return np.ascontiguousarray(planes), key_plane


@dataclass(frozen=True)
class SNMState:
    """What the reconstruction neurons hold at the key plane, per pixel (all float32 (H, W) tensors).

    Attributes
    ----------
    threshold_excess_mv : tensor
        ``theta - theta_rest`` of the reconstruction neuron (both time directions), mV.
    mass : tensor
        The matching running mass (kernel-weighted planes of known current), >= 0.
    count : tensor
        Spikes of the pixel in the whole window.
    first_spike : tensor
        Plane of the pixel's first spike in the window, -1 without one.
    excited_planes : tensor
        Planes of the window on which the pixel was excited by motion (its own or a neighbour's).
    """

    threshold_excess_mv: torch.Tensor
    mass: torch.Tensor
    count: torch.Tensor
    first_spike: torch.Tensor
    excited_planes: torch.Tensor


def _next_spike_tables(spikes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Backward pass: for every plane j, the first spike at or after j and the ISI that follows it.

    Parameters
    ----------
    spikes : uint8 tensor (T, H, W) of 0 and 1.

    Returns
    -------
    next_plane : integer tensor (T, H, W)
        Plane of the first spike at or after plane j; -1 where the pixel fires no more.
    next_isi : integer tensor (T, H, W)
        The complete ISI that this spike opens; 0 where it does not close inside the window.
    count : float32 tensor (H, W)
        Spikes per pixel in the window.

    The tables are int16 when T fits, int32 otherwise. Per plane the work is a handful of in-place
    operations on (H, W) buffers (fresh (H, W) tensors cost more than the arithmetic on them).
    """
    num_planes, height, width = spikes.shape
    dtype = torch.int16 if num_planes <= torch.iinfo(torch.int16).max else torch.int32
    next_plane = torch.empty((num_planes, height, width), dtype=dtype)
    next_isi = torch.empty((num_planes, height, width), dtype=dtype)
    nxt = torch.full((height, width), -1.0)
    nxt_isi = torch.zeros((height, width))
    count = torch.zeros((height, width))
    s, tmp, since = (torch.empty((height, width)) for _ in range(3))
    for j in range(num_planes - 1, -1, -1):
        s.copy_(spikes[j])
        # where the pixel fires at j: nxt_isi <- nxt - j if it fires later (else 0), nxt <- j
        torch.sub(nxt, j, out=since)
        torch.add(nxt, 1.0, out=tmp).clamp_(0.0, 1.0).mul_(since).sub_(nxt_isi).mul_(s)
        nxt_isi.add_(tmp)
        nxt.sub_(since.mul_(s))
        count.add_(s)
        next_plane[j].copy_(nxt)
        next_isi[j].copy_(nxt_isi)
    return next_plane, next_isi, count


def snm_state(
    planes: np.ndarray,
    key_plane: int,
    params: SNMParams = DEFAULT_PARAMS,
    *,
    plane_rate_hz: float,
    backend: str = "auto",
) -> SNMState:
    """Run the motion-excitation, refining and reconstruction layers over the window.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
        The spike window.
    key_plane : int in [0, T)
        The plane to reconstruct.
    params : SNMParams
        The model's parameters (the coupling is not used here).
    plane_rate_hz : float > 0
        Planes per second of sensor time (converts the time constants to planes).
    backend : {"auto", "numba", "torch"}
        ``"numba"``: the compiled kernel (:mod:`baselines.snm_kernels`); ``"torch"``: the reference
        plane loop of tensor operations; ``"auto"``: numba where it can be imported. Both compute
        the same float32 arithmetic in the same order (they agree to float32 rounding; see
        :data:`BACKENDS`).

    Returns
    -------
    SNMState
        Per-pixel threshold excess, mass, spike count and excited planes at the key plane; the
        coupling through the 3x3 synapses is not applied yet (see :func:`snm_rate`).

    Notes
    -----
    One forward loop over the planes, every pixel at once. For plane ``j`` of a pixel, ``last`` is its
    last spike before ``j`` and ``a`` the complete ISI that ended there (forward state); ``n`` is its
    first spike at or after ``j`` and ``c`` the ISI after that (from :func:`_next_spike_tables`). Plane
    ``j`` lies in the ISI ``b = n - last`` when both spikes exist. Each line below is an in-place update
    of an (H, W) float32 buffer; the comment above it gives the quantity.
    """
    planes, key_plane = _check_planes(planes, key_plane)
    p = _params(params, plane_rate_hz)
    if _resolve_backend(backend) == "numba" and _kernels.fits_exp_range(1.0 / p.motion_memory_isi, planes.shape[0]):
        return _integrate_compiled(planes, key_plane, p)
    with _one_intra_op_thread():
        return _integrate(torch.from_numpy(planes.view(np.uint8)), key_plane, p)


def _resolve_backend(backend: Any) -> str:
    """``"numba"`` or ``"torch"`` for a requested backend (see :data:`BACKENDS`)."""
    return resolve_backend(backend, compiled=_kernels is not None, reference="torch")


def _still_decay(p: _Params) -> np.float32:
    """``exp(-1/tau)``, the decay per plane of a pixel that is not excited, with the reference's
    own float32 operations (``0 / b * (-1 / memory) - 1 / tau``, then torch's exp)."""
    x = torch.zeros(64).div_(torch.ones(64)).mul_(-1.0 / p.motion_memory_isi).sub_(1.0 / p.threshold_tau_planes)
    return np.float32(x.exp_()[0].item())


def _integrate_compiled(planes: np.ndarray, key_plane: int, p: _Params) -> SNMState:
    """:func:`_integrate` through the compiled kernel (``planes`` bool (T, H, W), validated inputs)."""
    with KERNEL_LOCK:
        charge, mass, count, first, excited = _kernels.snm_integrate(
            planes, key_plane, motion_threshold=p.motion_threshold, dynamic_refining=p.dynamic_refining,
            lost_at_cut=-math.expm1(-p.step_forgetting), static_rate=1.0 / p.threshold_tau_planes,
            motion_rate=1.0 / p.motion_memory_isi, decay_still=_still_decay(p), min_weight=_MIN_WEIGHT,
        )
    charge *= np.float32(THRESHOLD_STEP_MV)
    return SNMState(
        threshold_excess_mv=torch.from_numpy(charge), mass=torch.from_numpy(mass), count=torch.from_numpy(count),
        first_spike=torch.from_numpy(first), excited_planes=torch.from_numpy(excited),
    )


def _integrate(spikes: torch.Tensor, key_plane: int, p: _Params) -> SNMState:
    """The plane loops of :func:`snm_state` (``spikes`` uint8 (T, H, W), validated inputs)."""
    next_plane, next_isi, count = _next_spike_tables(spikes)
    num_planes, height, width = spikes.shape

    static_rate = 1.0 / p.threshold_tau_planes
    motion_rate = 1.0 / p.motion_memory_isi
    lost_at_cut = -math.expm1(-p.step_forgetting)         # 1 - exp(-step_forgetting)
    thr = p.motion_threshold

    def buffer(*shape: int, fill: float = 0.0) -> torch.Tensor:
        return torch.full((*shape, height, width), fill)

    # abc[0], abc[1], abc[2] = a, b, c: the ISI before, around and after plane j. a is forward state
    # (the ISI that ended at the last spike, 0: unknown), b and c are filled per plane.
    abc = buffer(3)
    a, b, c = abc[0], abc[1], abc[2]
    last = buffer(fill=-1.0)                  # forward state: the last spike before plane j (-1: none)
    has_prev = buffer()                       # forward state: [last >= 0]
    charge_before, mass_before = buffer(), buffer()    # planes <= key, decayed to the key plane
    charge_after, mass_after = buffer(), buffer()      # planes > key, weighted by their decay from it
    weight_after, kept_prev = buffer(fill=1.0), buffer(fill=1.0)
    excited_planes = buffer()
    n, s, complete, mono, t_m, offset, current, kept, decay, t1, t2 = (buffer() for _ in range(11))
    has, diff, marked, shorter = buffer(2), buffer(2), buffer(2), buffer(2)
    excitation, rows = buffer(), buffer()

    for j in range(num_planes):
        n.copy_(next_plane[j])
        c.copy_(next_isi[j])
        # complete = [plane j lies in a complete ISI]
        torch.add(n, 1.0, out=complete).clamp_(0.0, 1.0).mul_(has_prev)
        # b = n - last where complete, 1 elsewhere (a safe divisor)
        torch.sub(n, last, out=b).sub_(1.0).mul_(complete).add_(1.0)
        # has = ([a known], [c known]) inside complete ISIs
        torch.clamp(abc[0::2], 0.0, 1.0, out=has).mul_(complete)
        # diff = (a - b, b - c)
        torch.sub(abc[:2], abc[1:], out=diff)

        # Layer 1, motion local excitation. marked = ([a -> b marked], [b -> c marked])
        torch.minimum(abc[:2], abc[1:], out=shorter)
        _marked_change(diff, shorter, thr, out=marked).mul_(has)
        after = marked[1]
        torch.maximum(marked[0], after, out=t1)
        # excitation = 3x3 maximum of t1 (the pixel's and its neighbours' changes)
        excitation.copy_(t1)
        if width > 1:
            torch.maximum(excitation[:, 1:], t1[:, :-1], out=excitation[:, 1:])
            torch.maximum(excitation[:, :-1], t1[:, 1:], out=excitation[:, :-1])
        rows.copy_(excitation)
        if height > 1:
            torch.maximum(rows[1:], excitation[:-1], out=rows[1:])
            torch.maximum(rows[:-1], excitation[1:], out=rows[:-1])
        excitation, rows = rows, excitation
        excited_planes.add_(excitation)

        # Layer 2, spike refining. mono = [a > b > c or a < b < c] (dynamic refining only)
        if p.dynamic_refining:
            torch.mul(diff[0], diff[1], out=mono).sign_().clamp_(min=0.0).mul_(has[0]).mul_(has[1])
        # t_m = a (c - b) / (c - a) where mono, 0 elsewhere
        step_instant(a, b, c, mask=mono, out=t_m, scratch=t1)
        # offset = j - last: plane j is plane `offset` (1..b) of its ISI, covering [offset - 1, offset)
        torch.mul(last, -1.0, out=offset).add_(j)
        # t1 = share of plane j before t_m;  current = 1/b, or t1/a + (1 - t1)/c where mono
        torch.sub(t_m, offset, out=t1).add_(1.0).clamp_(0.0, 1.0)
        torch.neg(t1, out=t2).add_(1.0).div_(torch.clamp(c, min=1.0, out=current))
        t1.div_(torch.clamp(a, min=1.0, out=current)).add_(t2)
        torch.reciprocal(b, out=t2)
        torch.sub(t1, t2, out=current).mul_(mono).add_(t2).mul_(complete)
        # The located change lies after plane `ceil(t_m)` where mono, after the closing spike
        # (plane b) where `after`: kept = exp(-step_forgetting) on that plane, 1 elsewhere, i.e.
        # min(1, 1 - lost + lost * |plane - offset|) for integers. (mono and after are 0 outside
        # complete ISIs, where offset >= 1: no cut there.)
        torch.mul(after, b, out=t2)
        torch.ceil(t_m, out=kept).sub_(t2).mul_(mono).add_(t2)
        kept.sub_(offset).abs_().mul_(lost_at_cut).add_(1.0 - lost_at_cut).clamp_(max=1.0)

        # Layer 3, the reconstruction neuron. decay = exp(-(1/tau + excitation / (memory * b)))
        torch.mul(excitation, complete, out=decay).div_(b).mul_(-motion_rate).sub_(static_rate).exp_()
        if j < key_plane:
            charge_before.mul_(decay).add_(current).mul_(kept)
            mass_before.mul_(decay).add_(complete).mul_(kept)
        elif j == key_plane:
            charge_before.mul_(decay).add_(current)
            mass_before.mul_(decay).add_(complete)
            kept_prev.copy_(kept)
        else:
            weight_after.mul_(kept_prev).mul_(decay).clamp_(min=_MIN_WEIGHT)
            charge_after.addcmul_(weight_after, current)
            mass_after.addcmul_(weight_after, complete)
            kept_prev.copy_(kept)

        # Forward state: where the pixel fires at j, a <- j - last (if last exists), last <- j.
        s.copy_(spikes[j])
        torch.mul(offset, has_prev, out=t1).sub_(a).mul_(s)
        a.add_(t1)
        last.addcmul_(offset, s)
        has_prev.clamp_(min=s)

    charge_before.add_(charge_after)
    mass_before.add_(mass_after)
    return SNMState(
        threshold_excess_mv=charge_before.mul_(THRESHOLD_STEP_MV),
        mass=mass_before,
        count=count,
        first_spike=next_plane[0].to(torch.float32),
        excited_planes=excited_planes,
    )


def _single_spike_rate(first_spike: torch.Tensor, num_planes: float) -> torch.Tensor:
    """Read-out of a pixel whose only spike in ``T`` planes is at plane ``t1`` (see the module docstring).

    The integral of ``T / (2 G(t)^2)``, ``G(t) = max(t, T - t)``, over the plane ``[t1, t1 + 1)`` in
    which the threshold crossing happened; its antiderivative is
    ``F(t) = 1/2 + sign(t - T/2) (1 - T / (2 G(t)))``, with ``F(0) = 0`` and ``F(T) = 1``.
    """
    half = 0.5 * num_planes

    def antiderivative(t: torch.Tensor) -> torch.Tensor:
        longer = torch.maximum(t, num_planes - t)
        return 0.5 + torch.sign(t - half) * (1.0 - half / longer)

    return antiderivative(first_spike + 1.0) - antiderivative(first_spike)


def _couple(rate: torch.Tensor, mass: torch.Tensor, weights: np.ndarray, stdp_tau_planes: float) -> torch.Tensor:
    """Pass each pixel's read-out through the 3x3 synapses (see the module docstring).

    Neighbour ``k`` of pixel ``i`` weighs ``w_d * exp(-dt / tau_stdp) * min(M_i, M_k)``, where
    ``dt = min(M_i, M_k) * 2 |r_i - r_k| / (r_i + r_k)`` is the timing drift that two regular trains
    of rates ``r_i`` and ``r_k`` build up, released together, over the planes both neurons integrated.
    Pixels with zero mass neither give nor take; where a pixel and all its neighbours have zero mass
    its own value is returned.
    """
    height, width = rate.shape
    pad = lambda t: torch.nn.functional.pad(t[None, None], (1, 1, 1, 1))[0, 0]  # noqa: E731
    rate_p, mass_p = pad(rate), pad(mass)
    num = torch.zeros_like(rate)
    den = torch.zeros_like(rate)
    for dy in range(3):
        for dx in range(3):
            w = float(weights[dy, dx])
            if w == 0.0:
                continue
            rate_k = rate_p[dy : dy + height, dx : dx + width]
            pair_mass = torch.minimum(mass, mass_p[dy : dy + height, dx : dx + width])
            relative = 2.0 * (rate - rate_k).abs() / (rate + rate_k).clamp(min=1e-30)
            c = w * torch.exp(-pair_mass * relative / stdp_tau_planes) * pair_mass
            num += c * rate_k
            den += c
    return torch.where(den > 0, num / den.clamp(min=1e-30), rate)


def snm_rate(
    planes: np.ndarray,
    key_plane: int,
    params: SNMParams = DEFAULT_PARAMS,
    *,
    plane_rate_hz: float,
    backend: str = "auto",
) -> np.ndarray:
    """SNM-style spike rate at the key plane, read out of the adaptive thresholds.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
        The spike window.
    key_plane : int in [0, T)
        The plane to reconstruct.
    params : SNMParams
        The model's parameters.
    plane_rate_hz : float > 0
        Planes per second of sensor time.
    backend : {"auto", "numba", "torch"}
        The plane loops' implementation (see :func:`snm_state`).

    Returns
    -------
    ndarray float32 (H, W), spikes per plane in [0, 1]: the calibrated read-out
    ``rate_from_threshold(theta - theta_rest, mass)`` after the 3x3 coupling; pixels without a
    complete ISI read 0 without a spike and the phase-unbiased single-spike estimate with one (see
    the module docstring).
    """
    p = _params(params, plane_rate_hz)
    state = snm_state(planes, key_plane, params, plane_rate_hz=plane_rate_hz, backend=backend)
    with _one_intra_op_thread():
        known = state.mass > 0
        rate = torch.where(
            known,
            rate_from_threshold(state.threshold_excess_mv, state.mass.clamp(min=1e-30)),
            torch.zeros_like(state.mass),
        )
        rate = _couple(rate, torch.where(known, state.mass, torch.zeros_like(state.mass)),
                       coupling_weights(p.coupling_length_px), p.stdp_tau_planes)
        # count is 0 or 1 here (count 0 zeroes the term whatever first_spike = -1 gives).
        single = _single_spike_rate(state.first_spike, float(planes.shape[0]))
        rate = torch.where(known, rate, state.count * single)
        return rate.clamp_(0.0, 1.0).numpy()


class SNM(Method):
    """SNM-style spiking neural model reconstruction (see the module docstring).

    Parameters
    ----------
    name : str, optional
        Registry name.
    threshold_time_constant_ms : float > 0
        Time constant of the reconstruction neuron's adaptive threshold for static pixels (20 ms).
    stdp_time_constant_ms : float > 0
        Time constant of the synapses' STDP-style timing factor (10 ms).
    coupling_length_px : float >= 0
        e-folding length of the 3x3 synaptic weights in pixel pitches (1.5; 0: no coupling).
    motion_threshold : float >= 0
        Relative ISI change, beyond one plane, that marks a pixel as changing (0.25).
    motion_memory_isi : float > 0
        Time constant of an excited pixel, in its own ISIs (1).
    step_forgetting : float >= 0
        Discount ``exp(-step_forgetting)`` of everything before a located change (4; 0: none).
    dynamic_refining : bool
        Split ISIs that straddle a change at ``t_m`` (the authors' moving-camera mode; True).
    """

    inputs = frozenset({"spikes"})

    def __init__(
        self,
        name: str | None = None,
        *,
        threshold_time_constant_ms: float = THRESHOLD_TIME_CONSTANT_MS,
        stdp_time_constant_ms: float = STDP_TIME_CONSTANT_MS,
        coupling_length_px: float = COUPLING_LENGTH_PX,
        motion_threshold: float = MOTION_THRESHOLD,
        motion_memory_isi: float = MOTION_MEMORY_ISI,
        step_forgetting: float = STEP_FORGETTING,
        dynamic_refining: bool = True,
    ) -> None:
        self.snm = SNMParams(threshold_time_constant_ms, stdp_time_constant_ms, coupling_length_px,
                             motion_threshold, motion_memory_isi, step_forgetting, dynamic_refining)
        super().__init__(name, **dataclasses.asdict(self.snm))

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        stream = sample.spikes
        rate = snm_rate(stream.planes, sample.key_plane, self.snm, plane_rate_hz=stream.plane_rate_hz)
        return stream_rate_to_image(rate, stream)


def register_methods(register) -> None:
    """Register ``snm``."""
    register(
        "snm",
        SNM,
        params={},
        description="SNM-style spiking neural model: motion excitation, spike refining, adaptive-threshold read-out",
    )
