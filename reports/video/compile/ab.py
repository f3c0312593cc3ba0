"""Streamed video with and without ``torch.compile``, interleaved in one run (ratios, not absolute times).

    python reports/video/compile/ab.py [--methods e2vid] [--repeats 3] [--cache runs/vcache50]

The video benchmark's standard recording (the fan at 2600 RPM, 400x250, its default first 50 ms, 50
frames at 1,000 frames/s; simulated into ``--cache`` when missing) is streamed by each method eager and
compiled (:class:`~neuspike.methods.learned.LearnedMethod` ``compiled=True``), alternately, ``--repeats``
times each, on the threads the benchmark would use. The compiled method first streams two untimed
frames (the compile, timed separately, as ``python -m bench.video --compile`` does). Prints ms per
streamed frame per pass, the ratio of means and the largest image difference over the first frames.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--methods", default="e2vid", help="comma list of learned methods (default: e2vid)")
    p.add_argument("--repeats", type=int, default=3, help="passes of each variant (default: 3)")
    p.add_argument("--cache", type=Path, default=Path("runs/vcache50"), help="the simulated recording")
    p.add_argument("--weights", default="../shared/weights", help="published weights (FireNet's)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default: 2)")
    args = p.parse_args()

    from bench import video as vb
    from neuspike.methods import create_many
    from neuspike.utils.parallel import set_threads
    from neuspike.video import frame_times, open_recording, stream_methods

    set_threads(args.threads)
    spec = vb.VideoBenchSpec()
    args.cache.mkdir(parents=True, exist_ok=True)
    vb.simulate_standard(spec, args.cache)
    times = frame_times(vb.MARGIN_S, vb.MARGIN_S + spec.duration_s, spec.fps)
    for name in [m.strip() for m in args.methods.split(",") if m.strip()]:
        made = {c: create_many([name], weights_dir=args.weights, compiled=c, skip_unavailable=False)[name].method
                for c in (False, True)}
        print(f"{name}: precision {made[False].params['precision']}, {args.threads} threads")
        with open_recording(args.cache) as rec:
            t0 = time.perf_counter()
            for _ in stream_methods([made[True]], rec, times[:2]):
                pass
            print(f"  compile (two untimed frames): {time.perf_counter() - t0:.1f} s")
            means: dict[bool, list[float]] = {False: [], True: []}
            for rep in range(args.repeats):
                for c in (False, True):
                    busy = [sec[name] for _, _, sec in stream_methods([made[c]], rec, times)]
                    means[c].append(1000 * float(np.mean(busy)))
                    load = open("/proc/loadavg").read().split()[0] if Path("/proc/loadavg").exists() else "?"
                    print(f"  pass {rep + 1} {'compiled' if c else 'eager   '}: {means[c][-1]:.0f} ms per frame "
                          f"(steps/frame {made[c].last_steps}, 1-min load {load})")
            first = {c: [im[name] for _, im, _ in stream_methods([made[c]], rec, times[:5])] for c in (False, True)}
        diff = max(float(np.abs(a - b).max()) for a, b in zip(first[False], first[True]))
        print(f"  mean ms per frame: eager {np.mean(means[False]):.0f}, compiled {np.mean(means[True]):.0f}; "
              f"compiled / eager {np.mean(means[True]) / np.mean(means[False]):.2f}; "
              f"largest image difference over 5 frames {diff:.4f}")


if __name__ == "__main__":
    main()
