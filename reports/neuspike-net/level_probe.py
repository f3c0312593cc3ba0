"""Which level of the motion path costs the fusion its SSIM at the sweeps' high noise (a probe, training photographs).

    python reports/neuspike-net/level_probe.py [FOLDER] [--noise high] [--threads 1] [--heldout]

Simulates the full sweeps' noise point (L = 1/4, S = 128, the given noise level) on the four training
photographs of ``fullsize_check.py`` through all four scene kinds (16 windows, seed 0: the grid's own
cells), and scores the fusion (float32, the method's counted mean level) with its motion gate's four
gains as trained and with one level's gain scaled by 0 or 0.5 at a time (x_m^3 .. x_m^0; 0 everywhere
is the spike-only network inside the fusion; every level x 0.75 and x 0.5 too), beside the folder's spike-only
file. Prints mean PSNR / SSIM per setting and the SSIM by scene kind, then the fusion's margin over the file
by picture, so a reader sees where the events cost structure.
``--heldout`` uses the seven held-out pictures of ``fullsize_check.py --grid heldout`` (28 windows) in place
of the training photographs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from bench import grid as grids
from neuspike.conditions import Condition
from neuspike.methods import create
from neuspike.metrics import ssim
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

from fullsize_check import PHOTOS, heldout_pictures, trained_design  # noqa: E402  (beside this script: Python puts its folder on the path)

KINDS = ("pan", "zoom", "fan", "still")
LEVELS = ("x_m^3", "x_m^2", "x_m^1", "x_m^0")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", nargs="?", help="weights folder (default: the shipped weights)")
    p.add_argument("--noise", default="high", help="the noise level (default high)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    p.add_argument("--heldout", action="store_true",
                   help="the held-out pictures of fullsize_check.py --grid heldout in place of the training "
                        "photographs")
    p.add_argument("--pictures", type=Path, default=Path("runs/heldout-pictures"),
                   help="with --heldout: their folder (written there if missing; default runs/heldout-pictures)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    pictures = [str(path) for path in heldout_pictures(args.pictures)] if args.heldout else list(PHOTOS)
    cells = [(kind, photo) for kind in KINDS for photo in pictures]
    cond = Condition(light=1 / 4, motion=128, noise=args.noise, effects=grids.DEFAULT_EFFECTS)
    samples = [simulate_sample(grids.scene_entry(f"{kind}:{photo}", (400, 250)).spec, cond, sensor=SensorConfig(),
                               seed=0, modalities=("spikes", "events")) for kind, photo in cells]
    fusion = create("neuspike-net", weights_dir=args.folder, precision="float32",
                    **trained_design(args.folder, "neuspike-net"))
    spike = create("neuspike-net-spike", weights_dir=args.folder, precision="float32",
                   **trained_design(args.folder, "neuspike-net-spike"))

    def score(method) -> tuple[np.ndarray, np.ndarray]:
        psnr, structure = [], []
        for sample in samples:
            y, truth = method.reconstruct(sample), sample.ground_truth
            psnr.append(10 * np.log10(1.0 / max(float(np.mean((y - truth) ** 2)), 1e-12)))
            structure.append(ssim(y, truth, data_range=1.0))
        return np.array(psnr), np.array(structure)

    def line(label: str, psnr: np.ndarray, structure: np.ndarray) -> None:
        n = len(pictures)
        kinds = " / ".join(f"{structure[i * n:(i + 1) * n].mean():.4f}" for i in range(len(KINDS)))
        print(f"{label:34s} {psnr.mean():6.2f} / {structure.mean():.4f}   SSIM {' / '.join(KINDS)}: {kinds}")

    source = "held-out pictures" if args.heldout else "training photographs"
    print(f"noise {args.noise}, L = 1/4, S = 128, {len(samples)} windows of {source}")
    spike_scores = score(spike)
    line("spike-only file", *spike_scores)
    gate = fusion.module.motion_gate
    trained = gate.forward
    settings = [("as trained", np.ones(4))]
    for level in range(4):
        for factor in (0.0, 0.5):
            scale = np.ones(4)
            scale[level] = factor
            settings.append((f"{LEVELS[level]} x {factor:g}", scale))
    settings += [("every level x " + f"{c:g}", np.full(4, c)) for c in (0.75, 0.5, 0.0)]
    as_trained = None
    try:
        for label, scale in settings:
            factors = torch.tensor(scale, dtype=torch.float32)
            gate.forward = lambda s, e, *rest, f=factors: trained(s, e, *rest) * f
            scores = score(fusion)
            as_trained = scores if as_trained is None else as_trained
            line(f"fusion, {label}", *scores)
    finally:
        gate.forward = trained
    print("fusion as trained - spike-only file, by picture (PSNR / SSIM over its four kinds):")
    for j, picture in enumerate(pictures):
        pick = [i * len(pictures) + j for i in range(len(KINDS))]
        d_psnr, d_ssim = (float(np.mean(a[pick] - b[pick])) for a, b in zip(as_trained, spike_scores))
        print(f"    {Path(picture).stem}: {d_psnr:+.2f} dB / {d_ssim:+.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
