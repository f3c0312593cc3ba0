"""Figures, tables and a PDF from a results folder alone (the library of ``python -m bench.report RESULTS_DIR``).

Nothing is simulated and no method runs: the report reads only the files of the folder, so it can
be rebuilt at any time, on any machine, and gives the same tables byte for byte.

Inputs (in ``RESULTS_DIR``; each optional, at least one of the first two)
    ``results.csv``            a sweep's long results (:mod:`bench.harness.results`); a committed report may
                               keep it gzipped as ``results.csv.gz`` (read when ``results.csv`` is absent)
    ``timing.csv``             Table 2 rows written by :mod:`bench.timing`
    ``accuracy_vs_time.csv``   accuracy-versus-time points joined by :mod:`bench.timing`
    ``config.json``, ``metadata.json``  what ran and where (shown on the title page)
    ``images/``                reconstructions for the figure grid (below)

A folder written by ``python -m bench.dataset`` (``config.json`` holds ``dataset``) gets the dataset
report of :mod:`bench.reporting.dataset_report` instead: the protocol first, a table per recording and method,
and a contact sheet per recording.

Outputs (into ``RESULTS_DIR``, or ``--out``; every file written atomically)
    ``figures/<axis>_psnr_ssim.png``, ``figures/<axis>_affine.png``  metrics against each swept axis
    ``figures/grid_<scene>_<axis>.png``  reconstruction grid of every scene with images (the PDF
                                         shows the first scene of each scene kind)
    ``figures/accuracy_vs_time.png``     PSNR and SSIM against ms per frame, Pareto front marked
    ``tables/summary``, ``tables/<axis>``, ``tables/noise_table3`` (with a noise axis), ``tables/light_by_noise``
    and ``figures/light_psnr_ssim_noise=<level>.png`` (light and noise both swept),
    ``tables/failures``, ``tables/accuracy_vs_time``, ``tables/claims``, ``tables/timing``
    (with ``timing.csv``): each as ``.md`` and ``.csv``
    ``report.pdf``  title page with provenance, the claims page, the figures, the tables

Reconstruction images (the convention a harness follows to get the figure grid)
    ``images/<scene>/<axis>=<value>/<method>.png`` and ``images/<scene>/<axis>=<value>/gt.png``

    * ``<scene>`` is the scene's name (``KIND:IMAGE``) passed through :func:`safe_name` (characters
      other than letters, digits, ``.``, ``_``, ``-`` and ``=`` become ``_``: ``pan:camera`` ->
      ``pan_camera``);
    * ``<axis>`` is ``light``, ``motion`` or ``noise``; ``<value>`` is the axis value as written in
      ``results.csv`` (``light=0.03125``, ``motion=128``, ``noise=high``);
    * ``<method>`` is the registry name through :func:`safe_name`; ``gt.png`` is the ground truth;
    * each PNG is 8-bit greyscale, ``round(255 * clip(image, 0, 1))``, of one seed (the first).

    :func:`image_path` builds these paths and :func:`write_image_png` writes such a PNG atomically,
    so a harness need not re-implement the convention. Without ``images/`` there is no grid figure
    and everything else is unchanged.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from bench.reporting import figures as figs
from bench.reporting import tables as tb
from neuspike.utils.atomic import write_text
from bench.harness.results import tfp_windows
from bench.reporting.claims import claims_markdown, evaluate_claims

#: Resolution of the reconstruction grids' PNGs (each cell about 220 pixels wide).
GRID_DPI = 100

# ----------------------------------------------------------------------------------------------
# The image convention
# ----------------------------------------------------------------------------------------------

# the layout a run writes its images in (read back here for the figure grid)
from bench.harness.images import axis_folder, safe_name  # noqa: E402

_read_gray = figs.read_gray


def load_images(images_dir: Path, frame: pd.DataFrame, axis: str) -> dict[str, dict[tuple[str, Any], np.ndarray]]:
    """``{scene name: {(row, axis value): image}}`` for the ``axis`` folders under ``images_dir``.

    Rows are ``"gt"`` and method names; a scene folder that matches no scene of ``frame`` keeps its
    folder name. Axis values are matched to those of ``frame`` through :func:`axis_folder`.
    """
    scenes = {safe_name(s): s for s in pd.unique(frame["scene"])} if "scene" in frame else {}
    methods = {safe_name(m): m for m in pd.unique(frame["method"])}
    values = {axis_folder(axis, v): v for v in tb.axis_values(frame, axis)} if axis in frame else {}
    out: dict[str, dict[tuple[str, Any], np.ndarray]] = {}
    for scene_dir in sorted(p for p in images_dir.iterdir() if p.is_dir()):
        scene = scenes.get(scene_dir.name, scene_dir.name)
        for value_dir in sorted(p for p in scene_dir.iterdir() if p.is_dir()):
            if value_dir.name not in values:
                continue
            value = values[value_dir.name]
            for png in sorted(value_dir.glob("*.png")):
                row = "gt" if png.stem == "gt" else methods.get(png.stem, png.stem)
                out.setdefault(scene, {})[(row, value)] = _read_gray(png)
    return out


# ----------------------------------------------------------------------------------------------
# Reading a results folder
# ----------------------------------------------------------------------------------------------

@dataclass
class ReportInputs:
    """What a results folder holds (each part ``None`` / empty when its file is absent)."""

    folder: Path
    results: pd.DataFrame | None = None
    timing: pd.DataFrame | None = None
    accuracy: pd.DataFrame | None = None
    config: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)


def _read_json(path: Path) -> dict[str, Any]:
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not readable JSON ({exc})") from exc
    return data if isinstance(data, dict) else {}


def results_file(folder: str | os.PathLike) -> Path:
    """A folder's ``results.csv``, or its gzipped ``results.csv.gz`` where only that is there (a
    committed report keeps its long results compressed: a 29 MB table is 1.1 MB gzipped)."""
    plain = Path(folder) / "results.csv"
    packed = plain.with_name("results.csv.gz")
    return packed if not plain.exists() and packed.exists() else plain


def read_results(path: Path) -> pd.DataFrame:
    """``results.csv`` with the harness's dtypes (:func:`bench.harness.results.read_csv`)."""
    from bench.harness.results import read_csv

    return read_csv(path)


def load_inputs(results_dir: str | os.PathLike) -> ReportInputs:
    """Read the files of a results folder (module docstring).

    Raises
    ------
    FileNotFoundError
        When the folder holds neither ``results.csv`` nor ``timing.csv``.
    """
    folder = Path(results_dir)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: not a folder")
    res, timing, acc = results_file(folder), folder / "timing.csv", folder / "accuracy_vs_time.csv"
    if not res.exists() and not timing.exists():
        raise FileNotFoundError(f"{folder}: neither results.csv nor timing.csv is there; nothing to report")
    inputs = ReportInputs(folder=folder, config=_read_json(folder / "config.json"),
                          metadata=_read_json(folder / "metadata.json"))
    if res.exists():
        inputs.results = read_results(res)
    if timing.exists():
        inputs.timing = pd.read_csv(timing, keep_default_na=False, na_values={c: [""] for c in _TIMING_NUMERIC})
        for col in ("error", "status", "method", "family", "resolution", "inputs"):
            if col in inputs.timing:
                inputs.timing[col] = inputs.timing[col].astype(str)
    if acc.exists():
        inputs.accuracy = pd.read_csv(acc, keep_default_na=False,
                                      na_values={c: [""] for c in ("ms_per_frame", "psnr", "ssim")})
        inputs.accuracy["method"] = inputs.accuracy["method"].astype(str)
        inputs.accuracy["family"] = inputs.accuracy["family"].astype(str)
    return inputs


_TIMING_NUMERIC = ("median_ms", "min_ms", "max_ms", "q1_ms", "q3_ms", "steps", "ms_per_frame", "min_frame_ms",
                   "max_frame_ms", "parameters", "threads", "repeats", "warmup", "width", "height")


# ----------------------------------------------------------------------------------------------
# The title page
# ----------------------------------------------------------------------------------------------

def _fmt_list(values: Sequence[Any], axis: str | None = None, limit: int = 12) -> str:
    items = [tb.axis_label(axis, v) if axis else str(v) for v in values]
    return ", ".join(items[:limit]) + (f", ... ({len(items)} in all)" if len(items) > limit else "")


def _effect_text(effect: Any) -> str:
    if not isinstance(effect, dict):
        return str(effect)
    params = ", ".join(f"{k}={v}" for k, v in effect.items() if k != "name")
    return f"{effect.get('name', '?')}" + (f" ({params})" if params else "")


def title_blocks(inputs: ReportInputs) -> list[tuple[str, str]]:
    """The title page's text: what ran (config.json, the results) and provenance (metadata.json)."""
    blocks: list[tuple[str, str]] = []
    cfg, meta = inputs.config, inputs.metadata
    sweep = cfg.get("sweep") if isinstance(cfg.get("sweep"), dict) else None
    timing_cfg = cfg.get("timing") if isinstance(cfg.get("timing"), dict) else None
    blocks.append(("p", f"Results folder: {inputs.folder.resolve().name}/"))
    if inputs.results is not None:
        f = inputs.results
        blocks.append(("h", "What was run"))
        name = (sweep or {}).get("name") or meta.get("sweep") or "?"
        axes = tb.swept_axes(f)
        blocks.append(("p", f"Sweep: {name}; swept axes: {', '.join(axes) or 'none (one condition)'}; "
                            f"{len(f)} rows, {f['method'].nunique()} methods, "
                            f"{f.drop_duplicates(['scene', 'light', 'motion', 'noise', 'seed']).shape[0]} cells."))
        blocks.append(("p", "Scenes: " + _fmt_list(list(pd.unique(f["scene"])))))
        sizes = sorted({f"{int(w)}x{int(h)}" for w, h in zip(f["width"], f["height"])}) if "width" in f else []
        blocks.append(("p", f"Light L: {_fmt_list(tb.axis_values(f, 'light'), 'light')}; motion S: "
                            f"{_fmt_list(tb.axis_values(f, 'motion'), 'motion')}; noise: "
                            f"{_fmt_list(tb.axis_values(f, 'noise'))}; seeds: {_fmt_list(sorted(pd.unique(f['seed'])))}; "
                            f"size: {', '.join(sizes) or '?'}; planes per window: "
                            f"{_fmt_list(sorted(pd.unique(f['planes']))) if 'planes' in f else '?'}."))
        blocks.append(("p", "Methods: " + _fmt_list(tb.method_order(f), limit=40)))
        if sweep:
            effects = (sweep.get("grid") or {}).get("effects") or []
            eff = "; ".join(_effect_text(e) for e in effects) or "none"
            blocks.append(("p", f"Declared effects in every condition: {eff}. Event history for recurrent "
                                f"methods: {sweep.get('history_windows', '?')} windows. Sensor: "
                                + ", ".join(f"{k} {v}" for k, v in (sweep.get("sensor") or {}).items())))
        status = f.drop_duplicates(["method", "scene", "light", "motion", "noise", "seed"])["status"].value_counts()
        blocks.append(("p", "Method runs by status: " + ", ".join(f"{int(n)} {s}" for s, n in status.items())))
    if timing_cfg:
        blocks.append(("h", "Timing run"))
        blocks.append(("p", "; ".join(f"{k}: {', '.join(map(str, v)) if isinstance(v, list) else v}"
                                      for k, v in sorted(timing_cfg.items()))))
    if cfg.get("execution"):
        ex = cfg["execution"]
        blocks.append(("p", "Execution: " + ", ".join(f"{k} {ex[k]}" for k in ("executor", "workers", "threads_per_worker")
                                                      if k in ex)))
    if meta:
        blocks.append(("h", "Provenance (metadata.json)"))
        src = meta.get("source") or {}
        blocks.append(("p", f"Commit {src.get('commit') or 'unknown'}"
                            + (" with uncommitted changes" if src.get("dirty") else "")
                            + f"; run from {meta.get('start', '?')} to {meta.get('end', '?')}"
                            + (f" ({meta['wall_seconds']:.1f} s)" if isinstance(meta.get("wall_seconds"), (int, float)) else "")
                            + (f"; {len(meta['previous_runs'])} earlier run(s) resumed" if meta.get("previous_runs") else "")
                            + "."))
        mach = meta.get("machine") or {}
        mem = mach.get("memory_bytes")
        blocks.append(("p", f"Machine: {mach.get('cpu_model', '?')}, {mach.get('usable_cpus', '?')} usable CPUs"
                            + (f", {mem / 2 ** 30:.0f} GiB" if isinstance(mem, (int, float)) else "")
                            + f", {mach.get('system', '?')}; torch threads per worker: "
                            + f"{meta.get('threads_per_worker', meta.get('threads', '?'))}"
                            + (("; timings contended: " + ", ".join(meta.get("contention")
                                                                    or ["workers side by side"]))
                               if meta.get("timing_contended") else "")
                            + "."))
        vers = meta.get("versions") or {}
        blocks.append(("p", "Versions: " + ", ".join(f"{k} {v}" for k, v in vers.items() if v)))
        split = meta.get("time_split") or {}
        if split.get("method_ms_per_frame"):
            blocks.append(("p", f"Time: simulation {split.get('simulation_s_per_cell', float('nan')):.3f} s per cell; "
                                "median ms per frame: " + ", ".join(f"{m} {v:.3g}" for m, v in
                                                                    split["method_ms_per_frame"].items())))
    blocks.append(("h", "Contents"))
    blocks.append(("p", "The claims page; figures (metrics against each swept axis, with and without affine "
                        "alignment; the reconstruction grid when images were saved; accuracy against time); the "
                        "tables (per method, per axis value, noise levels beside the paper's Table 3, failures, "
                        "timing). Every figure and table is also a file under figures/ and tables/."))
    return blocks


# ----------------------------------------------------------------------------------------------
# Building the report
# ----------------------------------------------------------------------------------------------

def _write_table(tables_dir: Path, name: str, markdown: str, frame: pd.DataFrame, written: list[Path]) -> None:
    written.append(write_text(tables_dir / f"{name}.md", markdown))
    written.append(write_text(tables_dir / f"{name}.csv", tb.to_csv_text(frame)))


def write_timing_tables(tables_dir: Path, timing: pd.DataFrame, metadata: dict[str, Any]) -> list[Path]:
    """``tables/timing.md`` and ``tables/timing.csv`` from Table 2 rows (what ``bench.timing`` writes)."""
    threads = sorted({int(v) for v in timing["threads"].dropna()}) if "threads" in timing else []
    info = metadata.get("machine") or {}
    machine = info.get("cpu_model", "")
    on_gpu = any(str(d).startswith("cuda") for d in timing.get("device", pd.Series(dtype=str)).dropna())
    if on_gpu and info.get("gpus"):  # the learned methods ran on a GPU: name it first
        machine = f"{info['gpus'][0]} (learned methods) and {machine or 'an unnamed CPU'} (the others)"
    md = tb.timing_markdown(timing, threads=",".join(map(str, threads)) or None, machine=machine)
    written: list[Path] = []
    _write_table(Path(tables_dir), "timing", md, timing, written)
    return written


def _accuracy_note(inputs: ReportInputs) -> str:
    if inputs.accuracy is not None:
        res = sorted({r for r in inputs.accuracy.get("resolution", pd.Series(dtype=str)).astype(str) if r not in ("", "nan")})
        # the sweep folders by name: an absolute path says only where the machine that made it kept them
        src = sorted({Path(r).name for r in inputs.accuracy.get("results", pd.Series(dtype=str)).astype(str)
                      if r not in ("", "nan")})
        return (f"PSNR/SSIM: means of the sweep results in {', '.join(src) or '?'}; ms per frame: bench.timing at "
                f"{', '.join(res) or '?'} (filled: one reconstruct call, a streaming method's warm-up over its "
                "event history included; hollow: one new frame of a running video)")
    return ("PSNR/SSIM: means over every cell; ms per frame: median wall time of one reconstruct call in the sweep "
            "(recurrent methods: including their warm-up)")


def build_report(results_dir: Path, out_dir: Path | None = None, *, spread: str = "std") -> Path:
    """Write every figure, table and ``report.pdf`` of a results folder; return the PDF's path.

    Parameters
    ----------
    results_dir : path
        A folder with ``results.csv`` and/or ``timing.csv`` (module docstring).
    out_dir : path, optional
        Where to write (default: ``results_dir``).
    spread : ``"std"`` or ``"minmax"``
        The band around each line of the axis figures: mean ± one sample standard deviation over
        scenes and seeds (default), or their min..max range.

    Raises
    ------
    FileNotFoundError
        When ``results_dir`` holds nothing to report.
    """
    if spread not in ("std", "minmax"):
        raise ValueError(f"spread: expected 'std' or 'minmax', got {spread!r}")
    from neuspike.formats.staging import check_writable_folder, remove_stale_temporaries

    inputs = load_inputs(results_dir)
    out = Path(out_dir) if out_dir is not None else Path(results_dir)
    check_writable_folder(out, what="--out" if out_dir is not None else "results folder")  # before any work
    fig_dir, tab_dir = out / "figures", out / "tables"
    for folder in (out, fig_dir, tab_dir):  # a killed report's temporaries (a half PDF can be 20 MB)
        if folder.is_dir():
            remove_stale_temporaries(folder)
    if isinstance(inputs.config.get("dataset"), dict):  # a folder of bench.dataset: its own tables and sheets
        from bench.reporting.dataset_report import build_dataset_report

        return build_dataset_report(inputs, out, provenance=title_blocks(replace(inputs, results=None)))
    written: list[Path] = []
    figure_pages: list[Any] = []
    table_pages: list[Any] = []
    claim_pages: list[Any] = []
    try:
        f = inputs.results
        if f is not None and len(f):
            _report_results(inputs, f, fig_dir, tab_dir, written, figure_pages, table_pages, claim_pages, spread)
        points = None
        if inputs.accuracy is not None and len(inputs.accuracy):
            keep = [c for c in ("method", "family", "ms_per_frame", "psnr", "ssim", "stream_ms") if c in inputs.accuracy]
            points = tb.with_fronts(inputs.accuracy[keep])
        elif f is not None and len(f):
            points = tb.accuracy_points(f)
        if points is not None and len(points):
            note = _accuracy_note(inputs)
            fig = figs.accuracy_time_figure(points, note, tfp_windows(f) if f is not None else None)
            written.append(figs.save_png(fig, fig_dir / "accuracy_vs_time.png"))
            figure_pages.append(fig)
            cols = ["method", "family", "ms_per_frame", "psnr", "ssim", "front_psnr", "front_ssim"]
            _write_table(tab_dir, "accuracy_vs_time", tb.accuracy_markdown(points[cols], note), points[cols], written)
            table_pages += figs.table_figures(
                ["method", "family", "ms/frame", "PSNR", "SSIM", "PSNR front", "SSIM front"],
                [[r.method, r.family, tb.fmt(r.ms_per_frame, "ms"), tb.fmt(r.psnr, "psnr"), tb.fmt(r.ssim, "ssim"),
                  "yes" if r.front_psnr else "", "yes" if r.front_ssim else ""] for r in points.itertuples()],
                "Accuracy against time", note=note)
        if inputs.timing is not None and len(inputs.timing):
            t = inputs.timing
            written += write_timing_tables(tab_dir, t, inputs.metadata)
            table_pages += _timing_pages(t)
        pdf = out / "report.pdf"
        _write_pdf(pdf, figs.text_figures("NeuSpike Bench report", title_blocks(inputs), width=128) + claim_pages
                   + figure_pages + table_pages)
        written.append(pdf)
    finally:
        figs.close_all(figure_pages + table_pages + claim_pages)
        import matplotlib.pyplot as plt

        plt.close("all")
    return pdf


def _axis_table_pages(f: pd.DataFrame, axis: str, metric: str, title: str) -> list[Any]:
    """The PDF pages of one metric's means against ``axis`` (none without ok rows)."""
    wide = tb.axis_means(f, axis, metric)
    if wide.empty:
        return []
    values = tb.axis_values(f, axis)
    return figs.table_figures(
        [f"method \\ {axis}", *[tb.axis_label(axis, v) for v in values]],
        [[m, *[tb.fmt(wide.loc[m, v] if v in wide.columns else math.nan, metric) for v in values]] for m in wide.index],
        title, note=f"Mean over scenes and seeds of the ok cells, {tb.held_conditions(f, axis) or 'one condition'}.")


def _report_results(inputs: ReportInputs, f: pd.DataFrame, fig_dir: Path, tab_dir: Path, written: list[Path],
                    figure_pages: list[Any], table_pages: list[Any], claim_pages: list[Any], spread: str) -> None:
    """The sweep part of the report: claims, axis figures and tables, the grid, Table 3, failures."""
    verdicts = evaluate_claims(f)
    _write_table(tab_dir, "claims", claims_markdown(verdicts), verdicts, written)
    claim_pages += figs.claims_figures(verdicts)

    summary = tb.method_summary(f)
    _write_table(tab_dir, "summary", tb.summary_markdown(summary), summary, written)
    table_pages += figs.table_figures(
        ["method", "family", "inputs", "params", "normalisation", "ok", "failed", "skipped", "PSNR", "SSIM",
         "PSNR aff.", "SSIM aff.", "ms/frame"],
        [[r.method, r.family, r.inputs, f"{r.parameters:,}" if r.parameters else "-", r.normalisation or "-",
          r.cells_ok, r.cells_error, r.cells_skipped, tb.fmt(r.psnr, "psnr"), tb.fmt(r.ssim, "ssim"),
          tb.fmt(r.psnr_affine, "psnr"), tb.fmt(r.ssim_affine, "ssim"), tb.fmt(r.ms_per_frame, "ms")]
         for r in summary.itertuples()],
        "Methods", note="Means over every scene, condition and seed of the ok cells; ms/frame: median of one "
                        "reconstruct call (recurrent methods: with their warm-up).", wrap={4: 18})

    for axis in tb.swept_axes(f):
        for name, metrics in ((f"{axis}_psnr_ssim", ("psnr", "ssim")), (f"{axis}_affine", ("psnr_affine", "ssim_affine"))):
            fig = figs.axis_figure(f, axis, metrics, spread=spread)
            written.append(figs.save_png(fig, fig_dir / f"{name}.png"))
            figure_pages.append(fig)
        _write_table(tab_dir, axis, tb.axis_markdown(f, axis), tb.axis_csv(f, axis), written)
        values = tb.axis_values(f, axis)
        for metric in ("psnr", "ssim"):
            table_pages += _axis_table_pages(f, axis, metric, f"{tb.METRIC_LABELS[metric]} against the {tb.AXIS_TITLES[axis]}")
        images_dir = inputs.folder / "images"
        if images_dir.is_dir():
            kinds_in_pdf: set[str] = set()
            for scene, images in load_images(images_dir, f, axis).items():
                rows = ["gt"] + [m for m in tb.method_order(f) if any((m, v) in images for v in values)]
                extra = sorted({r for r, _ in images} - set(rows))
                fig = figs.recon_grid_figure(images, rows + extra, values, axis,
                                             f"{scene}: reconstructions across the {tb.AXIS_TITLES[axis]}")
                written.append(figs.save_png(fig, fig_dir / f"grid_{safe_name(scene)}_{axis}.png", dpi=GRID_DPI))
                kind = scene.split(":", 1)[0]
                if kind not in kinds_in_pdf:  # the PDF shows one scene per kind; figures/ holds them all
                    kinds_in_pdf.add(kind)
                    figure_pages.append(fig)
                else:
                    figs.close_all([fig])

    crossed = tb.crossed_axes(f)
    if crossed is not None:  # the light x noise grid: the light axis at each noise level
        axis, by = crossed
        _write_table(tab_dir, f"{axis}_by_{by}", tb.crossed_markdown(f, axis, by), tb.crossed_csv(f, axis, by), written)
        for level in tb.axis_values(f, by):
            part = f[f[by] == level]
            fig = figs.axis_figure(part, axis, ("psnr", "ssim"), spread=spread)
            written.append(figs.save_png(fig, fig_dir / f"{axis}_psnr_ssim_{safe_name(f'{by}={level}')}.png"))
            figure_pages.append(fig)
            for metric in ("psnr", "ssim", "specks"):
                table_pages += _axis_table_pages(part, axis, metric, f"{tb.METRIC_LABELS[metric]} against the "
                                                 f"{tb.AXIS_TITLES[axis]}, {tb.AXIS_TITLES[by]} {tb.axis_label(by, level)}")

    if "noise" in f and any(lv in set(f["noise"].astype(str)) for lv in tb.PAPER_TABLE3):
        ours = tb.noise_table(f)
        _write_table(tab_dir, "noise_table3", tb.noise_markdown(ours), tb.noise_csv(ours), written)
        levels = [lv for lv in tb.PAPER_TABLE3 if f"psnr_{lv}" in ours.columns]
        header = ["method", *[f"PSNR {lv}" for lv in levels], *[f"SSIM {lv}" for lv in levels]]
        rows = [[r["method"], *[tb.fmt(r[f"psnr_{lv}"], "psnr") for lv in levels],
                 *[tb.fmt(r[f"ssim_{lv}"], "ssim") for lv in levels]] for _, r in ours.iterrows()]
        paper = tb.paper_table3()
        rows += [[f"paper: {r['method']} ({r['inputs']})", *[tb.fmt(r[f"psnr_{lv}"], "psnr") for lv in levels],
                  *[tb.fmt(r[f"ssim_{lv}"], "ssim") for lv in levels]] for _, r in paper.iterrows()]
        table_pages += figs.table_figures(header, rows, "Noise levels (the paper's Table 3)",
                                          note="Ours: mean over scenes and seeds at the sweep's L and S. 'paper:' rows "
                                               "are the published numbers (simulated KITTI 0001), for orientation only.")

    failures = tb.failures_table(f)
    _write_table(tab_dir, "failures", tb.failures_markdown(failures), failures, written)
    if len(failures):
        table_pages += figs.table_figures(["method", "status", "cells", "error"],
                                          [[r.method, r.status, r.cells, r.error] for r in failures.itertuples()],
                                          "Failed and skipped methods", wrap={3: 110}, rows_per_page=12)


def _timing_pages(t: pd.DataFrame) -> list[Any]:
    resolutions = list(dict.fromkeys(t["resolution"]))
    rows = []
    for m in dict.fromkeys(t["method"]):
        sub = t[t["method"] == m]
        cells = []
        for res in resolutions:
            r = sub[sub["resolution"] == res]
            if r.empty:
                cells.append("-")
            elif r.iloc[0]["status"] != "ok":
                cells.append(r.iloc[0]["status"])
            else:
                r = r.iloc[0]
                cells.append(f"{tb.fmt(r['ms_per_frame'], 'ms')} [{tb.fmt(r['min_frame_ms'], 'ms')}-"
                             f"{tb.fmt(r['max_frame_ms'], 'ms')}]")
        params = int(sub["parameters"].max()) if sub["parameters"].notna().any() else 0
        rows.append([m, f"{params:,}" if params else "-", *cells])
    pages = figs.table_figures(["method", "parameters", *resolutions], rows, "Time per frame, ms (the paper's Table 2)",
                               note="Median [min-max] after warm-up. Recurrent methods: per network step (one voxel "
                                    "grid). Not timed methods show their status; reasons in tables/timing.md.")
    paper = tb.paper_table2()
    pages += figs.table_figures(
        ["method", "device", "parameters", *tb.PAPER_TABLE2],
        [[r["method"], r["device"], f"{tb.PAPER_PARAMETERS[r['method']]:,}", *[f"{r[res]:g}" for res in tb.PAPER_TABLE2]]
         for _, r in paper.iterrows()],
        "Published Table 2 (NeuSpike-Net), ms per frame",
        note="NVIDIA Titan Xp GPU and Intel E5-2630 2.2 GHz CPU; for orientation only.")
    return pages


_write_pdf = figs.write_pdf


def report_after_run(outcome: Any) -> Any:
    """Build the report of a finished run (a :class:`bench.harness.runner.SweepOutcome`) into its folder
    and record the outcome on it (``report_path``, or ``report_note`` and ``report_failed``), as the
    commands do after ``run_sweep``: a run whose results are empty gets no report, and a report that
    fails is said in one line (``results.csv`` holds every number)."""
    from neuspike.errors import one_line

    results = Path(outcome.results_path)
    if not results.is_file() or results.stat().st_size == 0 or len(pd.read_csv(results, nrows=1)) == 0:
        return outcome
    try:
        outcome.report_path = Path(build_report(Path(outcome.out_dir)))
    except Exception as exc:
        outcome.report_note, outcome.report_failed = f"report failed: {one_line(exc)}", True
    return outcome
