"""The report of a dataset run (:mod:`bench.harness.datasets`), from its folder alone.

Called by :func:`bench.reporting.build.build_report` when ``config.json`` holds a ``dataset``. Writes

``tables/dataset.md`` / ``.csv``   one row per recording and method: inputs, normalisation, instants
                                   ok / failed / skipped, the mean of each metric over the instants
                                   (PSNR, SSIM and the affine variants where a ground truth exists;
                                   the no-reference measures always) and the median ms per frame
``tables/failures.md`` / ``.csv``  failed and skipped methods with their error and instant count
``figures/sheet_<recording>.png``   the contact sheet of a recording: its ground truth (when there is
                                   one) and every method's image at its middle instant, each labelled
                                   with the method, its time and (with ground truth) its PSNR
``report.pdf``                     the protocol and provenance first, then the tables and the sheets
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from bench.reporting import figures as figs
from bench.reporting import tables as tb
from bench.harness.images import recording_image_path, safe_name
from bench.harness.results import ERROR, OK, SKIPPED

#: Tiles per row of a contact sheet.
SHEET_COLUMNS = 4
#: Widest sheet embedded in the PDF (the PNG under figures/ keeps every pixel); an A4 page shows no more.
PDF_SHEET_WIDTH_PX = 800
METRIC_ORDER = ("psnr", "ssim", "psnr_affine", "ssim_affine", "noise_sigma", "laplacian_var")


def dataset_table(frame: pd.DataFrame) -> pd.DataFrame:
    """One row per (recording, method) with instant counts, metric means and the median time."""
    records = []
    order = tb.method_order(frame)
    for scene in pd.unique(frame["scene"]):
        sub = frame[frame["scene"] == scene]
        for method in [m for m in order if m in set(sub["method"])]:
            rows = sub[sub["method"] == method]
            per_instant = rows.drop_duplicates("instant")
            ok = rows[rows["status"] == OK]
            rec: dict[str, Any] = {
                "recording": scene, "method": method, "inputs": rows["inputs"].iloc[0],
                "normalisation": ";".join(sorted({n for n in ok["normalisation"] if n})),
                "instants_ok": int((per_instant["status"] == OK).sum()),
                "instants_failed": int((per_instant["status"] == ERROR).sum()),
                "instants_skipped": int((per_instant["status"] == SKIPPED).sum()),
            }
            for metric in METRIC_ORDER:
                vals = ok.loc[ok["metric"] == metric, "value"]
                rec[metric] = float(vals.mean()) if len(vals) else math.nan
            ms = ok.drop_duplicates("instant")["ms_per_frame"].dropna()
            rec["ms_per_frame"] = float(ms.median()) if len(ms) else math.nan
            records.append(rec)
    cols = ["recording", "method", "inputs", "normalisation", "instants_ok", "instants_failed", "instants_skipped",
            *METRIC_ORDER, "ms_per_frame"]
    out = pd.DataFrame(records, columns=cols)
    return out.dropna(axis=1, how="all") if len(out) else out


_KIND = {"psnr": "psnr", "psnr_affine": "psnr", "ssim": "ssim", "ssim_affine": "ssim", "ms_per_frame": "ms"}


def _fmt(metric: str, value: Any) -> str:
    if metric in _KIND:
        return tb.fmt(value, _KIND[metric])
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.4g}"


def dataset_markdown(table: pd.DataFrame) -> str:
    metrics = [m for m in (*METRIC_ORDER, "ms_per_frame") if m in table.columns]
    header = ["recording", "method", "normalisation", "ok/failed/skipped", *metrics]
    rows = [[r["recording"], r["method"], r["normalisation"] or "-",
             f"{r['instants_ok']}/{r['instants_failed']}/{r['instants_skipped']}",
             *[_fmt(m, r[m]) for m in metrics]] for _, r in table.iterrows()]
    return ("Means over each recording's instants (ok rows); ms_per_frame: median. noise_sigma: Haar-MAD noise "
            "estimate (lower is less noise); laplacian_var: variance of the Laplacian (higher is sharper or noisier).\n\n"
            + tb.markdown_table(header, rows))


def failures(frame: pd.DataFrame) -> pd.DataFrame:
    bad = frame[frame["status"] != OK].drop_duplicates(["scene", "instant", "method"])
    cols = ["method", "status", "instants", "error"]
    if bad.empty:
        return pd.DataFrame(columns=cols)
    g = bad.groupby(["method", "status", "error"], sort=True).size().reset_index(name="instants")
    return g[cols].reset_index(drop=True)


def contact_sheet(folder: Path, recording: str, frame: pd.DataFrame) -> np.ndarray | None:
    """uint8 sheet of a recording's saved images (``images/<recording>/``), or ``None`` without images."""
    from neuspike.formats.images import to_uint8
    from neuspike.video.writers import label_image, tile_row

    sub = frame[(frame["scene"] == recording) & (frame["status"] == OK)]
    names = ["gt"] + [m for m in tb.method_order(frame) if m in set(sub["method"])]
    tiles = []
    for name in names:
        path = recording_image_path(folder / "images", recording, name)
        if not path.is_file():
            continue
        image = figs.read_gray(path)
        label = "ground truth" if name == "gt" else name
        if name != "gt":
            mine = sub[sub["method"] == name]
            middle = mine[mine["instant"] == _middle_instant(frame, recording)]
            ms = middle["ms_per_frame"].dropna()
            psnr = middle.loc[middle["metric"] == "psnr", "value"]
            label += f"  {ms.iloc[0]:.0f} ms" if len(ms) else ""
            label += f"  {psnr.iloc[0]:.1f} dB" if len(psnr) else ""
        tiles.append(label_image(to_uint8(image, clip=True), label))
    if not tiles:
        return None
    h, w = tiles[0].shape
    blank = np.full((h, w), 255, dtype=np.uint8)
    lines = []
    for i in range(0, len(tiles), SHEET_COLUMNS):
        row = tiles[i:i + SHEET_COLUMNS]
        if lines:
            row += [blank] * (SHEET_COLUMNS - len(row))
        lines.append(tile_row(row))
    width = max(line.shape[1] for line in lines)
    gap = np.full((4, width), 128, dtype=np.uint8)
    out: list[np.ndarray] = []
    for line in lines:
        if out:
            out.append(gap)
        out.append(np.pad(line, ((0, 0), (0, width - line.shape[1])), constant_values=255))
    return np.concatenate(out, axis=0)


def _fit(sheet: np.ndarray, width_px: int) -> np.ndarray:
    """``sheet`` shrunk (area averaging) to at most ``width_px`` wide; never enlarged."""
    if sheet.shape[1] <= width_px:
        return sheet
    import cv2

    height = max(1, round(sheet.shape[0] * width_px / sheet.shape[1]))
    return cv2.resize(sheet, (width_px, height), interpolation=cv2.INTER_AREA)


def _middle_instant(frame: pd.DataFrame, recording: str) -> int:
    """The instant whose images were kept: the middle of the recording's instants."""
    instants = sorted(int(i) for i in pd.unique(frame.loc[frame["scene"] == recording, "instant"].dropna()))
    return len(instants) // 2 if instants else 0


def protocol_blocks(dataset: dict[str, Any]) -> list[tuple[str, str]]:
    """The protocol of ``config.json`` as the title page's text."""
    proto = dataset.get("protocol") or {}
    blocks: list[tuple[str, str]] = [("h", "Protocol")]
    for key in ("window", "key_instant", "rate", "normalisation", "ground_truth"):
        if key in proto:
            blocks.append(("p", f"{key.replace('_', ' ').capitalize()}: {proto[key]}."))
    blocks.append(("p", f"Data range: {proto.get('data_range', '?')}; {proto.get('metrics', '')}."))
    nr = proto.get("no_reference") or {}
    if nr:
        blocks.append(("p", "No-reference measures: " + "; ".join(f"{k}: {nr[k]}" for k in nr.get("measures", []))))
    if proto.get("timing"):
        blocks.append(("p", f"Timing: {proto['timing']}."))
    recs = proto.get("recordings") or {}
    if recs:
        blocks.append(("h", "Recordings"))
        for name, r in recs.items():
            gain = "unknown" if r.get("gain") is None else f"{r['gain']:g} ({r.get('gain_source')})"
            first = r.get("first_instant") or {}
            first_text = ", ".join(f"{k} {v:.6f}" if isinstance(v, float) else f"{k} {v}" for k, v in first.items())
            blocks.append(("p", f"{name}: {r.get('inputs')}, {r.get('size')}, {r.get('plane_rate_hz')} planes/s, "
                                f"window {r.get('window_planes')} planes, gain {gain}; {r.get('instants')} instant(s) "
                                f"(first: {first_text}), {r.get('ground_truth')} with ground truth"
                                + (f"; unreadable: {r['damaged']}" if r.get("damaged") else "")))
    return blocks


def build_dataset_report(inputs: Any, out: Path, *, provenance: list[tuple[str, str]]) -> Path:
    """Write the tables, the contact sheets and ``report.pdf`` of a dataset folder; return the PDF's path.

    ``inputs`` is :func:`bench.reporting.build.load_inputs`'s; ``provenance`` the title page's provenance
    blocks (:func:`bench.reporting.build.title_blocks` without the results).
    """
    from neuspike.formats.images import write_png
    from neuspike.utils.atomic import write_text

    f = inputs.results
    dataset = inputs.config.get("dataset") or {}
    fig_dir, tab_dir = out / "figures", out / "tables"
    pages: list[Any] = []
    try:
        blocks: list[tuple[str, str]] = [("p", f"Dataset: {dataset.get('name', '?')}; manifest layout "
                                               f"{(dataset.get('manifest') or {}).get('layout', '?')}; "
                                               f"{f['scene'].nunique() if f is not None else 0} recordings, "
                                               f"{len(tb.method_order(f)) if f is not None and len(f) else 0} methods.")]
        blocks += protocol_blocks(dataset)
        blocks += [b for b in provenance if not (b[0] == "h" and b[1] == "Contents")][:-1]
        pages += figs.text_figures("NeuSpike Bench dataset report", blocks, width=128)
        if f is not None and len(f):
            table = dataset_table(f)
            write_text(tab_dir / "dataset.md", dataset_markdown(table))
            write_text(tab_dir / "dataset.csv", tb.to_csv_text(table))
            metrics = [m for m in (*METRIC_ORDER, "ms_per_frame") if m in table.columns]
            pages += figs.table_figures(
                ["recording", "method", "ok/fail/skip", *metrics],
                [[r["recording"], r["method"], f"{r['instants_ok']}/{r['instants_failed']}/{r['instants_skipped']}",
                 *[_fmt(m, r[m]) for m in metrics]] for _, r in table.iterrows()],
                "Methods on each recording", note="Means over the instants of the ok rows; ms per frame: median.")
            bad = failures(f)
            write_text(tab_dir / "failures.md", tb.markdown_table(["method", "status", "instants", "error"],
                                                                  [[r.method, r.status, r.instants, r.error]
                                                                   for r in bad.itertuples()]))
            write_text(tab_dir / "failures.csv", tb.to_csv_text(bad))
            if len(bad):
                pages += figs.table_figures(["method", "status", "instants", "error"],
                                            [[r.method, r.status, r.instants, r.error] for r in bad.itertuples()],
                                            "Failed and skipped methods", wrap={3: 110}, rows_per_page=12)
            import matplotlib.pyplot as plt

            for recording in pd.unique(f["scene"]):
                sheet = contact_sheet(inputs.folder, recording, f)
                if sheet is None:
                    continue
                write_png(fig_dir / f"sheet_{safe_name(recording)}.png", sheet.astype(np.float32) / 255.0, clip=False)
                fig = plt.figure(figsize=figs.PAGE_SIZE_IN)
                fig.text(0.04, 0.96, f"{recording}: every method at its middle instant", fontsize=13, weight="bold",
                         va="top")
                ax = fig.add_axes((0.03, 0.03, 0.94, 0.88))
                ax.imshow(_fit(sheet, PDF_SHEET_WIDTH_PX), cmap="gray", vmin=0, vmax=255, interpolation="none")
                ax.axis("off")
                pages.append(fig)
        pdf = out / "report.pdf"
        figs.write_pdf(pdf, pages)
    finally:
        figs.close_all(pages)
        import matplotlib.pyplot as plt

        plt.close("all")
    return pdf
