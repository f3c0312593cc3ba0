"""``python -m neuspike.train NAME``: train a registered learned method on simulated data.

A few flags are parsed into a frozen :class:`~neuspike.train.spec.TrainSpec` (saved as
``spec.json`` in the run folder) and :func:`~neuspike.train.loop.train` runs it. Running the same
command again resumes from the run folder's last checkpoint.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields

from neuspike.errors import NeuSpikeError
from neuspike.train.spec import TrainSpec, load_spec

_DEFAULTS = TrainSpec()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m neuspike.train",
        description="Train a registered learned method (e.g. neuspike-net) on windows simulated from the "
                    "training photographs and dead-leaves scenes. Resumes from OUT/checkpoint.pt when it exists.",
        epilog="The shipped NeuSpike-Net weights: python -m neuspike.train neuspike-net --export "
               "(about 75-90 minutes on two CPU cores).")
    p.add_argument("method", help="registered method name (e.g. neuspike-net)")
    p.add_argument("--spec", help="a spec.json to run (other flags then ignored, except --out)")
    p.add_argument("--out", help=f"run folder (default runs/METHOD)")
    p.add_argument("--shard", default=_DEFAULTS.shard_dir, help="folder of the simulated windows (default %(default)s)")
    p.add_argument("--steps", type=int, default=_DEFAULTS.steps, help="optimiser steps (default %(default)s)")
    p.add_argument("--batch", type=int, default=_DEFAULTS.batch, help="samples per step (default %(default)s)")
    p.add_argument("--crop", type=int, default=_DEFAULTS.crop, help="training crop side (default %(default)s)")
    p.add_argument("--windows", type=int, default=_DEFAULTS.shard_size,
                   help="training windows simulated once and reused (default %(default)s)")
    p.add_argument("--val-windows", type=int, default=_DEFAULTS.val_size, help="validation windows (default %(default)s)")
    p.add_argument("--val-every", type=int, default=_DEFAULTS.val_every, help="steps between validations (default %(default)s)")
    p.add_argument("--lr", type=float, default=_DEFAULTS.lr, help="peak learning rate (default %(default)s)")
    p.add_argument("--warmup", type=int, default=_DEFAULTS.warmup, help="warm-up steps (default %(default)s)")
    p.add_argument("--spike-only-fraction", type=float, default=_DEFAULTS.spike_only_fraction,
                   help="fraction of steps training the spike-only variant inside a fusion network (default %(default)s)")
    p.add_argument("--seed", type=int, default=_DEFAULTS.seed, help="seed of data, order and weights (default %(default)s)")
    p.add_argument("--threads", type=int, default=_DEFAULTS.threads, help="torch threads (default %(default)s)")
    p.add_argument("--workers", type=int, default=_DEFAULTS.workers, help="processes simulating windows (default %(default)s)")
    p.add_argument("--precision", choices=("auto", "float32", "bfloat16"), default="auto",
                   help="autocast precision (default: bfloat16 where the CPU has it natively)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=JSON",
                   help="override a parameter of the method's registry entry (e.g. fusion='\"attention\"')")
    p.add_argument("--export", action="store_true", help="also write the best weights into neuspike/trained/")
    p.add_argument("--init-from", metavar="FILE.safetensors",
                   help="start from these weights (the full module, e.g. an earlier run's export) instead of fresh ones")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def spec_from_args(args: argparse.Namespace) -> TrainSpec:
    if args.spec:
        spec = load_spec(args.spec)
        if args.out:
            spec = TrainSpec(**{**spec.as_dict(), "out_dir": args.out})
        return spec
    params = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep:
            raise NeuSpikeError(f"--param: expected KEY=JSON, got {item!r}")
        try:
            params[key] = json.loads(value)
        except ValueError:
            params[key] = value
    return TrainSpec(method=args.method, out_dir=args.out or f"runs/{args.method}", shard_dir=args.shard,
                     steps=args.steps, batch=args.batch, crop=args.crop, shard_size=args.windows,
                     val_size=args.val_windows, val_every=args.val_every, lr=args.lr, warmup=args.warmup,
                     spike_only_fraction=args.spike_only_fraction, seed=args.seed,
                     threads=args.threads, workers=args.workers, precision=args.precision, params=params,
                     export=args.export, init_from=args.init_from)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        spec = spec_from_args(args)
        from neuspike.train.loop import train

        result = train(spec, quiet=args.quiet)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
