"""Milliseconds per reconstructed frame of every method at 400x250: ``python -m bench.method_speed``.

Every registered method (or ``--methods``) reconstructs from one representative recording at the
Vidar size, 400x250 (:func:`bench.harness.timer.representative_sample`: the ``camera`` photograph panning,
L = 1/4, S = 128, a 256-plane window, events with one window of history): ``--warmup`` untimed calls,
then the median and spread of ``--repeats`` timed calls, each after ``reset()``
(:func:`bench.harness.timer.time_method`, the same code as Table 2).

Columns
    ``T=256``    ms per call on the full 256-plane window (the sweeps' window)
    ``T=41``     spike methods only: ms per call on the 41 planes around the key plane, the window
                 shape of the Spike-Zoo reference figures ((41, 250, 400))
    ``per step`` recurrent methods: ms per network step (one event voxel grid): the call divided
                 by the event windows it processed

References measured in the same run (rows ``ref:...``, same sample, same threads)
    ``ref:spikezoo-tfp-wN``  a straightforward NumPy TFP as Spike-Zoo writes it: the mean of the N
                 planes around the key plane (``planes[k - N // 2 : ...].mean(axis=0)``), divided by
                 the gain and clipped to [0, 1]; one per window length the TFP entries use on T=41
    ``ref:snm-torch``  ``snm`` through its reference backend (the plane loop of torch operations)
    ``ref:tfstp-numpy``  ``tfstp`` through its reference backend (the NumPy plane loop)

Targets, each with a one-line verdict (met / missed and the ratio to the limit)
    ``snm``    at most 30 ms per frame (T=256); its torch reference is printed beside it
    ``tfstp``  at most 10 ms per frame (T=256); its NumPy reference is printed beside it
    ``tfp``    every TFP entry no slower than the Spike-Zoo-style reference of its window (T=41)
    ``tfi``    no slower than Spike-Zoo's published TFI, 1.99 ms on a (41, 250, 400) window (T=41)
    ``firenet``  at most 30 ms per voxel grid (the FireNet paper's CPU figure is 56 ms)

Threads: torch's intra-op pool and numba's pool are both pinned to ``--threads`` (default: the CPUs
this process may use) before anything is timed, and both counts are recorded in every row, with the
1-minute load average before and after the run (a loaded machine slows everything; the references
in the same run are slowed alike). Timings on a shared 2-core machine are noisy: the spread
(min-max) is printed with each median.

    python -m bench.method_speed [--methods tfp,tfi] [--repeats 7] [--warmup 1] [--weights DIR]
                                 [--threads N] [--out DIR]
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from neuspike.errors import InputError, one_line
from neuspike.utils.cli import MethodOptions
from neuspike.utils.parallel import set_threads
from neuspike.utils.resources import usable_cpus

WIDTH, HEIGHT = 400, 250
REFERENCE_PLANES = 41

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class Target:
    """A speed target: the methods it covers (a name, and its ``name-*`` variants), which column it
    reads (``"ms_41"``, ``"ms_256"`` or ``"ms_step"``), and either a fixed limit in ms or the
    same-run reference row whose median is the limit (``reference_row``; for TFP the reference of the
    method's own window, see :func:`tfp_reference_row`), with a text saying what the reference is."""

    name: str
    column: str
    limit_ms: float | None
    reference: str
    reference_row: str | None = None

    def covers(self, method: str) -> bool:
        return method == self.name or method.startswith(self.name + "-")


TARGETS: tuple[Target, ...] = (
    Target("tfp", "ms_41", None, "Spike-Zoo-style NumPy TFP, same window, same run", "ref:spikezoo-tfp"),
    Target("tfi", "ms_41", 1.99, "Spike-Zoo TFI 1.99 ms, (41, 250, 400) window (published)"),
    Target("tfstp", "ms_256", 10.0, "NumPy reference backend, same run", "ref:tfstp-numpy"),
    Target("snm", "ms_256", 30.0, "torch reference backend, same run", "ref:snm-torch"),
    Target("firenet", "ms_step", 30.0, "FireNet paper CPU 56 ms (10-core Xeon)"),
)
_TFP = TARGETS[0]
COLUMN_TEXT = {"ms_41": "T=41", "ms_256": "T=256", "ms_step": "per step"}


def target_of(method: str) -> Target | None:
    """The target covering ``method``, or ``None`` (reference rows have none)."""
    if method.startswith("ref:"):
        return None
    return next((t for t in TARGETS if t.covers(method)), None)


# --- the same-run references ------------------------------------------------------------------

def spikezoo_tfp(planes: np.ndarray, key_plane: int, window: int, gain: float) -> np.ndarray:
    """TFP written the plain way (as Spike-Zoo does): the mean of ``window`` planes around the key plane.

    Parameters
    ----------
    planes : ndarray bool (T, H, W)
    key_plane : int
    window : int, planes averaged (shifted inward where it would spill over an end)
    gain : float > 0, expected spikes per plane per unit radiance

    Returns
    -------
    ndarray float32 (H, W) in [0, 1]
    """
    start = min(max(0, key_plane - window // 2), max(0, planes.shape[0] - window))
    rate = planes[start:start + window].mean(axis=0, dtype=np.float32)
    return np.clip(rate / np.float32(gain), 0.0, 1.0)


def tfp_window_planes(method: Any, num_planes: int) -> int:
    """Planes a TFP entry averages on a ``num_planes`` window (its ``window`` parameter, or all)."""
    window = getattr(method, "params", {}).get("window")
    return num_planes if window is None else min(int(window), num_planes)


def tfp_reference_row(window: int) -> str:
    return f"ref:spikezoo-tfp-w{window}"


def _time_row(name: str, fn: Callable[[], Any], column: str, *, repeats: int, warmup: int) -> dict[str, Any]:
    from bench.harness import timer

    stats = timer.time_callable(fn, repeats=repeats, warmup=warmup).summary()
    return {"method": name, "family": "reference", "status": "ok", "error": "",
            f"{column}_median": stats["median_ms"], f"{column}_min": stats["min_ms"], f"{column}_max": stats["max_ms"]}


def reference_rows(names: Sequence[str], created: dict[str, tuple[Any, str]], sample: Any, short: Any, *,
                   repeats: int, warmup: int) -> list[dict[str, Any]]:
    """The same-run references the requested methods' targets need (see the module docstring)."""
    rows: list[dict[str, Any]] = []
    if short is not None:
        gain = short.spikes.gain if short.spikes.gain else 1.0
        windows = sorted({tfp_window_planes(created[n][0], short.spikes.num_planes)
                          for n in names if created[n][0] is not None and _TFP.covers(n)})
        for w in windows:
            rows.append(_time_row(tfp_reference_row(w),
                                  lambda w=w: spikezoo_tfp(short.spikes.planes, short.key_plane, w, gain),
                                  "ms_41", repeats=repeats, warmup=warmup))
    if sample is not None and sample.spikes is not None:
        planes, key, rate_hz = sample.spikes.planes, sample.key_plane, sample.spikes.plane_rate_hz
        if "snm" in names:
            from baselines.snm import snm_rate

            rows.append(_time_row("ref:snm-torch", lambda: snm_rate(planes, key, plane_rate_hz=rate_hz, backend="torch"),
                                  "ms_256", repeats=max(1, min(repeats, 3)), warmup=min(warmup, 1)))
        if "tfstp" in names:
            from baselines.tfstp import tfstp_rate

            rows.append(_time_row("ref:tfstp-numpy", lambda: tfstp_rate(planes, key, backend="numpy"),
                                  "ms_256", repeats=repeats, warmup=warmup))
    return rows


# --- measuring ----------------------------------------------------------------------------------

def _spread(row: dict[str, Any], prefix: str) -> str:
    from bench.reporting import tables as tb

    med = row.get(f"{prefix}_median")
    if med is None or (isinstance(med, float) and math.isnan(med)):
        return "-"
    return f"{tb.fmt(med, 'ms')} [{tb.fmt(row[f'{prefix}_min'], 'ms')}-{tb.fmt(row[f'{prefix}_max'], 'ms')}]"


def _value(row: dict[str, Any], column: str) -> float | None:
    value = row.get(f"{column}_median")
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    return float(value)


def thread_counts() -> dict[str, int]:
    """The torch and numba thread counts in force now."""
    import numba
    import torch

    return {"torch_threads": int(torch.get_num_threads()), "numba_threads": int(numba.get_num_threads())}


def pin_threads(threads: int) -> dict[str, int]:
    """Set torch's intra-op pool and numba's pool to ``threads`` (numba: at most its launch count)."""
    from bench.harness import timer

    set_threads(timer.check_count("threads", threads, 1))
    return thread_counts()


def load_average() -> float:
    """The 1-minute load average (NaN where the system has none)."""
    from bench.harness.provenance import load_1min

    load = load_1min()
    return math.nan if load is None else load


def judge(frame: pd.DataFrame) -> pd.DataFrame:
    """Fill ``limit_ms``, ``target``, ``reference``, ``ratio`` and ``verdict`` of every method row.

    ``ratio`` is the method's median over the limit (<= 1 meets it); the limit is the target's fixed
    figure or the median of its same-run reference row.
    """
    import pandas as pd
    from bench.reporting import tables as tb

    medians = {str(r["method"]): r for r in frame.to_dict("records")}
    out = []
    for row in frame.to_dict("records"):
        name = str(row["method"])
        target = target_of(name)
        row.update(limit_ms=math.nan, ratio=math.nan, target="-", reference="-", verdict="-")
        if target is not None:
            ref_name = target.reference_row
            if ref_name == "ref:spikezoo-tfp":
                window = row.get("window_41")
                ref_name = tfp_reference_row(int(window)) if window is not None and not pd.isna(window) else None
            limit = target.limit_ms
            if ref_name is not None and ref_name in medians:
                ref_value = _value(medians[ref_name], target.column)
                if target.limit_ms is None:
                    limit = ref_value
                row["reference"] = f"{ref_name} {tb.fmt(ref_value, 'ms') if ref_value is not None else '-'} ms"
            else:
                row["reference"] = target.reference
            row["target"] = (f"<= {target.limit_ms:g} ms ({COLUMN_TEXT[target.column]})" if target.limit_ms is not None
                             else f"<= reference ({COLUMN_TEXT[target.column]})")
            value = _value(row, target.column)
            if row["status"] != "ok" or value is None or limit is None or not limit > 0:
                row["verdict"] = "not measured"
            else:
                row.update(limit_ms=limit, ratio=value / limit, verdict="met" if value <= limit else "missed")
        out.append(row)
    return pd.DataFrame(out)


def verdict_lines(frame: pd.DataFrame) -> list[str]:
    """One line per target row: the figure, the limit, met / missed with the ratio, and the reference."""
    from bench.reporting import tables as tb

    lines = []
    for row in frame.to_dict("records"):
        target = target_of(str(row["method"]))
        if target is None:
            continue
        value = _value(row, target.column)
        if row["verdict"] in ("met", "missed"):
            lines.append(f"{row['method']}: {tb.fmt(value, 'ms')} ms ({COLUMN_TEXT[target.column]}), target {row['target']}"
                         f" -> {row['verdict']} ({row['ratio']:.2f}x the limit of {tb.fmt(row['limit_ms'], 'ms')} ms);"
                         f" reference: {row['reference']}")
        else:
            lines.append(f"{row['method']}: {row['verdict']} ({row['status']}{': ' + row['error'] if row['error'] else ''})")
    return lines


def measure(names: Sequence[str], *, repeats: int, warmup: int, weights_dir=None, device: str = "cpu",
            log=None) -> pd.DataFrame:
    """One row per method and per same-run reference: ms on the 256-plane and (spike methods) 41-plane
    windows, per step, threads, load, and the verdict of the method's target."""
    import pandas as pd
    from bench.harness import timer

    created = timer.create_methods(names, weights_dir=weights_dir, device=device)
    needs = {m for method, _ in created.values() if method is not None for m in method.inputs}
    if "snm" in names or "tfstp" in names:
        needs.add("spikes")
    sample = timer.representative_sample(WIDTH, HEIGHT, modalities=sorted(needs)) if needs else None
    short = timer.cut_spike_window(sample, REFERENCE_PLANES) if sample is not None and sample.spikes is not None else None
    threads = thread_counts()
    load_before = load_average()
    rows = []
    for name in names:
        method, reason = created[name]
        info = timer.method_info(name, method)
        row: dict[str, Any] = {"method": name, "family": info["family"], "parameters": info["parameters"],
                               "status": "ok", "error": ""}
        if method is None:
            status, _, msg = reason.partition(": ")
            row.update(status=status, error=msg)
        else:
            try:
                full = timer.time_method(method, sample, repeats=repeats, warmup=warmup).row()
                row.update(ms_256_median=full["median_ms"], ms_256_min=full["min_ms"], ms_256_max=full["max_ms"])
                if not math.isnan(full["steps"]):
                    row.update(steps=full["steps"], ms_step_median=full["ms_per_frame"],
                               ms_step_min=full["min_frame_ms"], ms_step_max=full["max_frame_ms"])
                if info["family"] == "spike" and short is not None:
                    cut = timer.time_method(method, short, repeats=repeats, warmup=warmup).row()
                    row.update(ms_41_median=cut["median_ms"], ms_41_min=cut["min_ms"], ms_41_max=cut["max_ms"])
                    if _TFP.covers(name):
                        row["window_41"] = tfp_window_planes(method, short.spikes.num_planes)
            except Exception as exc:  # a failing method is a row
                row.update(status="error", error=one_line(exc))
        if log:
            log(f"{name}: " + (_spread(row, "ms_256") + " ms" if row["status"] == "ok" else f"{row['status']} ({row['error']})"))
        rows.append(row)
    for row in reference_rows(names, created, sample, short, repeats=repeats, warmup=warmup):
        if log:
            log(f"{row['method']}: " + _spread(row, "ms_256" if "ms_256_median" in row else "ms_41") + " ms")
        rows.append(row)
    load_after = load_average()
    for row in rows:
        row.update(threads)
        row.update(load_before=load_before, load_after=load_after)
    cols = ["method", "family", "status", "ms_256_median", "ms_256_min", "ms_256_max", "ms_41_median", "ms_41_min",
            "ms_41_max", "window_41", "steps", "ms_step_median", "ms_step_min", "ms_step_max", "reference", "target",
            "limit_ms", "ratio", "verdict", "parameters", "torch_threads", "numba_threads", "load_before",
            "load_after", "error"]
    return judge(pd.DataFrame(rows)).reindex(columns=cols)


def markdown(frame: pd.DataFrame, repeats: int, warmup: int, machine: str) -> str:
    """The benchmark's table: median [min-max] ms per frame beside the references, targets and verdicts."""
    import pandas as pd
    from bench.reporting import tables as tb

    rows = []
    methods = frame[~frame["method"].astype(str).str.startswith("ref:")]
    refs = frame[frame["method"].astype(str).str.startswith("ref:")]
    order = {m: i for i, m in enumerate(tb.timing_method_order(methods))}
    methods = methods.iloc[sorted(range(len(methods)), key=lambda i: order[str(methods["method"].iloc[i])])]
    for _, r in pd.concat([methods, refs]).iterrows():
        d = r.to_dict()
        status = "" if d["status"] == "ok" else f" ({d['status']})"
        rows.append([d["method"] + status, _spread(d, "ms_256"), _spread(d, "ms_41"), _spread(d, "ms_step"),
                     d["reference"], d["target"], d["verdict"]])
    first = frame.iloc[0] if len(frame) else {}
    text = (f"# Method speed at {WIDTH}x{HEIGHT}\n\nms per reconstructed frame, median [min-max] of {repeats} timed "
            f"calls after {warmup} warm-up call(s) (torch reference of snm: at most 3), on {machine or 'this machine'}; "
            f"torch threads {first.get('torch_threads', '-')}, numba threads {first.get('numba_threads', '-')}; "
            f"1-minute load average {first.get('load_before', math.nan):.2f} before, "
            f"{first.get('load_after', math.nan):.2f} after. T=256: the sweeps' 256-plane window; T=41: spike methods "
            "on the 41 planes around the key plane (the references' window); per step: recurrent methods, per event "
            "voxel grid. Rows ref:... are references measured in this run.\n\n"
            + tb.markdown_table(["method", "T=256", "T=41", "per step", "reference", "target", "verdict"], rows,
                                ["l", "r", "r", "r", "l", "l", "l"]))
    lines = verdict_lines(frame)
    if lines:
        text += "\nVerdicts:\n\n" + "".join(f"- {line}\n" for line in lines)
    bad = frame[frame["status"] != "ok"]
    if len(bad):
        text += "\nNot timed:\n\n" + "".join(f"- {r.method} ({r.status}): {r.error}\n" for r in bad.itertuples())
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.method_speed",
        description=f"ms per reconstructed frame of every registered method at {WIDTH}x{HEIGHT} (median of several "
        "timed calls after warm-up), beside references measured in the same run, with a verdict per speed target.",
    )
    parser.add_argument("--methods", help="comma-separated registry names (default: every registered method)")
    parser.add_argument("--repeats", type=int, default=7, help="timed calls per method (default 7)")
    parser.add_argument("--warmup", type=int, default=1, help="untimed calls first (default 1)")
    parser.add_argument("--threads", type=int,
                        help="torch and numba threads, both pinned (default: the CPUs this process may use)")
    MethodOptions.add_arguments(parser, flags=("weights",))
    parser.add_argument("--out", help="also write method_speed.csv and method_speed.md into this folder")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from bench.reporting import tables as tb
    from bench.harness import timer
    from bench.harness.provenance import machine
    from neuspike.utils.atomic import write_text

    try:
        if args.out:
            from neuspike.formats.staging import check_writable_folder

            # before measuring, not after; created by the first write, so a refusal leaves no folder
            check_writable_folder(Path(args.out), what="--out", create=False)
        weights = MethodOptions.from_args(args).weights_dir
        pin_threads(timer.check_count("--threads", args.threads, 1) if args.threads is not None else usable_cpus())
        names = timer.method_names(args.methods)
        frame = measure(names, repeats=args.repeats, warmup=args.warmup, weights_dir=weights,
                        log=lambda s: print(s, file=sys.stderr, flush=True))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    text = markdown(frame, args.repeats, args.warmup, machine().get("cpu_model") or "")
    print(text)
    if args.out:
        out = Path(args.out)
        write_text(out / "method_speed.csv", tb.to_csv_text(frame))
        write_text(out / "method_speed.md", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
