"""Margins of the networks trained here on the full sweeps (the tables of the learned-method notes).

    python -m bench.reporting.margins reports/light reports/motion reports/noise > reports/margins.md

(``python -m bench.rebuild`` writes ``reports/margins.md`` over every committed sweep.)

For every point of each sweep (mean over scenes and seeds of the ok cells, as the sweep tables):

* ``neuspike-net`` against the best *other* method (its own spike-only variant excluded, shown
  beside it), in PSNR and SSIM, with the margin;
* fusion over spike-only: ``neuspike-net`` minus ``neuspike-net-spike``;
* the noise sweep's PSNR lost from small to high noise;
* ``e2vid`` and ``firenet-sim`` against the published ``firenet`` in mean SSIM per sweep and per point;
* the held targets at each point: ``neuspike-net``'s raw PSNR within 1 dB of its affine-aligned PSNR,
  the fusion not below its spike-only variant by more than 0.02 dB or 0.001 SSIM, and its specks
  (isolated outliers, :func:`neuspike.metrics.isolated_outliers`) at or below SNM's.

A light x noise folder (both axes swept) is read one noise level at a time, along the light axis.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from bench.reporting.build import results_file
from bench.harness.results import read_csv
from bench.reporting.tables import axis_label, axis_means, crossed_axes, swept_axes

NET, SPIKE = "neuspike-net", "neuspike-net-spike"
#: The compact variants and the full network each is held to.
LITE = {"neuspike-net-lite": NET, "neuspike-net-spike-lite": SPIKE}
#: The networks trained here: never a rival of one another in the margins.
OURS = (NET, SPIKE, *LITE)
#: The networks not trained here (the rest are classical methods).
PUBLISHED_NETS = ("e2vid", "firenet-sim", "firenet", "firenet-plus")


def _point_table(frame: pd.DataFrame, axis: str) -> str:
    lines = [f"| {axis} | metric | `{NET}` | best other | its value | margin | `{SPIKE}` |",
             "|---|---|---:|---|---:|---:|---:|"]
    for metric in ("psnr", "ssim"):
        wide = axis_means(frame, axis, metric)
        if NET not in wide.index:
            return f"`{NET}` has no ok rows in this sweep.\n"
        digits = 2 if metric == "psnr" else 3
        for v in wide.columns:
            others = wide.loc[[m for m in wide.index if m not in OURS], v].dropna()
            best = others.idxmax()
            ours = wide.loc[NET, v]
            margin = ours - others.max()
            spike = wide.loc[SPIKE, v] if SPIKE in wide.index else float("nan")
            mark = "**" if margin > 0 else ""
            lines.append(f"| {axis_label(axis, v)} | {metric.upper()} | {ours:.{digits}f} | `{best}` | "
                         f"{others.max():.{digits}f} | {mark}{margin:+.{digits}f}{mark} | {spike:.{digits}f} |")
    return "\n".join(lines) + "\n"


def _fusion_gain(frame: pd.DataFrame, axis: str) -> str:
    wide = axis_means(frame, axis, "psnr")
    if NET not in wide.index or SPIKE not in wide.index:
        return ""
    gain = wide.loc[NET] - wide.loc[SPIKE]
    points = ", ".join(f"{axis_label(axis, v)}: {gain[v]:+.2f}" for v in gain.index)
    return f"Fusion over spike-only (PSNR dB): mean {gain.mean():+.2f}; {points}.\n"


def _event_nets(frame: pd.DataFrame, axis: str) -> str:
    wide = axis_means(frame, axis, "ssim")
    names = [m for m in ("e2vid", "firenet-sim", "firenet", "firenet-plus") if m in wide.index]
    if "firenet" not in names:
        return ""
    lines = [f"| {axis} | " + " | ".join(f"`{m}`" for m in names) + " | `e2vid` - `firenet` |",
             "|---|" + "---:|" * (len(names) + 1)]
    for v in list(wide.columns) + ["mean"]:
        row = [wide.loc[m].mean() if v == "mean" else wide.loc[m, v] for m in names]
        diff = (row[names.index("e2vid")] - row[names.index("firenet")]) if "e2vid" in names else float("nan")
        label = "**mean**" if v == "mean" else axis_label(axis, v)
        lines.append(f"| {label} | " + " | ".join(f"{x:.3f}" for x in row) + f" | {diff:+.3f} |")
    return "Mean SSIM of the recurrent event networks:\n\n" + "\n".join(lines) + "\n"


def _targets(frame: pd.DataFrame, axis: str) -> str:
    """The held targets per point, each marked met (yes) or missed (NO)."""
    means = {m: axis_means(frame, axis, m) for m in ("psnr", "psnr_affine", "ssim", "specks")}
    if NET not in means["psnr"].index:
        return ""
    lines = [f"| {axis} | raw - aligned PSNR | fusion - spike-only PSNR | fusion - spike-only SSIM | "
             f"specks `{NET}` / `snm` (per mille) |", "|---|---:|---:|---:|---:|"]

    def get(metric: str, method: str, v) -> float:
        wide = means[metric]
        return float(wide.loc[method, v]) if method in wide.index and v in wide.columns else float("nan")

    def mark(ok: bool) -> str:
        return "yes" if ok else "**NO**"

    for v in means["psnr"].columns:
        gap = get("psnr", NET, v) - get("psnr_affine", NET, v)
        dp, ds = get("psnr", NET, v) - get("psnr", SPIKE, v), get("ssim", NET, v) - get("ssim", SPIKE, v)
        ours, snm = get("specks", NET, v), get("specks", "snm", v)
        specks = (f"{1000 * ours:.2f} / {1000 * snm:.2f} {mark(ours <= snm)}" if ours == ours and snm == snm else "-")
        lines.append(f"| {axis_label(axis, v)} | {gap:+.2f} {mark(gap >= -1.0)} | {dp:+.2f} {mark(dp >= -0.02)} | "
                     f"{ds:+.4f} {mark(ds >= -0.001)} | {specks} |")
    return "Targets at each point:\n\n" + "\n".join(lines) + "\n"


def _lite(frame: pd.DataFrame, axis: str) -> str:
    """Each compact variant against its full network (within 0.5 dB PSNR and 0.005 SSIM) and against the
    best classical method that reads nothing it does not read (above it), per point, each marked met
    (yes) or missed (NO)."""
    wide = {m: axis_means(frame, axis, m) for m in ("psnr", "ssim")}
    present = [m for m in LITE if m in wide["psnr"].index and LITE[m] in wide["psnr"].index]
    if not present:
        return ""
    classical = [m for m in wide["psnr"].index if m not in OURS and m not in PUBLISHED_NETS]
    inputs = frame.groupby("method")["inputs"].first().astype(str)
    lines = [f"| {axis} | network | - full PSNR | - full SSIM | - best classical PSNR | - best classical SSIM |",
             "|---|---|---:|---:|---:|---:|"]

    def mark(ok: bool) -> str:
        return "yes" if ok else "**NO**"

    for v in wide["psnr"].columns:
        for lite in present:
            full = LITE[lite]
            # the rivals: classical methods that read nothing the network does not read
            mine = set(inputs[lite].split("+"))
            rivals = [m for m in classical if set(inputs[m].split("+")) <= mine]
            dp = wide["psnr"].loc[lite, v] - wide["psnr"].loc[full, v]
            ds = wide["ssim"].loc[lite, v] - wide["ssim"].loc[full, v]
            cp = wide["psnr"].loc[lite, v] - wide["psnr"].loc[rivals, v].max()
            cs = wide["ssim"].loc[lite, v] - wide["ssim"].loc[rivals, v].max()
            lines.append(f"| {axis_label(axis, v)} | `{lite}` | {dp:+.2f} {mark(dp >= -0.5)} | {ds:+.4f} {mark(ds >= -0.005)} "
                         f"| {cp:+.2f} {mark(cp > 0)} | {cs:+.3f} {mark(cs > 0)} |")
    return "Compact networks at each point:\n\n" + "\n".join(lines) + "\n"


def _sections(frame: pd.DataFrame, folder: str) -> list[tuple[str, pd.DataFrame, str]]:
    """(heading, rows, axis) for each table: every swept axis, or the light axis at each noise level."""
    crossed = crossed_axes(frame)
    if crossed is None:
        return [(f"{folder}: {axis}", frame, axis) for axis in swept_axes(frame)]
    axis, by = crossed
    return [(f"{folder}: {axis} at {by} {level}", frame[frame[by] == level], axis)
            for level in [v for v in ("none", "small", "medium", "high") if v in set(frame[by])]]


def margins_markdown(folders: list[str | Path]) -> str:
    """The margins page over these results folders (each ``results.csv`` or ``results.csv.gz``)."""
    out = ["# Margins of the networks trained here on the full sweeps\n",
           "Generated by `python -m bench.rebuild` (`python -m bench.reporting.margins FOLDER...`) from each folder's "
           "`results.csv` (mean over scenes and seeds of the ok cells). Margin: `neuspike-net` minus the best "
           "other method (its spike-only variant excluded); bold where `neuspike-net` is best.\n"]
    for folder in folders:
        folder = Path(folder).as_posix()
        whole = read_csv(results_file(folder))
        for heading, frame, axis in _sections(whole, folder):
            out.append(f"\n## {heading}\n\n")
            out.append(_point_table(frame, axis))
            out.append("\n" + _fusion_gain(frame, axis))
            out.append("\n" + _targets(frame, axis))
            lite = _lite(frame, axis)
            if lite:
                out.append("\n" + lite)
            if axis == "noise":
                wide = axis_means(frame, axis, "psnr")
                if NET in wide.index and {"small", "high"} <= set(wide.columns):
                    lost = {m: wide.loc[m, "small"] - wide.loc[m, "high"] for m in wide.index}
                    best = min((m for m in lost if m not in OURS), key=lambda m: lost[m])
                    out.append(f"\nPSNR lost from small to high noise: `{NET}` {lost[NET]:.2f} dB, `{SPIKE}` "
                               f"{lost.get(SPIKE, float('nan')):.2f} dB; least among the others: `{best}` "
                               f"{lost[best]:.2f} dB.\n")
            out.append("\n" + _event_nets(frame, axis))
    return "".join(out)


def main(argv: list[str] | None = None) -> int:
    folders = sys.argv[1:] if argv is None else argv
    if not folders:
        print("usage: python -m bench.reporting.margins RESULTS_DIR... (each with results.csv or results.csv.gz)", file=sys.stderr)
        return 2
    try:
        sys.stdout.write(margins_markdown(folders))
    except (FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
