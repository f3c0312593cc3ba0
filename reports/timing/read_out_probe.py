"""What ``read_out="window"`` saves and costs a streamed recurrent event network, against ``"key"``.

    python reports/timing/read_out_probe.py [--method e2vid] [--frames 24] [--threads 1] [--photo astronaut]

A running video like the timing command's (:func:`bench.harness.timer.running_video`: a pan at the
representative condition, L = 1/4, S = 128, 1,000 frames/s of sensor time, 400x250) but of a
*training* photograph, so that the choice between the read-outs is never made on a test photograph.
The first frame warms up from a reset (the same for both read-outs); every later frame streams
(``reconstruct_next``). For each read-out it prints, over the streamed frames, the mean time per
frame, the network steps per frame, how far before the key instant the image is (``"window"``), and
the mean PSNR / SSIM against the scene's rendered ground truth at each frame's key instant. float32.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def running_video_of(photo: str, width: int, height: int, frames: int, fps: float):
    """``(samples, ground truth)`` of a pan of ``photo`` streamed at ``fps`` (the timing video's recipe)."""
    from bench.harness import grid as grids
    from bench.harness.timer import LIGHT, MOTION, PLANES
    from neuspike.conditions import Condition
    from neuspike.scenes import make_scene
    from neuspike.simulation.recording import SensorConfig
    from neuspike.simulation.writing import write_sequence
    from neuspike.utils.rng import derive_rng
    from neuspike.video import frame_times, open_recording, stream_samples
    from neuspike.video.truth import ground_truth_for

    entry = grids.scene_entry(f"pan:{photo}", (width, height))
    condition = Condition(light=LIGHT, motion=MOTION, effects=grids.DEFAULT_EFFECTS)
    half = PLANES / 2 / SensorConfig().plane_rate_hz
    with tempfile.TemporaryDirectory(prefix="read-out-probe-") as tmp:
        write_sequence(make_scene(entry.spec), condition, Path(tmp), rng=derive_rng(0, "read_out_probe"),
                       start_s=0.0, duration_s=2 * half + frames / fps, seed=0, progress=False)
        with open_recording(Path(tmp)) as rec:
            samples = list(stream_samples(rec, frame_times(half, half + frames / fps, fps), window_planes=PLANES))
            truth = ground_truth_for(rec.folder, rec.meta, height=rec.height, width=rec.width, tolerance_s=0.5 / fps)
            images = [truth.at(s.key_time_s)[1] for s in samples]
    return samples, images


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--method", default="e2vid", help="a recurrent event network (e2vid, firenet-sim, firenet)")
    p.add_argument("--frames", type=int, default=24, help="frames of the running video (default 24)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    p.add_argument("--photo", default="astronaut", help="a training photograph (default astronaut)")
    p.add_argument("--size", default="400x250", help="WxH (default 400x250)")
    p.add_argument("--weights", default="../shared/weights", help="published weights (for firenet)")
    args = p.parse_args(argv)
    from bench.harness.timer import STREAM_FPS, set_threads
    from neuspike.methods import create
    from neuspike.scenes.photos import TEST_PHOTOS
    from neuspike.video.truth import score_frame

    if args.photo in TEST_PHOTOS:
        p.error(f"--photo {args.photo}: a test photograph; choose a training one")
    width, height = (int(v) for v in args.size.split("x"))
    set_threads(args.threads)
    samples, truth = running_video_of(args.photo, width, height, args.frames, STREAM_FPS)
    print(f"{args.method}, pan:{args.photo} {width}x{height}, {args.frames} frames at {STREAM_FPS:g} frames/s, "
          f"{args.threads} thread(s), float32")
    for read_out in ("key", "window"):
        method = create(args.method, precision="float32", read_out=read_out, weights_dir=args.weights)
        method.reconstruct(samples[0])
        times, steps, lags, psnrs, ssims = [], [], [], [], []
        for k in range(1, len(samples)):
            t0 = time.perf_counter()
            image = method.reconstruct_next(samples[k], previous_s=samples[k - 1].key_time_s)
            times.append(time.perf_counter() - t0)
            steps.append(method.last_steps)
            lag = re.search(r"([0-9.e+-]+) ms before the key instant", method.last_normalisation)
            lags.append(float(lag.group(1)) if lag else 0.0)
            q = score_frame(image, truth[k])
            psnrs.append(q[0])
            ssims.append(q[1])
        print(f"read_out={read_out}: {1e3 * np.mean(times):.0f} ms per streamed frame "
              f"(median {1e3 * np.median(times):.0f}), {np.mean(steps):.2f} steps per frame, image "
              f"{np.mean(lags):.3f} ms (at most {np.max(lags):.3f}) before the key instant; "
              f"PSNR {np.mean(psnrs):.3f} dB, SSIM {np.mean(ssims):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
