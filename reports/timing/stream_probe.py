"""Where a streamed ``e2vid`` frame spends its time: its network steps, and what runs outside them.

    python reports/timing/stream_probe.py [THREADS] [WxH]      # default: 1 thread, 400x250

On the timing command's running video (:func:`bench.harness.timer.running_video`, 1,000 frames/s of sensor
time), prints the times of back-to-back network steps on one frame's voxel grids, then for each
streamed frame (``reconstruct_next``) its total, each network step inside it and the time outside the
steps (event slicing, voxel grids, the read-out), and a profile of one frame. float32.
"""

from __future__ import annotations

import cProfile
import io
import pstats
import sys
import time

from bench.harness.timer import running_video, set_threads
from neuspike.methods import create


def main(argv: list[str]) -> int:
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    threads = int(argv[0]) if argv else 1
    width, height = (int(v) for v in (argv[1] if len(argv) > 1 else "400x250").split("x"))
    set_threads(threads)
    method = create("e2vid", precision="float32")
    video = running_video(width, height, 8)
    grids = method.encode(video[0])
    method.reset()
    for g in grids[:2]:  # warm-up
        method.run_step(g)
    method.reset()
    times = []
    for g in grids[:6]:
        t0 = time.perf_counter()
        method.run_step(g)
        times.append(time.perf_counter() - t0)
    print(f"{width}x{height}, {threads} thread(s): back-to-back steps, ms: {[round(1000 * t) for t in times]}")
    method.reset()
    method.reconstruct(video[0])
    inner, steps = method.run_step, []

    def timed(inputs):
        t0 = time.perf_counter()
        out = inner(inputs)
        steps.append(time.perf_counter() - t0)
        return out

    method.run_step = timed
    profile = cProfile.Profile()
    for k in range(1, len(video)):
        steps.clear()
        t0 = time.perf_counter()
        if k == 4:
            profile.enable()
        method.reconstruct_next(video[k], previous_s=video[k - 1].key_time_s)
        if k == 4:
            profile.disable()
        total = time.perf_counter() - t0
        print(f"frame {k}: {1000 * total:.0f} ms; steps, ms: {[round(1000 * s) for s in steps]}; "
              f"outside the steps {1000 * (total - sum(steps)):.0f} ms")
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("cumulative").print_stats(14)
    print(text.getvalue())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
