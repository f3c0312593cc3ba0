"""``python -m neuspike.train NAME``: train a registered learned method on simulated data.

The method says what it trains on: a recurrent method (``e2vid``, ``firenet-sim``) on sequences of
event windows, a feed-forward one (``neuspike-net``) on single windows. A few flags are parsed into
one frozen :class:`~neuspike.train.spec.TrainSpec` (saved as ``spec.json`` in the run folder) and
:func:`~neuspike.train.loop.train` runs it; the same command again resumes from the run folder's
checkpoint (on the same or another ``--device``). Nothing heavy (torch) is imported before the
arguments are parsed; the device is resolved when the trainer starts, before anything is simulated
or written.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any, Sequence

from neuspike.methods.precision import PRECISIONS

#: Flags that apply to one data kind only (a flag given for the other kind is refused).
WINDOW_ONLY = ("val_windows", "spike_only_fraction", "speed_range", "val_view", "scale_range", "crop_trim",
               "train_parts")
SEQUENCE_ONLY = ("size", "view", "length", "kinds", "hdr_fraction", "view_fraction")
#: Flags that make a spec (refused beside --spec, which runs its file as written).
SPEC_FLAGS = ("shard", "steps", "batch", "crop", "lr", "lr_min", "warmup", "val_every", "seed", "threads", "precision",
              "init_from", "windows", "train_items", "val_items", "val_windows", "noise_levels", "speed_range",
              "scale_range", "spike_only_fraction", "workers", "val_view", "crop_trim", "train_parts", "size", "view", "length", "kinds",
              "hdr_fraction", "view_fraction", "export_dir")
#: Of those, the ones that apply beside --spec: where the run writes and on what it runs, not what it trains.
SPEC_OVERRIDES = ("shard", "workers", "threads", "export_dir")

#: Defaults of each data kind where they differ from :class:`TrainSpec`'s, and per method.
KIND_DEFAULTS: dict[str, dict[str, Any]] = {
    "windows": {},
    "sequences": {"optimizer": "adam", "weight_decay": 0.0, "lr": 2e-4, "lr_min": None, "warmup": 50, "steps": 2000,
                  "batch": 4, "crop": 96, "val_every": 100, "checkpoint_every": 25, "threads": None},
}
PRESETS: dict[str, dict[str, Any]] = {
    # lr per network size: FireNet's 38k parameters take a larger step than E2VID's 10.7M
    "firenet-sim": {"lr": 1e-3, "crop": 64, "batch": 4, "length": 8, "steps": 3000, "val_every": 50,
                    "checkpoint_every": 25, "precision": "float32", "val_items": 8},
    "e2vid": {"lr": 5e-4, "crop": 48, "batch": 4, "length": 6, "steps": 4000, "val_every": 50,
              "checkpoint_every": 10, "val_items": 8},
}
QUICK = {"steps": 20, "val_every": 10, "checkpoint_every": 10, "batch": 2, "train_items": 8, "val_items": 2}
QUICK_KIND = {"windows": {"crop": 32, "view": 32}, "sequences": {"crop": 32, "size": 48, "windows": 4, "length": 4}}

DESCRIPTION = """\
Train a registered learned method on data simulated from the training photographs (the test
photographs are refused) and procedural scenes. What a training item is follows from the method:
a recurrent method (e2vid, firenet-sim) trains on sequences of event windows of one moving scene,
with exact-flow temporal loss; a feed-forward one (neuspike-net) on single windows of spikes and
events. The data are simulated once into a shard and reused; the run folder (--out) holds
spec.json, checkpoint.pt, train_log.csv and the best-by-validation weights with their JSON card.
Running the same command again resumes from the checkpoint (a different spec is refused).

The loss of single windows is a sum of registered terms, each with its parameters (the data section's
"losses"; by default l1 and ssim): offset, support, edge_ssim, gate_target, distill and spike_floor
are set with --set data.losses.TERM=WEIGHT or --set 'data.losses.TERM={...}' (neuspike/train/terms.py
lists each term's parameters). The data's draw takes registered data terms likewise (the data
section's "mixture"; by default none): for single windows sweep (a share of the windows at the
sweeps' points, optionally with the sweeps' own scenes), broad (a share of broad-leaves pictures),
smooth (a share of photographs blurred outside a sharp ellipse) and fast_pans (a share of pans at 2-16x the sweeps' speed),
for sequences partial_first (a share of runs whose first window is cut short), set with
--set data.mixture.TERM=FRACTION or --set 'data.mixture.TERM={...}' (neuspike/train/mixture.py)."""

EPILOG = """\
examples (the spec behind each shipped network is in its JSON card; its model card says how to run it):
  python -m neuspike.train neuspike-net --steps 1600 --batch 8 --crop 64 --windows 2000 \\
      --val-windows 32 --val-every 200 --lr 1e-3 --warmup 100 --threads 1 --export
  python -m neuspike.train neuspike-net --spec spec.json --out runs/nsn-again   # a spec file, as written
  python -m neuspike.train neuspike-net --set data.losses.offset=0.5 \\
      --set 'data.losses.distill={"weight": 1, "teacher": "neuspike/trained/neuspike-net.safetensors"}'
  python -m neuspike.train neuspike-net --set 'data.mixture.sweep={"fraction": 0.5, "grid": "light-noise"}'
  python -m neuspike.train firenet-sim --train-items 166 --threads 1 --max-minutes 25
  python -m neuspike.train e2vid --device cuda            # on a GPU (--device cpu resumes it on a CPU)
  python -m neuspike.train e2vid --quick                  # a one-minute smoke run (its weights stay in runs/)"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m neuspike.train", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("method", help="registered learned method (neuspike-net, e2vid, firenet-sim, ...)")
    p.add_argument("--spec", help="run this spec.json (a run folder's, a campaign's, or one written out of a card) as "
                                  "written: beside it only --set, --out, --device, --threads, --shard, --workers, "
                                  "--export, --no-export, --export-dir and the run options apply; a flag that would "
                                  "change what it trains is refused (change a field with --set instead)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="settings",
                   help="set a field of the spec (of --spec's file, or of the one the flags make), checked as a spec "
                        "file is; KEY dotted into a section, VALUE JSON or text, repeatable: --set lr=1e-4 "
                        "--set data.speed_range=[2000,24000] --set params.width=0.45")
    p.add_argument("--out", "--run-dir", dest="out", help="run folder (default runs/METHOD)")
    p.add_argument("--shard", "--shards", dest="shard",
                   help="folder of the simulated data (default runs/shard for windows, runs/shards for sequences)")
    g = p.add_argument_group("optimisation")
    g.add_argument("--steps", type=int, help="optimiser steps")
    g.add_argument("--batch", type=int, help="items per step")
    g.add_argument("--crop", type=int, help="side of the square training crops (pixels)")
    g.add_argument("--lr", type=float, help="peak learning rate")
    g.add_argument("--lr-min", type=float,
                   help="decay the rate along a cosine to this value at --steps (windows default 1e-5; sequences "
                        "default: constant rate)")
    g.add_argument("--warmup", type=int, help="learning-rate warm-up steps (windows 200, sequences 50)")
    g.add_argument("--val-every", type=int, help="validate (and export a new best) every N steps")
    g.add_argument("--seed", type=int, help="seed of data, order and initial weights (default 0)")
    g.add_argument("--threads", type=int, help="torch threads (windows default 1; 1 when another job shares the CPU)")
    g.add_argument("--device", help="torch device to train on: cpu (default), or cuda, cuda:1, ... where torch sees "
                                    "a GPU (a device this machine lacks is refused before anything is simulated or "
                                    "written). The data and their random draws stay on the CPU, so a seed gives the "
                                    "same data on any device; a run may resume on another device")
    g.add_argument("--precision", choices=PRECISIONS,
                   help="autocast precision (default auto: float32 unless the device computes bfloat16 natively and "
                        "a timed training step is at least 10%% faster in it; the choice is kept in the run "
                        "folder's precision.json; firenet-sim float32)")
    g.add_argument("--param", action="append", default=[], metavar="KEY=JSON",
                   help="override a parameter of the method's registry entry (e.g. fusion='\"attention\"')")
    g.add_argument("--init-from", metavar="FILE.safetensors",
                   help="start from these weights instead of fresh ones (copy shipped weights elsewhere first: "
                        "an export overwrites them); a checkpoint in the run folder still wins")
    d = p.add_argument_group("data")
    d.add_argument("--windows", type=int,
                   help="single windows: training windows simulated (default 4000); sequences: event windows per "
                        "sequence (default 8)")
    d.add_argument("--train-items", type=int, help="training windows or sequences simulated")
    d.add_argument("--val-items", type=int, help="validation windows or sequences simulated")
    d.add_argument("--val-windows", type=int, help="single windows: validation windows (= --val-items)")
    d.add_argument("--noise-levels", metavar="N1,N2,...",
                   help="noise levels drawn (default none,small,medium,high); a level listed twice is drawn twice "
                        "as often (sequences)")
    d.add_argument("--speed-range", metavar="LOW,HIGH",
                   help="single windows: pan speeds drawn log-uniformly (px/s at a view 400 pixels wide; default "
                        "100,4000; the sweeps pan at 1000)")
    d.add_argument("--scale-range", metavar="LOW,HIGH",
                   help="single windows: scale of a photograph's region relative to the sweeps' frame, drawn "
                        "log-uniformly; speeds then scale with it (default: the original 0.3-1.2 draw with the "
                        "sensor shrunk to the view)")
    d.add_argument("--spike-only-fraction", type=float,
                   help="single windows: fraction of steps training the spike-only variant of a fusion network "
                        "(default 0.3)")
    d.add_argument("--workers", type=int,
                   help="processes simulating the shard (default: 2 for single windows, 1 for sequences); the same "
                        "data whatever the count")
    d.add_argument("--val-view", metavar="WxH",
                   help="single windows: validate on windows of this size (e.g. 400x250, the sweeps' frame) "
                        "instead of the square training view, so the best step is chosen on whole frames")
    d.add_argument("--crop-trim", type=int, metavar="N",
                   help="single windows: cut 0..N rows and 0..N columns (drawn per step) off each batch's crops, so "
                        "the network trains on sides that it pads as at inference (0..7; default 0)")
    d.add_argument("--train-parts", choices=("all", "motion"),
                   help="single windows, fusion networks with --init-from: 'motion' trains the motion path only and "
                        "holds the rest (so the spike-only variant stays as given; default all)")
    d.add_argument("--size", type=int, help="sequences: simulated item size (pixels, square; default 128)")
    d.add_argument("--view", metavar="WxH",
                   help="sequences: fit the photographs to a WxH view and cut each item from it (e.g. 400x250, "
                        "the sweeps' scale); default: the photograph fitted to the item itself")
    d.add_argument("--length", type=int, help="sequences: windows per training sequence (<= --windows)")
    d.add_argument("--kinds", metavar="K1,K2,...",
                   help="sequences: scene kinds drawn, from pan,zoom,fan,dead_leaves,broad_leaves (default pan,zoom,fan; "
                        "broad_leaves: dead leaves with tens of large leaves and wide uniform regions)")
    d.add_argument("--view-fraction", type=float, metavar="F",
                   help="sequences, with --view: share of items cut from the view, the rest fitted whole (default 1)")
    d.add_argument("--hdr-fraction", type=float, metavar="F",
                   help="sequences: share of items with high-dynamic-range radiance (default 0.5)")
    o = p.add_argument_group("output and run")
    o.add_argument("--export", action="store_true",
                   help="also write the best weights into neuspike/trained/, replacing the shipped ones (never by "
                   "default, never with --quick)")
    o.add_argument("--no-export", action="store_true",
                   help="write the best weights into the run folder only (the default)")
    o.add_argument("--export-dir", help="also write the best weights into this folder (not into neuspike/trained/)")
    o.add_argument("--snapshot-every", type=int, metavar="N",
                   help="also keep every N-th step's weights under RUN/snapshots/")
    o.add_argument("--max-minutes", type=float, help="stop after this many minutes, checkpointed (resume later)")
    o.add_argument("--simulate-only", action="store_true", help="build the simulated data and stop")
    o.add_argument("--quick", action="store_true", help="a tiny run that finishes in a minute (smoke test)")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _list(text: str) -> tuple[str, ...]:
    return tuple(v.strip() for v in text.split(",") if v.strip())


def _numbers(text: str, flag: str, form: str, count: int) -> tuple[float, ...]:
    """``"A,B,..."`` -> ``count`` floats; a clear error naming ``flag`` and the expected ``form`` otherwise."""
    from neuspike.errors import InputError

    try:
        values = tuple(float(v) for v in _list(text))
    except ValueError:
        values = ()
    if len(values) != count:
        raise InputError(f"{flag}: expected {form}, got {text!r}")
    return values


def _pair(text: str, flag: str, unit: str) -> tuple[float, float]:
    """``"LOW,HIGH"`` -> (low, high); a clear error naming ``flag`` otherwise."""
    return _numbers(text, flag, f"LOW,HIGH{unit}", 2)


def spec_from_args(args: argparse.Namespace):
    """The :class:`~neuspike.train.spec.TrainSpec` of parsed arguments (imports the registry): ``--spec``'s
    file or the flags' spec, then each ``--set``."""
    from neuspike.errors import InputError
    from neuspike.train.spec import apply_settings

    spec = _spec_of_flags(args)
    if args.settings:
        spec = apply_settings(spec, args.settings)
        if spec.method != args.method:
            raise InputError(f"--set method: the command trains {args.method!r}")
    return spec


def _spec_of_flags(args: argparse.Namespace):
    """The spec of ``--spec`` or of the flags, before ``--set``."""
    from dataclasses import replace

    from neuspike.errors import InputError
    from neuspike.methods import entry
    from neuspike.train.spec import SequenceData, TrainSpec, WindowData, load_spec, with_out_dir

    if args.spec:
        given = [n for n in SPEC_FLAGS if n not in SPEC_OVERRIDES and getattr(args, n) is not None]
        given += [n for n in ("param", "quick") if getattr(args, n)]
        if given:
            flags = ", ".join("--" + n.replace("_", "-") for n in given)
            raise InputError(f"--spec runs {args.spec} as written; {flags} would change what it trains: edit the file "
                             f"or give --set KEY=VALUE (beside a spec file only --set, --out, --device, --threads, "
                             f"--shard, --workers, --export, --no-export, --export-dir and the run options apply)")
        if args.export and args.no_export:
            raise InputError("--export and --no-export: choose one")
        spec = load_spec(args.spec, out_dir=args.out or f"runs/{args.method}")
        if spec.method != args.method:
            raise InputError(f"--spec {args.spec} trains {spec.method!r}, not {args.method!r}")
        top = {k: getattr(args, k) for k in ("device", "threads", "export_dir") if getattr(args, k) is not None}
        top["export"] = bool(args.export)  # the package's weights change only on --export, whatever the file says
        data = {}
        if args.shard is not None:
            data["shard_dir" if spec.kind == "windows" else "shard_root"] = args.shard
        if args.workers is not None:
            data["workers"] = args.workers
        spec = replace(spec, **top, **({"data": replace(spec.data, **data)} if data else {}))
        return with_out_dir(spec, args.out) if args.out else spec
    e = entry(args.method)
    kind = "sequences" if getattr(e.factory, "recurrent", False) else "windows"
    wrong = SEQUENCE_ONLY if kind == "windows" else WINDOW_ONLY
    given = [n for n in wrong if getattr(args, n) is not None]
    if given:
        raise InputError(f"{', '.join('--' + n.replace('_', '-') for n in given)}: not for {args.method!r}, "
                         f"which trains on {kind}")
    if args.export and args.no_export:
        raise InputError("--export and --no-export: choose one")
    if args.export and args.quick:
        raise InputError("--quick trains a smoke-test network, which never replaces the shipped weights: drop "
                         "--export (or --export-dir FOLDER to keep its weights elsewhere)")
    kw: dict[str, Any] = {**KIND_DEFAULTS[kind], **PRESETS.get(args.method, {})}
    if args.quick:
        kw.update(QUICK, **QUICK_KIND[kind])
    data_fields = WindowData.__dataclass_fields__ if kind == "windows" else SequenceData.__dataclass_fields__
    top = {"steps", "batch", "crop", "lr", "lr_min", "warmup", "val_every", "threads", "device", "precision",
           "init_from"}
    for name in top:
        if getattr(args, name) is not None:
            kw[name] = getattr(args, name)
    for name in ("train_items", "val_items", "spike_only_fraction", "workers", "size", "length", "hdr_fraction",
                 "view_fraction", "crop_trim", "train_parts"):
        if getattr(args, name) is not None:
            kw[name] = getattr(args, name)
    if args.val_windows is not None:
        kw["val_items"] = args.val_windows
    if args.windows is not None:
        kw["train_items" if kind == "windows" else "windows"] = args.windows
    for name, unit in (("speed_range", " in px/s"), ("scale_range", "")):
        if getattr(args, name) is not None:
            kw[name] = _pair(getattr(args, name), f"--{name.replace('_', '-')}", unit)
    for name in ("view", "val_view"):
        if getattr(args, name) is not None:
            from neuspike.utils.checks import parse_size

            kw[name] = parse_size(getattr(args, name))
    for name in ("kinds", "noise_levels"):
        if getattr(args, name) is not None:
            kw[name] = _list(getattr(args, name))
    if args.shard is not None:
        kw["shard_dir" if kind == "windows" else "shard_root"] = args.shard
    params = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--param: expected KEY=JSON, got {item!r}")
        try:
            params[key] = json.loads(value)
        except ValueError:
            params[key] = value
    if args.export:
        kw["export"] = True
    if args.no_export or args.export_dir is not None:
        kw["export"] = False
    data = (WindowData if kind == "windows" else SequenceData)(**{k: kw.pop(k) for k in list(kw) if k in data_fields})
    out = args.out or f"runs/{args.method}" + ("-quick" if args.quick and kind == "sequences" else "")
    seed = 0 if args.seed is None else args.seed
    return TrainSpec(method=args.method, data=data, out_dir=out, seed=seed, params=params, export_dir=args.export_dir,
                     **kw)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from neuspike.errors import NeuSpikeError

    try:
        spec = spec_from_args(args)
        from neuspike.train.loop import train

        result = train(spec, quiet=args.quiet, max_minutes=args.max_minutes, snapshot_every=args.snapshot_every,
                       simulate_only=args.simulate_only)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a full disk, a file size limit, a folder that cannot be written
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
