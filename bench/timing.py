"""Time per frame of every method (the paper's Table 2): ``python -m bench.timing``.

For each resolution (400x250 by default, the paper's four with ``--full``: 240x180, 346x260, 400x250,
640x480) one representative recording is
simulated once: the ``camera`` photograph panning (the sweeps' pan scene, scaled to the width) at
L = 1/4, S = 128, 256 planes, both modalities, with the sweeps' default effects and
``--history-windows`` windows of event history for recurrent methods to warm up on. Every method
then reconstructs from it: ``--warmup`` untimed calls, then ``--repeats`` timed calls, each after
``reset()`` (outside the timed region). Reported: the median and the spread (min, max, quartiles)
of the timed calls, torch's thread count, and the method's learned parameter count.

Recurrent methods (FireNet, E2VID) warm up on the event history inside every call; their ms per
frame is the cost of one network step, the call's time divided by the event windows it processed
(``last_steps``), as in the paper's Table 2 (one inference per voxel grid). The whole call is
kept in ``median_ms``.

Two honest costs for methods that continue a video from their previous frame (they override
``reconstruct_next``: the recurrent ones carry their state, NeuSpike-Net slides its
representations): ``cold_ms``, one whole call (the cold start: a recurrent method's warm-up over the
event history included), and ``stream_ms``, one new frame of a running video at
:data:`bench.harness.timer.STREAM_FPS` (1,000) frames per second of sensor time, timed on consecutive frames
of the representative scene simulated as one continuous recording (``stream_steps``: network steps
per new frame). Table 2 lists both, labelled, and the accuracy-versus-time chart draws such a method
twice: filled at its cold start, hollow at its streaming cost.

A method that cannot run (e.g. FireNet without weights: ``MethodUnavailable``) or fails is a row
with its status and reason, not a crash.

Outputs in ``--out`` (default ``runs/timing``; ``runs/timing-full`` with ``--full``)
    ``timing.csv`` (one row per method and resolution), ``tables/timing.md`` and ``.csv``,
    ``config.json``, ``metadata.json``; with sweep results (``--results``): ``accuracy_vs_time.csv``
    (each method's mean PSNR and SSIM from the sweep beside its ms per frame here, at the sweep's
    resolution when it was timed, else at the timed resolution closest in pixel count) and
    ``figures/accuracy_vs_time.png``; and ``report.pdf`` (:func:`bench.reporting.build.build_report`).

``--results`` defaults to the newest (by the time ``results.csv`` was written) of ``runs/light``,
``runs/light-full``, ``runs/motion``, ``runs/motion-full``, ``runs/noise``, ``runs/noise-full``
(relative to the current folder); ``--results none`` skips the chart.

The shared timing code (:func:`time_callable`, :func:`time_method`, :func:`representative_sample`)
is also what :mod:`bench.method_speed` uses. Timings on a shared 2-core machine are noisy; the
spread columns say how much.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Iterable, Sequence

from bench.harness import grid as grids
from neuspike.errors import InputError
from neuspike.utils.cli import MethodOptions
from neuspike.simulation.recording import DEFAULT_HISTORY_WINDOWS

#: Default resolutions (width, height): the paper's Table 2.
RESOLUTIONS: tuple[tuple[int, int], ...] = grids.TABLE2_RESOLUTIONS
#: Timed and warm-up calls: quick (the default) and full.
QUICK = {"repeats": 3, "warmup": 1, "sizes": ((400, 250),)}
FULL = {"repeats": 10, "warmup": 2, "sizes": RESOLUTIONS}
#: Result folders searched (newest first) for the accuracy-versus-time chart.
DEFAULT_RESULTS = ("runs/light", "runs/light-full", "runs/motion", "runs/motion-full", "runs/noise", "runs/noise-full")


def _sizes_text(sizes: Iterable[tuple[int, int]]) -> str:
    return ", ".join(f"{w}x{h}" for w, h in sizes)


def newest_results(candidates: Sequence[str | os.PathLike] = DEFAULT_RESULTS) -> Path | None:
    """The candidate folder whose ``results.csv`` was written last, or ``None``."""
    from bench.reporting.build import results_file

    paths = [Path(c) for c in candidates if results_file(c).is_file()]
    if not paths:
        return None
    return max(paths, key=lambda p: results_file(p).stat().st_mtime_ns)


def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``"240x180,400x250"`` -> ``((240, 180), (400, 250))``."""
    from bench.harness.grid import parse_list, parse_size

    return tuple(parse_list(text, parse_size))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.timing",
        description="Time per frame of every registered method (median and "
        "spread after warm-up, torch threads recorded, learned parameter counts), beside the paper's published "
        "figures; and the accuracy-versus-time chart joined with the latest sweep results.",
        epilog="examples:\n"
        f"  python -m bench.timing                                   # quick: {QUICK['repeats']} timed calls per method at "
        f"{_sizes_text(QUICK['sizes'])}\n"
        "  python -m bench.timing --full --weights ../shared/weights/firenet\n"
        "  python -m bench.timing --methods tfp,tfi --sizes 400x250 --results runs/light\n"
        "  python -m bench.timing --plugin my_methods.py --methods mine,snm --results none\n\n"
        "--full: the paper's Table 2 resolutions (" + _sizes_text(FULL["sizes"]) + ").\n"
        "recurrent methods (FireNet): ms per frame is one network step (one event voxel grid); the whole call,\n"
        "warm-up over the event history included, is in timing.csv (median_ms). Timings on a shared machine\n"
        "are noisy: min, max and quartiles are in timing.csv.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--methods", help="comma-separated registry names (default: every registered method)")
    parser.add_argument("--sizes", help=f"comma-separated WxH (default: {_sizes_text(QUICK['sizes'])}; "
                                        f"with --full {_sizes_text(FULL['sizes'])})")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help=f"the default: {QUICK['repeats']} timed calls after "
                      f"{QUICK['warmup']} warm-up call(s), at {_sizes_text(QUICK['sizes'])}")
    mode.add_argument("--full", action="store_true", help=f"{FULL['repeats']} timed calls after {FULL['warmup']} warm-up "
                      f"calls, at the paper's four resolutions")
    parser.add_argument("--repeats", type=int, help="timed calls per method and size (overrides --quick/--full)")
    parser.add_argument("--warmup", type=int, help="untimed calls first (overrides --quick/--full)")
    parser.add_argument("--threads", type=int, help="torch intra-op threads (default: the usable CPUs that "
                        "other processes leave idle)")
    MethodOptions.add_arguments(parser, flags=("weights", "device", "precision", "compile", "plugin"))
    parser.add_argument("--history-windows", type=float, default=DEFAULT_HISTORY_WINDOWS,
                        help=f"event history for recurrent methods, in window durations (default {DEFAULT_HISTORY_WINDOWS:g}, "
                        "as the sweeps)")
    parser.add_argument("--results", help="sweep results folder for the accuracy-versus-time chart (default: the newest "
                        "of " + ", ".join(DEFAULT_RESULTS) + "); 'none' skips the chart")
    parser.add_argument("--out", help="output folder (default: runs/timing, runs/timing-full with --full)")
    parser.add_argument("--no-report", action="store_true", help="do not build report.pdf")
    return parser


def run(args: argparse.Namespace) -> Path:
    """Run a parsed ``bench.timing`` command; return the output folder."""
    import torch

    from bench.reporting import tables as tb
    from bench.harness.timer import LIGHT, MOTION, PLANES, check_count, measure, method_names
    from bench.reporting.accuracy import join_accuracy, sweep_resolution
    from neuspike.utils.parallel import set_threads

    from neuspike.utils.atomic import write_json, write_text
    from bench.harness.provenance import LoadWatch, command_line, machine, now_iso, package_versions, source_state
    from neuspike.utils.jsonio import portable_path
    from bench.reporting.build import write_timing_tables

    options = MethodOptions.from_args(args)
    weights, precision = options.weights_dir, options.precision or "auto"
    if args.threads is not None:
        set_threads(check_count("--threads", args.threads, 1))
    else:  # the CPUs other processes leave idle: oversubscribed threads wait on each other
        from neuspike.utils.resources import announce_default_threads

        set_threads(announce_default_threads())
    preset = FULL if args.full else QUICK
    repeats = args.repeats if args.repeats is not None else preset["repeats"]
    warmup = args.warmup if args.warmup is not None else preset["warmup"]
    sizes = parse_sizes(args.sizes) if args.sizes else preset["sizes"]
    if options.compiled and warmup < 1:
        raise InputError("--compile needs at least one warm-up call (--warmup 1 or more): the first call compiles")
    from neuspike.methods.plugins import load_requested

    plugins = load_requested(args.plugin)  # before the names are checked against the registry
    names = method_names(args.methods)

    from neuspike import methods as registry

    registry.check_device(options.device, [registry.entry(n) for n in names])  # before any measurement
    out = Path(args.out or ("runs/timing-full" if args.full else "runs/timing"))
    from neuspike.formats.staging import check_writable_folder

    check_writable_folder(out, what="--out", create=False)  # before any measurement; created by the first write

    results_dir = None if (args.results or "").lower() == "none" else (Path(args.results) if args.results else newest_results())
    results = None
    if results_dir is not None:
        from bench.reporting.build import read_results, results_file

        if not results_file(results_dir).is_file():
            raise InputError(f"--results: {results_dir} holds no results.csv (or results.csv.gz)")
        results = read_results(results_file(results_dir))
        sweep_size = sweep_resolution(results)
        if sweep_size is not None and sweep_size not in sizes:
            # time the methods at the sweep's own resolution too, so the chart pairs like with like
            sizes = (*sizes, sweep_size)
            print(f"also timing at the sweep's resolution {sweep_size[0]}x{sweep_size[1]}", file=sys.stderr)
    watch = LoadWatch(torch.get_num_threads())

    config = {"timing": {"methods": list(names), "sizes": [f"{w}x{h}" for w, h in sizes], "repeats": repeats,
                         "warmup": warmup, "history_windows": args.history_windows, "light": LIGHT, "motion": MOTION,
                         "planes": PLANES, "scene": "pan:camera", "threads": torch.get_num_threads(),
                         "device": options.device, "precision": precision, "compiled": options.compiled,
                         "weights": portable_path(weights) if weights is not None else None}}
    if plugins:  # what registered the methods (absent from runs without plug-ins, as before)
        config["timing"]["plugins"] = list(plugins)
    write_json(out / "config.json", config)
    meta = {"source": source_state(), "versions": package_versions(), "machine": machine(),
            "command": command_line(), "executor": {"executor": "timing", "workers": 1},
            "threads": torch.get_num_threads(), "timing_contended": None, "start": now_iso(), "end": None}
    write_json(out / "metadata.json", meta)
    t0 = time.perf_counter()
    timing = measure(names, sizes, repeats=repeats, warmup=warmup, history_windows=args.history_windows,
                     weights_dir=weights, device=options.device, precision=precision, threads=torch.get_num_threads(),
                     compiled=options.compiled,
                     log=lambda s: (watch.read(), print(s, file=sys.stderr, flush=True)))
    write_text(out / "timing.csv", tb.to_csv_text(timing))
    meta = {**meta, "end": now_iso(), "wall_seconds": time.perf_counter() - t0, **watch.summary()}
    if meta["timing_contended"]:
        print("note: timings contended: " + "; ".join(meta["contention"]), file=sys.stderr)
    write_json(out / "metadata.json", meta)
    write_timing_tables(out / "tables", timing, meta)

    acc_path = out / "accuracy_vs_time.csv"
    if results is not None:
        joined = join_accuracy(results, timing, portable_path(results_dir))
        write_text(acc_path, tb.to_csv_text(joined))
        print(f"accuracy against time: sweep results from {results_dir}", file=sys.stderr)
    elif acc_path.exists():
        acc_path.unlink()  # a chart from an earlier run would not match these timings
    if not args.no_report:
        from bench.reporting.build import build_report

        print(f"report: {build_report(out)}")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        out = run(args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"timing: {out / 'timing.csv'}")
    print((out / "tables" / "timing.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
