"""The spike camera: integrate-and-fire pixels with reset by subtraction (Algorithm 1 of NeuSpike-Net).

Every pixel integrates ``light * radiance`` per plane into a charge ``I``; where ``I`` reaches the
threshold ``phi`` the pixel fires (one spike, at most one per plane) and ``phi`` is subtracted, so
the remainder is kept. In the paper's window mode each of S scene instants is held for
``floor(T / S)`` planes; in continuous mode every plane sees its own instant (``hold_planes=1``).

Two effect stages exist, each run only when declared (:mod:`neuspike.conditions`):

``initial_charge``
    the integrator starts at ``I = N * phi``, N a per-pixel standard normal draw.
``dark_current``
    a fixed-pattern dark charge ``phi / isi`` per plane and pixel, ``isi ~ Normal(mean, std**2)``
    redrawn while below 1, so that in total darkness the pixel fires every ``isi`` planes.

The computation is :func:`integrate_and_fire`, a pure function; :class:`SpikeCamera` only holds
the parameters, the frozen dark pattern and the charge that persists between captures.

Two implementations give the same planes bit for bit (``backend=``): a fused compiled kernel
(:mod:`neuspike.sensors.spike_kernels`, numba, threads over bands of rows) and the plain NumPy
plane loop below, the reference and the fallback where numba cannot be imported. Either can emit
the planes bit-packed in the Vidar ``.dat`` layout (:class:`PackedPlanes`), eight times smaller;
the compiled kernel packs them as it goes.

Arithmetic (float32, in this order, so that any implementation can be checked bit for bit)::

    q_k = float32(F_k) * float32(light)            once per frame
    q_k = q_k + dark                               once per frame, only with a dark charge
    for each of the hold_planes planes of frame k:
        I = I + q_k
        spike = I >= float32(threshold)
        I = I - threshold  where spike
"""

from __future__ import annotations

import math
import time
from typing import Any, Iterable

import numpy as np

from neuspike.utils.checks import check_ndim, check_nonnegative, check_positive, check_positive_int, check_size
from neuspike.conditions import Effect, declared_stages
from neuspike.errors import InputError
from neuspike.utils.parallel import KERNEL_LOCK, parallel_usable
from neuspike.utils.parallel import resolve_backend
from neuspike.streams import VIDAR_PLANE_RATE_HZ, SpikeStream

__all__ = [
    "SPIKE_STAGES",
    "PackedPlanes",
    "pack_planes",
    "SpikeCamera",
    "draw_dark_charge",
    "draw_initial_charge",
    "integrate_and_fire",
]

#: The effect stages of the spike camera, in the order they draw from the generator.
SPIKE_STAGES: tuple[str, ...] = ("initial_charge", "dark_current")

#: Lowest acceptable probability that one ISI draw is >= 1 plane (else redrawing could not end).
_MIN_ACCEPTANCE = 1e-3


def _check_shape(name: str, shape: Any) -> tuple[int, int]:
    try:
        dims = tuple(shape)
    except TypeError:
        raise InputError(f"{name}: expected a shape (H, W), got {shape!r}") from None
    if len(dims) != 2:
        raise InputError(f"{name}: expected a shape (H, W), got {shape!r}")
    h = check_positive_int(f"{name} height", dims[0])
    w = check_positive_int(f"{name} width", dims[1])
    return h, w


def _check_rng(rng: Any) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    return rng


def _as_float32(name: str, value: float) -> np.float32:
    """``value`` (already checked > 0) as a float32 that is still finite and > 0."""
    v32 = np.float32(value)
    if not (np.isfinite(v32) and v32 > 0):
        raise InputError(f"{name}: {value!r} is not representable as a positive float32 (got {v32!r})")
    return v32


def _charge_map(name: str, array: Any, shape: tuple[int, int], *, nonnegative: bool) -> np.ndarray:
    """Validated float32 copy of an (H, W) charge map."""
    a = np.asarray(array)
    check_ndim(name, a, 2)
    if a.shape != shape:
        raise InputError(f"{name}: expected shape {shape} to match the frames, got {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)) or a.dtype == np.bool_:
        raise InputError(f"{name}: expected a real-valued array, got dtype {a.dtype}")
    out = np.array(a, dtype=np.float32, order="C", copy=True)
    if not np.isfinite(out).all():
        raise InputError(f"{name}: expected finite values, got {int(np.count_nonzero(~np.isfinite(out)))} "
                         "NaN or infinite entries (after conversion to float32)")
    if nonnegative and out.size and out.min() < 0:
        raise InputError(f"{name}: expected values >= 0, got a minimum of {float(out.min())!r}")
    return out


def _frames_array(frames: Any) -> np.ndarray:
    f = np.asarray(frames)
    check_ndim("frames", f, 3)
    if not np.issubdtype(f.dtype, np.floating):
        raise InputError(
            f"frames: expected floating-point radiance (1.0 = reference white), got dtype {f.dtype}; "
            "convert and scale integer images explicitly"
        )
    if 0 in f.shape[1:]:
        raise InputError(f"frames: expected a non-empty sensor, got shape {f.shape}")
    return f


#: Set bits of every byte value, for counting spikes in packed planes.
_BITS_SET = np.array([bin(v).count("1") for v in range(256)], np.uint8)


class PackedPlanes:
    """Spike planes bit-packed in the Vidar ``.dat`` layout (8 pixels per byte).

    Each plane is flipped vertically (stored row ``s`` is image row ``H - 1 - s``) and flattened;
    stored pixel ``p`` is bit ``p % 8`` of byte ``p // 8``, least significant bit first. ``data``
    is therefore exactly the bytes of a ``.dat`` file, plane after plane.

    Parameters
    ----------
    data : ndarray of uint8, shape (T, H * W / 8), C-contiguous
    height, width : int
        Sensor size H, W; ``H * W`` is a multiple of 8.
    """

    __slots__ = ("data", "height", "width")

    def __init__(self, data: np.ndarray, *, height: int, width: int) -> None:
        h, w = _check_shape("PackedPlanes shape", (height, width))
        if (h * w) % 8:
            raise InputError(f"PackedPlanes: H x W must be a multiple of 8 to pack, got {h} x {w}")
        d = np.asarray(data)
        if d.dtype != np.uint8 or d.ndim != 2 or d.shape[1] != h * w // 8:
            raise InputError(f"PackedPlanes.data: expected uint8 of shape (T, {h * w // 8}), "
                             f"got {d.dtype} {d.shape}")
        self.data = np.ascontiguousarray(d)
        self.height, self.width = h, w

    @property
    def num_planes(self) -> int:
        return self.data.shape[0]

    def unpack(self) -> np.ndarray:
        """The planes as bool (T, H, W), row 0 at the top of the image, C-contiguous."""
        t = self.data.shape[0]
        bits = np.unpackbits(self.data, axis=1, bitorder="little").view(np.bool_)
        return np.ascontiguousarray(bits.reshape(t, self.height, self.width)[:, ::-1, :])

    def count(self) -> int:
        """Number of spikes (set bits)."""
        if hasattr(np, "bitwise_count"):  # NumPy >= 2.0
            return int(np.bitwise_count(self.data).sum(dtype=np.int64))
        return int(_BITS_SET[self.data].sum(dtype=np.int64))

    def __repr__(self) -> str:
        return f"PackedPlanes({self.num_planes} planes of {self.width}x{self.height})"


def pack_planes(planes: np.ndarray) -> PackedPlanes:
    """Bool planes (T, H, W) (row 0 at the top) packed in the ``.dat`` layout (:class:`PackedPlanes`)."""
    p = np.asarray(planes)
    check_ndim("planes", p, 3)
    if p.dtype != np.bool_:
        raise InputError(f"planes: expected bool spike planes, got dtype {p.dtype}")
    t, h, w = p.shape
    if (h * w) % 8:
        raise InputError(f"planes: H x W must be a multiple of 8 to pack, got {h} x {w}")
    stored = p[:, ::-1, :].reshape(t, h * w)
    return PackedPlanes(np.packbits(stored, axis=1, bitorder="little"), height=h, width=w)


def integrate_and_fire(
    frames: np.ndarray,
    *,
    hold_planes: int,
    light: float,
    threshold: float,
    initial_charge: np.ndarray | None = None,
    dark_charge: np.ndarray | None = None,
    packed: bool = False,
    backend: str = "auto",
) -> tuple[np.ndarray | PackedPlanes, np.ndarray]:
    """Integrate radiance frames into binary spike planes (reset by subtraction).

    Parameters
    ----------
    frames : ndarray, shape (K, H, W), floating point
        Linear radiance, finite and >= 0 (1.0 = reference white). Converted to float32 value by
        value (no full-size copy).
    hold_planes : int
        Planes each frame is held for (``floor(T / S)`` in the paper's window mode; 1 in
        continuous mode, where every plane sees its own frame).
    light : float
        Light scale L > 0: each plane adds ``L * radiance`` to the charge.
    threshold : float
        Firing threshold phi > 0, in the charge's units.
    initial_charge : ndarray (H, W), optional
        Charge at the start (any finite values, negative allowed); zeros when ``None``. Not modified.
    dark_charge : ndarray (H, W), optional
        Extra charge per plane (finite, >= 0), e.g. from :func:`draw_dark_charge`.
    packed : bool
        Return the planes bit-packed (:class:`PackedPlanes`, the ``.dat`` layout; ``H * W`` must
        be a multiple of 8) instead of a bool array.
    backend : {"auto", "numba", "numpy"}
        ``"numba"``: the fused compiled kernel on ``numba.get_num_threads()`` threads;
        ``"numpy"``: the plain NumPy plane loop; ``"auto"``: numba where it can be imported.
        Same planes and charge, bit for bit. (A process forked after a GNU OpenMP parallel region
        ran takes the NumPy path: that runtime cannot start in such a child; see
        :mod:`neuspike.utils.parallel`.)

    Returns
    -------
    planes : ndarray of bool, shape (K * hold_planes, H, W), C-contiguous, or PackedPlanes
        ``True`` where the pixel fired; plane ``k * hold_planes + i`` belongs to frame ``k``.
    final_charge : ndarray of float32, shape (H, W)
        The charge after the last plane. Charge is conserved:
        ``initial + sum over planes of input = threshold * spikes + final`` (float32 rounding aside).

    Raises
    ------
    InputError
        For NaN, infinite or negative radiance (naming the first such frame), shapes that
        disagree, a non-positive ``light``, ``threshold`` or ``hold_planes``, an unknown backend,
        or ``packed`` with ``H * W`` not a multiple of 8.

    Notes
    -----
    At most one spike fires per plane, as on the real sensor: where ``light * radiance`` (plus the
    dark charge) exceeds the threshold the pixel fires on every plane and the surplus stays in
    the charge (it is neither clipped nor discarded). The float32 arithmetic order is given in
    the module docstring.
    """
    f = _frames_array(frames)
    k_frames, h, w = f.shape
    hold = check_positive_int("hold_planes", hold_planes)
    light32 = _as_float32("light", check_positive("light", light))
    thr32 = _as_float32("threshold", check_positive("threshold", threshold))
    engine = _runnable(resolve_backend(backend))
    if packed and (h * w) % 8:
        raise InputError(f"packed: H x W must be a multiple of 8 to pack planes, got {h} x {w}")
    if initial_charge is None:
        charge = np.zeros((h, w), np.float32)
    else:
        charge = _charge_map("initial_charge", initial_charge, (h, w), nonnegative=False)
    dark = None if dark_charge is None else _charge_map("dark_charge", dark_charge, (h, w), nonnegative=True)

    if engine == "numba":
        planes = _integrate_compiled(f, hold, light32, thr32, charge, dark, packed)
    else:
        planes = np.empty((k_frames * hold, h, w), dtype=np.bool_)
        _integrate(f, hold, light32, thr32, charge, dark, planes)
        if packed:
            planes = pack_planes(planes)
    if not np.isfinite(charge).all():
        raise InputError(
            "frames: the charge overflowed float32; a frame holds +inf radiance or light * radiance is too large"
        )
    return planes, charge


def _runnable(engine: str) -> str:
    """The backend that will actually run: ``"numpy"`` for ``"numba"`` where a parallel kernel cannot
    start (a child forked after a GNU OpenMP region ran in its parent: :mod:`neuspike.utils.parallel`)."""
    return "numpy" if engine == "numba" and not parallel_usable() else engine


#: Most pixels per band of the compiled kernel: a band's charge (4 bytes a pixel) stays in the L2
#: cache while the frames stream through it, contiguously, from memory.
_KERNEL_BAND_PIXELS = 1 << 16


def _band_rows(h: int, w: int, multiple: int, threads: int) -> int:
    """Rows per band (a multiple of ``multiple``): at least one band per thread, bands of equal size."""
    n_bands = max(threads, -(-(h * w) // _KERNEL_BAND_PIXELS))
    rows = -(-h // n_bands)
    return -(-rows // multiple) * multiple


def _first_bad_frame(frames: np.ndarray) -> None:
    """Raise for the first frame holding a value that is not >= 0 after conversion to float32."""
    for k in range(frames.shape[0]):
        frame = frames[k] if frames.dtype == np.float32 else frames[k].astype(np.float32)
        lowest = np.minimum.reduce(frame, axis=None)
        if not lowest >= 0:  # also true for NaN
            raise InputError(f"frames[{k}]: expected finite radiance >= 0, got a minimum of {float(lowest)!r}")


def _integrate_compiled(frames: np.ndarray, hold: int, light: np.float32, threshold: np.float32,
                        charge: np.ndarray, dark: np.ndarray | None, packed: bool) -> np.ndarray | PackedPlanes:
    """The fused kernel, in place on ``charge``; validates the radiance from its counts."""
    import numba

    from neuspike.sensors import spike_kernels

    k_frames, h, w = frames.shape
    threads = numba.get_num_threads()
    if packed:
        rows = _band_rows(h, w, 8, threads)
        out = np.empty((k_frames * hold, h * w // 8), np.uint8)
        kernel = spike_kernels.fire_packed
    else:
        rows = _band_rows(h, w, 1, threads)
        out = np.empty((k_frames * hold, h, w), np.bool_)
        kernel = spike_kernels.fire_planes
    negatives = np.zeros(-(-h // rows), np.int64)
    if frames.dtype == np.float32:
        with KERNEL_LOCK:
            kernel(np.ascontiguousarray(frames), hold, light, threshold, charge, dark, rows, out, negatives)
    else:
        # other float types go through a small float32 buffer, a few frames at a time: the kernel
        # is compiled for float32 frames only, and no full-size copy is made
        step = max(1, _CONVERT_CHUNK_PIXELS // (h * w))
        staging = np.empty((min(step, k_frames), h, w), np.float32)
        counts = np.zeros_like(negatives)
        for k0 in range(0, k_frames, step):
            k1 = min(k_frames, k0 + step)
            chunk = staging[:k1 - k0]
            np.copyto(chunk, frames[k0:k1], casting="same_kind")
            with KERNEL_LOCK:
                kernel(chunk, hold, light, threshold, charge, dark, rows, out[k0 * hold:k1 * hold], counts)
            negatives += counts
    # NaN and +inf cannot leave the charge, so a finite charge and no negative value mean valid input
    if negatives.any() or not np.isfinite(charge).all():
        _first_bad_frame(frames)
    return PackedPlanes(out, height=h, width=w) if packed else out


#: Pixels converted to float32 at a time for frames of another float type.
_CONVERT_CHUNK_PIXELS = 1 << 20


#: Bytes of per-pixel float32 state the plane loop aims to keep in cache at once (see _integrate).
_CACHE_BUDGET_BYTES = 1 << 20


def _integrate(frames: np.ndarray, hold: int, light: np.float32, threshold: np.float32,
               charge: np.ndarray, dark: np.ndarray | None, planes: np.ndarray,
               *, band_rows: int | None = None) -> None:
    """The plane loop, in place on ``charge`` and ``planes`` (see the module docstring).

    Pixels are independent, so the sensor is processed in bands of rows, each band through all
    planes before the next: the band's charge, drive, reset and dark maps then stay in cache while
    only the frames stream in from memory. ``band_rows`` (default: from ``_CACHE_BUDGET_BYTES``)
    changes the speed, never the result.
    """
    h, w = charge.shape
    if band_rows is None:
        maps = 4 + (dark is not None) + (hold > 1)  # frame, drive/reset, charge, output, [dark], [reset]
        band_rows = max(1, _CACHE_BUDGET_BYTES // (maps * 4 * w))
    for top in range(0, h, band_rows):
        rows = slice(top, min(h, top + band_rows))
        _integrate_band(frames[:, rows], hold, light, threshold, charge[rows],
                        None if dark is None else dark[rows], planes[:, rows])


def _integrate_band(frames: np.ndarray, hold: int, light: np.float32, threshold: np.float32,
                    charge: np.ndarray, dark: np.ndarray | None, planes: np.ndarray) -> None:
    """One band of rows through all planes.

    Every operation writes into preallocated float32 buffers: per plane one add, one compare
    (straight into the output plane), one bool-to-float copy and one subtract; a masked
    subtract (``where=``) costs about four times as much as the copy and the plain subtract.
    """
    h, w = charge.shape
    drive = np.empty((h, w), np.float32)
    # with one plane per frame the drive is spent once added, so its buffer doubles as the reset
    # buffer: one map less to keep in cache
    reset = drive if hold == 1 else np.empty((h, w), np.float32)
    staging = None if frames.dtype == np.float32 else np.empty((h, w), np.float32)
    # x * 1 == x exactly in IEEE arithmetic, so a unit light or threshold skips its multiply
    unit_light = bool(light == 1)
    unit_threshold = bool(threshold == 1)
    j = 0
    for k in range(frames.shape[0]):
        frame = frames[k]
        if staging is not None:
            np.copyto(staging, frame, casting="same_kind")
            frame = staging
        drive_k = frame if unit_light else np.multiply(frame, light, out=drive)
        # validate on the product while it is in cache (light > 0 keeps signs and NaN); a product
        # whose minimum is not > 0 may hide a negative value that underflowed: check the frame then
        if not np.minimum.reduce(drive_k, axis=None) > 0:
            lowest = np.minimum.reduce(frame, axis=None)
            if not lowest >= 0:  # also true for NaN
                raise InputError(f"frames[{k}]: expected finite radiance >= 0, got a minimum of {float(lowest)!r}")
        if dark is not None:
            drive_k = np.add(drive_k, dark, out=drive)
        for _ in range(hold):
            fired = planes[j]
            np.add(charge, drive_k, out=charge)
            np.greater_equal(charge, threshold, out=fired)
            np.copyto(reset, fired)
            if not unit_threshold:
                np.multiply(reset, threshold, out=reset)
            np.subtract(charge, reset, out=charge)
            j += 1


def draw_initial_charge(shape: tuple[int, int], *, threshold: float, rng: np.random.Generator) -> np.ndarray:
    """Random start of the integrator, ``I = N * threshold`` (Algorithm 1).

    Parameters
    ----------
    shape : (H, W)
    threshold : float
        The firing threshold phi > 0.
    rng : numpy.random.Generator
        Draws ``H * W`` standard normals (float64), in row-major order.

    Returns
    -------
    ndarray of float32, shape (H, W)
        Charge in the threshold's units, mean 0 and standard deviation ``threshold``.
    """
    h, w = _check_shape("shape", shape)
    phi = check_positive("threshold", threshold)
    n = _check_rng(rng).standard_normal((h, w))
    return (n * phi).astype(np.float32)


def draw_dark_charge(
    shape: tuple[int, int],
    *,
    threshold: float,
    isi_mean_planes: float,
    isi_std_planes: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Fixed-pattern dark charge per plane: ``threshold / isi`` with a per-pixel ISI.

    Each pixel's inter-spike interval in total darkness is drawn as
    ``isi ~ Normal(isi_mean_planes, isi_std_planes**2)``; draws below 1 plane are redrawn (only
    those pixels, until none is left), so that the pixel fires every ``isi`` planes in the dark.
    The paper's measured dark statistics are mean 180 and spread 50 planes.

    Parameters
    ----------
    shape : (H, W)
    threshold : float
        The firing threshold phi > 0.
    isi_mean_planes, isi_std_planes : float
        Mean and standard deviation of the dark ISI, in planes (std >= 0).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray of float32, shape (H, W)
        Dark charge per plane, in ``(0, threshold]``.

    Raises
    ------
    InputError
        If fewer than 1 in 1,000 draws would reach 1 plane (redrawing would not end).
    """
    h, w = _check_shape("shape", shape)
    phi = check_positive("threshold", threshold)
    mean = float(isi_mean_planes)
    if not math.isfinite(mean):
        raise InputError(f"isi_mean_planes: expected a finite number, got {isi_mean_planes!r}")
    std = check_nonnegative("isi_std_planes", isi_std_planes)
    if std == 0:
        acceptance = 1.0 if mean >= 1 else 0.0
    else:
        acceptance = 0.5 * math.erfc((1.0 - mean) / (std * math.sqrt(2.0)))
    if acceptance < _MIN_ACCEPTANCE:
        raise InputError(
            f"dark current: an ISI of Normal({mean}, {std}**2) planes is >= 1 plane with probability "
            f"{acceptance:.2g}; expected a mean ISI of at least about 1 plane"
        )
    gen = _check_rng(rng)
    isi = gen.normal(mean, std, (h, w))
    bad = np.flatnonzero(isi < 1.0)
    flat = isi.reshape(-1)
    while bad.size:
        flat[bad] = gen.normal(mean, std, bad.size)
        bad = bad[flat[bad] < 1.0]
    return (phi / isi).astype(np.float32)


class SpikeCamera:
    """A spike camera: parameters, the frozen dark pattern and the charge carried between captures.

    Parameters
    ----------
    width, height : int
        Sensor size in pixels (Vidar: 400 x 250).
    light : float
        Light scale L > 0 (the paper uses 1/2 ... 1/32).
    threshold : float
        Firing threshold phi > 0.
    plane_rate_hz : float
        Planes per second (20,000 for Vidar); recorded in the streams.
    effects : tuple of Effect
        Declared spike-camera stages (``initial_charge``, ``dark_current``); any other effect
        raises. A stage that is not declared does not run and draws nothing.
    rng : numpy.random.Generator or None
        Source of the effect stages' random draws, made at construction in the order of
        :data:`SPIKE_STAGES`. May be ``None`` only when no effect is declared.
    backend : {"auto", "numba", "numpy"}
        Implementation of the plane loop (see :func:`integrate_and_fire`); never changes the planes.

    Notes
    -----
    :meth:`capture` continues from the charge left by the previous capture, so capturing a
    sequence in chunks gives the same planes as one capture of the whole sequence.
    """

    def __init__(
        self,
        width: int,
        height: int,
        *,
        light: float,
        threshold: float = 1.0,
        plane_rate_hz: float = VIDAR_PLANE_RATE_HZ,
        effects: Iterable[Effect] = (),
        rng: np.random.Generator | None,
        backend: str = "auto",
    ) -> None:
        self._width, self._height = check_size("SpikeCamera", width, height)
        self._backend = resolve_backend(backend)
        self._light = check_positive("light", light)
        self._threshold = check_positive("threshold", threshold)
        _as_float32("light", self._light)
        _as_float32("threshold", self._threshold)
        self._plane_rate_hz = check_positive("plane_rate_hz", plane_rate_hz)
        declared = declared_stages(effects, stages=SPIKE_STAGES, camera="spike-camera")
        if declared or rng is not None:
            rng = _check_rng(rng)
        shape = (self._height, self._width)
        self._effects = tuple(declared[name] for name in SPIKE_STAGES if name in declared)
        self._setup_seconds: dict[str, float] = {}
        self._charge = np.zeros(shape, np.float32)
        self._dark_charge: np.ndarray | None = None
        for e in self._effects:
            t0 = time.perf_counter()
            if e.name == "initial_charge":
                self._charge = draw_initial_charge(shape, threshold=self._threshold, rng=rng)
            else:  # dark_current
                self._dark_charge = draw_dark_charge(
                    shape, threshold=self._threshold, isi_mean_planes=e.param("isi_mean_planes"),
                    isi_std_planes=e.param("isi_std_planes"), rng=rng,
                )
            self._setup_seconds[e.name] = time.perf_counter() - t0
        self._captures = 0

    # ---- read-only views -------------------------------------------------------------------
    @property
    def width(self) -> int:
        return self._width

    @property
    def height(self) -> int:
        return self._height

    @property
    def light(self) -> float:
        return self._light

    @property
    def threshold(self) -> float:
        return self._threshold

    @property
    def plane_rate_hz(self) -> float:
        return self._plane_rate_hz

    @property
    def gain(self) -> float:
        """Expected spikes per plane per unit radiance, ``light / threshold``."""
        return self._light / self._threshold

    @property
    def dark_rate(self) -> float:
        """Spikes per plane a pixel fires in total darkness, averaged over the pixels (0 without dark
        current): the dark level a capped calibration of this camera measures."""
        if self._dark_charge is None:
            return 0.0
        return float(np.mean(self._dark_charge, dtype=np.float64)) / self._threshold

    @property
    def backend(self) -> str:
        """The implementation in use, ``"numba"`` or ``"numpy"``."""
        return self._backend

    @property
    def effects(self) -> tuple[Effect, ...]:
        """The declared stages, in the order they run."""
        return self._effects

    @property
    def charge(self) -> np.ndarray:
        """A read-only copy of the current charge, float32 (H, W)."""
        c = self._charge.copy()
        c.flags.writeable = False
        return c

    @property
    def dark_charge(self) -> np.ndarray | None:
        """A read-only copy of the dark charge per plane, float32 (H, W); ``None`` without ``dark_current``."""
        if self._dark_charge is None:
            return None
        d = self._dark_charge.copy()
        d.flags.writeable = False
        return d

    # ---- capture ---------------------------------------------------------------------------
    def capture(self, frames: np.ndarray, *, hold_planes: int, start_s: float = 0.0) -> SpikeStream:
        """Expose the sensor to ``frames`` and return the spike planes.

        Parameters
        ----------
        frames : ndarray, shape (K, H, W), floating point
            Radiance (finite, >= 0; 1.0 = reference white) at the camera's size.
        hold_planes : int
            Planes each frame is held for (1 in continuous mode).
        start_s : float
            Sensor time of the first plane, in seconds, recorded in the stream.

        Returns
        -------
        SpikeStream
            ``K * hold_planes`` planes with ``gain = light / threshold``, the threshold, the dark
            rate (:attr:`dark_rate`), the plane rate and ``meta = {"stages": [...], "spike_count": int}``. Each stage entry is
            ``{"name", "params", "seconds"}``; effect stages draw once, at construction, and their
            time is reported by the first capture (0.0 afterwards); ``integrate_and_fire`` is
            always listed, its time covering the plane loop (with the dark charge added in it).

        Raises
        ------
        InputError
            For frames of the wrong size or invalid radiance; the camera's charge is then unchanged.
        """
        planes, stages = self._expose(frames, hold_planes, start_s, packed=False)
        return SpikeStream(
            planes,
            plane_rate_hz=self._plane_rate_hz,
            start_s=float(start_s),
            gain=self.gain,
            threshold=self._threshold,
            dark_rate=self.dark_rate,
            meta={"stages": stages, "spike_count": int(np.count_nonzero(planes))},
        )

    def capture_packed(self, frames: np.ndarray, *, hold_planes: int,
                       start_s: float = 0.0) -> tuple[PackedPlanes, dict[str, Any]]:
        """:meth:`capture` with the planes bit-packed in the ``.dat`` layout.

        The same planes (and the same charge carried on) as :meth:`capture`, eight times smaller;
        ``packed.data`` is exactly the bytes of a ``.dat`` file. ``W * H`` must be a multiple of 8.

        Returns
        -------
        packed : PackedPlanes
            ``K * hold_planes`` planes.
        meta : dict
            What :meth:`capture` records in ``SpikeStream.meta`` plus ``start_s``, ``gain``,
            ``threshold`` and ``plane_rate_hz``.
        """
        packed, stages = self._expose(frames, hold_planes, start_s, packed=True)
        meta = {"stages": stages, "spike_count": packed.count(), "start_s": float(start_s), "gain": self.gain,
                "threshold": self._threshold, "plane_rate_hz": self._plane_rate_hz}
        return packed, meta

    def _expose(self, frames: np.ndarray, hold_planes: int, start_s: float, *, packed: bool):
        f = _frames_array(frames)
        if f.shape[1:] != (self._height, self._width):
            raise InputError(
                f"frames: expected shape (K, {self._height}, {self._width}) for a {self._width}x{self._height} "
                f"camera, got {f.shape}"
            )
        start = float(start_s)
        if not math.isfinite(start):
            raise InputError(f"start_s: expected a finite time, got {start_s!r}")
        hold = check_positive_int("hold_planes", hold_planes)
        t0 = time.perf_counter()
        planes, charge = integrate_and_fire(
            f, hold_planes=hold, light=self._light, threshold=self._threshold,
            initial_charge=self._charge, dark_charge=self._dark_charge, packed=packed, backend=self._backend,
        )
        seconds = time.perf_counter() - t0
        first = self._captures == 0
        stages: list[dict[str, Any]] = [
            {"name": e.name, "params": dict(e.params),
             "seconds": self._setup_seconds.get(e.name, 0.0) if first else 0.0}
            for e in self._effects
        ]
        stages.append({
            "name": "integrate_and_fire",
            "params": {"light": self._light, "threshold": self._threshold, "hold_planes": hold,
                       "backend": _runnable(self._backend)},
            "seconds": seconds,
        })
        self._charge = charge
        self._captures += 1
        return planes, stages

    def __repr__(self) -> str:
        names = ", ".join(e.name for e in self._effects) or "none"
        return (f"SpikeCamera({self._width}x{self._height}, light={self._light:g}, threshold={self._threshold:g}, "
                f"plane_rate_hz={self._plane_rate_hz:g}, backend={self._backend}, effects: {names})")
