"""The motion gate's gains by noise level, on a training shard's validation windows (no training).

    python reports/neuspike-net/gate_probe.py [--weights FOLDER] [--shard runs/shard-stage17]

For each validation window (training photographs and dead leaves; never the test photographs) the
fusion network's four motion-gate gains ``g = 2 sigmoid(mlp(s))`` (x_m^3, x_m^2, x_m^1, x_m^0; 1 at
construction, 0 shuts the motion path at that level) are computed from the window's representations,
and their mean and range are printed per noise level of the window. A gate that has learned to turn
noise-dominated events down gives lower gains at higher noise.
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights",
                    help="folder holding neuspike-net.safetensors and its card (default: the shipped weights)")
    ap.add_argument("--shard", default="runs/shard-stage17", help="a training shard (its val/ windows are read)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    from neuspike.methods import create
    from neuspike.train.windows import load_sample

    torch.set_num_threads(args.threads)
    method = create("neuspike-net", weights_dir=args.weights, precision="float32")
    net = method.module.eval()
    if not hasattr(net, "motion_gate"):
        raise SystemExit("these weights have no motion gate")
    paths = sorted(Path(args.shard, "val").glob("*.npz"))
    if not paths:
        raise SystemExit(f"{args.shard}/val: no windows (build the shard with the stage's spec first)")
    gains = collections.defaultdict(list)
    for path in paths:
        sample = load_sample(path)
        spikes, events = method.encode(sample)[0][:2]
        with torch.no_grad():
            g = net.motion_gate(net._split(spikes)[0], events)[0].numpy()
        gains[sample.meta["cell"]["noise"]].append(g)
    print(f"{args.weights or 'shipped'}: motion-gate gains (x_m^3, x_m^2, x_m^1, x_m^0), {len(paths)} windows")
    for level in ("none", "small", "medium", "high"):
        if level in gains:
            g = np.array(gains[level])
            print(f"    {level:6s} ({len(g):2d}): mean {np.round(g.mean(0), 3)}, min {np.round(g.min(0), 3)}, "
                  f"max {np.round(g.max(0), 3)}")


if __name__ == "__main__":
    main()
