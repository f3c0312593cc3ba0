"""Table 2's accuracy join: each method's mean accuracy in a sweep beside its measured time.

Read by ``python -m bench.timing`` (after it times) and ``python -m bench.rebuild`` (from the committed
results, without timing anything again); the report draws the accuracy-against-time chart from it.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.reporting import tables as tb


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
    A method that streams (``stream_ms`` timed) has two honest costs: ``ms_per_frame`` is its cold
    start (one whole call, a recurrent method's warm-up over the history included) and
    ``stream_ms`` one new frame of a running video; for the others ``stream_ms`` is NaN.

    Returns
    -------
    DataFrame ``method, family, ms_per_frame, psnr, ssim, resolution, results, stream_ms``.
    """
    summary = tb.method_summary(results)
    summary = summary[summary["cells_ok"] > 0]
    sweep_w, sweep_h = sweep_resolution(results) or (0, 0)
    ok = timing[timing["status"] == "ok"]
    records = []
    for r in summary.itertuples():
        t = ok[ok["method"] == r.method]
        ms, res, cold, stream = math.nan, "", math.nan, math.nan
        if len(t):
            dist = (t["width"] * t["height"] - sweep_w * sweep_h).abs().to_numpy()
            exact = t[(t["width"] == sweep_w) & (t["height"] == sweep_h)]
            pick = exact.iloc[0] if len(exact) else t.iloc[int(np.argmin(dist))]
            ms, res = float(pick["ms_per_frame"]), str(pick["resolution"])
            cold = float(pick.get("cold_ms", math.nan))
            stream = float(pick.get("stream_ms", math.nan))
            if not math.isnan(stream):  # a streaming method: its point is the cold start, beside its streaming cost
                ms = cold
        records.append({"method": r.method, "family": r.family, "ms_per_frame": ms, "psnr": r.psnr, "ssim": r.ssim,
                        "resolution": res, "results": source, "stream_ms": stream})
    return pd.DataFrame(records, columns=["method", "family", "ms_per_frame", "psnr", "ssim", "resolution", "results",
                                          "stream_ms"])
