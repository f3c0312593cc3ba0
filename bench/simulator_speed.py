"""Throughput of the spike and event camera simulators on a reproducible standard input.

Standard input: scikit-image's ``camera`` photograph panning 2 px per frame, 256 frames at
22,500 frames/s, 400x250 (the scene is rendered once, outside the timed region). The spike camera
holds each frame for one plane (256 planes); the event camera sees the 256 frames at their times.

Prints planes/s for the spike camera and frames/s plus events/s for the event camera, each with no
effects, with the presets and with every effect, beside the reference figures measured on this
machine class (a plain NumPy integrate-and-fire loop; Spike-Zoo's simulator; v2e's DVS emulator).

    python -m bench.simulator_speed [--repeats 7] [--size 400x250] [--threads N]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np
import torch

from neuspike.conditions import EVENT_PRESETS, effect
from neuspike.scenes import SceneSpec, make_scene
from neuspike.sensors.event_camera import EventCamera
from neuspike.sensors.spike_camera import SpikeCamera

FRAME_RATE_HZ = 22_500.0
PX_PER_FRAME = 2.0
FRAMES = 256

REFERENCE = {
    "plain NumPy integrate-and-fire loop": "24,900 planes/s",
    "Spike-Zoo simulator": "1,211 planes/s",
    "v2e DVS, clean preset": "156 frames/s (6.9 M events/s)",
    "v2e DVS, noisy preset": "270 frames/s",
}

SPIKE_CONFIGS = {
    "no effects": (),
    "all effects (initial_charge, dark_current sigma 50)": (effect("initial_charge"), effect("dark_current")),
}
EVENT_CONFIGS = {
    "no effects": (),
    "clean preset (v2e)": EVENT_PRESETS["clean"],
    "noisy preset (v2e)": EVENT_PRESETS["noisy"],
    "all effects": (
        effect("threshold_mismatch", sigma=0.05), effect("bandwidth", cutoff_hz=30.0),
        effect("refractory", period_s=5e-4), effect("leak", rate_hz=0.1), effect("shot_noise", rate_hz=5.0),
    ),
}


def standard_input(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """The panning ``camera`` frames (256, H, W) and their times (256,)."""
    times = np.arange(FRAMES, dtype=np.float64) / FRAME_RATE_HZ
    scene = make_scene(SceneSpec(kind="pan", image="camera", size=(width, height),
                                 velocity_px_s=(PX_PER_FRAME * FRAME_RATE_HZ, 0.0)))
    return np.ascontiguousarray(scene.render(times), dtype=np.float32), times


def _median_time(fn, repeats: int) -> tuple[float, float, float, object]:
    fn()  # warm-up
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times), max(times), result


def run(width: int = 400, height: int = 250, repeats: int = 7) -> list[dict]:
    frames, times = standard_input(width, height)
    rows = []
    for label, effects in SPIKE_CONFIGS.items():
        def once(effects=effects):
            cam = SpikeCamera(width, height, light=1.0, threshold=1.0, effects=effects, rng=np.random.default_rng(0))
            return cam.capture(frames, hold_planes=1)
        med, lo, hi, stream = _median_time(once, repeats)
        rows.append({"sensor": "spike", "config": label, "seconds": med, "min": lo, "max": hi,
                     "rate": FRAMES / med, "unit": "planes/s", "count": int(np.count_nonzero(stream.planes))})
    for label, effects in EVENT_CONFIGS.items():
        def once(effects=effects):
            cam = EventCamera(width, height, light=1.0, effects=effects, rng=np.random.default_rng(0))
            return cam.capture(frames, times)
        med, lo, hi, stream = _median_time(once, repeats)
        # the first frame only initialises the pixels; 255 intervals produce events
        rows.append({"sensor": "event", "config": label, "seconds": med, "min": lo, "max": hi,
                     "rate": FRAMES / med, "unit": "frames/s", "count": len(stream),
                     "events_per_s": len(stream) / med})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.simulator_speed", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=7, help="timed runs per configuration (median reported)")
    p.add_argument("--size", default="400x250", help="sensor size WxH (default 400x250)")
    p.add_argument("--threads", type=int, help="torch threads (default: torch's choice)")
    args = p.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    w, h = (int(v) for v in args.size.lower().split("x"))
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"torch threads {torch.get_num_threads()}, numpy {np.__version__}")
    print(f"input: camera panning {PX_PER_FRAME:g} px/frame, {FRAMES} frames at {FRAME_RATE_HZ:,.0f} frames/s, "
          f"{w}x{h}; median of {args.repeats} runs after one warm-up\n")
    rows = run(w, h, args.repeats)
    print(f"{'sensor':<7} {'configuration':<52} {'rate':>16} {'median s':>9} {'spread s':>15} {'output':>22}")
    for r in rows:
        extra = f"{r['count']:,} {'spikes' if r['sensor'] == 'spike' else 'events'}"
        rate = f"{r['rate']:,.0f} {r['unit']}"
        print(f"{r['sensor']:<7} {r['config']:<52} {rate:>16} {r['seconds']:>9.4f} "
              f"{r['min']:>7.4f}-{r['max']:<7.4f} {extra:>22}")
        if "events_per_s" in r:
            print(f"{'':<7} {'':<52} {r['events_per_s'] / 1e6:>12.1f} M events/s")
    print("\nreference figures on this machine class:")
    for k, v in REFERENCE.items():
        print(f"  {k}: {v}")
    print("targets: spike camera >= 20,000 planes/s; event camera >= 5x v2e (>= 780 frames/s clean, "
          ">= 1,350 frames/s with every effect)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
