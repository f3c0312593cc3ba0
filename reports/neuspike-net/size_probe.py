"""Fusion against spike-only at the sweeps' frame and at the training view, on training photographs.

    python reports/neuspike-net/size_probe.py [WEIGHTS_FOLDER] [--threads N]

The grid check's cells at L = 1/4, S = 128 (four training photographs x pan, zoom, fan, still;
seed 0), without noise and at the high noise level, rendered at 400x250 (the sweeps' frame) and at
128x128 (the whole photograph shrunk to the training view's side). Prints the mean PSNR of
``neuspike-net`` and ``neuspike-net-spike`` (counted level) and their difference, overall and per
scene kind. Default: the shipped weights.
"""

from __future__ import annotations

import numpy as np

from bench import grid as grids
from fullsize_check import probe_start  # beside this script
from neuspike.conditions import Condition
from neuspike.methods import create
from neuspike.metrics import psnr
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

PHOTOS = ("astronaut", "brick", "coffee", "rocket")
KINDS = ("pan", "zoom", "fan", "still")


def main(argv: list[str] | None = None) -> int:
    args, fusion = probe_start(__doc__, argv)
    spike = create("neuspike-net-spike", weights_dir=args.folder, precision="float32")
    for size in ((400, 250), (128, 128)):
        for noise in ("none", "high"):
            diffs: dict[str, list[float]] = {k: [] for k in KINDS}
            scores = []
            for photo in PHOTOS:
                for kind in KINDS:
                    scene = grids.scene_entry(f"{kind}:{photo}", size)
                    cond = Condition(light=0.25, motion=128, noise=noise, effects=grids.DEFAULT_EFFECTS)
                    s = simulate_sample(scene.spec, cond, sensor=SensorConfig(), seed=0, modalities=("spikes", "events"))
                    f = psnr(fusion.reconstruct(s), s.ground_truth, data_range=1.0)
                    o = psnr(spike.reconstruct(s), s.ground_truth, data_range=1.0)
                    scores.append((f, o))
                    diffs[kind].append(f - o)
            v = np.array(scores)
            per_kind = ", ".join(f"{k} {np.mean(d):+.2f}" for k, d in diffs.items())
            print(f"{size[0]}x{size[1]}, noise {noise}: fusion {v[:, 0].mean():.2f}, spike-only {v[:, 1].mean():.2f}, "
                  f"fusion - spike {np.mean(v[:, 0] - v[:, 1]):+.2f} ({per_kind})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
