"""Tidy results: one row per (method, scene, condition, seed, metric).

Columns (:data:`COLUMNS`)
-------------------------
``cell``            the cell's id (a hash of its identity and the sweep's methods; the part file's name)
``scene``           ``KIND:IMAGE``; ``kind`` and ``image`` split out; ``width``, ``height`` in pixels
``planes``          spike planes per window (T)
``light``           light scale L; ``motion`` motion scale S; ``noise`` the noise level
``effects``         the simulator stages that ran for the method's inputs, ``modality:name`` joined by ``;``
``seed``            the cell's seed
``method``          registry name; ``inputs`` its modalities joined by ``+``; ``recurrent`` bool;
                    ``parameters`` its learned parameter count
``normalisation``   the label the method reported (e.g. ``gain``, ``robust-p99``)
``method_params``   the method's description as canonical JSON: its implementation, parameters (window,
                    cutoff, ...), and for learned methods the weights file, its sha256 and the device
                    (``Method.describe()``); reports read a method's parameters here, never from its name
``metric``          one of ``psnr``, ``ssim``, ``psnr_affine``, ``ssim_affine``, ``static_texture`` (the
                    gradient correlation over the pixels that never change, NaN where a cell has no
                    static region: :func:`neuspike.metrics.static_texture`), ``specks`` (the fraction
                    of pixels that are isolated outliers where the truth has none:
                    :func:`neuspike.metrics.isolated_outliers`); ``value`` its value
``status``          ``ok``; ``error`` (the method or the simulation raised: ``value`` is NaN and
                    ``error`` holds the exception's type and message); ``skipped`` (the method
                    cannot run here, e.g. learned weights not given: ``error`` holds the reason;
                    a skip is not a failure)
``ms_per_frame``    wall time of the method's ``reconstruct`` call in milliseconds (simulation
                    excluded; for recurrent methods the call includes the warm-up over the event
                    history, as a recurrent method pays it once per sequence)
``sim_seconds``     wall time of the cell's simulation (every stage, both modalities), from the
                    recording's metadata, so a cached recording reports the time it originally took
``stage_seconds``   JSON object ``{"modality:name": seconds}`` for every stage that ran
``time_s``          the reconstruction instant in the recording's sensor seconds (rows of a dataset,
                    :mod:`bench.harness.datasets`); empty for simulated cells
``instant``         the instant's index among its recording's instants (datasets); empty otherwise
``reference``       the ground-truth file a dataset row was scored against, as the manifest names it;
                    empty where there is none (no-reference measures) and for simulated cells

Rows of a dataset (:mod:`bench.harness.datasets`) hold a recording instead of a simulated cell: ``scene`` is
the recording's name, ``kind`` its inputs (``spikes``, ``events`` or ``events+spikes``), ``image``
its files, ``planes`` the spike window; ``light``, ``motion``, ``seed`` and ``noise`` are empty
(nothing was simulated), and the metrics are the full-reference ones where a ground truth exists
and the no-reference ones (``noise_sigma``, ``laplacian_var``) always.

Timing columns (:data:`TIMING_COLUMNS`) are measurements of one run on one machine and differ between
any two runs; everything else is a deterministic function of the configuration and the seeds.
Compare runs with :func:`drop_timing`.

Files are written atomically. ``results.csv`` is assembled from the per-cell part files in the
order of :data:`SORT_COLUMNS`, so it does not depend on which cells finished first.
"""

from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from neuspike.utils.atomic import write_text
from neuspike.errors import FormatError, one_line

COLUMNS: tuple[str, ...] = (
    "cell", "scene", "kind", "image", "width", "height", "planes",
    "light", "motion", "noise", "effects", "seed",
    "method", "inputs", "recurrent", "parameters", "normalisation", "method_params",
    "metric", "value", "status", "error",
    "ms_per_frame", "sim_seconds", "stage_seconds", "time_s", "instant", "reference",
)
#: Columns that hold run-dependent measurements of time.
TIMING_COLUMNS: tuple[str, ...] = ("ms_per_frame", "sim_seconds", "stage_seconds")
#: Columns added after the first results were published; read as empty when absent.
OPTIONAL_COLUMNS: tuple[str, ...] = ("method_params", "time_s", "instant", "reference")
#: The ``implementation`` of TFP in a method's description.
TFP_IMPLEMENTATION = "baselines.tfp.TFP"
#: The order of rows in ``results.csv``.
SORT_COLUMNS: tuple[str, ...] = ("scene", "noise", "light", "motion", "seed", "time_s", "method", "metric")
#: Row statuses.
OK, ERROR, SKIPPED = "ok", "error", "skipped"

_DTYPES: Mapping[str, Any] = {
    "cell": str, "scene": str, "kind": str, "image": str, "width": "int64", "height": "int64",
    "planes": "int64", "light": "float64", "motion": "Int64", "noise": str, "effects": str,
    "seed": "Int64", "method": str, "inputs": str, "recurrent": bool, "parameters": "int64",
    "normalisation": str, "method_params": str, "metric": str, "value": "float64", "status": str, "error": str,
    "ms_per_frame": "float64", "sim_seconds": "float64", "stage_seconds": str,
    "time_s": "float64", "instant": "Int64", "reference": str,
}
_TEXT = [c for c, t in _DTYPES.items() if t is str]


def rows_frame(rows: Iterable[Mapping[str, Any]]) -> pd.DataFrame:
    """Rows (dicts with every key of :data:`COLUMNS`) as a typed DataFrame in column order."""
    rows = list(rows)
    missing = [sorted(set(COLUMNS) - set(r)) for r in rows if set(COLUMNS) - set(r)]
    if missing:
        raise ValueError(f"result rows lack columns {missing[0]}")
    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    return _typed(frame)


def _typed(frame: pd.DataFrame) -> pd.DataFrame:
    for col in _TEXT:
        frame[col] = frame[col].fillna("").astype(str)
    if frame["recurrent"].dtype == object:  # text from a CSV reader that did not infer booleans
        frame["recurrent"] = frame["recurrent"].map(lambda v: v if isinstance(v, bool) else str(v) == "True")
    for col, dtype in _DTYPES.items():
        if dtype is not str:
            frame[col] = frame[col].astype(dtype)
    return frame


def to_csv_text(frame: pd.DataFrame) -> str:
    """CSV text; floats written with full precision (``repr``), NaN as an empty field."""
    buf = io.StringIO()
    frame.to_csv(buf, index=False, lineterminator="\n")
    return buf.getvalue()


def read_csv(path: str | os.PathLike) -> pd.DataFrame:
    """Read a part file or ``results.csv`` back with the documented dtypes."""
    try:
        frame = pd.read_csv(path, dtype={c: str for c in _TEXT}, keep_default_na=False,
                            na_values={c: [""] for c in _DTYPES if _DTYPES[c] is not str})
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, EOFError, OSError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        first = next((line for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
        raise FormatError(f"{path}: not a results table ({first})") from None
    for column in OPTIONAL_COLUMNS:  # results written before the column existed
        if column not in frame.columns:
            frame[column] = "" if _DTYPES[column] is str else np.nan
    missing = sorted(set(COLUMNS) - set(frame.columns))
    if missing:
        shown = ", ".join(missing[:4]) + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
        raise FormatError(f"{path}: not a results table (missing the columns {shown})")
    try:
        return _typed(frame[list(COLUMNS)].copy())
    except (ValueError, TypeError) as exc:  # a column that does not hold its type
        raise FormatError(f"{path}: a column does not hold its documented type ({one_line(exc)})") from None


def method_descriptions(frame: pd.DataFrame) -> dict[str, dict[str, Any]]:
    """``{method: description}`` from the ``method_params`` column (empty for rows without one)."""
    out: dict[str, dict[str, Any]] = {}
    for method, text in zip(frame["method"], frame["method_params"]):
        if method not in out or (not out[method] and text):
            out[method] = json.loads(text) if text else {}
    return out


def tfp_windows(frame: pd.DataFrame) -> dict[str, float]:
    """Planes per window of every TFP method of ``frame`` (``inf`` for the whole window), from its parameters."""
    windows = {}
    for method, info in method_descriptions(frame).items():
        if info.get("implementation") == TFP_IMPLEMENTATION:
            window = info.get("params", {}).get("window")
            windows[method] = math.inf if window is None else float(window)
    return windows


def write_part(parts_dir: str | os.PathLike, cell_id: str, rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write one cell's rows to ``<parts_dir>/<cell_id>.csv`` atomically."""
    return write_text(Path(parts_dir) / f"{cell_id}.csv", to_csv_text(rows_frame(rows)))


def part_path(parts_dir: str | os.PathLike, cell_id: str) -> Path:
    return Path(parts_dir) / f"{cell_id}.csv"


def sort_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """Rows in the order of :data:`SORT_COLUMNS` (stable), index reset."""
    return frame.sort_values(list(SORT_COLUMNS), kind="mergesort").reset_index(drop=True)


def assemble(parts_dir: str | os.PathLike, cell_ids: Iterable[str], out_path: str | os.PathLike) -> pd.DataFrame:
    """Join the part files of ``cell_ids`` (those that exist) into ``out_path``, sorted, atomically."""
    frames = [read_csv(p) for p in (part_path(parts_dir, c) for c in cell_ids) if p.exists()]
    frame = pd.concat(frames, ignore_index=True) if frames else rows_frame([])
    frame = sort_rows(frame)
    write_text(out_path, to_csv_text(frame))
    return frame


def drop_timing(frame: pd.DataFrame) -> pd.DataFrame:
    """The frame without :data:`TIMING_COLUMNS` (what two runs of one configuration share)."""
    return frame.drop(columns=[c for c in TIMING_COLUMNS if c in frame.columns])


def base_row(**fields: Any) -> dict[str, Any]:
    """A row with every column, defaults for the ones not given (NaN numbers, empty text)."""
    row: dict[str, Any] = {c: ("" if _DTYPES[c] is str else np.nan) for c in COLUMNS}
    row.update(recurrent=False, parameters=0)
    row.update(fields)
    return row


def family_of(inputs: Iterable[str]) -> str:
    """``"spike"``, ``"event"``, ``"fusion"`` or ``"unknown"`` from a method's inputs."""
    ins = frozenset(inputs)
    if ins == {"spikes"}:
        return "spike"
    if ins == {"events"}:
        return "event"
    if ins == {"spikes", "events"}:
        return "fusion"
    return "unknown"
