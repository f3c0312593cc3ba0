"""Every method on a folder of real or peer recordings: ``python -m bench.dataset DIR``.

The command: it reads the manifest (``--manifest``) or infers one from the folder's layout
(:mod:`bench.harness.manifest`), checks it against the files before any work, and runs
:func:`bench.harness.datasets.run_dataset` (outputs, resuming and scoring are described there). Only light
modules are imported before the arguments are parsed, so ``--help`` and usage errors answer at once.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Sequence

from bench.harness.executors import EXECUTORS
from neuspike.errors import InputError, NeuSpikeError
from neuspike.utils.cli import MethodOptions

EPILOG = """\
layouts read without a manifest (--layout auto picks the one the folder is in):
  spike-gt       spike/NAME.dat (or .npz) and gt/NAME.png (or .npy), same stem: one instant at the
                 centre plane (T // 2), scored against the image; --gain states the rate (expected
                 spikes per plane at intensity 1); a .dat takes its size from its ground truth
  events-frames  one event file, images/ and images.txt ('<t seconds> images/<file>' lines): an
                 instant at each frame's time inside the event recording, from the events before it,
                 scored against that frame
  files          spike files in spike/ and event files in events/ (or at the top): each recording at
                 its centre, no ground truth (no-reference measures)
The manifest used (inferred or given) is written to OUT/manifest.json: rerun with --manifest
OUT/manifest.json to repeat the run exactly, or edit it (instants: a key plane, a list of planes
or times, or every N planes; window; gain; ground truth per instant). Its format is described in
bench/harness/manifest.py.

scoring: PSNR and SSIM (data_range 1, the pinned SSIM settings) and their affine-aligned variants
where the manifest names a ground truth; the no-reference measures noise_sigma and laplacian_var
always; ms_per_frame always. The protocol (window, key instants, gain, normalisation, data range,
SSIM settings) is in config.json and on the report's first page. Methods run only on recordings
that hold the inputs they read.

bad input: a missing file, a ground truth whose size differs from the sensor, an instant outside
the recording, a rate or gain of 0, an unknown layout: one line naming the recording, exit 2,
before any work. A recording that exists but cannot be read gives failed rows; the others run.

outputs in --out: manifest.json, results.csv (one row per recording, instant, method and metric),
config.json, metadata.json, parts/, errors/, images/ (each recording's middle instant), and the
report (figures/ with a contact sheet per recording, tables/, report.pdf).
A rerun of the same command resumes; a different configuration in the same --out is refused unless
--force.

exit status: 0 all ok; 1 a method or a recording failed (unless --allow-failures) or instants are
missing; 2 invalid options or a bad manifest; 130 interrupted (rerun to resume)."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m bench.dataset",
        description="Run every registered method (or --methods) on every recording of a folder: real "
        "recordings or a peer benchmark set. Scores each reconstruction against ground truth where the "
        "dataset has it, with no-reference measures where it does not, times every method, and writes the "
        "same tidy results.csv, tables, contact sheets and PDF as the sweeps (the paper's Figures 5 and 6 "
        "from ../shared/realdata).",
        epilog="examples:\n"
        "  python -m bench.dataset ../shared/realdata --methods tfp,tfi,snm --out runs/realdata\n"
        "  python -m bench.dataset my_spike_set --gain 0.6 --out runs/myset        # spike/ + gt/ layout\n"
        "  python -m bench.dataset my_davis_clip --weights ../shared/weights      # events + images/ layout\n"
        "  python -m bench.dataset ../shared/realdata --manifest reports/realdata/manifest.json "
        "--weights ../shared/weights\n"
        "  python -m bench.dataset DIR --infer-only --out runs/x   # write runs/x/manifest.json and stop\n\n"
        + EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("folder", metavar="DIR", help="the dataset folder (the manifest's paths are relative to it)")
    g = p.add_argument_group("the dataset")
    g.add_argument("--manifest", metavar="FILE", help="a manifest (JSON); default: inferred from DIR's layout")
    g.add_argument("--allow-outside", action="store_true",
                   help="read files the manifest names outside DIR (absolute paths, '..', links that lead out); "
                   "refused by default")
    g.add_argument("--layout", default="auto", help="layout to infer: auto (default), spike-gt, events-frames or files")
    g.add_argument("--gain", type=float, metavar="G", help="inferred spike recordings: expected spikes per plane at "
                   "intensity 1 (default: an .npz's own, else unknown: each method normalises robustly)")
    g.add_argument("--plane-rate", type=float, metavar="HZ", help="inferred recordings: spike planes per second "
                   "(default: the file's, else 20000)")
    g.add_argument("--window-planes", type=int, metavar="N", help="inferred recordings: spike window in planes "
                   "(default 256; a shorter file is used whole)")
    g.add_argument("--height", type=int, metavar="H", help="inferred .dat recordings without ground truth: sensor height")
    g.add_argument("--width", type=int, metavar="W", help="inferred .dat recordings without ground truth: sensor width")
    g.add_argument("--infer-only", action="store_true", help="write OUT/manifest.json and stop (nothing runs)")
    m = p.add_argument_group("what to run")
    m.add_argument("--methods", help="comma-separated registry names (default: every registered method; each "
                   "recording runs those whose inputs it has)")
    MethodOptions.add_arguments(m, flags=("weights", "plugin"))
    r = p.add_argument_group("how to run")
    r.add_argument("--out", help="output folder (default: runs/dataset-<DIR's name>)")
    r.add_argument("--executor", choices=EXECUTORS, default="local", help="local worker processes (default) or Dask")
    r.add_argument("--workers", type=int, default=1, help="worker processes (default: 1 = in this process)")
    r.add_argument("--scheduler", help="address of an existing Dask scheduler (with --executor dask)")
    r.add_argument("--threads", type=int, help="torch threads per worker (default: the usable CPUs that other processes leave idle, / workers)")
    MethodOptions.add_arguments(r, flags=("device", "precision"))
    r.add_argument("--allow-failures", action="store_true", help="exit 0 even when methods or recordings failed")
    r.add_argument("--force", action="store_true", help="replace results of a different configuration in --out")
    r.add_argument("--retry-failed", action="store_true", help="run instants with failures again")
    r.add_argument("--no-report", action="store_true", help="do not build the report at the end")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _methods(args: argparse.Namespace) -> tuple[str, ...]:
    from bench.sweep import methods_from

    return methods_from(args)


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    t0 = time.perf_counter()
    try:
        from bench.harness import manifest as mf
        from bench.harness.datasets import DatasetSpec, prepare, run_dataset
        from bench.harness.runner import Execution
        from neuspike.formats.staging import check_writable_folder

        folder = Path(args.folder)
        if not folder.is_dir():
            raise InputError(f"dataset {folder}: not a folder")
        out = Path(args.out or f"runs/dataset-{folder.resolve().name}")
        if args.manifest:
            inferred = {"--layout": args.layout != "auto", "--gain": args.gain is not None,
                        "--plane-rate": args.plane_rate is not None, "--window-planes": args.window_planes is not None,
                        "--height": args.height is not None, "--width": args.width is not None}
            given = [k for k, v in inferred.items() if v]
            if given:
                raise InputError(f"{', '.join(given)} apply to an inferred manifest; with --manifest, state them in it")
            manifest = mf.read_manifest(args.manifest)
        else:
            manifest = mf.infer_manifest(folder, layout=args.layout, gain=args.gain, plane_rate_hz=args.plane_rate,
                                         window_planes=args.window_planes, height=args.height, width=args.width)
            print(f"inferred the {manifest.layout} layout: {len(manifest.recordings)} recording(s)", file=sys.stderr)
            for note in manifest.notes:
                print(f"note: {note}", file=sys.stderr)
        check_writable_folder(out, what="--out", create=False)  # created only once every input is accepted
        if args.infer_only:
            path = mf.write_manifest(out / mf.MANIFEST_NAME, manifest)
            print(f"manifest: {path}")
            return 0
        options = MethodOptions.from_args(args)
        weights = options.weights_dir
        spec = DatasetSpec(name=folder.resolve().name, root=str(folder), manifest=manifest, methods=_methods(args),
                           weights=str(weights) if weights is not None else None, allow_outside=args.allow_outside)
        # an unusable device refuses before anything is announced (run_dataset checks the methods it runs)
        from neuspike import methods as registry

        registry.check_device(options.device, [registry.entry(name) for name in spec.methods])
        resolved = prepare(spec)
        n = sum(len(r.instants) for r in resolved)
        damaged = [r.recording.name for r in resolved if r.damaged]
        print(f"{spec.name}: {len(resolved)} recording(s), {n} instant(s), up to {len(spec.methods)} methods -> {out}"
              + (f"; unreadable (their rows will fail): {', '.join(damaged)}" if damaged else ""), file=sys.stderr)
        execution = Execution(
            executor=args.executor, workers=args.workers, scheduler=args.scheduler, threads=args.threads,
            device=options.device, precision=options.precision, use_cache=False, plugins=tuple(args.plugin), allow_failures=args.allow_failures,
            force=args.force, retry_failed=args.retry_failed, progress=False if args.no_progress else None,
            report=not args.no_report,
        )
        outcome = run_dataset(spec, out, execution, resolved=resolved)
        if execution.report:
            from bench.reporting.build import report_after_run

            report_after_run(outcome)
    except KeyboardInterrupt:
        print("interrupted: finished instants are saved; rerun the same command to resume", file=sys.stderr)
        return 130
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(outcome.summary().replace(" cells ", " instants ", 1))
    print(f"results: {outcome.results_path}  (manifest: {out / 'manifest.json'}; {time.perf_counter() - t0:.1f} s)")
    if outcome.report_path is not None:
        print(f"report: {outcome.report_path}")
    elif outcome.report_note:
        print(outcome.report_note)
    return outcome.exit_code


if __name__ == "__main__":
    sys.exit(main())
