"""Timing methods: the shared code of ``python -m bench.timing`` (the paper's Table 2) and
:mod:`bench.method_speed`.

:func:`time_callable` times any call (warm-up, then timed calls, each after an optional setup
outside the timed region), :func:`time_method` one method's ``reconstruct`` (per network step for
recurrent methods), :func:`representative_sample` simulates the recording every method is timed on,
and :func:`measure` times every method at every resolution into tidy rows (:data:`TIMING_COLUMNS`).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace
import sys
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from bench.harness import grid as grids
from bench.harness.results import family_of
from neuspike.utils.checks import check_int
from neuspike.conditions import Condition
from neuspike.errors import InputError, one_line
from neuspike.utils.parallel import set_threads
from neuspike.sample import Sample
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import DEFAULT_HISTORY_WINDOWS, SensorConfig

#: The representative condition.
LIGHT, MOTION, PLANES = 0.25, 128, 256

TIMING_COLUMNS = ("method", "family", "inputs", "resolution", "width", "height", "status", "error", "threads",
                  "device", "precision", "parameters", "warmup", "repeats", "median_ms", "min_ms", "max_ms", "q1_ms",
                  "q3_ms", "steps", "ms_per_frame", "min_frame_ms", "max_frame_ms", "gflop_per_step", "gflop_s", "flop_bound_ms",
                  "matmul_gflop_s", "cold_ms", "stream_ms", "stream_min_ms", "stream_max_ms", "stream_steps",
                  "encode_ms")
#: Output rate of the running video a streaming method is timed on (frames per second of sensor time).
STREAM_FPS = 1000.0
#: Side of the square float32 matrix product whose rate is the machine's reference (GFLOP/s).
MATMUL_SIDE = 2048


def count_module_gflop(module: Any, inputs: Sequence[Any], *, recurrent: bool = False) -> float:
    """Floating-point operations (GFLOP) of one call of ``module`` on ``inputs``, counted by torch's
    FLOP counter (:class:`torch.utils.flop_counter.FlopCounterMode`: 2 per multiply-add of every
    convolution and matrix product; element-wise work is not counted), in float32. A recurrent
    module is called from an empty state."""
    import torch
    from torch.utils.flop_counter import FlopCounterMode

    counter = FlopCounterMode(display=False)
    with torch.inference_mode(), counter:
        module(*inputs, None) if recurrent else module(*inputs)
    return counter.get_total_flops() / 1e9


def step_gflop(method: Any, sample: Any) -> float | None:
    """GFLOP of one network step of a learned method on ``sample`` (its first encoded step); ``None``
    for a method without a torch module."""
    module = getattr(method, "module", None)
    if module is None or not hasattr(method, "encode"):
        return None
    steps = method.encode(sample)
    if not steps:
        return None
    inputs = tuple(t.to(method.device) for t in steps[0])
    return count_module_gflop(module, inputs, recurrent=bool(getattr(method, "recurrent", False)))


def encode_ms(method: Any, sample: Any, *, repeats: int, warmup: int) -> float:
    """Median ms of building a learned method's network inputs from ``sample`` (``method.encode``: a
    feed-forward method's representations, part of its time per frame; a recurrent method's voxel
    grids of the whole event history, divided by their count: per network step, as its time is)."""
    count = [1]

    def build() -> None:
        count[0] = max(1, len(method.encode(sample)))

    stats = time_callable(build, repeats=repeats, warmup=warmup)
    return stats.median_ms / (count[0] if getattr(method, "recurrent", False) else 1)


def matmul_gflop_s(side: int = MATMUL_SIDE, repeats: int = 3, device: str = "cpu") -> float:
    """The rate (GFLOP/s) of a ``side`` x ``side`` float32 matrix product on ``device`` (on the CPU with
    torch's current threads): the reference a network's achieved rate on that device is read against.
    A CUDA device is synchronised inside each timed call."""
    import torch

    from neuspike.methods.learned import synchronize

    dev = torch.device(device)
    gen = torch.Generator().manual_seed(0)
    a = torch.rand(side, side, generator=gen).to(dev)
    b = torch.rand(side, side, generator=gen).to(dev)
    out = torch.empty(side, side, device=dev)

    def product() -> None:
        torch.mm(a, b, out=out)
        synchronize(dev)

    stats = time_callable(product, repeats=repeats, warmup=1)
    median_s = float(np.median(stats.samples_ms)) / 1000.0
    return 2.0 * side**3 / median_s / 1e9


# ----------------------------------------------------------------------------------------------
# Timing one callable (shared with bench.method_speed)
# ----------------------------------------------------------------------------------------------

def summarize_ms(samples_ms: Sequence[float]) -> dict[str, float]:
    """Median, min, max and quartiles (linear interpolation) of timings in ms.

    Raises
    ------
    InputError
        When there is no sample or a sample is not a finite number >= 0.
    """
    a = np.asarray(list(samples_ms), dtype=np.float64)
    if a.ndim != 1 or a.size == 0:
        raise InputError(f"summarize_ms: expected at least one timing, got {a.size}")
    if not np.isfinite(a).all() or (a < 0).any():
        raise InputError(f"summarize_ms: expected finite timings >= 0, got {a.tolist()}")
    q1, med, q3 = np.percentile(a, [25, 50, 75])
    return {"median_ms": float(med), "min_ms": float(a.min()), "max_ms": float(a.max()),
            "q1_ms": float(q1), "q3_ms": float(q3), "n": int(a.size)}


@dataclass(frozen=True)
class TimingStats:
    """The timed calls of one measurement (ms) and how many untimed warm-up calls preceded them."""

    samples_ms: tuple[float, ...]
    warmup: int

    def summary(self) -> dict[str, float]:
        return summarize_ms(self.samples_ms)

    @property
    def median_ms(self) -> float:
        return self.summary()["median_ms"]


def check_count(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int when it is a whole number >= ``minimum``; else :class:`InputError`."""
    return check_int(name, value, minimum=minimum)


def time_callable(fn: Callable[[], Any], *, repeats: int, warmup: int, setup: Callable[[], Any] | None = None,
                  timer: Callable[[], int] = time.perf_counter_ns) -> TimingStats:
    """Time ``fn()``: ``warmup`` untimed calls, then ``repeats`` timed calls.

    Parameters
    ----------
    fn : callable with no arguments
    repeats : int >= 1
    warmup : int >= 0
    setup : callable, optional
        Called before every call (warm-up and timed), outside the timed region (e.g. ``method.reset``).
    timer : callable returning integer nanoseconds
        ``time.perf_counter_ns`` by default; read once before and once after each timed call.

    Returns
    -------
    TimingStats
    """
    repeats = check_count("repeats", repeats, 1)
    warmup = check_count("warmup", warmup, 0)
    for _ in range(warmup):
        if setup is not None:
            setup()
        fn()
    samples = []
    for _ in range(repeats):
        if setup is not None:
            setup()
        t0 = timer()
        fn()
        t1 = timer()
        samples.append((t1 - t0) / 1e6)
    return TimingStats(tuple(samples), warmup)


@dataclass(frozen=True)
class MethodTiming:
    """A method's timing on a sample: the call statistics and the event windows (network steps) one
    call processed (``None`` for methods that do not report ``last_steps``)."""

    stats: TimingStats
    steps: int | None

    def row(self) -> dict[str, Any]:
        """``median_ms ... q3_ms``, ``steps`` and the per-frame figures (per step when ``steps``)."""
        s = self.stats.summary()
        per = self.steps if self.steps else 1
        return {"warmup": self.stats.warmup, "repeats": s["n"], "median_ms": s["median_ms"], "min_ms": s["min_ms"],
                "max_ms": s["max_ms"], "q1_ms": s["q1_ms"], "q3_ms": s["q3_ms"],
                "steps": self.steps if self.steps else math.nan, "ms_per_frame": s["median_ms"] / per,
                "min_frame_ms": s["min_ms"] / per, "max_frame_ms": s["max_ms"] / per}


def time_method(method: Any, sample: Any, *, repeats: int, warmup: int,
                timer: Callable[[], int] = time.perf_counter_ns) -> MethodTiming:
    """Time ``method.reconstruct(sample)`` with ``reset()`` before every call (outside the timing).

    For recurrent methods that report ``last_steps`` (the event windows one call stepped through),
    :attr:`MethodTiming.steps` holds it, so that the cost of one step can be derived.

    On a GPU the clock is read after the device's work, with no synchronisation here: a call returns
    a host array, which a learned method copies from its device with a blocking copy
    (:meth:`neuspike.methods.learned.LearnedMethod.to_image`). The same holds for
    :func:`time_streaming`.
    """
    stats = time_callable(lambda: method.reconstruct(sample), repeats=repeats, warmup=warmup,
                          setup=method.reset, timer=timer)
    steps = method.last_steps if method.recurrent else None
    steps = int(steps) if isinstance(steps, (int, np.integer)) and steps > 0 else None
    return MethodTiming(stats, steps)


def streams(method: Any) -> bool:
    """Whether ``method`` continues a video from its previous frame (it overrides ``reconstruct_next``:
    recurrent methods carry their state, NeuSpike-Net slides its representations)."""
    from neuspike.methods import Method

    hook = getattr(type(method), "reconstruct_next", None)
    return hook is not None and hook is not Method.reconstruct_next


def time_streaming(method: Any, frames: Sequence[Any], *, warmup: int,
                   timer: Callable[[], int] = time.perf_counter_ns) -> dict[str, Any]:
    """One new frame of a running video: ``reconstruct`` on ``frames[0]`` after ``reset()`` (the
    cold start, untimed), then ``reconstruct_next`` on each later frame, the first ``warmup`` of them
    untimed. Returns ``stream_ms`` (median), ``stream_min_ms``, ``stream_max_ms`` and
    ``stream_steps`` (mean ``last_steps`` of the timed frames; NaN for methods without steps)."""
    if len(frames) < warmup + 2:
        raise InputError(f"time_streaming: {len(frames)} frames leave none to time after {warmup} warm-up frame(s)")
    method.reset()
    method.reconstruct(frames[0])
    times_ms, steps = [], []
    for k in range(1, len(frames)):
        t0 = timer()
        method.reconstruct_next(frames[k], previous_s=frames[k - 1].key_time_s)
        t1 = timer()
        if k > warmup:
            times_ms.append((t1 - t0) / 1e6)
            n = getattr(method, "last_steps", None) if method.recurrent else None
            if isinstance(n, (int, np.integer)):
                steps.append(int(n))
    return {"stream_ms": float(np.median(times_ms)), "stream_min_ms": float(np.min(times_ms)),
            "stream_max_ms": float(np.max(times_ms)), "stream_steps": float(np.mean(steps)) if steps else math.nan}


def running_video(width: int, height: int, frames: int, *, seed: int = 0,
                  fps: float = STREAM_FPS) -> list[Sample]:
    """``frames`` consecutive samples of a running video of the representative scene at ``fps``.

    The panning ``camera`` at the representative condition, simulated as one continuous recording
    (:func:`neuspike.simulation.writing.write_sequence`) long enough for every frame's 256-plane
    window to be centred on it, cut by the video stream (:func:`neuspike.video.stream_samples`).
    The samples stay valid after the recording is closed (their arrays are kept).
    """
    import tempfile
    from pathlib import Path

    from neuspike.simulation.writing import write_sequence
    from neuspike.utils.rng import derive_rng
    from neuspike.video import frame_times, open_recording, stream_samples
    from neuspike.scenes import make_scene

    entry = grids.scene_entry("pan:camera", (int(width), int(height)))
    condition = Condition(light=LIGHT, motion=MOTION, effects=grids.DEFAULT_EFFECTS)
    rate = SensorConfig().plane_rate_hz
    half = PLANES / 2 / rate
    duration = 2 * half + frames / fps
    with tempfile.TemporaryDirectory(prefix="timing-video-") as tmp:
        write_sequence(make_scene(entry.spec), condition, Path(tmp), rng=derive_rng(seed, "bench.timing.video"),
                       start_s=0.0, duration_s=duration, seed=seed, progress=False)
        with open_recording(Path(tmp)) as rec:
            times = frame_times(half, half + frames / fps, fps)
            return list(stream_samples(rec, times, window_planes=PLANES))


# ----------------------------------------------------------------------------------------------
# The representative recording
# ----------------------------------------------------------------------------------------------

def representative_sample(width: int, height: int, *, history_windows: float = DEFAULT_HISTORY_WINDOWS,
                          modalities: Iterable[str] = ("spikes", "events"), seed: int = 0) -> Sample:
    """The sample every method is timed on at one resolution (module docstring), without ground truth.

    Built by :func:`neuspike.simulation.cell.simulate_sample`, the sweeps' own cell-to-sample path, so a
    timed sample is the one a sweep cell of the same scene, condition and seed would see.

    Parameters
    ----------
    width, height : int
        Sensor size in pixels.
    history_windows : float >= 0
        Event history before the window, in window durations (for recurrent methods).
    modalities : the inputs to simulate
    seed : int
        The cell's seed.
    """
    if not history_windows >= 0 or not math.isfinite(history_windows):
        raise InputError(f"history_windows: expected a finite number >= 0, got {history_windows!r}")
    entry = grids.scene_entry("pan:camera", (int(width), int(height)))
    sensor = SensorConfig(planes=PLANES)
    condition = Condition(light=LIGHT, motion=MOTION, effects=grids.DEFAULT_EFFECTS)
    window_s = sensor.planes / sensor.plane_rate_hz
    sample = simulate_sample(entry.spec, condition, sensor=sensor, seed=seed, modalities=modalities,
                             history_s=history_windows * window_s)
    return sample.without_ground_truth()


def cut_spike_window(sample: Any, planes: int) -> Any:
    """``sample`` with its spike window cut to ``planes`` planes around the key plane.

    The window is planes ``[k - planes // 2, k - planes // 2 + planes)`` of the key plane ``k``; the
    sample's window becomes that span and its events stop at the new window's end.

    Raises
    ------
    InputError
        When the sample has no spikes or fewer than ``planes`` planes around the key plane.
    """
    planes = check_count("planes", planes, 1)
    if sample.spikes is None:
        raise InputError("cut_spike_window: the sample has no spikes")
    k = sample.key_plane
    start = k - planes // 2
    if start < 0 or start + planes > sample.spikes.num_planes:
        raise InputError(f"cut_spike_window: {planes} planes around plane {k} do not fit in "
                         f"{sample.spikes.num_planes} planes")
    spikes = sample.spikes.window(start, start + planes)
    events = sample.events
    if events is not None:
        t0 = min(float(events.t_s[0]), spikes.start_s) if len(events) else spikes.start_s
        events = events.between(t0, spikes.end_s)
    return replace(sample, spikes=spikes, events=events, window_start_s=spikes.start_s, window_end_s=spikes.end_s)


# ----------------------------------------------------------------------------------------------
# Table 2
# ----------------------------------------------------------------------------------------------

def create_methods(names: Sequence[str], *, weights_dir: str | os.PathLike | None = None,
                   device: str = "cpu", precision: str | None = None, compiled: bool = False
                   ) -> dict[str, tuple[Any, str]]:
    """``{name: (method or None, reason)}``: each method created once by
    :func:`neuspike.methods.create_many`; a method that cannot be created gives ``None`` and
    ``"skipped: ..."`` (``MethodUnavailable``) or ``"error: ..."`` (anything else). Unknown names and
    an unusable device raise :class:`~neuspike.errors.InputError` before anything is built. ``precision``
    (``None``: each method's own, ``"auto"`` for the learned ones) and ``compiled`` are given to every learned
    method."""
    from neuspike import methods as registry

    made = registry.create_many(list(names), weights_dir=weights_dir, device=device, precision=precision,
                                compiled=compiled, keep_errors=True)
    out: dict[str, tuple[Any, str]] = {}
    for name, c in made.items():
        if c.unavailable is not None:
            out[name] = (None, f"skipped: {one_line(c.unavailable)}")
        elif c.error is not None:  # a method that cannot even be created is a row, not a crash
            out[name] = (None, f"error: {one_line(c.error)}")
        else:
            out[name] = (c.method, "")
    return out


def method_info(name: str, method: Any) -> dict[str, Any]:
    """Family, inputs and parameter count of a method (registry entry when it could not be created)."""
    ins: frozenset[str] = frozenset()
    try:
        from neuspike import methods as registry

        ins = frozenset(registry.entry(name).inputs)
    except Exception:
        ins = frozenset(getattr(method, "inputs", ()) or ())
    params = 0
    if method is not None:
        try:
            params = int(method.parameter_count())
        except Exception:
            params = 0
    # a learned method's device and the precision it runs in ("auto" resolved); empty for the others
    learned = method is not None and getattr(method, "module", None) is not None
    device = str(getattr(method, "device", "")) if learned else ""
    precision = str(method.params.get("precision", "")) if learned else ""
    if learned and method.params.get("compiled"):
        precision += ", compiled"
    return {"family": family_of(ins), "inputs": "+".join(sorted(ins)), "parameters": params,
            "device": device, "precision": precision}


def measure(names: Sequence[str], sizes: Sequence[tuple[int, int]], *, repeats: int, warmup: int,
            history_windows: float = DEFAULT_HISTORY_WINDOWS, seed: int = 0,
            weights_dir: str | os.PathLike | None = None, device: str = "cpu", precision: str | None = None,
            threads: int | None = None, compiled: bool = False, log: Callable[[str], Any] | None = None) -> pd.DataFrame:
    """Table 2 rows (:data:`TIMING_COLUMNS`): every method at every size.

    Each size's recording is simulated once (:func:`representative_sample`); each method is
    created once and timed with :func:`time_method`. ``threads`` (when given) is re-applied to
    torch before every method: the simulator's compiled kernels start an OpenMP pool that can
    change the count torch uses.
    """
    import torch

    repeats = check_count("repeats", repeats, 1)
    warmup = check_count("warmup", warmup, 0)
    created = create_methods(names, weights_dir=weights_dir, device=device, precision=precision, compiled=compiled)
    needs = {m for name, (method, _) in created.items() if method is not None for m in method.inputs}
    learned = any(getattr(method, "module", None) is not None for method, _ in created.values())
    reference = None
    if learned:
        if threads is not None:
            set_threads(threads)
        reference = matmul_gflop_s(device=device)
        if log:
            log(f"reference: a {MATMUL_SIDE}x{MATMUL_SIDE} float32 matrix product on {device} runs at "
                f"{reference:.1f} GFLOP/s")
    rows = []
    streaming = any(method is not None and streams(method) for method, _ in created.values())
    for width, height in sizes:
        res = f"{width}x{height}"
        sample = None
        video: list[Sample] = []
        if needs:
            if log:
                log(f"{res}: simulating the representative recording")
            sample = representative_sample(width, height, history_windows=history_windows,
                                           modalities=sorted(needs), seed=seed)
        if streaming:
            if log:
                log(f"{res}: simulating a running video ({STREAM_FPS:g} frames/s) for the streaming costs")
            video = running_video(width, height, 1 + warmup + repeats, seed=seed)
        for name in names:
            method, reason = created[name]
            if threads is not None:
                set_threads(threads)
            row: dict[str, Any] = {c: math.nan for c in TIMING_COLUMNS}
            row.update(method=name, resolution=res, width=width, height=height, threads=torch.get_num_threads(),
                       error="", **method_info(name, method))
            if method is None:
                status, _, msg = reason.partition(": ")
                row.update(status=status, error=msg)
            else:
                try:
                    timing = time_method(method, sample, repeats=repeats, warmup=warmup)
                    row.update(status="ok", **timing.row())
                    row["cold_ms"] = row["median_ms"]  # the whole call: a recurrent method's warm-up included
                    if streams(method):
                        row.update(time_streaming(method, video, warmup=warmup))
                    gflop = step_gflop(method, sample)
                    if gflop is not None and reference:
                        # recurrent methods: ms per network step; others: the whole call, encoding included
                        row.update(gflop_per_step=gflop, gflop_s=gflop / (row["ms_per_frame"] / 1000.0),
                                   flop_bound_ms=gflop / reference * 1000.0, matmul_gflop_s=reference)
                        row["encode_ms"] = encode_ms(method, sample, repeats=repeats, warmup=min(warmup, 1))
                except Exception as exc:
                    row.update(status="error", error=one_line(exc))
            if log:
                stream = (f"; streaming {row['stream_ms']:.3g} ms per new frame"
                          if row["status"] == "ok" and not math.isnan(row["stream_ms"]) else "")
                if row["status"] == "ok" and not math.isnan(row["encode_ms"]):
                    stream += f"; building its inputs {row['encode_ms']:.3g} ms"
                log(f"{res} {name}: " + (f"{row['ms_per_frame']:.3g} ms per frame{stream}" if row["status"] == "ok"
                                          else f"{row['status']} ({row['error']})"))
            rows.append(row)
    return pd.DataFrame(rows, columns=list(TIMING_COLUMNS))


# ----------------------------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------------------------

def method_names(text: str | None) -> tuple[str, ...]:
    """The methods a command names (comma-separated ``text``), or every registered one when ``None``.

    Raises
    ------
    InputError
        An unknown name (the message lists the known ones), or no method registered at all.
    """
    from bench.harness.grid import parse_list
    from neuspike import methods as registry

    for problem in registry.load_entry_points():
        print(f"warning: a method plug-in failed to load: {problem}", file=sys.stderr)
    if text:
        names = parse_list(text)
        for name in names:
            registry.entry(name)  # unknown names raise with the list of known ones
        if len(set(names)) != len(names):
            raise InputError(f"--methods repeats a name: {text!r}")
        return names
    names = tuple(registry.available())
    if not names:
        raise InputError("no methods are registered")
    return names


