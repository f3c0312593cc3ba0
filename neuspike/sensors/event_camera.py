"""Event camera (DVS) simulator: a v2e-class pixel with exact crossing timestamps.

The camera sees ``intensity = light * radiance`` (radiance 1.0 is the reference white). Each pixel
works on the log of its intensity (:func:`log_intensity`) and keeps a *memorised level*; it emits an
ON event each time the log rises a full threshold ``theta_on`` above that level and an OFF event
each time it falls ``theta_off`` below it, and the memorised level moves by exactly the emitted
crossings (the remainder is kept).

Time model
    The very first frame a camera ever receives only initialises it (memorised level = that frame's
    log intensity; no events, as in v2e). Between two consecutive samples the log intensity is
    interpolated *linearly in time*, and every crossing gets its own timestamp where the line meets
    the crossing level (ESIM's model; no v2e "pyramids" of evenly spread events). Crossing times
    are computed in float64 from the float32 pixel state and resolved to ``2**-44`` of the sample
    interval (``2**-(62 - b)`` for sensors whose key needs ``b > 18`` bits) or two float64 ulps of
    the timestamp, whichever is coarser: far below a picosecond at 22,500 frames/s. Timestamps
    are float64 seconds. A later call continues from the previous call's last frame, so a
    sequence captured in chunks gives exactly the same events as one call (including the random
    draws of shot noise, which are made per sample interval).

Output order
    Events are sorted by time; events with equal timestamps are ordered by pixel index
    ``y * W + x`` (then OFF before ON).

Effect stages (:mod:`neuspike.conditions`, modality ``"events"``). Only declared stages run; an
undeclared stage executes no code and draws no random numbers.

``threshold_mismatch(sigma)``
    per-pixel thresholds ``N(theta, sigma**2)`` (ON and OFF drawn independently, ON first), frozen
    at construction, floored at 0.01.
``bandwidth(cutoff_hz)``
    first-order low-pass of the log intensity, updated at every sample with
    ``eps = min(1, ((I8 + 20) / 275) * dt * 2 pi cutoff_hz)`` where ``I8 = 255 * intensity`` of the
    new sample (darker pixels are slower); crossings are computed on the filtered log, still
    interpolated linearly between samples. The filter starts at the first frame's log intensity.
``leak(rate_hz)``
    the memorised level drifts down at ``rate_pixel * theta_on_pixel`` per second, giving spurious
    ON events at about ``rate_hz`` on a static scene; ``rate_pixel = rate_hz * 10**(0.1 N(0, 1))``
    (log-normal spread of 0.1 decade), frozen at construction.
``shot_noise(rate_hz)``
    ON and OFF noise events, each a Poisson process in continuous time with rate
    ``(R / 2) * (1 - 0.75 * I01) * theta_nominal / theta_pixel``, ``I01 = clip((I8 + 20) / 275, 0, 1)``
    taken from the interval's end sample (as v2e does). They are drawn by Poisson thinning over each
    sample interval (never a per-pixel-per-frame coin flip, which is slower and biased at high
    rates). A noise event resets the pixel's memorised level to its current (filtered) log
    intensity; crossings after it in the same interval are measured from the new level.
``refractory(period_s)``
    a pixel emits no event within ``period_s`` of its previous *emitted* event. As in v2e the
    suppressed events are dropped, and the pixel's state is not held: its memorised level still
    moves by the suppressed crossings (and a suppressed noise event still resets it). The period
    therefore only thins the output; it never delays or merges events.

Presets with v2e's numbers are in :data:`neuspike.conditions.EVENT_PRESETS`.

Implementation
    Two backends give the same events, byte for byte (``backend=``). On the compiled one
    (:mod:`neuspike.sensors.event_kernels`, numba) a single pass per interval finishes the
    lin-log (the ``log`` itself stays NumPy's), runs ``bandwidth`` and ``leak``, and lists the
    crossing pixels with their event counts; a second compiled pass builds the interval's keys
    (below) with the ``refractory`` filter, a third the keys of the pixels with ``shot_noise``
    (whose draws stay NumPy's, from the camera's generator), NumPy's sort orders the keys and a
    last pass decodes them into the output, optionally in a worker thread (``threads=2``).
    ``backend="numpy"`` (the reference, and the fallback where numba cannot be imported) runs
    everything in NumPy.

    On the NumPy path, per sample interval every pixel is updated with whole-array float32 operations into
    preallocated buffers; only the pixels that cross a threshold go further. Each of their
    crossings becomes an int64 key ``(time fraction << b) | (pixel << 1) | ON`` whose numeric order
    is the output order, so one in-place sort per interval orders the events and the sorted keys
    decode straight into ``t``, ``x``, ``y``, ``p`` (x, y, p from lookup tables). The pixel's own
    log is kept minus the constant ``ln(255 * light)``, which cancels in every difference.
"""

from __future__ import annotations

import time
from typing import Any, Iterable

import numpy as np

from neuspike.utils.checks import check_positive, check_positive_int
from neuspike.conditions import Effect, declared_stages
from neuspike.errors import InputError
from neuspike.utils.parallel import resolve_backend
from neuspike.sensors.dvs_pixel import DARK_FLOOR_8BIT, REFERENCE_WHITE_8BIT, log_intensity
from neuspike.sensors.event_capture import (STAGE_ORDER, THRESHOLD_FLOOR, Capture, PixelArray, PixelState,
                                            leak_rates, shot_noise_rates, threshold_mismatch)
from neuspike.streams import EventStream

__all__ = [
    "DARK_FLOOR_8BIT",
    "REFERENCE_WHITE_8BIT",
    "THRESHOLD_FLOOR",
    "EventCamera",
    "log_intensity",
]

_RANDOM_STAGES = ("threshold_mismatch", "leak", "shot_noise")


class EventCamera:
    """A DVS event camera with explicit pixel state (see the module docstring for the model).

    Parameters
    ----------
    width, height : int
        Sensor size W, H in pixels.
    light : float
        Light scale L > 0: the camera sees ``intensity = light * radiance``.
    threshold_on, threshold_off : float
        Nominal ON and OFF contrast thresholds in natural-log units (v2e: 0.2).
    effects : sequence of Effect
        Declared event-camera stages (``threshold_mismatch``, ``bandwidth``, ``leak``,
        ``shot_noise``, ``refractory``), each at most once. Any other effect raises.
    rng : numpy.random.Generator or None
        Source of every random draw: frozen per-pixel parameters are drawn here at construction
        (mismatch, then leak rates) and shot noise is drawn from it during :meth:`capture`, one
        batch per sample interval. Required when a random stage (``threshold_mismatch``, ``leak``,
        ``shot_noise``) is declared; never touched otherwise.
    threads : int, optional
        ``2`` sorts and writes each interval's events in a worker thread while the pixels of the
        next interval are updated (same output, byte for byte). It pays only when a second core
        is idle; the default is ``1``.
    backend : {"auto", "numba", "numpy"}
        ``"numba"`` runs the compiled kernels where the declared stages allow it (all but
        ``shot_noise`` and ``refractory``), the NumPy path otherwise; ``"numpy"`` always runs the
        NumPy path; ``"auto"`` is ``"numba"`` where numba can be imported. Same events either way.

    Notes
    -----
    The camera holds two values and the order of the stages; the work is done by
    :mod:`neuspike.sensors.event_capture` over those values. ``pixels``
    (:class:`~neuspike.sensors.event_capture.PixelArray`): the frozen per-pixel parameters, drawn at
    construction. ``state`` (:class:`~neuspike.sensors.event_capture.PixelState`): what persists between
    :meth:`capture` calls (the time of the last sample, the (filtered) log intensity and memorised level
    of every pixel, and, with ``refractory``, the time of each pixel's last emitted event); a capture
    starts from it and replaces it only when it completes. :meth:`reset` forgets it; the frozen
    per-pixel parameters stay.
    """

    def __init__(
        self,
        width: int,
        height: int,
        *,
        light: float,
        threshold_on: float = 0.2,
        threshold_off: float = 0.2,
        effects: Iterable[Effect] = (),
        rng: np.random.Generator | None = None,
        threads: int | None = None,
        backend: str = "auto",
    ) -> None:
        self.threads = check_positive_int("EventCamera threads", 1 if threads is None else threads)
        self._backend = resolve_backend(backend)
        self.width = check_positive_int("EventCamera width", width)
        self.height = check_positive_int("EventCamera height", height)
        self.light = check_positive("EventCamera light", light)
        self.threshold_on = check_positive("threshold_on", threshold_on)
        self.threshold_off = check_positive("threshold_off", threshold_off)
        self._effects = declared_stages(effects, stages=STAGE_ORDER, camera="event-camera")
        random_stages = [n for n in _RANDOM_STAGES if n in self._effects]
        if random_stages and not isinstance(rng, np.random.Generator):
            raise InputError(
                f"EventCamera: stages {random_stages} draw random numbers and need "
                f"rng=numpy.random.Generator, got {rng!r}"
            )
        self._rng = rng
        n = self.width * self.height
        # frozen per-pixel parameters, drawn in a fixed order by the stage functions: mismatch (ON, OFF), then leak
        self._setup_seconds: dict[str, float] = {}
        c0 = time.perf_counter()
        if "threshold_mismatch" in self._effects:
            th_on, th_off = threshold_mismatch(rng, n, self.threshold_on, self.threshold_off,
                                               self._effects["threshold_mismatch"].param("sigma"))
            self._setup_seconds["threshold_mismatch"] = time.perf_counter() - c0
        else:
            th_on = np.full(n, self.threshold_on, dtype=np.float32)
            th_off = np.full(n, self.threshold_off, dtype=np.float32)
        leak = None
        if "leak" in self._effects:
            c0 = time.perf_counter()
            leak = leak_rates(rng, th_on, self._effects["leak"].param("rate_hz"))
            self._setup_seconds["leak"] = time.perf_counter() - c0
        noise = None
        if "shot_noise" in self._effects:
            noise = shot_noise_rates(th_on, th_off, self.threshold_on, self.threshold_off,
                                     self._effects["shot_noise"].param("rate_hz"))
        #: The frozen per-pixel parameters (:class:`~neuspike.sensors.event_capture.PixelArray`).
        self.pixels = PixelArray(
            width=self.width, height=self.height, light=self.light, threshold_on=self.threshold_on,
            threshold_off=self.threshold_off, th_on=th_on, th_off=th_off, leak_per_s=leak, noise=noise,
            symmetric="threshold_mismatch" not in self._effects and self.threshold_on == self.threshold_off)
        if self.pixels.fraction_bits < 16:
            raise InputError(f"EventCamera: sensor {self.width}x{self.height} is too large")
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget the pixel state (the next frame initialises again); frozen parameters stay."""
        #: What the next capture continues from (:class:`~neuspike.sensors.event_capture.PixelState`).
        self.state = PixelState()

    @property
    def initialised(self) -> bool:
        """Whether the camera has received its first frame."""
        return self.state.t_last is not None

    @property
    def last_time_s(self) -> float | None:
        """Time of the last sample received, or ``None`` before the first."""
        return self.state.t_last

    @property
    def backend(self) -> str:
        """The implementation that :meth:`capture` runs: ``"numba"`` or ``"numpy"``."""
        return self._backend

    @property
    def effects(self) -> tuple[Effect, ...]:
        """The declared stages."""
        return tuple(self._effects.values())

    @property
    def theta_on(self) -> np.ndarray:
        """Per-pixel ON thresholds in use, float32 (H, W) (a copy)."""
        return self.pixels.th_on.reshape(self.height, self.width).copy()

    @property
    def theta_off(self) -> np.ndarray:
        """Per-pixel OFF thresholds in use, float32 (H, W) (a copy)."""
        return self.pixels.th_off.reshape(self.height, self.width).copy()

    # ---------------------------------------------------------------- capture
    def _check_inputs(self, radiance_frames: Any, times_s: Any) -> tuple[np.ndarray, np.ndarray, float]:
        frames = np.asarray(radiance_frames)
        if frames.ndim != 3:
            raise InputError(f"radiance_frames: expected shape (K, H, W), got {frames.shape}")
        if frames.shape[1:] != (self.height, self.width):
            raise InputError(
                f"radiance_frames: expected frames of H x W = {self.height} x {self.width}, "
                f"got {frames.shape[1]} x {frames.shape[2]}"
            )
        if not (np.issubdtype(frames.dtype, np.floating) or np.issubdtype(frames.dtype, np.integer)):
            raise InputError(f"radiance_frames: expected a float array, got dtype {frames.dtype}")
        if frames.shape[0] == 0:
            raise InputError("radiance_frames: expected at least one frame, got 0")
        frames = np.ascontiguousarray(frames, dtype=np.float32)
        times = np.asarray(times_s, dtype=np.float64)
        if times.shape != (frames.shape[0],):
            raise InputError(
                f"times_s: expected shape ({frames.shape[0]},) matching the frames, got {times.shape}"
            )
        if not np.isfinite(times).all():
            raise InputError("times_s: expected finite times, found NaN or infinity")
        if times.shape[0] > 1:
            steps = np.diff(times)
            if not (steps > 0).all():
                k = int(np.argmax(steps <= 0)) + 1
                raise InputError(
                    f"times_s: expected strictly increasing times; sample {k} at {times[k]!r} s does "
                    f"not follow sample {k - 1} at {times[k - 1]!r} s"
                )
        t_last = self.state.t_last
        if t_last is not None and not times[0] > t_last:
            raise InputError(
                f"times_s: the first sample at {times[0]!r} s must follow the previous capture's "
                f"last sample at {t_last!r} s"
            )
        lo, hi = float(frames.min()), float(frames.max())
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise InputError("radiance_frames: expected finite radiance, found NaN or infinity")
        if lo < 0:
            raise InputError(f"radiance_frames: expected radiance >= 0, got a minimum of {lo!r}")
        return frames, times, hi

    def capture(self, radiance_frames: Any, times_s: Any) -> EventStream:
        """Events produced while the camera watches ``radiance_frames``.

        Parameters
        ----------
        radiance_frames : ndarray, shape (K, H, W), float32
            Linear radiance samples, >= 0 (1.0 = reference white).
        times_s : ndarray, shape (K,), float64
            Sample times in seconds, strictly increasing and after the previous call's last sample.

        Returns
        -------
        EventStream
            The events in ``(previous sample, times_s[-1]]`` sorted by time (ties by pixel index),
            with ``meta = {"stages": [{"name", "params", "seconds"}, ...], "event_count": N}``
            listing the stages that ran (always ``dvs_pixel``, the ideal pixel, first) and the
            wall time charged to each; the frozen draws of ``threshold_mismatch`` and ``leak``
            (made at construction) are charged to the capture that initialises the camera. On
            the numba backend ``bandwidth``, ``leak`` and ``refractory`` run inside the compiled
            passes: their entries say ``"fused_into": "dvs_pixel"`` and their time is part of
            ``dvs_pixel``'s (``shot_noise`` keeps its own: its draws and its pixels' events).
            ``dvs_pixel``'s params name the backend.

        Raises
        ------
        InputError
            For a wrong shape, NaN, infinite or negative radiance, or times that do not increase.
            A rejected call leaves the camera's state unchanged.
        """
        frames, times, max_radiance = self._check_inputs(radiance_frames, times_s)
        run = Capture(self.pixels, self._effects, self._rng, self.state, max_radiance=max_radiance,
                      threads=self.threads, backend=self._backend, setup_seconds=self._setup_seconds)
        with np.errstate(divide="ignore", invalid="ignore"):
            state = run.run(frames.reshape(frames.shape[0], self.pixels.n), times)
        self.state = state  # only a completed capture moves the camera on
        return run.result()

