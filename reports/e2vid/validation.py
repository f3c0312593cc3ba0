"""The event networks on the held-out validation sequences of the training data (run from the repository root).

python reports/e2vid/validation.py [--weights ../shared/weights] [--items 16] [--view 400x250]

Every method that reads normalised 5-bin voxel grids in 0.35 events/pixel windows (``e2vid``,
``firenet-sim`` and, given its weights folder, the published ``firenet``) runs through the same
validation sequences the trainer scores (training photographs and procedural motion only; no test
photograph), with the trainer's own score: mean SSIM over the steps after the 2-window warm-up.
The shard is the trainer's (``runs/shards``), simulated first when it is missing: the photographs
fitted to the 128x128 items, or with ``--view`` items cut from larger views (the sweeps' scale).
Writes ``validation.csv`` here (``validation_view.csv`` with ``--view``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd
import torch

here = Path(__file__).resolve().parent
sys.path.insert(0, str(here.parents[1]))

from neuspike.utils.checks import parse_size  # noqa: E402
from neuspike.methods import create  # noqa: E402
from neuspike.train.loop import training_method  # noqa: E402
from neuspike.train.sequences import build_shard, load_shard, validate_sequences  # noqa: E402
from neuspike.train.spec import SequenceData, TrainSpec  # noqa: E402

METHODS = ("e2vid", "firenet-sim", "firenet")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--weights", default=None, help="folder of published weights (for firenet)")
    p.add_argument("--items", type=int, default=16, help="validation sequences (the first N of the shard)")
    p.add_argument("--shards", type=Path, default=Path("runs/shards"))
    p.add_argument("--view", default=None, metavar="WxH", help="items cut from views of this size")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    view = None if args.view is None else parse_size(args.view)
    data = SequenceData(view=view, length=8, val_items=args.items)
    spec = TrainSpec(method="e2vid", data=data, crop=48)
    paths = build_shard(training_method(spec), data, seed=spec.seed, split="val", count=args.items,
                        folder=args.shards / data.key())
    shard = load_shard(paths)
    rows = []
    for name in METHODS:
        if name == "firenet" and args.weights is None:
            print("firenet: skipped (no --weights folder)", file=sys.stderr)
            continue
        method = create(name, weights_dir=args.weights)
        module = method.module.float()
        scores = validate_sequences(module, shard, data, precision="float32")
        rows.append({"method": name, "sequences": len(paths), "view": args.view or "128x128", **scores,
                     "weights": str(method.weights_path.name)})
        print(f"{name}: val SSIM {scores['val_ssim']:.4f} (last step {scores['val_ssim_last']:.4f}), "
              f"L1 {scores['val_l1']:.4f}", file=sys.stderr)
    name = "validation.csv" if view is None else "validation_view.csv"
    pd.DataFrame(rows).to_csv(here / name, index=False, float_format="%.4f")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
