"""Full-size validation on *training* photographs: raw and affine-aligned PSNR of NeuSpike-Net weights.

    python reports/neuspike-net/fullsize_check.py [WEIGHTS_DIR ...] [--references snm,tfi]

The training validation windows are 128x128, but the sweeps reconstruct 400x250 frames. There the
instance-normalised features see other statistics, and the correction channel of the support
head can shift a whole image. This check simulates 400x250 pans and stills of four training
photographs (astronaut, brick, coffee, rocket) at L = 1/32, 1/8, 1/2, without noise and at the high
noise level, seed 0, and prints the mean PSNR and affine-aligned PSNR of `neuspike-net` for each
weights folder (default: the shipped weights), with the head its card names. It decides between
candidate weights without touching the test photographs.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

from bench import grid as grids
from neuspike.conditions import Condition
from neuspike.methods import create
from neuspike.methods.weights import read_card
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

PHOTOS = ("astronaut", "brick", "coffee", "rocket")
LIGHTS = (1 / 32, 1 / 8, 1 / 2)
NOISES = ("none", "high")


def _psnr(x: np.ndarray, truth: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / max(float(np.mean((x - truth) ** 2)), 1e-12)))


def _score(method, samples) -> tuple[list[float], list[float]]:
    raw, aligned = [], []
    for sample in samples:
        y, truth = method.reconstruct(sample), sample.ground_truth
        design = np.stack([y.ravel(), np.ones(y.size)], 1)
        (a, b), *_ = np.linalg.lstsq(design, truth.ravel(), rcond=None)
        raw.append(_psnr(y, truth))
        aligned.append(_psnr(np.clip(a * y + b, 0, 1), truth))
    return raw, aligned


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="*", help="weights folders (default: the shipped weights)")
    p.add_argument("--references", default="snm", help="methods scored beside them (default: snm)")
    args = p.parse_args(argv)
    folders = args.folders or [None]
    torch.set_num_threads(2)
    samples, keys = [], []
    for photo in PHOTOS:
        for kind in ("pan", "still"):
            scene = grids.scene_entry(f"{kind}:{photo}", (400, 250))
            for light in LIGHTS:
                for noise in NOISES:
                    cond = Condition(light=light, motion=128, noise=noise, effects=grids.DEFAULT_EFFECTS)
                    keys.append((light, noise))
                    samples.append(simulate_sample(scene.spec, cond, sensor=SensorConfig(), seed=0,
                                                   modalities=("spikes", "events")))
    groups = {key: [i for i, k in enumerate(keys) if k == key] for key in dict.fromkeys(keys)}
    best_ref = {key: -np.inf for key in groups}
    for name in filter(None, args.references.split(",")):
        raw, _ = _score(create(name), samples)
        print(f"{name}: PSNR {np.mean(raw):.2f}")
        for key, pick in groups.items():
            best_ref[key] = max(best_ref[key], float(np.mean([raw[i] for i in pick])))
    for folder in folders:
        head = {}  # the head the weights were trained with (their card), so any candidate loads
        card = read_card(f"{folder}/neuspike-net.safetensors") if folder else None
        if card and "head" in card.get("model", {}).get("params", {}):
            head = {"head": card["model"]["params"]["head"]}
        method = create("neuspike-net", weights_dir=folder, precision="float32", **head)
        raw, aligned = _score(method, samples)
        print(f"{folder or 'shipped'}: {len(samples)} windows, PSNR {np.mean(raw):.2f}, "
              f"affine-aligned {np.mean(aligned):.2f}")
        for key, pick in groups.items():  # each light and noise level: raw / aligned, margin to the references
            r = float(np.mean([raw[i] for i in pick]))
            margin = f", {r - best_ref[key]:+.2f} dB over the best reference" if np.isfinite(best_ref[key]) else ""
            print(f"    L = 1/{round(1 / key[0])}, noise {key[1]}: {r:.2f} / "
                  f"{np.mean([aligned[i] for i in pick]):.2f}{margin}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
