"""The fusion's gate gains by noise level, and how well the gates' inputs tell the levels apart (no training).

    python reports/neuspike-net/gate_probe.py [--weights FOLDER ...] [--shard runs/shard-stage17] [--split val]
    python reports/neuspike-net/gate_probe.py --separability [--shard runs/shard-stage38] --split train --windows 900

Gains: for each window of a training shard's split (training photographs and dead leaves; never the
test photographs; the first ``--windows`` of them, default all) the fusion network's per-image gains
``g = 2 sigmoid(mlp(s))`` (x_m^3, x_m^2, x_m^1, x_m^0; 1 at construction, 0 shuts the motion path at
that level) are computed from the window's representations (full size, float32): the motion gate's,
and where the network has one (``motion_gate "stats-noise"``) the noise gate's and their product, the
gain the motion features get. Their mean and range are printed per noise level of the window. A gate
that has learned to turn noise-dominated events down gives lower gains at higher noise.

``--separability``: how well each set of gate statistics tells the noise levels apart. The statistics
of the windows (the motion gate's 128 image means, the noise gate's 20 quantiles, and both) fit a
32-unit MLP (Adam 1e-2, 500 full-batch steps, seed 0, inputs standardised on the fit part) on the
first ``--fit`` windows to tell "high" from the rest and "medium or high" from the rest; the accuracy
on the remaining windows and the share called positive at each level are printed.
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

import numpy as np
import torch

NOISE = ("none", "small", "medium", "high")


def gains(weights: list[str | None], samples: list) -> None:
    from neuspike.methods import create

    from fullsize_check import trained_design  # beside this script: Python puts its folder on the path

    for folder in weights:
        method = create("neuspike-net", weights_dir=folder, precision="float32",
                        **trained_design(folder, "neuspike-net"))
        net = method.module.eval()
        if not hasattr(net, "motion_gate"):
            raise SystemExit(f"{folder or 'shipped'}: these weights have no motion gate")
        rows = collections.defaultdict(list)
        for sample in samples:
            spikes, events = method.encode(sample)[0][:2]
            with torch.no_grad():
                spikes = net._split(spikes)[0]
                g = net.motion_gate(spikes, events)[0]
                n = net.noise_gate(spikes, events)[0] if hasattr(net, "noise_gate") else None
            rows[sample.meta["cell"]["noise"]].append((g.numpy(), None if n is None else n.numpy()))
        print(f"{folder or 'shipped'}: gains (x_m^3, x_m^2, x_m^1, x_m^0), {len(samples)} windows")
        for level in NOISE:
            if level not in rows:
                continue
            g = np.array([r[0] for r in rows[level]])
            parts = [("motion gate", g)]
            if rows[level][0][1] is not None:
                n = np.array([r[1] for r in rows[level]])
                parts += [("noise gate", n), ("product", g * n)]
            for name, a in parts:
                print(f"    {level:6s} ({len(a):3d}) {name:11s}: mean {np.round(a.mean(0), 3)}, "
                      f"min {np.round(a.min(0), 3)}, max {np.round(a.max(0), 3)}")


def separability(samples: list, fit: int) -> None:
    from neuspike.methods import create
    from neuspike.nets.network import NoiseGate

    if not 0 < fit < len(samples):
        raise SystemExit(f"--fit {fit}: needs 0 < fit < the windows read ({len(samples)})")
    method = create("neuspike-net", precision="float32")
    net = method.module
    feats, levels = [], []
    with torch.no_grad():
        for sample in samples:
            spikes, events = method.encode(sample)[0][:2]
            feats.append(NoiseGate.statistics(net._split(spikes)[0], events)[0])
            levels.append(sample.meta["cell"]["noise"])
    full = torch.stack(feats)
    y = torch.tensor([NOISE.index(v) for v in levels])
    base = 4 * net.in_channels
    print(f"{len(samples)} windows ({', '.join(f'{n} {int((y == i).sum())}' for i, n in enumerate(NOISE))}); "
          f"fit on the first {fit}, scored on the other {len(samples) - fit}")
    for name, cols in (("motion gate means", slice(0, base)), ("noise gate quantiles", slice(base, None)),
                       ("both", slice(None))):
        x = full[:, cols]
        x = (x - x[:fit].mean(0)) / (x[:fit].std(0) + 1e-6)
        for task, target in (("high vs rest", (y == 3).float()), ("medium+ vs rest", (y >= 2).float())):
            torch.manual_seed(0)
            mlp = torch.nn.Sequential(torch.nn.Linear(x.shape[1], 32), torch.nn.ReLU(), torch.nn.Linear(32, 1))
            opt = torch.optim.Adam(mlp.parameters(), 1e-2)
            for _ in range(500):
                opt.zero_grad()
                torch.nn.functional.binary_cross_entropy_with_logits(mlp(x[:fit])[:, 0], target[:fit]).backward()
                opt.step()
            with torch.no_grad():
                called = (mlp(x[fit:])[:, 0] > 0).float()
            accuracy = float((called == target[fit:]).float().mean())
            shares = ", ".join(f"{n} {float(called[y[fit:] == i].mean()):.3f}" for i, n in enumerate(NOISE)
                               if bool((y[fit:] == i).any()))
            print(f"    {name:20s} {task:15s}: accuracy {accuracy:.3f}; called positive: {shares}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", action="append",
                    help="folder holding neuspike-net.safetensors and its card (repeatable; default: the shipped weights)")
    ap.add_argument("--shard", default="runs/shard-stage17", help="a training shard (default runs/shard-stage17)")
    ap.add_argument("--split", choices=("val", "train"), default="val", help="the shard's windows read (default val)")
    ap.add_argument("--windows", type=int, help="read only the first N windows of the split (default all)")
    ap.add_argument("--separability", action="store_true", help="score the gate statistics as noise classifiers")
    ap.add_argument("--fit", type=int, default=600, help="with --separability: windows the classifier fits on")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    from neuspike.train.windows import load_sample

    torch.set_num_threads(args.threads)
    paths = sorted(Path(args.shard, args.split).glob("*.npz"))[:args.windows]
    if not paths:
        raise SystemExit(f"{args.shard}/{args.split}: no windows (build the shard with the stage's spec first)")
    samples = [load_sample(p) for p in paths]
    if args.separability:
        separability(samples, args.fit)
    else:
        gains(args.weights or [None], samples)


if __name__ == "__main__":
    main()
