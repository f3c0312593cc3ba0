"""Time per frame of every method (the paper's Table 2): ``python -m bench.timing``.

For each resolution (400x250 by default, the paper's four with ``--full``: 240x180, 346x260, 400x250,
640x480) one representative recording is
simulated once: the ``camera`` photograph panning (the sweeps' pan scene, scaled to the width) at
L = 1/4, S = 128, 256 planes, both modalities, with the sweeps' default effects and
``--history-windows`` windows of event history for recurrent methods to warm up on. Every method
then reconstructs from it: ``--warmup`` untimed calls, then ``--repeats`` timed calls, each after
``reset()`` (outside the timed region). Reported: the median and the spread (min, max, quartiles)
of the timed calls, torch's thread count, and the method's learned parameter count.

Recurrent methods (FireNet) warm up on the event history inside every call; their ms per frame is
the cost of one network step, the call's time divided by the event windows it processed
(``last_steps``), as in the paper's Table 2 (one inference per voxel grid). The whole call is
kept in ``median_ms``.

A method that cannot run (e.g. FireNet without weights: ``MethodUnavailable``) or fails is a row
with its status and reason, not a crash.

Outputs in ``--out`` (default ``runs/timing``; ``runs/timing-full`` with ``--full``)
    ``timing.csv`` (one row per method and resolution), ``tables/timing.md`` and ``.csv``,
    ``config.json``, ``metadata.json``; with sweep results (``--results``): ``accuracy_vs_time.csv``
    (each method's mean PSNR and SSIM from the sweep beside its ms per frame here, at the sweep's
    resolution when it was timed, else at the timed resolution closest in pixel count) and
    ``figures/accuracy_vs_time.png``; and ``report.pdf`` (:func:`bench.report.build_report`).

``--results`` defaults to the newest (by the time ``results.csv`` was written) of ``runs/light``,
``runs/light-full``, ``runs/motion``, ``runs/motion-full``, ``runs/noise``, ``runs/noise-full``
(relative to the current folder); ``--results none`` skips the chart.

The shared timing code (:func:`time_callable`, :func:`time_method`, :func:`representative_sample`)
is also what :mod:`bench.method_speed` uses. Timings on a shared 2-core machine are noisy; the
spread columns say how much.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from bench import grid as grids
from bench import tables as tb
from neuspike.checks import check_int
from neuspike.conditions import Condition
from neuspike.errors import InputError
from neuspike.parallel import set_threads
from neuspike.sample import Sample
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import DEFAULT_HISTORY_WINDOWS, SensorConfig
from neuspike.weights import WEIGHTS_ENV, weights_dir_from_env

#: Default resolutions (width, height): the paper's Table 2.
RESOLUTIONS: tuple[tuple[int, int], ...] = tb.TABLE2_RESOLUTIONS
#: Timed and warm-up calls: quick (the default) and full.
QUICK = {"repeats": 3, "warmup": 1, "sizes": ((400, 250),)}
FULL = {"repeats": 10, "warmup": 2, "sizes": RESOLUTIONS}
#: The representative condition.
LIGHT, MOTION, PLANES = 0.25, 128, 256
#: Result folders searched (newest first) for the accuracy-versus-time chart.
DEFAULT_RESULTS = ("runs/light", "runs/light-full", "runs/motion", "runs/motion-full", "runs/noise", "runs/noise-full")

TIMING_COLUMNS = ("method", "family", "inputs", "resolution", "width", "height", "status", "error", "threads",
                  "parameters", "warmup", "repeats", "median_ms", "min_ms", "max_ms", "q1_ms", "q3_ms", "steps",
                  "ms_per_frame", "min_frame_ms", "max_frame_ms")


# ----------------------------------------------------------------------------------------------
# Timing one callable (shared with bench.method_speed)
# ----------------------------------------------------------------------------------------------

def summarize_ms(samples_ms: Sequence[float]) -> dict[str, float]:
    """Median, min, max and quartiles (linear interpolation) of timings in ms.

    Raises
    ------
    InputError
        When there is no sample or a sample is not a finite number >= 0.
    """
    a = np.asarray(list(samples_ms), dtype=np.float64)
    if a.ndim != 1 or a.size == 0:
        raise InputError(f"summarize_ms: expected at least one timing, got {a.size}")
    if not np.isfinite(a).all() or (a < 0).any():
        raise InputError(f"summarize_ms: expected finite timings >= 0, got {a.tolist()}")
    q1, med, q3 = np.percentile(a, [25, 50, 75])
    return {"median_ms": float(med), "min_ms": float(a.min()), "max_ms": float(a.max()),
            "q1_ms": float(q1), "q3_ms": float(q3), "n": int(a.size)}


@dataclass(frozen=True)
class TimingStats:
    """The timed calls of one measurement (ms) and how many untimed warm-up calls preceded them."""

    samples_ms: tuple[float, ...]
    warmup: int

    def summary(self) -> dict[str, float]:
        return summarize_ms(self.samples_ms)

    @property
    def median_ms(self) -> float:
        return self.summary()["median_ms"]


def _sizes_text(sizes: Iterable[tuple[int, int]]) -> str:
    return ", ".join(f"{w}x{h}" for w, h in sizes)


def check_count(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int when it is a whole number >= ``minimum``; else :class:`InputError`."""
    return check_int(name, value, minimum=minimum)


def time_callable(fn: Callable[[], Any], *, repeats: int, warmup: int, setup: Callable[[], Any] | None = None,
                  timer: Callable[[], int] = time.perf_counter_ns) -> TimingStats:
    """Time ``fn()``: ``warmup`` untimed calls, then ``repeats`` timed calls.

    Parameters
    ----------
    fn : callable with no arguments
    repeats : int >= 1
    warmup : int >= 0
    setup : callable, optional
        Called before every call (warm-up and timed), outside the timed region (e.g. ``method.reset``).
    timer : callable returning integer nanoseconds
        ``time.perf_counter_ns`` by default; read once before and once after each timed call.

    Returns
    -------
    TimingStats
    """
    repeats = check_count("repeats", repeats, 1)
    warmup = check_count("warmup", warmup, 0)
    for _ in range(warmup):
        if setup is not None:
            setup()
        fn()
    samples = []
    for _ in range(repeats):
        if setup is not None:
            setup()
        t0 = timer()
        fn()
        t1 = timer()
        samples.append((t1 - t0) / 1e6)
    return TimingStats(tuple(samples), warmup)


@dataclass(frozen=True)
class MethodTiming:
    """A method's timing on a sample: the call statistics and the event windows (network steps) one
    call processed (``None`` for methods that do not report ``last_steps``)."""

    stats: TimingStats
    steps: int | None

    def row(self) -> dict[str, Any]:
        """``median_ms ... q3_ms``, ``steps`` and the per-frame figures (per step when ``steps``)."""
        s = self.stats.summary()
        per = self.steps if self.steps else 1
        return {"warmup": self.stats.warmup, "repeats": s["n"], "median_ms": s["median_ms"], "min_ms": s["min_ms"],
                "max_ms": s["max_ms"], "q1_ms": s["q1_ms"], "q3_ms": s["q3_ms"],
                "steps": self.steps if self.steps else math.nan, "ms_per_frame": s["median_ms"] / per,
                "min_frame_ms": s["min_ms"] / per, "max_frame_ms": s["max_ms"] / per}


def time_method(method: Any, sample: Any, *, repeats: int, warmup: int,
                timer: Callable[[], int] = time.perf_counter_ns) -> MethodTiming:
    """Time ``method.reconstruct(sample)`` with ``reset()`` before every call (outside the timing).

    For recurrent methods that report ``last_steps`` (the event windows one call stepped through),
    :attr:`MethodTiming.steps` holds it, so that the cost of one step can be derived.
    """
    stats = time_callable(lambda: method.reconstruct(sample), repeats=repeats, warmup=warmup,
                          setup=method.reset, timer=timer)
    steps = method.last_steps if method.recurrent else None
    steps = int(steps) if isinstance(steps, (int, np.integer)) and steps > 0 else None
    return MethodTiming(stats, steps)


# ----------------------------------------------------------------------------------------------
# The representative recording
# ----------------------------------------------------------------------------------------------

def representative_sample(width: int, height: int, *, history_windows: float = DEFAULT_HISTORY_WINDOWS,
                          modalities: Iterable[str] = ("spikes", "events"), seed: int = 0) -> Sample:
    """The sample every method is timed on at one resolution (module docstring), without ground truth.

    Built by :func:`neuspike.simulate.simulate_sample`, the sweeps' own cell-to-sample path, so a
    timed sample is the one a sweep cell of the same scene, condition and seed would see.

    Parameters
    ----------
    width, height : int
        Sensor size in pixels.
    history_windows : float >= 0
        Event history before the window, in window durations (for recurrent methods).
    modalities : the inputs to simulate
    seed : int
        The cell's seed.
    """
    if not history_windows >= 0 or not math.isfinite(history_windows):
        raise InputError(f"history_windows: expected a finite number >= 0, got {history_windows!r}")
    entry = grids.scene_entry("pan:camera", (int(width), int(height)))
    sensor = SensorConfig(planes=PLANES)
    condition = Condition(light=LIGHT, motion=MOTION, effects=grids.DEFAULT_EFFECTS)
    window_s = sensor.planes / sensor.plane_rate_hz
    sample = simulate_sample(entry.spec, condition, sensor=sensor, seed=seed, modalities=modalities,
                             history_s=history_windows * window_s)
    return sample.without_ground_truth()


def cut_spike_window(sample: Any, planes: int) -> Any:
    """``sample`` with its spike window cut to ``planes`` planes around the key plane.

    The window is planes ``[k - planes // 2, k - planes // 2 + planes)`` of the key plane ``k``; the
    sample's window becomes that span and its events stop at the new window's end.

    Raises
    ------
    InputError
        When the sample has no spikes or fewer than ``planes`` planes around the key plane.
    """
    planes = check_count("planes", planes, 1)
    if sample.spikes is None:
        raise InputError("cut_spike_window: the sample has no spikes")
    k = sample.key_plane
    start = k - planes // 2
    if start < 0 or start + planes > sample.spikes.num_planes:
        raise InputError(f"cut_spike_window: {planes} planes around plane {k} do not fit in "
                         f"{sample.spikes.num_planes} planes")
    spikes = sample.spikes.window(start, start + planes)
    events = sample.events
    if events is not None:
        t0 = min(float(events.t_s[0]), spikes.start_s) if len(events) else spikes.start_s
        events = events.between(t0, spikes.end_s)
    return replace(sample, spikes=spikes, events=events, window_start_s=spikes.start_s, window_end_s=spikes.end_s)


# ----------------------------------------------------------------------------------------------
# Table 2
# ----------------------------------------------------------------------------------------------

def one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}"
    return " | ".join(p.strip() for p in text.splitlines() if p.strip())


def create_methods(names: Sequence[str], *, weights_dir: str | os.PathLike | None = None,
                   device: str = "cpu") -> dict[str, tuple[Any, str]]:
    """``{name: (method or None, reason)}``: each method created once by
    :func:`neuspike.methods.create_many`; a method that cannot be created gives ``None`` and
    ``"skipped: ..."`` (``MethodUnavailable``) or ``"error: ..."`` (anything else). Unknown names and
    an unusable device raise :class:`~neuspike.errors.InputError` before anything is built."""
    from neuspike import methods as registry

    made = registry.create_many(list(names), weights_dir=weights_dir, device=device, keep_errors=True)
    out: dict[str, tuple[Any, str]] = {}
    for name, c in made.items():
        if c.unavailable is not None:
            out[name] = (None, f"skipped: {one_line(c.unavailable)}")
        elif c.error is not None:  # a method that cannot even be created is a row, not a crash
            out[name] = (None, f"error: {one_line(c.error)}")
        else:
            out[name] = (c.method, "")
    return out


def method_info(name: str, method: Any) -> dict[str, Any]:
    """Family, inputs and parameter count of a method (registry entry when it could not be created)."""
    ins: frozenset[str] = frozenset()
    try:
        from neuspike import methods as registry

        ins = frozenset(registry.entry(name).inputs)
    except Exception:
        ins = frozenset(getattr(method, "inputs", ()) or ())
    params = 0
    if method is not None:
        try:
            params = int(method.parameter_count())
        except Exception:
            params = 0
    return {"family": tb.family_of(ins), "inputs": "+".join(sorted(ins)), "parameters": params}


def measure(names: Sequence[str], sizes: Sequence[tuple[int, int]], *, repeats: int, warmup: int,
            history_windows: float = DEFAULT_HISTORY_WINDOWS, seed: int = 0,
            weights_dir: str | os.PathLike | None = None, device: str = "cpu", threads: int | None = None,
            log: Callable[[str], Any] | None = None) -> pd.DataFrame:
    """Table 2 rows (:data:`TIMING_COLUMNS`): every method at every size.

    Each size's recording is simulated once (:func:`representative_sample`); each method is
    created once and timed with :func:`time_method`. ``threads`` (when given) is re-applied to
    torch before every method: the simulator's compiled kernels start an OpenMP pool that can
    change the count torch uses.
    """
    import torch

    repeats = check_count("repeats", repeats, 1)
    warmup = check_count("warmup", warmup, 0)
    created = create_methods(names, weights_dir=weights_dir, device=device)
    needs = {m for name, (method, _) in created.items() if method is not None for m in method.inputs}
    rows = []
    for width, height in sizes:
        res = f"{width}x{height}"
        sample = None
        if needs:
            if log:
                log(f"{res}: simulating the representative recording")
            sample = representative_sample(width, height, history_windows=history_windows,
                                           modalities=sorted(needs), seed=seed)
        for name in names:
            method, reason = created[name]
            if threads is not None:
                set_threads(threads)
            row: dict[str, Any] = {c: math.nan for c in TIMING_COLUMNS}
            row.update(method=name, resolution=res, width=width, height=height, threads=torch.get_num_threads(),
                       error="", **method_info(name, method))
            if method is None:
                status, _, msg = reason.partition(": ")
                row.update(status=status, error=msg)
            else:
                try:
                    timing = time_method(method, sample, repeats=repeats, warmup=warmup)
                    row.update(status="ok", **timing.row())
                except Exception as exc:
                    row.update(status="error", error=one_line(exc))
            if log:
                log(f"{res} {name}: " + (f"{row['ms_per_frame']:.3g} ms per frame" if row["status"] == "ok"
                                          else f"{row['status']} ({row['error']})"))
            rows.append(row)
    return pd.DataFrame(rows, columns=list(TIMING_COLUMNS))


# ----------------------------------------------------------------------------------------------
# Accuracy against time
# ----------------------------------------------------------------------------------------------

def newest_results(candidates: Sequence[str | os.PathLike] = DEFAULT_RESULTS) -> Path | None:
    """The candidate folder whose ``results.csv`` was written last, or ``None``."""
    paths = [Path(c) for c in candidates if (Path(c) / "results.csv").is_file()]
    if not paths:
        return None
    return max(paths, key=lambda p: (p / "results.csv").stat().st_mtime_ns)


def sweep_resolution(results: pd.DataFrame) -> tuple[int, int] | None:
    """The (width, height) most of a sweep's rows were measured at (``None`` for no rows)."""
    if not len(results):
        return None
    counts = results.groupby(["width", "height"]).size().sort_values(ascending=False, kind="mergesort")
    return tuple(int(v) for v in counts.index[0])


def join_accuracy(results: pd.DataFrame, timing: pd.DataFrame, source: str) -> pd.DataFrame:
    """Mean PSNR and SSIM per method from sweep ``results`` beside its ms per frame from ``timing``.

    The time is taken at the sweep's resolution when it was timed, else at the timed resolution
    closest in pixel count (``resolution`` says which). Methods without an ok timing keep a NaN time.

    Returns
    -------
    DataFrame ``method, family, ms_per_frame, psnr, ssim, resolution, results``.
    """
    summary = tb.method_summary(results)
    summary = summary[summary["cells_ok"] > 0]
    sweep_w, sweep_h = sweep_resolution(results) or (0, 0)
    ok = timing[timing["status"] == "ok"]
    records = []
    for r in summary.itertuples():
        t = ok[ok["method"] == r.method]
        ms, res = math.nan, ""
        if len(t):
            dist = (t["width"] * t["height"] - sweep_w * sweep_h).abs().to_numpy()
            exact = t[(t["width"] == sweep_w) & (t["height"] == sweep_h)]
            pick = exact.iloc[0] if len(exact) else t.iloc[int(np.argmin(dist))]
            ms, res = float(pick["ms_per_frame"]), str(pick["resolution"])
        records.append({"method": r.method, "family": r.family, "ms_per_frame": ms, "psnr": r.psnr, "ssim": r.ssim,
                        "resolution": res, "results": source})
    return pd.DataFrame(records, columns=["method", "family", "ms_per_frame", "psnr", "ssim", "resolution", "results"])


# ----------------------------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------------------------

def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``"240x180,400x250"`` -> ``((240, 180), (400, 250))``."""
    from bench.grid import parse_list, parse_size

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
        "  python -m bench.timing --methods tfp,tfi --sizes 400x250 --results runs/light\n\n"
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
    parser.add_argument("--threads", type=int, help="torch intra-op threads (default: torch's own choice)")
    parser.add_argument("--weights", help="folder of published weights, e.g. FireNet's (default: $NEUSPIKE_WEIGHTS); "
                                          "the suite's own trained weights need no flag")
    parser.add_argument("--device", default="cpu", help="torch device of learned methods (default: cpu)")
    parser.add_argument("--history-windows", type=float, default=DEFAULT_HISTORY_WINDOWS,
                        help=f"event history for recurrent methods, in window durations (default {DEFAULT_HISTORY_WINDOWS:g}, "
                        "as the sweeps)")
    parser.add_argument("--results", help="sweep results folder for the accuracy-versus-time chart (default: the newest "
                        "of " + ", ".join(DEFAULT_RESULTS) + "); 'none' skips the chart")
    parser.add_argument("--out", help="output folder (default: runs/timing, runs/timing-full with --full)")
    parser.add_argument("--no-report", action="store_true", help="do not build report.pdf")
    return parser


def method_names(text: str | None) -> tuple[str, ...]:
    """The methods a command names (comma-separated ``text``), or every registered one when ``None``.

    Raises
    ------
    InputError
        An unknown name (the message lists the known ones), or no method registered at all.
    """
    from bench.grid import parse_list
    from neuspike import methods as registry

    for problem in registry.load_entry_points():
        print(f"warning: a method plug-in failed to load: {problem}", file=sys.stderr)
    if text:
        names = parse_list(text)
        for name in names:
            registry.entry(name)  # unknown names raise with the list of known ones
        if len(set(names)) != len(names):
            raise InputError(f"--methods repeats a name: {text!r}")
        return names
    names = tuple(registry.available())
    if not names:
        raise InputError("no methods are registered")
    return names


def run(args: argparse.Namespace) -> Path:
    """Run a parsed ``bench.timing`` command; return the output folder."""
    import torch

    from neuspike.atomic import write_json, write_text
    from bench.provenance import command_line, machine, now_iso, package_versions, source_state
    from bench.report import write_timing_tables

    weights = weights_dir_from_env(args.weights)
    if weights is not None and not weights.is_dir():
        origin = "--weights" if args.weights is not None else f"${WEIGHTS_ENV}"
        raise InputError(f"{origin}: {str(weights)!r} is not a folder")
    if args.threads is not None:
        set_threads(check_count("--threads", args.threads, 1))
    preset = FULL if args.full else QUICK
    repeats = args.repeats if args.repeats is not None else preset["repeats"]
    warmup = args.warmup if args.warmup is not None else preset["warmup"]
    sizes = parse_sizes(args.sizes) if args.sizes else preset["sizes"]
    names = method_names(args.methods)
    from neuspike import methods as registry

    registry.check_device(args.device, [registry.entry(n) for n in names])  # before any measurement
    out = Path(args.out or ("runs/timing-full" if args.full else "runs/timing"))
    from neuspike.formats.staging import check_writable_folder

    check_writable_folder(out, what="--out")  # before any measurement

    results_dir = None if (args.results or "").lower() == "none" else (Path(args.results) if args.results else newest_results())
    results = None
    if results_dir is not None:
        from bench.report import read_results

        if not (results_dir / "results.csv").is_file():
            raise InputError(f"--results: {results_dir} holds no results.csv")
        results = read_results(results_dir / "results.csv")
        sweep_size = sweep_resolution(results)
        if sweep_size is not None and sweep_size not in sizes:
            # time the methods at the sweep's own resolution too, so the chart pairs like with like
            sizes = (*sizes, sweep_size)
            print(f"also timing at the sweep's resolution {sweep_size[0]}x{sweep_size[1]}", file=sys.stderr)
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan

    config = {"timing": {"methods": list(names), "sizes": [f"{w}x{h}" for w, h in sizes], "repeats": repeats,
                         "warmup": warmup, "history_windows": args.history_windows, "light": LIGHT, "motion": MOTION,
                         "planes": PLANES, "scene": "pan:camera", "threads": torch.get_num_threads(),
                         "weights": str(weights) if weights is not None else None}}
    write_json(out / "config.json", config)
    meta = {"source": source_state(), "versions": package_versions(), "machine": machine(),
            "command": command_line(), "executor": {"executor": "timing", "workers": 1},
            "threads": torch.get_num_threads(), "timing_contended": False, "start": now_iso(), "end": None}
    write_json(out / "metadata.json", meta)
    t0 = time.perf_counter()
    timing = measure(names, sizes, repeats=repeats, warmup=warmup, history_windows=args.history_windows,
                     weights_dir=weights, device=args.device, threads=args.threads,
                     log=lambda s: print(s, file=sys.stderr, flush=True))
    write_text(out / "timing.csv", tb.to_csv_text(timing))
    load_after = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    meta = {**meta, "end": now_iso(), "wall_seconds": time.perf_counter() - t0,
            "load_1min": {"before": load_before, "after": load_after},
            "timing_contended": bool(max(load_before, load_after) > (os.cpu_count() or 1))}
    write_json(out / "metadata.json", meta)
    write_timing_tables(out / "tables", timing, meta)

    acc_path = out / "accuracy_vs_time.csv"
    if results is not None:
        joined = join_accuracy(results, timing, str(results_dir))
        write_text(acc_path, tb.to_csv_text(joined))
        print(f"accuracy against time: sweep results from {results_dir}", file=sys.stderr)
    elif acc_path.exists():
        acc_path.unlink()  # a chart from an earlier run would not match these timings
    if not args.no_report:
        from bench.report import build_report

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
