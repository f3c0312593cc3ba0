"""Figures of a results folder (matplotlib, Agg backend): each function returns a Figure.

* :func:`axis_figure` — per-method metric against a swept axis (light L and motion S on log2 axes,
  noise levels in order), one line per method, the mean over scenes and seeds with a band of
  mean ± one standard deviation (or the min/max range).
* :func:`recon_grid_figure` — reconstructions of one scene across the axis: ground truth on top,
  one row per method, one column per axis value (the paper's figure layout).
* :func:`accuracy_time_figure` — PSNR and SSIM against ms per frame (log x), one point per method
  and variant, the Pareto front (faster and better dominates) marked.
* :func:`table_figures`, :func:`text_figures` — tables and text as A4 landscape pages for the PDF.

Colours follow the method families (spike: blues and purples, event: reds and oranges, fusion:
greens); markers and line styles separate the members of a family. :func:`save_png` writes a
figure atomically.
"""

from __future__ import annotations

import io
import math
import textwrap
from pathlib import Path
from typing import Any, Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

plt.rcParams["figure.max_open_warning"] = 0  # a report holds its pages open until the PDF is written
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.table import Table  # noqa: E402

from neuspike.utils.atomic import write_with  # noqa: E402
from bench.harness.results import tfp_windows  # noqa: E402
from bench.harness.axes import AXIS  # noqa: E402
from bench.reporting.tables import (AXIS_TITLES, METRIC_LABELS, axis_label, axis_summary, axis_values, held_conditions,  # noqa: E402
                          method_families, method_order)

PAGE_SIZE_IN = (11.69, 8.27)  # A4 landscape
PALETTES: Mapping[str, Sequence[str]] = {
    "spike": ("#8e44ad", "#17becf", "#4d004b", "#6a51a3", "#0b6e8a", "#c51b8a", "#807dba"),
    "event": ("#d62728", "#ff7f0e", "#8c564b", "#e377c2", "#bcbd22", "#a50f15"),
    "fusion": ("#2ca02c", "#006d2c", "#74c476", "#238b45"),
    "unknown": ("#7f7f7f", "#444444", "#b0b0b0"),
}
LINESTYLES: Mapping[str, str] = {"spike": "-", "event": "--", "fusion": "-", "unknown": ":"}
MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*", "<", ">")
STATUS_COLOURS = {"holds": "#1a7f37", "does not hold": "#c62828", "cannot check": "#6e6e6e"}


def method_styles(methods: Sequence[str], families: Mapping[str, str],
                  tfp_windows: Mapping[str, float] | None = None) -> dict[str, dict[str, Any]]:
    """Colour, marker, line style and width of every method, stable for a given method list.

    ``tfp_windows`` (:func:`bench.harness.results.tfp_windows`) gives the TFP variants a blue ramp by window.
    """
    styles: dict[str, dict[str, Any]] = {}
    counters: dict[str, int] = {}
    windows = dict(tfp_windows or {})
    tfp = sorted((m for m in methods if m in windows), key=lambda m: windows[m])
    blues = plt.get_cmap("Blues")
    for m in methods:
        fam = families.get(m, "unknown")
        fam = fam if fam in PALETTES else "unknown"
        if m in tfp:  # TFP variants: a blue ramp, light for short windows, dark for long ones
            k = tfp.index(m)
            color = matplotlib.colors.to_hex(blues(0.45 + 0.5 * k / max(1, len(tfp) - 1)))
            marker = MARKERS[k % len(MARKERS)]
        else:
            i = counters.get(fam, 0)
            counters[fam] = i + 1
            color = PALETTES[fam][i % len(PALETTES[fam])]
            marker = MARKERS[(i + (len(tfp) if fam == "spike" else 0)) % len(MARKERS)]
        styles[m] = {"color": color, "marker": marker, "linestyle": LINESTYLES[fam],
                     "linewidth": 2.4 if fam == "fusion" else 1.6}
    return styles


def save_png(fig: Figure, path: str | Path, dpi: int = 130) -> Path:
    """Write ``fig`` as a PNG atomically (temporary file beside ``path``, then ``os.replace``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    data = buf.getvalue()
    return write_with(path, lambda f: f.write(data))


def _log2(axis: str) -> bool:
    return axis in AXIS and AXIS[axis].log2


def _axis_positions(axis: str, values: Sequence[Any]) -> np.ndarray:
    if _log2(axis):
        return np.asarray(values, dtype=np.float64)
    return np.arange(len(values), dtype=np.float64)


def _setup_x(ax: Any, axis: str, values: Sequence[Any]) -> None:
    pos = _axis_positions(axis, values)
    if _log2(axis):
        ax.set_xscale("log", base=2)
        ax.minorticks_off()
    ax.set_xticks(pos)
    ax.set_xticklabels([axis_label(axis, v) for v in values])
    if len(pos) > 1:
        if _log2(axis):
            ax.set_xlim(pos.min() / 2 ** 0.25, pos.max() * 2 ** 0.25)
        else:
            ax.set_xlim(pos.min() - 0.3, pos.max() + 0.3)
    ax.set_xlabel(AXIS_TITLES.get(axis, axis) + (" (log2 scale)" if _log2(axis) else ""))


def axis_figure(frame: pd.DataFrame, axis: str, metrics: Sequence[str] = ("psnr", "ssim"),
                spread: str = "std") -> Figure:
    """Each metric against ``axis``, one line per method, with the spread over scenes and seeds.

    Parameters
    ----------
    frame : DataFrame
        Long results (:mod:`bench.harness.results`).
    axis : {"light", "motion", "noise"}
    metrics : metrics of ``results.csv``, one panel each
    spread : ``"std"`` (mean ± sample standard deviation) or ``"minmax"`` (the range)
    """
    if spread not in ("std", "minmax"):
        raise ValueError(f"spread: expected 'std' or 'minmax', got {spread!r}")
    methods = method_order(frame)
    fams = method_families(frame)
    styles = method_styles(methods, fams, tfp_windows(frame))
    values = axis_values(frame, axis)
    fig, axes = plt.subplots(1, len(metrics), figsize=(6.2 * len(metrics) + 2.4, 5.0), squeeze=False)
    handles: dict[str, Any] = {}
    n_max = 0
    for ax, metric in zip(axes[0], metrics):
        s = axis_summary(frame, axis, metric)
        for m in methods:
            rows = s[s["method"] == m]
            if rows.empty:
                continue
            if not _log2(axis):  # a categorical axis: its values at their positions
                x = rows[axis].map({v: i for i, v in enumerate(values)}).to_numpy(dtype=np.float64)
            else:
                x = rows[axis].to_numpy(dtype=np.float64)
            y = rows["mean"].to_numpy(dtype=np.float64)
            st = styles[m]
            (line,) = ax.plot(x, y, color=st["color"], marker=st["marker"], linestyle=st["linestyle"],
                              linewidth=st["linewidth"], markersize=5, label=m)
            handles[m] = line
            if spread == "std":
                sd = rows["std"].to_numpy(dtype=np.float64)
                lo, hi = y - sd, y + sd
            else:
                lo, hi = rows["min"].to_numpy(dtype=np.float64), rows["max"].to_numpy(dtype=np.float64)
            ok = np.isfinite(lo) & np.isfinite(hi)
            if ok.sum() >= 2:
                ax.fill_between(x[ok], lo[ok], hi[ok], color=st["color"], alpha=0.12, linewidth=0)
            n_max = max(n_max, int(rows["n"].max()))
        _setup_x(ax, axis, values)
        ax.set_ylabel(METRIC_LABELS.get(metric, metric))
        ax.set_title(METRIC_LABELS.get(metric, metric))
        ax.grid(True, alpha=0.3)
    band = "mean ± 1 std" if spread == "std" else "mean, band = min..max"
    held = held_conditions(frame, axis)
    fig.suptitle(f"Against the {AXIS_TITLES.get(axis, axis)}: {band} over scenes and seeds "
                 f"(up to {n_max} per point{', ' + held if held else ''})", fontsize=12)
    if handles:
        fig.legend([handles[m] for m in methods if m in handles], [m for m in methods if m in handles],
                   loc="center right", fontsize=9, frameon=False, title="method")
    fig.tight_layout(rect=(0, 0, 1 - 2.2 / fig.get_figwidth(), 0.95))
    return fig


def recon_grid_figure(images: Mapping[tuple[str, Any], np.ndarray], rows: Sequence[str],
                      values: Sequence[Any], axis: str, title: str) -> Figure:
    """A grid of images: ``rows`` (``"gt"`` first, then methods) by axis ``values``.

    Parameters
    ----------
    images : mapping ``(row, value) -> float array (H, W)`` in [0, 1]; missing cells stay blank
    rows : row names in order (``"gt"`` is labelled "ground truth")
    values : axis values in column order
    axis : the axis the columns follow
    title : the figure's title
    """
    shapes = [im.shape for im in images.values()]
    h, w = shapes[0][:2] if shapes else (1, 1)
    cell_w = min(2.2, 13.0 / max(1, len(values)))
    cell_h = cell_w * h / w
    # room for the longest row label (about 0.075 in per character at 9 pt), so none is clipped
    longest = max([len("ground truth" if r == "gt" else str(r)) for r in rows] or [1])
    top_in, left_in = 0.75, max(1.5, 0.075 * longest + 0.3)
    fig, axes = plt.subplots(len(rows), len(values), squeeze=False,
                             figsize=(cell_w * len(values) + left_in + 0.1, cell_h * len(rows) * 1.06 + top_in + 0.1))
    for i, row in enumerate(rows):
        for j, v in enumerate(values):
            ax = axes[i][j]
            ax.set_xticks([])
            ax.set_yticks([])
            for spine in ax.spines.values():
                spine.set_edgecolor("#cccccc")
                spine.set_linewidth(0.6)
            im = images.get((row, v))
            if im is not None:
                ax.imshow(im, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
            else:
                ax.text(0.5, 0.5, "-", ha="center", va="center", transform=ax.transAxes, color="#999999")
            if i == 0:
                ax.set_title({"light": "L = ", "motion": "S = "}.get(axis, "noise ") + axis_label(axis, v), fontsize=9)
            if j == 0:
                ax.set_ylabel("ground truth" if row == "gt" else row, fontsize=9, rotation=0, ha="right",
                              va="center")
    height_in = fig.get_figheight()
    fig.suptitle(title, fontsize=11, y=1 - 0.12 / height_in, va="top")
    fig.subplots_adjust(left=left_in / fig.get_figwidth(), right=1 - 0.05 / fig.get_figwidth(),
                        top=1 - top_in / height_in, bottom=0.05 / height_in, wspace=0.04, hspace=0.06)
    return fig


def accuracy_time_figure(points: pd.DataFrame, note: str = "",
                         tfp_windows: Mapping[str, float] | None = None) -> Figure:
    """Mean PSNR and SSIM against ms per frame (log x), Pareto front marked.

    Parameters
    ----------
    points : DataFrame with ``method, family, ms_per_frame, psnr, ssim, front_psnr, front_ssim``, and
        optionally ``stream_ms``: a method that streams is drawn twice, filled at its cold start
        (``ms_per_frame``) and hollow at one new frame of a running video, joined by a dotted line
    note : one line under the title saying where the numbers come from
    """
    methods = list(points["method"])
    styles = method_styles(methods, dict(zip(points["method"], points["family"])), tfp_windows)
    fig, axes = plt.subplots(1, 2, figsize=(14.5, 5.6), squeeze=False)
    keys: list[Any] = []  # the marks' key, once below both panels
    for ax, metric in zip(axes[0], ("psnr", "ssim")):
        pts = points[np.isfinite(points["ms_per_frame"].to_numpy(float)) & np.isfinite(points[metric].to_numpy(float))
                     & (points["ms_per_frame"].to_numpy(float) > 0)]
        front = pts[pts[f"front_{metric}"].astype(bool)].sort_values("ms_per_frame")
        if len(front):
            ax.step(front["ms_per_frame"], front[metric], where="post", color="#333333", linewidth=1.2,
                    alpha=0.7, zorder=1, label="Pareto front")
        streamed = False
        for r in pts.itertuples():
            st = styles[r.method]
            on = bool(getattr(r, f"front_{metric}"))
            ax.scatter([r.ms_per_frame], [getattr(r, metric)], color=st["color"], marker=st["marker"],
                       s=70 if on else 40, edgecolors="black" if on else "none", linewidths=1.2, zorder=3,
                       label=r.method)
            stream = pd.to_numeric(getattr(r, "stream_ms", math.nan), errors="coerce")  # empty in a CSV read back
            if math.isfinite(stream) and stream > 0:
                # the same method's second cost: one new frame of a running video (hollow, joined)
                ax.plot([r.ms_per_frame, stream], [getattr(r, metric)] * 2, color=st["color"], lw=0.8, ls=":",
                        zorder=2)
                ax.scatter([stream], [getattr(r, metric)], facecolors="none", edgecolors=st["color"],
                           marker=st["marker"], s=40, linewidths=1.2, zorder=3)
                streamed = True
        # the key: points are named beside them, so the legend explains only the marks
        from matplotlib.lines import Line2D

        key = []
        if len(front):
            key.append(Line2D([], [], color="#333333", lw=1.2, alpha=0.7, label="Pareto front"))
        if streamed:
            key += [Line2D([], [], ls="none", marker="o", color="#555555", markersize=6,
                           label="filled: cold start (one call; recurrent: warm-up over the event history)"),
                    Line2D([], [], ls="none", marker="o", markerfacecolor="none", markeredgecolor="#555555",
                           markersize=6, label="hollow: streaming (one new frame of a running video)")]
        keys = key or keys
        ax.set_xscale("log")
        ax.set_xlabel("ms per frame (log scale)")
        ax.set_ylabel(METRIC_LABELS[metric])
        ax.grid(True, which="both", alpha=0.25)
        ax.set_title(f"{METRIC_LABELS[metric]} against time; ringed: on the Pareto front", fontsize=10)
        if len(pts):
            lo, hi = pts["ms_per_frame"].min(), pts["ms_per_frame"].max()
            if "stream_ms" in pts:
                lo = min(lo, float(np.nanmin(np.r_[pd.to_numeric(pts["stream_ms"], errors="coerce").to_numpy(float), lo])))
            ax.set_xlim(lo / 2.5, hi * 6.0)
            ys = pts[metric].to_numpy(float)
            pad = 0.08 * (ys.max() - ys.min()) if ys.max() > ys.min() else 0.5
            ax.set_ylim(ys.min() - pad, ys.max() + pad)
            _label_points(ax, pts["ms_per_frame"].to_numpy(float), ys, list(pts["method"]),
                          [styles[m]["color"] for m in pts["method"]])
    import textwrap

    lines = textwrap.wrap(note, 170) if note else []  # a long note wraps instead of running off the page
    fig.suptitle("\n".join(["Accuracy against time", *lines]), fontsize=11)
    if keys:
        fig.legend(handles=keys, loc="lower center", ncol=len(keys), fontsize=8.5, frameon=False)
    fig.tight_layout(rect=(0, 0.05 if keys else 0, 1, 0.97 - 0.04 * len(lines)))
    return fig


def _label_points(ax: Any, x: np.ndarray, y: np.ndarray, labels: Sequence[str], colors: Sequence[str]) -> None:
    """Label points to their right, moving a label down when it would overlap one already placed
    (positions compared in axes fractions; a moved label gets a thin leader line)."""
    to_axes = ax.transAxes.inverted()
    disp = ax.transData.transform(np.column_stack([x, y]))
    frac = to_axes.transform(disp)
    placed: list[tuple[float, float, float]] = []  # (x0, x1, y) of placed labels
    height = 0.045
    for i in np.argsort(-frac[:, 1], kind="stable"):
        fx, fy = frac[i]
        width = 0.012 * len(labels[i]) + 0.02
        ty = fy + 0.01
        for _ in range(len(labels)):
            clash = [p for p in placed if p[0] < fx + 0.015 + width and fx + 0.015 < p[1] and abs(p[2] - ty) < height]
            if not clash:
                break
            ty = min(p[2] for p in clash) - height
        placed.append((fx + 0.015, fx + 0.015 + width, ty))
        moved = abs(ty - (fy + 0.01)) > 1e-9
        ax.annotate(labels[i], (x[i], y[i]), xycoords="data", xytext=(fx + 0.015, ty), textcoords="axes fraction",
                    fontsize=8, color=colors[i], va="center", zorder=2,
                    bbox={"boxstyle": "round,pad=0.1", "facecolor": "white", "edgecolor": "none", "alpha": 0.75},
                    arrowprops={"arrowstyle": "-", "color": colors[i], "lw": 0.6, "alpha": 0.7} if moved else None)


# ----------------------------------------------------------------------------------------------
# Pages for the PDF
# ----------------------------------------------------------------------------------------------

def _wrap(text: str, width: int) -> str:
    return "\n".join(textwrap.wrap(str(text), width=width, break_long_words=True, break_on_hyphens=False)) or ""


def table_figures(header: Sequence[str], rows: Sequence[Sequence[str]], title: str,
                  wrap: Mapping[int, int] | None = None, rows_per_page: int = 26,
                  note: str = "") -> list[Figure]:
    """A table as A4 landscape pages (``rows_per_page`` rows each).

    ``wrap`` maps a column index to the characters per line at which its cells are wrapped.
    """
    wrap = dict(wrap or {})
    pages = max(1, math.ceil(len(rows) / rows_per_page))
    figs = []
    for p in range(pages):
        chunk = rows[p * rows_per_page:(p + 1) * rows_per_page]
        cells = [[_wrap(c, wrap[j]) if j in wrap else str(c) for j, c in enumerate(r)] for r in chunk]
        fig = plt.figure(figsize=PAGE_SIZE_IN)
        fig.text(0.04, 0.95, title + (f" ({p + 1}/{pages})" if pages > 1 else ""), fontsize=14, weight="bold",
                 va="top")
        if note:
            fig.text(0.04, 0.91, _wrap(note, 150), fontsize=8.5, va="top", color="#333333")
        ax = fig.add_axes((0.04, 0.04, 0.92, 0.82 if note else 0.86))
        ax.axis("off")
        if not cells:
            ax.text(0.0, 1.0, "(no rows)", va="top")
        else:
            lines = [max(1, max(str(c).count("\n") + 1 for c in r)) for r in cells]
            widths = [max(len(str(h)), *(max(len(s) for s in str(r[j]).split("\n")) for r in cells)) for j, h in
                      enumerate(header)]
            total = float(sum(widths))
            numeric = [all(_numeric_text(r[j]) for r in cells) for j in range(len(header))]
            unit = min(0.034, 0.95 / (sum(lines) + 1.5))
            table = Table(ax, loc="upper left")
            for i, row in enumerate([list(header), *cells]):
                for j, text in enumerate(row):
                    cell = table.add_cell(i, j, width=widths[j] / total, height=unit * (1.3 if i == 0 else lines[i - 1]),
                                          text=str(text), loc="right" if numeric[j] else "left",
                                          facecolor="#e8e8e8" if i == 0 else "white", edgecolor="#bbbbbb")
                    if i == 0:
                        cell.get_text().set_weight("bold")
            table.auto_set_font_size(False)
            table.set_fontsize(8)
            ax.add_table(table)
        figs.append(fig)
    return figs


def _numeric_text(text: Any) -> bool:
    t = str(text).replace(",", "").strip()
    if t in ("-", ""):
        return True
    try:
        float(t.split(" ")[0])
        return True
    except ValueError:
        return False


def text_figures(title: str, blocks: Sequence[tuple[str, str]], width: int = 120,
                 lines_per_page: int = 44) -> list[Figure]:
    """Pages of text: ``blocks`` are ``(style, text)`` with style ``"h"`` (heading), ``"p"``
    (paragraph), ``"mono"`` (preformatted) or a colour name for a coloured bold line."""
    lines: list[tuple[str, str]] = []
    for style, text in blocks:
        if style == "mono":
            lines += [("mono", ln) for ln in str(text).split("\n")]
        elif style == "h":
            lines += [("", ""), ("h", str(text))]
        elif style == "p":
            lines += [("p", ln) for ln in (textwrap.wrap(str(text), width=width) or [""])]
        else:
            lines += [(style, ln) for ln in (textwrap.wrap(str(text), width=width) or [""])]
    pages = [lines[i:i + lines_per_page] for i in range(0, max(1, len(lines)), lines_per_page)] or [[]]
    figs = []
    for k, page in enumerate(pages):
        fig = plt.figure(figsize=PAGE_SIZE_IN)
        fig.text(0.05, 0.95, title + (f" ({k + 1}/{len(pages)})" if len(pages) > 1 else ""), fontsize=15,
                 weight="bold", va="top")
        y = 0.89
        step = 0.84 / lines_per_page
        for style, text in page:
            kw: dict[str, Any] = {"fontsize": 9.5, "va": "top"}
            if style == "h":
                kw.update(fontsize=11, weight="bold")
            elif style == "mono":
                kw.update(family="monospace", fontsize=8.5)
            elif style not in ("p", ""):
                kw.update(color=style, weight="bold")
            fig.text(0.05, y, text, **kw)
            y -= step
        figs.append(fig)
    return figs


def claims_figures(verdicts: pd.DataFrame) -> list[Figure]:
    """The claims page(s): each statement with its verdict (coloured), test and evidence."""
    blocks: list[tuple[str, str]] = [
        ("p", "Statements of NeuSpike-Net (ICCV 2021) about its Figures 3 and 4 and "
              "Table 3, checked against these results. Numbers are mean PSNR (dB) over scenes and seeds "
              "unless said otherwise; the thresholds are stated in each test (bench/reporting/claims.py)."),
    ]
    if verdicts.attrs.get("caveat"):
        blocks.append(("firebrick", verdicts.attrs["caveat"]))
    counts = verdicts["status"].value_counts()
    blocks.append(("p", ", ".join(f"{int(counts.get(s, 0))} {s}" for s in STATUS_COLOURS) + "."))
    for r in verdicts.itertuples():
        blocks.append(("h", r.statement))
        blocks.append((STATUS_COLOURS.get(r.status, "black"), f"{r.status.upper()}  —  test: {r.test}"))
        blocks.append(("p", r.evidence + (f" (figure: {r.figure})" if r.figure else "")))
    return text_figures("The paper's claims against our numbers", blocks, width=130, lines_per_page=46)


def close_all(figs: Sequence[Figure]) -> None:
    for f in figs:
        plt.close(f)


def read_gray(path: Path) -> np.ndarray:
    """A PNG (or other image) as a float greyscale array in [0, 1]."""
    import matplotlib.image as mpimg

    raw = np.asarray(mpimg.imread(path))  # PNGs come back as floats in [0, 1]; other formats as integers
    im = raw / np.iinfo(raw.dtype).max if raw.dtype.kind in "ui" else raw.astype(np.float64)
    if im.ndim == 3:
        im = im[..., :3].mean(axis=2)
    return im


def write_pdf(path: Path, pages: Sequence[Any]) -> None:
    """The figures ``pages`` as one PDF, written atomically."""
    from matplotlib.backends.backend_pdf import PdfPages

    from neuspike.utils.atomic import replacing

    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp, PdfPages(tmp, metadata={"Creator": "NeuSpike Bench", "CreationDate": None}) as pdf:
        for page in pages:
            pdf.savefig(page)
