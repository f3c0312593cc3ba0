"""Tables of a results folder: aggregations of ``results.csv`` and their Markdown and CSV forms.

Every function here is a pure function of the results DataFrame (the long form of
:mod:`bench.harness.results`: one row per method, scene, condition, seed and metric). Only rows with
``status == "ok"`` and a non-missing ``value`` enter an average; failed and skipped methods are
listed in their own table (:func:`failures_table`) rather than shrinking an average.

Aggregation
    A method's value at an axis value is the mean over every scene and seed (and over the other
    axes' values, which a preset holds fixed); the spread is the sample standard deviation over
    the same rows, with their minimum, maximum and count.

Method families
    From the ``inputs`` column (``spikes``, ``events``, ``events+spikes``); where a row does not
    carry it (e.g. a method whose creation failed), from the registry entry
    (``neuspike.methods.entry(name).inputs``) when the method is registered here. ``spikes`` only:
    the *spike* family; ``events`` only: *event*; both: *fusion*; otherwise *unknown*.

Text output is deterministic: the same results give byte-identical Markdown and CSV files.
"""

from __future__ import annotations

import io
import math
import re
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from bench.harness.cells import METRICS
from bench.harness.axes import AXES, AXIS
from bench.harness.results import family_of

METRIC_LABELS: Mapping[str, str] = {
    "psnr": "PSNR (dB)", "ssim": "SSIM", "psnr_affine": "PSNR, affine-aligned (dB)",
    "ssim_affine": "SSIM, affine-aligned",
    "static_texture": "static texture (gradient correlation over the static regions)",
    "specks": "isolated outliers (per mille of pixels; lower is better)",
}
#: Method families, in the order they are listed.
FAMILIES: tuple[str, ...] = ("spike", "event", "fusion", "unknown")
#: Table 3 of the paper (NeuSpike-Net, ICCV 2021): noise level -> {method: (PSNR dB, SSIM)}.
PAPER_TABLE3: Mapping[str, Mapping[str, tuple[float, float]]] = {
    "small": {"E2VID": (14.76, 0.6463), "TFI": (21.76, 0.6911), "NeuSpike-Net": (26.07, 0.8578)},
    "medium": {"E2VID": (13.68, 0.5381), "TFI": (21.03, 0.6395), "NeuSpike-Net": (25.84, 0.8503)},
    "high": {"E2VID": (11.03, 0.3068), "TFI": (18.56, 0.5259), "NeuSpike-Net": (25.48, 0.8009)},
}
#: What each paper method consumed (for the reader of Table 3).
PAPER_TABLE3_INPUTS: Mapping[str, str] = {"E2VID": "events", "TFI": "spikes", "NeuSpike-Net": "events+spikes"}
#: Our method in each column of the paper's Table 3 (E2VID: the network trained here on the simulator).
PAPER_TABLE3_OURS: Mapping[str, str] = {"E2VID": "e2vid", "TFI": "tfi", "NeuSpike-Net": "neuspike-net"}

OK = "ok"


# ----------------------------------------------------------------------------------------------
# Selecting and classifying rows
# ----------------------------------------------------------------------------------------------

def ok_rows(frame: pd.DataFrame, metric: str | None = None) -> pd.DataFrame:
    """Rows with ``status == "ok"`` and a value (optionally of one ``metric``)."""
    keep = (frame["status"].astype(str) == OK) & frame["value"].notna()
    if metric is not None:
        keep &= frame["metric"] == metric
    return frame[keep]


def method_inputs(frame: pd.DataFrame) -> dict[str, frozenset[str]]:
    """The modalities of every method in ``frame`` (module docstring: where they come from)."""
    out: dict[str, frozenset[str]] = {}
    has_col = "inputs" in frame.columns
    for method in pd.unique(frame["method"]):
        ins: frozenset[str] = frozenset()
        if has_col:
            texts = [str(t) for t in frame.loc[frame["method"] == method, "inputs"] if str(t) not in ("", "nan")]
            if texts:
                ins = frozenset(texts[0].split("+"))
        if not ins:
            ins = _registry_inputs(str(method))
        out[str(method)] = ins
    return out


def _registry_inputs(name: str) -> frozenset[str]:
    try:
        from neuspike import methods as registry

        return frozenset(registry.entry(name).inputs)
    except Exception:  # not registered here, or the registry cannot load: family unknown
        return frozenset()


def method_families(frame: pd.DataFrame) -> dict[str, str]:
    """``{method: family}`` for every method in ``frame``."""
    return {m: family_of(ins) for m, ins in method_inputs(frame).items()}


def natural_key(name: str) -> tuple:
    """Sort key that orders embedded numbers by value (``tfp-w8`` before ``tfp-w16``)."""
    return tuple((0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", str(name)) if t)


def method_order(frame: pd.DataFrame) -> list[str]:
    """Methods by family (spike, event, fusion, unknown), then by name (numbers by value)."""
    fam = method_families(frame)
    return sorted(fam, key=lambda m: (FAMILIES.index(fam[m]), natural_key(m)))


def swept_axes(frame: pd.DataFrame) -> list[str]:
    """The axes of :data:`AXES` with more than one distinct value among the rows."""
    return [a for a in AXES if a in frame.columns and frame[a].nunique(dropna=True) > 1]


def axis_values(frame: pd.DataFrame, axis: str) -> list[Any]:
    """The distinct values of ``axis`` in its order (:meth:`bench.harness.axes.Axis.ordered`)."""
    return AXIS[axis].ordered(pd.unique(frame[axis].dropna()))


def axis_label(axis: str, value: Any) -> str:
    """How an axis value is written: ``1/32`` for light, ``128`` for motion, the noise level's name."""
    return AXIS[axis].label(value) if axis in AXIS else str(value)


AXIS_TITLES: Mapping[str, str] = {name: a.title for name, a in AXIS.items()}


# ----------------------------------------------------------------------------------------------
# Aggregations
# ----------------------------------------------------------------------------------------------

#: The condition axes; comparing along one holds the others fixed.
CONDITION_AXES = ("light", "motion", "noise")


def comparable_rows(frame: pd.DataFrame, axis: str) -> pd.DataFrame:
    """The rows that compare like with like along ``axis``.

    Along one axis, the other condition axes must take the same values at every point: a folder
    that merges sweeps (a light and a motion sweep at noise "none", a noise sweep at L = 1/4,
    S = 128) would otherwise average "none" over every light and motion cell and put it beside
    noise levels measured at one condition. Only the combinations of the other axes present at
    every value of ``axis`` are kept (all rows, when nothing was merged).
    """
    others = [c for c in CONDITION_AXES if c != axis and c in frame.columns]
    if not others or axis not in frame.columns or frame.empty:
        return frame
    keys = frame[others].astype(str).agg("|".join, axis=1)
    common = None
    for _, part in keys.groupby(frame[axis].astype(str), sort=False):
        present = set(part)
        common = present if common is None else common & present
    return frame[keys.isin(common or set())]


def held_conditions(frame: pd.DataFrame, axis: str) -> str:
    """What each point along ``axis`` averages over, e.g. ``"at L = 1/4, S = 128, noise none"``."""
    rows = comparable_rows(frame, axis)
    parts = []
    for other, name in (("light", "L"), ("motion", "S"), ("noise", "noise")):
        if other == axis or other not in rows.columns:
            continue
        values = axis_values(rows, other)
        shown = ", ".join(axis_label(other, v) for v in values)
        sep = " " if other == "noise" else " = "
        parts.append(f"{name}{sep}{shown}" if len(values) == 1 else f"{name} in {{{shown}}}")
    return ("at " + ", ".join(parts)) if parts else ""


def axis_summary(frame: pd.DataFrame, axis: str, metric: str) -> pd.DataFrame:
    """Mean and spread of ``metric`` per method and ``axis`` value over scenes and seeds.

    Only rows that compare like with like enter (:func:`comparable_rows`).

    Returns
    -------
    DataFrame with columns ``method, <axis>, mean, std, min, max, n`` (``std`` is NaN for a single
    row), sorted by method order then axis value. Methods without an ok row are absent.
    """
    rows = ok_rows(comparable_rows(frame, axis), metric)
    cols = ["method", axis, "mean", "std", "min", "max", "n"]
    if rows.empty:
        return pd.DataFrame(columns=cols)
    g = rows.groupby(["method", axis], sort=False)["value"]
    out = pd.DataFrame({"mean": g.mean(), "std": g.std(ddof=1), "min": g.min(), "max": g.max(),
                        "n": g.size()}).reset_index()
    order = {m: i for i, m in enumerate(method_order(frame))}
    vals = {v: i for i, v in enumerate(axis_values(frame, axis))}
    out = out.assign(_m=out["method"].map(order), _v=out[axis].map(vals))
    out = out.sort_values(["_m", "_v"], kind="mergesort").drop(columns=["_m", "_v"]).reset_index(drop=True)
    return out[cols]


def axis_means(frame: pd.DataFrame, axis: str, metric: str = "psnr") -> pd.DataFrame:
    """Wide table of means: index method (method order), columns the axis values in order."""
    s = axis_summary(frame, axis, metric)
    if s.empty:
        return pd.DataFrame()
    wide = s.pivot(index="method", columns=axis, values="mean")
    methods = [m for m in method_order(frame) if m in wide.index]
    values = [v for v in axis_values(frame, axis) if v in wide.columns]
    return wide.loc[methods, values]


def method_summary(frame: pd.DataFrame) -> pd.DataFrame:
    """One row per method: family, inputs, parameters, normalisation, cell counts, mean metrics, time.

    ``cells_ok``, ``cells_error``, ``cells_skipped`` count cells (scene, condition, seed) by status;
    metric columns are means over the ok rows; ``ms_per_frame`` is the median over ok cells.
    """
    fam = method_families(frame)
    ins = method_inputs(frame)
    cell_key = [c for c in ("scene", "light", "motion", "noise", "seed") if c in frame.columns]
    records = []
    for method in method_order(frame):
        rows = frame[frame["method"] == method]
        cells = rows.drop_duplicates(cell_key)
        status = cells["status"].astype(str)
        ok = ok_rows(rows)
        rec: dict[str, Any] = {
            "method": method, "family": fam[method], "inputs": "+".join(sorted(ins[method])),
            "parameters": int(rows["parameters"].max()) if "parameters" in rows and rows["parameters"].notna().any() else 0,
            "normalisation": summarise_notes(ok.drop_duplicates(cell_key).get("normalisation", pd.Series(dtype=str))),
            "cells_ok": int((status == OK).sum()), "cells_error": int((status == "error").sum()),
            "cells_skipped": int((status == "skipped").sum()),
        }
        for metric in METRICS:
            vals = ok.loc[ok["metric"] == metric, "value"]
            rec[metric] = float(vals.mean()) if len(vals) else math.nan
        ok_cells = ok.drop_duplicates(cell_key)
        ms = ok_cells["ms_per_frame"].dropna() if "ms_per_frame" in ok_cells else pd.Series(dtype=float)
        rec["ms_per_frame"] = float(ms.median()) if len(ms) else math.nan
        records.append(rec)
    cols = ["method", "family", "inputs", "parameters", "normalisation", "cells_ok", "cells_error",
            "cells_skipped", *METRICS, "ms_per_frame"]
    return pd.DataFrame(records, columns=cols)


def summarise_notes(notes: pd.Series) -> str:
    """A method's normalisation notes over its cells in one short line: each distinct note once (numbers
    written ``#``, so "warmed up on 13 of 24 windows" and "... 9 of 24 ..." are one note), with its
    number of cells where not every cell has it. The detail of each cell stays in ``results.csv``.
    """
    texts = [str(n) for n in notes if str(n) not in ("", "nan")]
    counts: dict[str, int] = {}
    for text in texts:
        for part in dict.fromkeys(p.strip() for p in text.split(";") if p.strip()):
            key = re.sub(r"\b\d+(?:\.\d+)?\b", "#", part)  # standalone numbers only (robust-p99 stays)
            counts[key] = counts.get(key, 0) + 1
    return "; ".join(k if n == len(texts) else f"{k} ({n} of {len(texts)} cells)" for k, n in counts.items())


def failures_table(frame: pd.DataFrame) -> pd.DataFrame:
    """Failed and skipped methods: one row per (method, status, error message) with its cell count."""
    cell_key = [c for c in ("scene", "light", "motion", "noise", "seed") if c in frame.columns]
    bad = frame[frame["status"].astype(str) != OK]
    cols = ["method", "status", "cells", "error"]
    if bad.empty:
        return pd.DataFrame(columns=cols)
    cells = bad.drop_duplicates(["method", *cell_key])
    g = cells.groupby(["method", "status", "error"], sort=True).size().reset_index(name="cells")
    return g[cols].reset_index(drop=True)


def noise_table(frame: pd.DataFrame) -> pd.DataFrame:
    """The paper's Table 3 for our methods: mean PSNR and SSIM per noise level (no paper rows).

    Columns ``method, family, psnr_<level>..., ssim_<level>...`` for the levels present among
    ``small``, ``medium``, ``high``.
    """
    levels = [lv for lv in PAPER_TABLE3 if lv in set(frame["noise"].astype(str))] if "noise" in frame else []
    fam = method_families(frame)
    records = []
    for method in method_order(frame):
        rows = frame[frame["method"] == method]
        rec: dict[str, Any] = {"method": method, "family": fam[method]}
        for metric in ("psnr", "ssim"):
            for lv in levels:
                vals = ok_rows(rows[rows["noise"].astype(str) == lv], metric)["value"]
                rec[f"{metric}_{lv}"] = float(vals.mean()) if len(vals) else math.nan
        records.append(rec)
    cols = ["method", "family", *[f"{m}_{lv}" for m in ("psnr", "ssim") for lv in levels]]
    return pd.DataFrame(records, columns=cols)


def paper_table3() -> pd.DataFrame:
    """The paper's published Table 3 in the layout of :func:`noise_table`."""
    records = []
    for method in ("E2VID", "TFI", "NeuSpike-Net"):
        rec: dict[str, Any] = {"method": method, "inputs": PAPER_TABLE3_INPUTS[method]}
        for i, metric in enumerate(("psnr", "ssim")):
            for lv in PAPER_TABLE3:
                rec[f"{metric}_{lv}"] = PAPER_TABLE3[lv][method][i]
        records.append(rec)
    return pd.DataFrame(records)


# ----------------------------------------------------------------------------------------------
# Accuracy against time and its Pareto front
# ----------------------------------------------------------------------------------------------

def pareto_front(time_ms: Sequence[float], score: Sequence[float]) -> np.ndarray:
    """Which points are on the Pareto front of (lower time, higher score).

    A point is dominated when another point is at least as fast and at least as good, and
    strictly better in one of the two. Points with a missing (NaN) coordinate are never on the front
    and dominate nothing. Identical points are both on the front when neither is dominated.

    Parameters
    ----------
    time_ms, score : sequences of float, same length N

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    t = np.asarray(time_ms, dtype=np.float64)
    s = np.asarray(score, dtype=np.float64)
    if t.shape != s.shape or t.ndim != 1:
        raise ValueError(f"pareto_front: expected two 1-D sequences of one length, got {t.shape} and {s.shape}")
    valid = ~(np.isnan(t) | np.isnan(s))
    front = np.zeros(t.shape, dtype=bool)
    for i in np.flatnonzero(valid):
        others = valid.copy()
        others[i] = False
        dominated = others & (t <= t[i]) & (s >= s[i]) & ((t < t[i]) | (s > s[i]))
        front[i] = not dominated.any()
    return front


def accuracy_points(frame: pd.DataFrame) -> pd.DataFrame:
    """One point per method: median ms per frame and mean PSNR / SSIM over its ok rows.

    Columns ``method, family, ms_per_frame, psnr, ssim, front_psnr, front_ssim`` (the fronts from
    :func:`pareto_front`). Methods without an ok row or without a time are absent.
    """
    summary = method_summary(frame)
    pts = summary.loc[summary["cells_ok"] > 0, ["method", "family", "ms_per_frame", "psnr", "ssim"]]
    pts = pts[pts["ms_per_frame"].notna()].reset_index(drop=True)
    return with_fronts(pts)


def with_fronts(points: pd.DataFrame) -> pd.DataFrame:
    """``points`` (columns ``ms_per_frame``, ``psnr``, ``ssim``) with ``front_psnr``, ``front_ssim``."""
    points = points.copy()
    for metric in ("psnr", "ssim"):
        points[f"front_{metric}"] = pareto_front(points["ms_per_frame"].to_numpy(float),
                                                 points[metric].to_numpy(float)) if len(points) else []
    return points


# ----------------------------------------------------------------------------------------------
# Text forms
# ----------------------------------------------------------------------------------------------

def fmt(value: Any, kind: str = "g") -> str:
    """A cell's text: ``"psnr"`` 2 decimals, ``"ssim"`` 4 decimals, ``"ms"`` 3 significant figures
    (2 below 1, whole numbers from 100), ``"int"``; NaN is written ``-``; anything else ``str``."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else ""
    if kind in ("psnr", "psnr_affine", "db"):
        return f"{float(value):.2f}"
    if kind in ("ssim", "ssim_affine", "static_texture"):
        return f"{float(value):.4f}"
    if kind == "specks":  # a fraction of the pixels, written per mille
        return f"{1000 * float(value):.2f}"
    if kind == "ms":
        v = float(value)
        if math.isinf(v):
            return str(v)
        if abs(v) >= 100:
            return f"{v:.0f}"
        return f"{v:.3g}" if abs(v) >= 1 else f"{v:.2g}" if v else "0"
    if kind == "int":
        return str(int(value))
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]], align: Sequence[str] | None = None) -> str:
    """A GitHub Markdown table; ``align`` holds ``"l"`` or ``"r"`` per column (default: left)."""
    header = [str(h) for h in header]
    body = [[_md_cell(c) for c in r] for r in rows]
    align = list(align) if align is not None else ["l"] * len(header)
    rule = ["---:" if a == "r" else "---" for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(rule) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in body]
    return "\n".join(lines) + "\n"


def _md_cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def to_csv_text(frame: pd.DataFrame) -> str:
    """CSV text with ``\\n`` line ends; floats as ``repr`` (exact), NaN empty."""
    buf = io.StringIO()
    frame.to_csv(buf, index=False, lineterminator="\n")
    return buf.getvalue()


def summary_markdown(summary: pd.DataFrame) -> str:
    header = ["method", "family", "inputs", "params", "normalisation", "ok", "failed", "skipped",
              "PSNR", "SSIM", "PSNR aff.", "SSIM aff.", "ms/frame"]
    rows = [[r.method, r.family, r.inputs, fmt(r.parameters, "int") if r.parameters else "-",
             r.normalisation or "-", fmt(r.cells_ok, "int"), fmt(r.cells_error, "int"),
             fmt(r.cells_skipped, "int"), fmt(r.psnr, "psnr"), fmt(r.ssim, "ssim"),
             fmt(r.psnr_affine, "psnr"), fmt(r.ssim_affine, "ssim"), fmt(r.ms_per_frame, "ms")]
            for r in summary.itertuples()]
    return ("# Methods\n\nMeans over every scene, condition and seed of the ok cells; ms/frame is the "
            "median wall time of one reconstruct call (recurrent methods: including their warm-up).\n\n"
            + markdown_table(header, rows, ["l"] * 5 + ["r"] * 8))


def axis_markdown(frame: pd.DataFrame, axis: str) -> str:
    """Per-method means per axis value, one table per metric (the tables of Figures 3 and 4)."""
    values = axis_values(frame, axis)
    labels = [axis_label(axis, v) for v in values]
    parts = [f"# PSNR and SSIM against the {AXIS_TITLES.get(axis, axis)}\n\n",
             "Mean over scenes and seeds of the ok cells; `-`: no ok cell.\n"]
    for metric in METRICS:
        wide = axis_means(frame, axis, metric)
        parts.append(f"\n## {METRIC_LABELS[metric]}\n\n")
        if wide.empty:
            parts.append("No ok rows.\n")
            continue
        rows = [[m, *[fmt(wide.loc[m, v] if v in wide.columns else math.nan, metric) for v in values]]
                for m in wide.index]
        parts.append(markdown_table([f"method \\ {axis}", *labels], rows, ["l"] + ["r"] * len(values)))
    return "".join(parts)


def crossed_axes(frame: pd.DataFrame) -> tuple[str, str] | None:
    """``("light", "noise")`` when both are swept (the light x noise grid), else None."""
    axes = swept_axes(frame)
    return ("light", "noise") if "light" in axes and "noise" in axes else None


def crossed_markdown(frame: pd.DataFrame, axis: str, by: str) -> str:
    """Per-method means against ``axis`` at each value of ``by``: one table per metric and ``by`` value."""
    parts = [f"# Against the {AXIS_TITLES.get(axis, axis)} at each {AXIS_TITLES.get(by, by)}\n\n",
             "Mean over scenes and seeds of the ok cells; `-`: no ok cell.\n"]
    labels = [axis_label(axis, v) for v in axis_values(frame, axis)]
    for metric in METRICS:
        parts.append(f"\n## {METRIC_LABELS[metric]}\n")
        for value in axis_values(frame, by):
            wide = axis_means(frame[frame[by] == value], axis, metric)
            parts.append(f"\n### {AXIS_TITLES.get(by, by)} {axis_label(by, value)}\n\n")
            if wide.empty:
                parts.append("No ok rows.\n")
                continue
            rows = [[m, *[fmt(wide.loc[m, v] if v in wide.columns else math.nan, metric)
                          for v in axis_values(frame, axis)]] for m in wide.index]
            parts.append(markdown_table([f"method \\ {axis}", *labels], rows, ["l"] + ["r"] * len(labels)))
    return "".join(parts)


def crossed_csv(frame: pd.DataFrame, axis: str, by: str) -> pd.DataFrame:
    """Tidy form of :func:`crossed_markdown`: ``metric, method, <by>, <axis>, mean, std, min, max, n``."""
    parts = [axis_csv(frame[frame[by] == value], axis).assign(**{by: value}) for value in axis_values(frame, by)]
    out = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=[by])
    return out[["metric", "method", by, axis, "mean", "std", "min", "max", "n"]]


def axis_csv(frame: pd.DataFrame, axis: str) -> pd.DataFrame:
    """Tidy form of :func:`axis_markdown`: ``metric, method, <axis>, mean, std, min, max, n``."""
    parts = []
    for metric in METRICS:
        s = axis_summary(frame, axis, metric)
        if not s.empty:
            parts.append(s.assign(metric=metric))
    if not parts:
        return pd.DataFrame(columns=["metric", "method", axis, "mean", "std", "min", "max", "n"])
    out = pd.concat(parts, ignore_index=True)
    return out[["metric", "method", axis, "mean", "std", "min", "max", "n"]]


def noise_markdown(ours: pd.DataFrame) -> str:
    levels = [lv for lv in PAPER_TABLE3 if f"psnr_{lv}" in ours.columns]
    header = ["method", *[f"PSNR {lv}" for lv in levels], *[f"SSIM {lv}" for lv in levels]]
    align = ["l"] + ["r"] * (2 * len(levels))
    rows = [[r["method"], *[fmt(r[f"psnr_{lv}"], "psnr") for lv in levels],
             *[fmt(r[f"ssim_{lv}"], "ssim") for lv in levels]] for _, r in ours.iterrows()]
    paper = paper_table3()
    prow = [[f"{r['method']} ({r['inputs']})", *[fmt(r[f"psnr_{lv}"], "psnr") for lv in levels],
             *[fmt(r[f"ssim_{lv}"], "ssim") for lv in levels]] for _, r in paper.iterrows()]
    side = []
    for paper_name, ours_name in PAPER_TABLE3_OURS.items():
        mine = ours[ours["method"] == ours_name]
        if mine.empty:
            continue
        r = mine.iloc[0]
        side.append([f"{paper_name}: ours (`{ours_name}`)", *[fmt(r[f"psnr_{lv}"], "psnr") for lv in levels],
                     *[fmt(r[f"ssim_{lv}"], "ssim") for lv in levels]])
        pub = paper[paper["method"] == paper_name].iloc[0]
        side.append([f"{paper_name}: paper", *[fmt(pub[f"psnr_{lv}"], "psnr") for lv in levels],
                     *[fmt(pub[f"ssim_{lv}"], "ssim") for lv in levels]])
    regenerated = ("\n## The paper's Table 3 regenerated\n\nEach of the paper's columns with our method beside "
                   "the published figure (ours: the test photographs at L = 1/4, S = 128; the paper: its KITTI "
                   "sequence).\n\n" + markdown_table(header, side, align)) if side else ""
    return ("# Noise (the paper's Table 3)\n\nOurs: mean over scenes and seeds at L = 1/4, S = 128.\n\n"
            + markdown_table(header, rows, align) + regenerated
            + "\nPublished (NeuSpike-Net, Table 3: simulated KITTI sequence 0001), for orientation only: "
            "a different scene, simulator and training set.\n\n" + markdown_table(header, prow, align))


def noise_csv(ours: pd.DataFrame) -> pd.DataFrame:
    """Ours and the paper's rows in one table with a ``source`` column."""
    paper = paper_table3().rename(columns={"inputs": "family"})
    paper = paper[[c for c in ours.columns if c in paper.columns]]
    return pd.concat([ours.assign(source="ours"), paper.assign(source="paper")], ignore_index=True)[
        ["source", *ours.columns]]


def failures_markdown(failures: pd.DataFrame) -> str:
    if failures.empty:
        return "# Failed and skipped methods\n\nNone: every method ran in every cell.\n"
    rows = [[r.method, r.status, fmt(r.cells, "int"), r.error or "-"] for r in failures.itertuples()]
    return ("# Failed and skipped methods\n\nA skip (the method cannot run here, e.g. weights not given) "
            "is not a failure.\n\n" + markdown_table(["method", "status", "cells", "error"], rows, ["l", "l", "r", "l"]))


def accuracy_markdown(points: pd.DataFrame, note: str = "") -> str:
    rows = [[r.method, r.family, fmt(r.ms_per_frame, "ms"), fmt(r.psnr, "psnr"), fmt(r.ssim, "ssim"),
             "yes" if r.front_psnr else "", "yes" if r.front_ssim else ""] for r in points.itertuples()]
    return ("# Accuracy against time\n\n" + (note + "\n\n" if note else "")
            + markdown_table(["method", "family", "ms/frame", "PSNR", "SSIM", "PSNR front", "SSIM front"],
                             rows, ["l", "l", "r", "r", "r", "l", "l"]))


# ----------------------------------------------------------------------------------------------
# Table 2: time per frame (written by bench.timing, rendered from its timing.csv)
# ----------------------------------------------------------------------------------------------

#: The resolutions of the paper's Table 2, (width, height).
#: Table 2 of the paper (NeuSpike-Net, ICCV 2021), ms per frame: "WxH" -> {(method, device): ms}.
PAPER_TABLE2: Mapping[str, Mapping[tuple[str, str], float]] = {
    "240x180": {("E2VID", "GPU"): 6.15, ("FireNet", "GPU"): 2.21, ("NeuSpike-Net", "GPU"): 10.31,
                ("E2VID", "CPU"): 116.14, ("FireNet", "CPU"): 25.57, ("NeuSpike-Net", "CPU"): 68.35},
    "346x260": {("E2VID", "GPU"): 11.13, ("FireNet", "GPU"): 3.48, ("NeuSpike-Net", "GPU"): 17.53,
                ("E2VID", "CPU"): 207.34, ("FireNet", "CPU"): 51.39, ("NeuSpike-Net", "CPU"): 120.34},
    "400x250": {("E2VID", "GPU"): 14.33, ("FireNet", "GPU"): 4.02, ("NeuSpike-Net", "GPU"): 22.49,
                ("E2VID", "CPU"): 227.14, ("FireNet", "CPU"): 55.84, ("NeuSpike-Net", "CPU"): 140.12},
    "640x480": {("E2VID", "GPU"): 28.46, ("FireNet", "GPU"): 10.25, ("NeuSpike-Net", "GPU"): 51.55,
                ("E2VID", "CPU"): 630.41, ("FireNet", "CPU"): 210.6, ("NeuSpike-Net", "CPU"): 473.46},
}
#: Published parameter counts (the paper's supplementary material).
PAPER_PARAMETERS: Mapping[str, int] = {"E2VID": 10_700_000, "FireNet": 38_000, "NeuSpike-Net": 5_985_000}


def paper_table2() -> pd.DataFrame:
    """The paper's Table 2 as rows ``method, device, <resolution>...`` (ms per frame)."""
    records = []
    for device in ("CPU", "GPU"):
        for method in ("E2VID", "FireNet", "NeuSpike-Net"):
            rec: dict[str, Any] = {"method": method, "device": device}
            for res, vals in PAPER_TABLE2.items():
                rec[res] = vals[(method, device)]
            records.append(rec)
    return pd.DataFrame(records)


def timing_method_order(timing: pd.DataFrame) -> list[str]:
    """Methods of ``timing.csv`` rows by family, then by name (numbers by value)."""
    if not len(timing):
        return []
    fam = {str(r.method): str(r.family) for r in timing.itertuples()}
    return sorted(fam, key=lambda m: (FAMILIES.index(fam[m]) if fam[m] in FAMILIES else len(FAMILIES), natural_key(m)))


def timing_markdown(timing: pd.DataFrame, threads: Any = None, machine: str = "") -> str:
    """Table 2 in Markdown from the rows of ``timing.csv`` (see :mod:`bench.timing`), with the paper's."""
    resolutions = list(dict.fromkeys(timing["resolution"])) if len(timing) else []
    fam = {r.method: r.family for r in timing.itertuples()} if len(timing) else {}
    methods = timing_method_order(timing)
    rows = []
    for m in methods:
        sub = timing[timing["method"] == m]
        params = int(sub["parameters"].max()) if sub["parameters"].notna().any() else 0
        cells = []
        for res in resolutions:
            r = sub[sub["resolution"] == res]
            if r.empty:
                cells.append("-")
                continue
            r = r.iloc[0]
            if r["status"] != OK:
                cells.append(str(r["status"]))
            else:
                cells.append(f"{fmt(r['ms_per_frame'], 'ms')} [{fmt(r['min_frame_ms'], 'ms')}-{fmt(r['max_frame_ms'], 'ms')}]")
        kinds = [str(v) for v in sub["precision"] if isinstance(v, str) and v] if "precision" in sub else []
        rows.append([m, fam.get(m, "unknown"), f"{params:,}" if params else "-", "/".join(dict.fromkeys(kinds)) or "-",
                     *cells])
    where = f" on {machine}" if machine else ""
    thr = f", {threads} torch thread(s)" if threads is not None else ""
    parts = [
        "# Time per frame (the paper's Table 2)\n\n",
        f"Ours{where}{thr}: median ms per frame [min-max] over the timed runs after warm-up. "
        "Recurrent methods: ms per network step (one voxel grid), i.e. one reconstruct call divided by the "
        "event windows it processed; the whole call, warm-up included, is in timing.csv (`median_ms`).\n\n",
        markdown_table(["method", "family", "parameters", "precision", *resolutions], rows,
                       ["l", "l", "r", "l"] + ["r"] * len(resolutions)),
    ]
    flops = ("gflop_per_step", "gflop_s", "flop_bound_ms", "matmul_gflop_s", "ms_per_frame")
    counted = timing.iloc[:0]
    if len(timing) and all(c in timing for c in flops):  # a timing.csv read back keeps empty cells as text
        numeric = timing.assign(**{c: pd.to_numeric(timing[c], errors="coerce") for c in flops})
        counted = numeric[numeric["gflop_per_step"].notna()]
    if len(counted):
        ref = float(counted["matmul_gflop_s"].iloc[0])
        # a timing.csv written before the representations were timed has no encode_ms: shown as "-"
        enc = pd.to_numeric(counted["encode_ms"], errors="coerce") if "encode_ms" in counted else \
            pd.Series(math.nan, index=counted.index)
        lrows = [[r.method, r.resolution, f"{r.gflop_per_step:.2f}", fmt(r.ms_per_frame, "ms"), fmt(e, "ms"),
                  fmt(r.flop_bound_ms, "ms"), f"{r.gflop_s:.1f}", f"{100.0 * r.gflop_s / r.matmul_gflop_s:.0f} %"]
                 for r, e in zip(counted.itertuples(), enc)]
        parts.append("\nThe networks against this machine's limit: GFLOP per network step (counted by torch's FLOP "
                     "counter: convolutions and matrix products), the measured ms per frame, the part of it spent "
                     "building the network's inputs on the CPU (a feed-forward method's representations; a "
                     "recurrent method's voxel grid, per step), the FLOP-bound time "
                     f"(GFLOP at the rate of a float32 matrix product measured in the same run: {ref:.1f} GFLOP/s) "
                     "and the rate achieved (a feed-forward method's time includes building its input "
                     "representations):\n\n"
                     + markdown_table(["method", "resolution", "GFLOP / step", "ms / frame", "inputs ms",
                                       "FLOP-bound ms", "GFLOP/s", "of the matmul rate"], lrows,
                                      ["l", "l", "r", "r", "r", "r", "r", "r"]))
    streamed = timing.iloc[:0]
    if len(timing) and "stream_ms" in timing:
        numeric = timing.assign(**{c: pd.to_numeric(timing[c], errors="coerce")
                                   for c in ("cold_ms", "stream_ms", "stream_min_ms", "stream_max_ms", "stream_steps",
                                             "steps")})
        streamed = numeric[(numeric["status"] == OK) & numeric["stream_ms"].notna()]
    if len(streamed):
        srows = [[r.method, r.resolution,
                  fmt(r.cold_ms, "ms") + (f" ({r.steps:.0f} steps)" if r.steps == r.steps else ""),
                  f"{fmt(r.stream_ms, 'ms')} [{fmt(r.stream_min_ms, 'ms')}-{fmt(r.stream_max_ms, 'ms')}]"
                  + (f" ({r.stream_steps:.1f} steps)" if r.stream_steps == r.stream_steps else ""),
                  f"{r.cold_ms / r.stream_ms:.1f}x"] for r in streamed.itertuples()]
        parts.append("\nTwo costs of the methods that continue a video from their previous frame: the **cold start** "
                     "(one whole reconstruct call; a recurrent method warms up over the event history, every "
                     "network step included) and **streaming**, one new frame of a running video at "
                     "1,000 frames/s of sensor time (recurrent methods carry their state and step only the event "
                     "windows completed since the previous frame plus the partial one; NeuSpike-Net assembles "
                     "its representations from bins shared with the previous frames). Median [min-max] ms:\n\n"
                     + markdown_table(["method", "resolution", "cold start ms", "streaming ms per new frame",
                                       "cold / streaming"], srows, ["l", "l", "r", "r", "r"]))
    bad = timing[timing["status"] != OK].drop_duplicates(["method", "error"]) if len(timing) else timing
    if len(bad):
        parts.append("\nNot timed:\n\n" + "".join(f"- {r.method} ({r.status}): {r.error}\n" for r in bad.itertuples()))
    paper = paper_table2()
    prow = [[r["method"], r["device"], f"{PAPER_PARAMETERS[r['method']]:,}",
             *[f"{r[res]:g}" for res in PAPER_TABLE2]] for _, r in paper.iterrows()]
    parts.append("\nPublished (NeuSpike-Net Table 2: NVIDIA Titan Xp GPU, Intel E5-2630 2.2 GHz CPU), for "
                 "orientation only:\n\n"
                 + markdown_table(["method", "device", "parameters", *PAPER_TABLE2], prow, ["l", "l", "r", "r", "r", "r", "r"]))
    return "".join(parts)
