"""Throughput of the spike and event camera simulators, each beside its reference in the same run.

Standard input: scikit-image's ``camera`` photograph panning 2 px per frame, 256 frames at
22,500 frames/s, 400x250 (rendered once, outside the timed region). The spike camera holds each
frame for one plane (256 planes); the event camera sees the 256 frames at their times.

Spike camera: planes/s of the compiled kernel (numba) on 1 and 2 threads, writing bool planes
and bit-packed planes, and of the suite's NumPy path, beside a plain NumPy integrate-and-fire loop
(the reference); for context, the memory floor (reading the input frames once) and the kernel on
one frame held for every plane (the same work without input traffic). Event camera: frames/s of the compiled backend (one thread, and with the worker
thread) beside the NumPy path (the reference), without effects, with the v2e presets and with
every effect. Whole window: one sample of the sweep's default cell (``pan`` over ``camera``, L
1/4, S 128, the harness's default effects; render + both cameras, ``simulate_sample``) per second
on one thread, at 128x128 (the training size) and at 400x250, beside the same window with every
stage on its NumPy reference path (scene samplers and both cameras).
Every configuration is timed in turn within each repeat, so a change in the
machine's load touches reference and candidate alike; the median is reported with its spread and
the 1-minute load average. Each target ends in a one-line verdict (met / missed, with the ratio).

    python -m bench.simulator_speed [--repeats 7] [--size 400x250] [--quick]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import statistics
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np

from neuspike.conditions import EVENT_PRESETS, effect
from neuspike.scenes import SceneSpec
from neuspike.utils.parallel import NUMBA_AVAILABLE, set_threads

FRAME_RATE_HZ = 22_500.0
PX_PER_FRAME = 2.0
FRAMES = 256

EVERY_EVENT_EFFECT = (
    effect("threshold_mismatch", sigma=0.05), effect("bandwidth", cutoff_hz=30.0),
    effect("refractory", period_s=5e-4), effect("leak", rate_hz=0.1), effect("shot_noise", rate_hz=5.0),
)
EVENT_CONFIGS = {
    "no effects": (),
    "clean preset (v2e)": EVENT_PRESETS["clean"],
    "noisy preset (v2e)": EVENT_PRESETS["noisy"],
    "every effect": EVERY_EVENT_EFFECT,
}
#: Targets: (sensor, configuration, candidate implementation, reference implementation, ratio).
TARGETS = (
    ("spike", "no effects", "numba, 2 threads", "plain NumPy loop", 3.0),
    ("spike", "no effects", "numba, 1 thread", "plain NumPy loop", 2.0),
    ("event", "no effects", "numba, best", "NumPy path (today's)", 2.0),
    ("event", "every effect", "numba, best", "NumPy path (today's)", 2.0),
    ("window", "400x250", "compiled, 1 thread", "NumPy reference paths", 3.0),
)
#: Whole windows per second on one thread at the training size (an absolute target: a training
#: step must never wait for data).
WINDOW_RATE_TARGET = ("window", "128x128", "compiled, 1 thread", 50.0)
WINDOW_SIZES = ((128, 128), (400, 250))


def standard_input(width: int, height: int, frames: int = FRAMES) -> tuple[np.ndarray, np.ndarray]:
    """The panning ``camera`` frames (frames, H, W) float32 and their times (frames,) in seconds."""
    from neuspike.scenes import make_scene

    times = np.arange(frames, dtype=np.float64) / FRAME_RATE_HZ
    scene = make_scene(SceneSpec(kind="pan", image="camera", size=(width, height),
                                 velocity_px_s=(PX_PER_FRAME * FRAME_RATE_HZ, 0.0)))
    return np.ascontiguousarray(scene.render(times), dtype=np.float32), times


def plain_integrate_and_fire(frames: np.ndarray, light: float = 1.0, threshold: float = 1.0) -> np.ndarray:
    """The reference: Algorithm 1 as a plain NumPy loop over planes (one plane per frame)."""
    light32, phi = np.float32(light), np.float32(threshold)
    charge = np.zeros(frames.shape[1:], np.float32)
    drive = np.empty_like(charge)
    planes = np.empty(frames.shape, np.bool_)
    for k in range(frames.shape[0]):
        np.multiply(frames[k], light32, out=drive)
        charge += drive
        np.greater_equal(charge, phi, out=planes[k])
        charge -= planes[k] * phi
    return planes


@dataclass
class Case:
    sensor: str
    config: str
    impl: str
    threads: int
    run: Callable[[], Any]
    count: Callable[[Any], int]
    setup: Callable[[], None] = lambda: None
    #: a context row (not an implementation of the configuration: its output differs by design)
    context: bool = False
    #: items per run (None: the input's frames); a whole-window case makes one window per run
    items: int | None = None


def _numba_threads(n: int) -> None:
    set_threads(n, torch_pool=False)


def _get_numba_threads() -> int:
    if NUMBA_AVAILABLE:
        import numba

        return numba.get_num_threads()
    return 1


def cases(frames: np.ndarray, times: np.ndarray) -> list[Case]:
    """Every timed configuration, references first."""
    from neuspike.sensors.event_camera import EventCamera
    from neuspike.sensors.spike_camera import SpikeCamera

    _, h, w = frames.shape
    out: list[Case] = [Case("spike", "no effects", "plain NumPy loop", 1, lambda: plain_integrate_and_fire(frames),
                            lambda p: int(np.count_nonzero(p)))]

    def spike(backend: str, packed: bool):
        def once():
            cam = SpikeCamera(w, h, light=1.0, threshold=1.0, rng=None, backend=backend)
            if packed:
                return cam.capture_packed(frames, hold_planes=1)[0].count()
            return int(np.count_nonzero(cam.capture(frames, hold_planes=1).planes))
        return once

    out.append(Case("spike", "no effects", "NumPy path", 1, spike("numpy", False), int))
    # context for the verdicts: what reading the input costs at all, and the kernel without input traffic
    out.append(Case("spike", "no effects", "floor: read the input", 1, lambda: float(frames.sum()), lambda _: 0,
                    context=True))
    if NUMBA_AVAILABLE:
        held = np.ascontiguousarray(frames[:1])

        def held_once():
            cam = SpikeCamera(w, h, light=1.0, threshold=1.0, rng=None, backend="numba")
            return int(np.count_nonzero(cam.capture(held, hold_planes=frames.shape[0]).planes))

        out.append(Case("spike", "no effects", "numba 1 thr, 1 frame held", 1, held_once, int,
                        setup=lambda: _numba_threads(1), context=True))
        for threads in (1, 2):
            s = "s" if threads > 1 else ""
            out.append(Case("spike", "no effects", f"numba, {threads} thread{s}", threads, spike("numba", False), int,
                            setup=lambda t=threads: _numba_threads(t)))
            out.append(Case("spike", "no effects", f"numba packed, {threads} thread{s}", threads,
                            spike("numba", True), int, setup=lambda t=threads: _numba_threads(t)))

    def event(effects, backend: str, threads: int):
        def once():
            cam = EventCamera(w, h, light=1.0, effects=effects, rng=np.random.default_rng(0), backend=backend,
                              threads=threads)
            return len(cam.capture(frames, times))
        return once

    for label, effects in EVENT_CONFIGS.items():
        out.append(Case("event", label, "NumPy path (today's)", 1, event(effects, "numpy", 1), int))
        if NUMBA_AVAILABLE:
            out.append(Case("event", label, "numba, 1 thread", 1, event(effects, "numba", 1), int,
                            setup=lambda: _numba_threads(1)))
            out.append(Case("event", label, "numba + worker thread", 2, event(effects, "numba", 2), int,
                            setup=lambda: _numba_threads(1)))
    return out


@contextlib.contextmanager
def numpy_reference_paths() -> Iterator[None]:
    """Every simulator stage on its NumPy reference path: both cameras and the scene samplers."""
    from unittest import mock

    import neuspike.scenes.sampling as sampling
    import neuspike.sensors.event_camera as event_camera
    import neuspike.sensors.spike_camera as spike_camera

    def numpy_only(backend: str, **_: object) -> str:
        return "numpy"

    with mock.patch.object(event_camera, "resolve_backend", numpy_only), \
            mock.patch.object(spike_camera, "resolve_backend", numpy_only), \
            mock.patch.object(sampling, "_kernels", None):
        yield


def window_cases(sizes=WINDOW_SIZES) -> list[Case]:
    """One simulated window of the sweep's default cell per run, compiled and on the reference paths."""
    from bench.harness.grid import DEFAULT_EFFECTS
    from neuspike.conditions import Condition
    from neuspike.simulation.cell import simulate_sample
    from neuspike.simulation.recording import SensorConfig

    condition = Condition(light=0.25, motion=128, effects=DEFAULT_EFFECTS)
    out = []
    for w, h in sizes:
        spec = SceneSpec(kind="pan", image="camera", size=(w, h))

        def once(spec=spec):
            sample = simulate_sample(spec, condition, sensor=SensorConfig(), seed=0)
            return len(sample.events)

        def reference(once=once):
            with numpy_reference_paths():
                return once()

        label = f"{w}x{h}"
        out.append(Case("window", label, "NumPy reference paths", 1, reference, int, items=1))
        if NUMBA_AVAILABLE:
            out.append(Case("window", label, "compiled, 1 thread", 1, once, int, setup=lambda: _numba_threads(1),
                            items=1))
    return out


def run(width: int = 400, height: int = 250, repeats: int = 7, frames: int = FRAMES,
        window_sizes=WINDOW_SIZES) -> list[dict]:
    """Time every case ``repeats`` times, round-robin; one row per case with the median rate."""
    images, times = standard_input(width, height, frames)
    all_cases = cases(images, times) + window_cases(window_sizes)
    previous = _get_numba_threads()
    results: dict[int, dict[str, Any]] = {}
    for i, case in enumerate(all_cases):  # warm-up: compilation, caches, first-touch allocations
        case.setup()
        results[i] = {"count": case.count(case.run()), "seconds": [], "cpu": [], "load": []}
    for _ in range(repeats):
        for i, case in enumerate(all_cases):
            case.setup()
            c0, t0 = time.process_time(), time.perf_counter()
            case.run()
            results[i]["seconds"].append(time.perf_counter() - t0)
            results[i]["cpu"].append(time.process_time() - c0)
            results[i]["load"].append(os.getloadavg()[0])
    _numba_threads(previous)
    rows = []
    for i, case in enumerate(all_cases):
        sec = results[i]["seconds"]
        med = statistics.median(sec)
        rows.append({"sensor": case.sensor, "config": case.config, "impl": case.impl, "threads": case.threads,
                     "seconds": med, "min": min(sec), "max": max(sec),
                     "rate": (frames if case.items is None else case.items) / med,
                     "cpu_seconds": statistics.median(results[i]["cpu"]),
                     "unit": {"spike": "planes/s", "event": "frames/s"}.get(case.sensor, "windows/s"),
                     "count": results[i]["count"], "context": case.context, "load_1min": statistics.median(results[i]["load"]),
                     "width": width, "height": height, "frames": frames})
    return rows


def _rate(rate: float, unit: str) -> str:
    return f"{rate:,.1f} {unit}" if unit == "windows/s" else f"{rate:,.0f} {unit}"


def verdicts(rows: list[dict]) -> list[str]:
    """One line per target: met or missed, with the measured ratio."""
    lines = []
    for sensor, config, impl, ref, target in TARGETS:
        pick = [r for r in rows if r["sensor"] == sensor and r["config"] == config]
        refs = [r for r in pick if r["impl"] == ref]
        if impl == "numba, best":
            cands = [r for r in pick if r["impl"].startswith("numba")]
            cands = [max(cands, key=lambda r: r["rate"])] if cands else []
        else:
            cands = [r for r in pick if r["impl"] == impl]
        if not refs or not cands:
            why = "numba not importable" if not NUMBA_AVAILABLE else "not in this run"
            lines.append(f"{sensor}, {config}, {impl} >= {target:g}x {ref}: not measured ({why})")
            continue
        ratio = cands[0]["rate"] / refs[0]["rate"]
        verdict = "met" if ratio >= target else "missed"
        what = f"{sensor} camera" if sensor != "window" else "whole window"
        lines.append(f"{what}, {config}: {cands[0]['impl']} >= {target:g}x {ref}: {verdict} "
                     f"({ratio:.2f}x: {_rate(cands[0]['rate'], cands[0]['unit'])} vs {_rate(refs[0]['rate'], refs[0]['unit'])})")
    sensor, config, impl, target = WINDOW_RATE_TARGET
    got = [r for r in rows if (r["sensor"], r["config"], r["impl"]) == (sensor, config, impl)]
    if got:
        verdict = "met" if got[0]["rate"] >= target else "missed"
        lines.append(f"whole window, {config}: {impl} >= {target:g} windows/s: {verdict} ({got[0]['rate']:.1f} windows/s)")
    else:
        lines.append(f"whole window, {config}: {impl} >= {target:g} windows/s: not measured (not in this run)")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.simulator_speed", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=7, help="timed runs per configuration (median reported)")
    p.add_argument("--size", default="400x250", help="sensor size WxH (default 400x250)")
    p.add_argument("--quick", action="store_true",
                   help="smoke test in seconds: 80x48, 16 frames, 1 repeat (figures not meaningful)")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    frames, repeats = FRAMES, args.repeats
    window_sizes = WINDOW_SIZES
    if args.quick:
        w, h, frames, repeats = 80, 48, 16, 1
        window_sizes = ((48, 32),)
    numba_version = "not importable"
    if NUMBA_AVAILABLE:
        import numba

        numba_version = f"{numba.__version__}, up to {numba.config.NUMBA_NUM_THREADS} threads"
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load average {load}; "
          f"numpy {np.__version__}, numba {numba_version}")
    print(f"input: camera panning {PX_PER_FRAME:g} px/frame, {frames} frames at {FRAME_RATE_HZ:,.0f} frames/s, "
          f"{w}x{h}; median of {repeats} runs after one warm-up, configurations timed in turn\n")
    rows = run(w, h, repeats, frames, window_sizes)
    print(f"{'sensor':<6} {'configuration':<20} {'implementation':<26} {'thr':>3} {'rate':>18} {'x ref':>6} "
          f"{'median s':>9} {'spread s':>15} {'cpu s':>7} {'load':>5} {'output':>20}")
    for r in rows:
        ref = next(x for x in rows if x["sensor"] == r["sensor"] and x["config"] == r["config"])
        rate = _rate(r["rate"], r["unit"])
        what = "spikes" if r["sensor"] == "spike" else "events"
        print(f"{r['sensor']:<6} {r['config']:<20} {r['impl']:<26} {r['threads']:>3} {rate:>18} "
              f"{r['rate'] / ref['rate']:>5.2f}x {r['seconds']:>9.4f} {r['min']:>7.4f}-{r['max']:<7.4f} "
              f"{r['cpu_seconds']:>7.4f} {r['load_1min']:>5.2f} {r['count']:>13,} {what}")
    print("\n(x ref: against the first row of the same sensor and configuration, measured in this run; cpu s: "
          "process CPU time, all threads, median; load: 1-minute load average while that row ran;\n"
          " floor: summing the input frames once, the memory traffic every spike camera pays on this input, so "
          "no implementation's rate exceeds it; 1 frame held: the compiled kernel on one frame held for every "
          "plane, the same work without the input traffic)")
    print("verdicts:")
    for line in verdicts(rows):
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
