"""Milliseconds per reconstructed frame of every method at 400x250: ``python -m bench.method_speed``.

Every registered method (or ``--methods``) reconstructs from one representative recording at the
Vidar size, 400x250 (:func:`bench.timing.representative_sample`: the ``camera`` photograph panning,
L = 1/4, S = 128, a 256-plane window, events with one window of history): ``--warmup`` untimed calls,
then the median and spread of ``--repeats`` timed calls, each after ``reset()``
(:func:`bench.timing.time_method`, the same code as Table 2).

Columns
    ``T=256``    ms per call on the full 256-plane window (the sweeps' window)
    ``T=41``     spike methods only: ms per call on the 41 planes around the key plane, the window
                 shape of the Spike-Zoo reference figures ((41, 250, 400))
    ``per step`` recurrent methods: ms per network step (one event voxel grid): the call divided
                 by the event windows it processed

Reference figures (measured on this machine class, or published) and targets
    ``tfp``  Spike-Zoo's TFP 0.19 ms on a (41, 250, 400) window; target: no slower (T=41)
    ``tfi``  Spike-Zoo's TFI 1.99 ms on a (41, 250, 400) window; target: no slower (T=41)
    ``tfstp``  SpikeCV's TFSTP 23 s per frame on a GPU; target under 200 ms (T=256)
    ``snm``  target under 1 s (T=256)
    ``firenet``  the FireNet paper's CPU figure 56 ms (10-core Xeon); target under 30 ms per voxel grid

The TFP target applies to every TFP variant (``tfp-w*``) and the FireNet target to ``firenet-plus``.
Timings on a shared 2-core machine are noisy: the spread (min-max) is printed with each median.

    python -m bench.method_speed [--methods tfp,tfi] [--repeats 7] [--warmup 1] [--weights DIR]
                                 [--threads N] [--out DIR]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import pandas as pd

from bench import tables as tb
from bench import timing
from neuspike.errors import InputError

WIDTH, HEIGHT = 400, 250
REFERENCE_PLANES = 41


@dataclass(frozen=True)
class Target:
    """A speed target: the methods it covers (a name, and its ``name-*`` variants), which column it
    reads (``"ms_41"``, ``"ms_256"`` or ``"ms_step"``), the limit in ms, and the reference figure."""

    name: str
    column: str
    limit_ms: float
    reference: str

    def covers(self, method: str) -> bool:
        return method == self.name or method.startswith(self.name + "-")


TARGETS: tuple[Target, ...] = (
    Target("tfp", "ms_41", 0.19, "Spike-Zoo TFP 0.19 ms, (41, 250, 400) window"),
    Target("tfi", "ms_41", 1.99, "Spike-Zoo TFI 1.99 ms, (41, 250, 400) window"),
    Target("tfstp", "ms_256", 200.0, "SpikeCV TFSTP 23 s per frame on a GPU"),
    Target("snm", "ms_256", 1000.0, "-"),
    Target("firenet", "ms_step", 30.0, "FireNet paper CPU 56 ms (10-core Xeon)"),
)
COLUMN_TEXT = {"ms_41": "T=41", "ms_256": "T=256", "ms_step": "per step"}


def target_of(method: str) -> Target | None:
    """The target covering ``method``, or ``None``."""
    return next((t for t in TARGETS if t.covers(method)), None)


def _spread(row: dict[str, Any], prefix: str) -> str:
    med = row.get(f"{prefix}_median")
    if med is None or (isinstance(med, float) and math.isnan(med)):
        return "-"
    return f"{tb.fmt(med, 'ms')} [{tb.fmt(row[f'{prefix}_min'], 'ms')}-{tb.fmt(row[f'{prefix}_max'], 'ms')}]"


def measure(names: Sequence[str], *, repeats: int, warmup: int, weights_dir=None, device: str = "cpu",
            log=None) -> pd.DataFrame:
    """One row per method: ms on the 256-plane and (spike methods) 41-plane windows, per step, verdict."""
    import torch

    created = timing.create_methods(names, weights_dir=weights_dir, device=device)
    needs = {m for method, _ in created.values() if method is not None for m in method.inputs}
    sample = timing.representative_sample(WIDTH, HEIGHT, modalities=sorted(needs)) if needs else None
    short = timing.cut_spike_window(sample, REFERENCE_PLANES) if sample is not None and sample.spikes is not None else None
    rows = []
    for name in names:
        method, reason = created[name]
        info = timing.method_info(name, method)
        row: dict[str, Any] = {"method": name, "family": info["family"], "parameters": info["parameters"],
                               "threads": torch.get_num_threads(), "status": "ok", "error": ""}
        if method is None:
            status, _, msg = reason.partition(": ")
            row.update(status=status, error=msg)
        else:
            try:
                full = timing.time_method(method, sample, repeats=repeats, warmup=warmup).row()
                row.update(ms_256_median=full["median_ms"], ms_256_min=full["min_ms"], ms_256_max=full["max_ms"])
                if not math.isnan(full["steps"]):
                    row.update(steps=full["steps"], ms_step_median=full["ms_per_frame"],
                               ms_step_min=full["min_frame_ms"], ms_step_max=full["max_frame_ms"])
                if info["family"] == "spike" and short is not None:
                    cut = timing.time_method(method, short, repeats=repeats, warmup=warmup).row()
                    row.update(ms_41_median=cut["median_ms"], ms_41_min=cut["min_ms"], ms_41_max=cut["max_ms"])
            except Exception as exc:  # a failing method is a row
                row.update(status="error", error=timing.one_line(exc))
        target = target_of(name)
        row["reference"] = target.reference if target else "-"
        row["target"] = f"< {target.limit_ms:g} ms ({COLUMN_TEXT[target.column]})" if target else "-"
        value = row.get(f"{target.column}_median") if target else None
        if target is None or value is None or row["status"] != "ok":
            row["verdict"] = "-" if target is None else "not measured"
        else:
            row["verdict"] = "meets" if value <= target.limit_ms else "misses"
        if log:
            log(f"{name}: " + (_spread(row, "ms_256") + " ms" if row["status"] == "ok" else f"{row['status']} ({row['error']})"))
        rows.append(row)
    cols = ["method", "family", "status", "ms_256_median", "ms_256_min", "ms_256_max", "ms_41_median", "ms_41_min",
            "ms_41_max", "steps", "ms_step_median", "ms_step_min", "ms_step_max", "reference", "target", "verdict",
            "parameters", "threads", "error"]
    return pd.DataFrame(rows).reindex(columns=cols)


def markdown(frame: pd.DataFrame, repeats: int, warmup: int, machine: str) -> str:
    """The benchmark's table: median [min-max] ms per frame beside the references and targets."""
    rows = []
    order = {m: i for i, m in enumerate(tb.timing_method_order(frame))}
    frame = frame.iloc[sorted(range(len(frame)), key=lambda i: order[str(frame["method"].iloc[i])])]
    for _, r in frame.iterrows():
        d = r.to_dict()
        status = "" if d["status"] == "ok" else f" ({d['status']})"
        rows.append([d["method"] + status, _spread(d, "ms_256"), _spread(d, "ms_41"), _spread(d, "ms_step"),
                     d["reference"], d["target"], d["verdict"]])
    threads = sorted({int(t) for t in frame["threads"].dropna()})
    text = (f"# Method speed at {WIDTH}x{HEIGHT}\n\nms per reconstructed frame, median [min-max] of {repeats} timed "
            f"calls after {warmup} warm-up call(s), on {machine or 'this machine'}, torch threads "
            f"{','.join(map(str, threads))}. T=256: the sweeps' 256-plane window; T=41: spike methods on the 41 planes "
            "around the key plane (the references' window); per step: recurrent methods, per event voxel grid.\n\n"
            + tb.markdown_table(["method", "T=256", "T=41", "per step", "reference", "target", "verdict"], rows,
                                ["l", "r", "r", "r", "l", "l", "l"]))
    bad = frame[frame["status"] != "ok"]
    if len(bad):
        text += "\nNot timed:\n\n" + "".join(f"- {r.method} ({r.status}): {r.error}\n" for r in bad.itertuples())
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.method_speed",
        description=f"ms per reconstructed frame of every registered method at {WIDTH}x{HEIGHT} (median of several "
        "timed calls after warm-up), beside the reference figures and the speed targets.",
    )
    parser.add_argument("--methods", help="comma-separated registry names (default: every registered method)")
    parser.add_argument("--repeats", type=int, default=7, help="timed calls per method (default 7)")
    parser.add_argument("--warmup", type=int, default=1, help="untimed calls first (default 1)")
    parser.add_argument("--threads", type=int, help="torch intra-op threads (default: torch's own choice)")
    parser.add_argument("--weights", help="folder of published weights (default: $NEUSPIKE_WEIGHTS)")
    parser.add_argument("--out", help="also write method_speed.csv and method_speed.md into this folder")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    import torch

    from neuspike.atomic import write_text
    from neuspike.weights import weights_dir_from_env
    from bench.provenance import machine

    args = build_parser().parse_args(argv)
    try:
        weights = weights_dir_from_env(args.weights)
        if weights is not None and not weights.is_dir():
            raise InputError(f"weights folder {str(weights)!r} is not a folder")
        if args.threads is not None:
            torch.set_num_threads(timing.check_count("--threads", args.threads, 1))
        names = timing.method_names(args.methods)
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
