"""Sweeps over light, motion, noise, and light and noise together: ``python -m bench.sweep``.

The command: it parses its options into a :class:`bench.harness.runner.SweepSpec` and an
:class:`bench.harness.runner.Execution` and runs :func:`bench.harness.runner.run_sweep` (outputs, resuming and exit
status are described there). :mod:`bench.noise` shares its options. Only light modules are imported
before the arguments are parsed, so ``--help`` and usage errors answer at once.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from bench.harness import grid as grids
from bench.harness.executors import EXECUTORS
from neuspike.conditions import parse_effects
from neuspike.errors import InputError, NeuSpikeError
from neuspike.simulation.recording import DEFAULT_HISTORY_WINDOWS
from neuspike.utils.cli import MethodOptions

if TYPE_CHECKING:
    from bench.harness.runner import Execution, SweepSpec


COMMON_EPILOG = """\
methods: every registered method by default (python -m neuspike.reconstruct --list shows them).
Learned methods need weights (--weights DIR or NEUSPIKE_WEIGHTS); without them they are skipped
and the reason is written in their rows; a skip is not a failure.

plug-ins: --plugin MODULE (repeatable; a dotted module name or a path to a .py file), or the
NEUSPIKE_PLUGINS environment variable (comma-separated), names modules that register extra methods
when imported (neuspike.methods.register). Every worker imports them, so your methods run on local
worker processes and on Dask workers alike; the module must be importable there.
Importing a plug-in runs its code with your permissions: name only files and modules you trust.

outputs in --out: results.csv (one row per method, scene, condition, seed and metric),
config.json, metadata.json, parts/ (one file per finished cell), errors/ (tracebacks), cache/
(simulated recordings, unless --cache says otherwise), images/ (reconstructions across the swept
axis, first seed), and the report (figures/, tables/, report.pdf) when bench.report exists.
A rerun of the same command resumes: finished cells are not recomputed. A different configuration
in the same --out is refused unless --force.

timing: ms_per_frame is the wall time of one reconstruct call (recurrent methods: including the
warm-up over the event history). --workers x --threads may not exceed the usable CPUs (refused).
With --workers > 1 cells run side by side and slow each other down on a small machine, and other
jobs on the machine do the same: metadata.json records the load average before and during the run
and marks such timings (timing_contended, with the reasons in contention; the report says so). Use
python -m bench.timing for careful timings.

exit status: 0 all cells ok; 1 a method or simulation failed (unless --allow-failures) or cells are
missing; 2 invalid options or a changed configuration; 130 interrupted (rerun to resume)."""


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """The options every sweep command shares."""
    g = parser.add_argument_group("what to measure")
    g.add_argument("--methods", help="comma-separated registry names (default: every registered method)")
    g.add_argument("--scenes", help="comma-separated KIND:IMAGE, KIND in pan, zoom, fan, still; IMAGE a "
                   f"bundled test photograph or an image file (default: {','.join(grids.QUICK_SCENES)}; "
                   f"with --full every kind over {','.join(grids.FULL_PHOTOS)})")
    g.add_argument("--seeds", help=f"comma-separated seeds (default: {','.join(map(str, grids.QUICK_SEEDS))}; "
                   f"with --full {','.join(map(str, grids.FULL_SEEDS))})")
    g.add_argument("--size", help=f"view WxH (default: {'x'.join(map(str, grids.QUICK_SIZE))}; "
                   f"with --full {'x'.join(map(str, grids.FULL_SIZE))})")
    g.add_argument("--full", action="store_true", help="the paper-size run: 400x250, every scene kind (pan, zoom, "
                   f"fan, still) over {' and '.join(grids.FULL_PHOTOS)}, seeds "
                   f"{','.join(map(str, grids.FULL_SEEDS))}")
    g.add_argument("--lights", help="override the light scales L, comma-separated (fractions allowed: 1/32)")
    g.add_argument("--motions", help="override the motion scales S, comma-separated (each must divide --planes)")
    g.add_argument("--planes", type=int, default=256, help="spike planes per window T (default: 256)")
    g.add_argument("--effects", help="extra simulator stages declared in every condition, e.g. "
                   "'initial_charge;threshold_mismatch:sigma=0.02' (default: exactly that: Algorithm 1's "
                   "random initial charge and v2e's clean event preset); 'none' declares nothing extra")
    g.add_argument("--history-windows", type=float, default=DEFAULT_HISTORY_WINDOWS,
                   help="event history before each window for recurrent methods to warm up on, in window "
                   f"durations (default: {DEFAULT_HISTORY_WINDOWS:g}; simulated only when a recurrent "
                   "method is requested)")
    MethodOptions.add_arguments(g, flags=("weights", "plugin"))
    r = parser.add_argument_group("how to run")
    r.add_argument("--out", help="output folder (default: runs/<sweep>, runs/<sweep>-full with --full)")
    r.add_argument("--executor", choices=EXECUTORS, default="local",
                   help="local worker processes (default) or a Dask cluster")
    r.add_argument("--workers", type=int, default=1,
                   help="worker processes (default: 1 = in this process)")
    r.add_argument("--scheduler", help="address of an existing Dask scheduler (with --executor dask); "
                   "without it a local Dask cluster of --workers processes is started")
    r.add_argument("--threads", type=int, help="torch threads per worker (default: the usable CPUs that other processes leave idle, / workers)")
    MethodOptions.add_arguments(r, flags=("device", "precision"),
                                device_note="; with the precision it resolves to, part of the sweep's identity, so a "
                                "resume must use the same")
    r.add_argument("--cache", help="folder of cached simulated recordings (default: <out>/cache); "
                   "'none' disables the cache")
    r.add_argument("--allow-failures", action="store_true",
                   help="exit 0 even when methods failed (their rows carry the error)")
    r.add_argument("--force", action="store_true",
                   help="replace results of a different configuration in --out")
    r.add_argument("--retry-failed", action="store_true", help="run cells with failed methods again")
    r.add_argument("--no-report", action="store_true", help="do not build the report at the end")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")


def methods_from(args: argparse.Namespace) -> tuple[str, ...]:
    """The requested method names (``--methods``, else every registered one), plug-ins loaded and each
    name checked against the registry."""
    from neuspike.methods.plugins import load_requested
    from neuspike import methods as registry

    load_requested(args.plugin)
    for problem in registry.load_entry_points():
        print(f"warning: a method plug-in failed to load: {problem}", file=sys.stderr)
    if args.methods is not None:  # an empty --methods is an error, not "every method"
        names = grids.parse_list(args.methods)
        for name in names:
            registry.entry(name)  # unknown names raise here, with the list of known ones
        return names
    names = tuple(registry.available())
    if not names:
        raise InputError("no methods are registered (is the package installed with its baselines?)")
    return names


def spec_from_args(args: argparse.Namespace, name: str, axis: str, noises: Sequence[str] | None = None) -> SweepSpec:
    """Build the :class:`SweepSpec` of a command line."""
    from bench.harness.runner import SweepSpec
    from neuspike.simulation.recording import SensorConfig

    weights = MethodOptions.from_args(args).weights_dir
    if args.effects is None:
        effects = None
    elif args.effects.strip().lower() == "none":
        effects = ()
    else:
        effects = parse_effects(args.effects)
    grid = grids.preset(
        axis, full=args.full,
        size=grids.parse_size(args.size) if args.size else None,
        scenes=grids.parse_list(args.scenes) if args.scenes else None,
        seeds=grids.parse_list(args.seeds, grids.parse_int) if args.seeds else None,
        lights=grids.parse_list(args.lights, grids.parse_fraction) if args.lights else None,
        motions=grids.parse_list(args.motions, grids.parse_int) if args.motions else None,
        noises=noises, effects=effects,
    )
    return SweepSpec(
        name=name, grid=grid, methods=methods_from(args), sensor=SensorConfig(planes=args.planes),
        history_windows=args.history_windows, weights=str(weights) if weights is not None else None,
        axis=grids.IMAGE_AXIS[axis],
    )


def execution_from_args(args: argparse.Namespace) -> Execution:
    from bench.harness.runner import Execution

    cache = args.cache
    if args.scheduler is not None:  # refused before anything is announced or created
        from bench.harness.executors import check_scheduler_address

        check_scheduler_address(args.scheduler)
    options = MethodOptions.from_args(args)
    return Execution(
        executor=args.executor, workers=args.workers, scheduler=args.scheduler, threads=args.threads,
        device=options.device, precision=options.precision,
        cache_dir=None if cache in (None, "none") else cache, use_cache=(cache != "none"),
        plugins=tuple(args.plugin), allow_failures=args.allow_failures, force=args.force,
        retry_failed=args.retry_failed, progress=False if args.no_progress else None,
        report=not args.no_report,
    )


def run_command(spec_builder, args: argparse.Namespace, default_out: str) -> int:
    """Run a parsed sweep command; print the summary and where the results are; return the exit code."""
    try:
        spec = spec_builder(args)
        execution = execution_from_args(args)
        out = Path(args.out or default_out)
        from bench.harness.runner import run_sweep
        from neuspike import methods as registry
        from neuspike.formats.staging import check_writable_folder

        # before any work and before anything is announced or created; run_sweep checks the cells
        registry.check_device(execution.device, [registry.entry(name) for name in spec.methods])
        check_writable_folder(out, what="--out", create=False)
        if execution.cache_dir is not None:  # an unusable cache would fail every cell: refused now
            check_writable_folder(Path(execution.cache_dir), what="--cache", create=False)
        print(f"{spec.name} sweep: {len(spec.grid.cells())} cells x {len(spec.methods)} methods -> {out}",
              file=sys.stderr)
        outcome = run_sweep(spec, out, execution)
        if execution.report:
            from bench.reporting.build import report_after_run

            report_after_run(outcome)
    except KeyboardInterrupt:
        print("interrupted: finished cells are saved; rerun the same command to resume", file=sys.stderr)
        return 130
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(outcome.summary())
    print(f"results: {outcome.results_path}")
    if outcome.report_path is not None:
        print(f"report: {outcome.report_path}")
    elif outcome.report_note:
        print(outcome.report_note)
    return outcome.exit_code


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.sweep",
        description="Sweep light, motion or noise, or light and noise together, over every registered method "
        "(the paper's Figures 3 and 4 and Table 3): "
        "simulate each cell once, reconstruct with every method, score PSNR and SSIM (and their "
        "affine-aligned variants), time each method, and write tidy results.",
        epilog="examples:\n"
        "  python -m bench.sweep --axis light                 # quick: 2 scenes at 160x100, L = 1/32 ... 1/2\n"
        "  python -m bench.sweep --axis motion --methods tfp-w32,tfi,events-integrate\n"
        "  python -m bench.sweep --axis light-noise --full --workers 2   # five light scales x four noise levels\n"
        "  python -m bench.sweep --axis light --full --workers 2 --weights ../shared/weights/firenet\n"
        "  python -m bench.sweep --axis light --executor dask --scheduler tcp://10.0.0.5:8786\n"
        "  python -m bench.sweep --axis motion --plugin my_methods --methods mine,tfi\n\n"
        "presets: light = S 128, L in {1/32, 1/16, 1/8, 1/4, 1/2}; motion = L 1/4, S in\n"
        "{16, 32, 64, 128, 256}; noise level none; noise = L 1/4, S 128, noise small, medium, high\n"
        "(python -m bench.noise is the same with a --level choice); light-noise = S 128, the light\n"
        "preset's five L at each noise level none, small, medium, high (--lights narrows it).\n\n"
        + COMMON_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--axis", choices=grids.PRESETS, default="light",
                        help="the swept axis, or light-noise for light and noise together (default: light)")
    add_common_arguments(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    default_out = f"runs/{args.axis}" + ("-full" if args.full else "")
    return run_command(lambda a: spec_from_args(a, a.axis, a.axis), args, default_out)


if __name__ == "__main__":
    sys.exit(main())
