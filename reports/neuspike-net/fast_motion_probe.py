"""Why the fusion network blurs fast pans: its support head and its motion gate, per speed and light.

    python reports/neuspike-net/fast_motion_probe.py --photos astronaut,coffee
    python reports/neuspike-net/fast_motion_probe.py --weights-file runs/nsn-stage22-cue/neuspike-net.safetensors \
        --support-cue spread        # a candidate (its card must match the design)

On pans of *training* photographs (400x250, S = 256, seed 0, no sensor noise; the test photographs are
for the fast-motion report only) at 1x, 4x and 16x the sweeps' speed and L = 1/4 and 1/16, one
forward pass of the shipped ``neuspike-net`` (float32) per cell, and prints:

* its PSNR, and the PSNR with the motion gate's four gains forced to 1 and to 2 (does the gate hold
  events back where they would help?), and of the texture path alone (``forward_texture_only``);
* the gate's gains ``g3 g2 g1 g0`` (x_m^3 ... the input-level skip x_m^0);
* the support head's softmax over the 32 radiance estimates (16 group rates, 16 interval estimates at
  the group centres) on the moving edges (the pixels whose ground-truth gradient is in the top 10 %,
  :func:`bench.fast_motion.edge_mask`) and over the whole image: the share on the interval channels,
  the participation ratio of the per-group weights in planes (16 planes a group), and the share on
  the four central groups. A support that adapts to motion narrows as the speed grows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from bench import grid as grids
from bench.fast_motion import edge_mask
from neuspike import metrics
from neuspike.conditions import Condition
from neuspike.methods import create
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

SPEEDS = ("", "@4x", "@16x")
LIGHTS = (0.25, 0.0625)


def psnr(image: np.ndarray, truth: np.ndarray) -> float:
    """The suite's PSNR of the image clamped to [0, 1], as the method's read-out clamps it."""
    return metrics.psnr(np.clip(image, 0.0, 1.0), truth, data_range=1.0)


def support_summary(weights: np.ndarray, mask: np.ndarray) -> str:
    """weights (32, H, W), a softmax over the channels; mask (H, W) -> one line."""
    w = weights[:, mask]
    per_group = w[:16] + w[16:]  # a group's rate and its centre's interval estimate together
    planes = float(np.mean(16.0 / np.sum(per_group ** 2, axis=0)))
    return (f"interval share {w[16:].sum(0).mean():.2f}, support {planes:.0f} planes, "
            f"central 4 groups {per_group[6:10].sum(0).mean():.2f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--photos", default="astronaut,coffee", help="training photographs (comma-separated)")
    p.add_argument("--weights", default="../shared/weights", help="weights folder (the shipped ones are found anyway)")
    p.add_argument("--weights-file", help="a candidate's fusion weights (.safetensors) instead of the shipped ones")
    p.add_argument("--support-cue", default="none", choices=("none", "spread"), help="the candidate's support cue")
    p.add_argument("--key-estimates", default="none", choices=("none", "isi-sequence"),
                   help="the candidate's key estimates")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    folder, extra = args.weights, {}
    if args.weights_file:
        folder, extra = str(Path(args.weights_file).parent), {"weights_file": Path(args.weights_file).name}
    method = create("neuspike-net", weights_dir=folder, precision="float32", support_cue=args.support_cue,
                    key_estimates=args.key_estimates, **extra)
    net = method.module.float().eval()
    logits: dict[str, torch.Tensor] = {}
    net.predict.register_forward_hook(lambda _m, _i, out: logits.__setitem__("y", out))
    gate = net.motion_gate.forward
    for photo in args.photos.split(","):
        for speed in SPEEDS:
            for light in LIGHTS:
                entry = grids.scene_entry(f"pan{speed}:{photo}", (400, 250))
                condition = Condition(light=light, motion=256, effects=grids.DEFAULT_EFFECTS)
                sample = simulate_sample(entry.spec, condition, sensor=SensorConfig(planes=256), seed=0,
                                         modalities=("spikes", "events"))
                truth, (h, w) = sample.ground_truth, sample.ground_truth.shape
                inputs = method.encode(sample)[0]
                with torch.inference_mode():
                    gains = net.motion_gate(inputs[0][:, :net.in_channels], inputs[1])[0].numpy()
                    image = net(*inputs)[0, 0].numpy()
                    softmax = torch.softmax(logits["y"][0, 1:, :h, :w].float(), dim=0).numpy()
                    forced = {}
                    for k in (1.0, 2.0):
                        net.motion_gate.forward = lambda s, e, k=k: torch.full((s.shape[0], 4), k)
                        forced[k] = net(*inputs)[0, 0].numpy()
                    net.motion_gate.forward = gate
                    texture = net.forward_texture_only(inputs[0], inputs[2])[0, 0].numpy()
                edges = edge_mask(truth)
                print(f"{photo} pan{speed or '@1x'} L={light:g}: PSNR {psnr(image, truth):.2f} (gate 1: "
                      f"{psnr(forced[1.0], truth):.2f}, gate 2: {psnr(forced[2.0], truth):.2f}, texture path "
                      f"{psnr(texture, truth):.2f}); gains {' '.join(f'{g:.2f}' for g in gains)}")
                print(f"    edges: {support_summary(softmax, edges)}; whole image: "
                      f"{support_summary(softmax, np.ones_like(edges))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
