"""The margins page's compact-network table: each lite variant against its full network and against the
best classical method that reads nothing it does not read."""

from __future__ import annotations

import pandas as pd

from bench.harness.results import read_csv
from bench.reporting.build import results_file
from bench.reporting.margins import _lite, _point_table


def _with_lite(shift_psnr: dict[float, float]) -> pd.DataFrame:
    frame = read_csv(results_file("reports/light"))
    lite = frame[frame["method"] == "neuspike-net-spike"].copy()
    lite["method"] = "neuspike-net-spike-lite"
    psnr = lite["metric"] == "psnr"
    lite.loc[psnr, "value"] = lite.loc[psnr, "value"] + lite.loc[psnr, "light"].map(shift_psnr).fillna(-0.3)
    return pd.concat([frame, lite], ignore_index=True)


def test_each_point_is_held_to_the_full_network_and_the_classical_methods():
    frame = _with_lite({1 / 32: -0.7})
    text = _lite(frame, "light")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if "`neuspike-net-spike-lite`" in line}
    assert set(rows) == {"1/32", "1/16", "1/8", "1/4", "1/2"}
    assert "-0.70 **NO**" in rows["1/32"] and "-0.30 yes" in rows["1/8"]
    assert "+0.0000 yes" in rows["1/8"]  # (SSIM unchanged)
    # the rivals read spikes only: the fusion-complementary method and the event methods are not among them
    snm = read_csv(results_file("reports/light"))
    best = (snm[(snm["metric"] == "psnr") & snm["method"].isin(["snm", "tfi", "tfp", "tfstp", "tfp-w8", "tfp-w16",
                                                                 "tfp-w32", "tfp-w64"])]
            .groupby(["light", "method"])["value"].mean().groupby("light").max())
    full = snm[(snm["metric"] == "psnr") & (snm["method"] == "neuspike-net-spike")].groupby("light")["value"].mean()
    margin = full[0.125] - 0.3 - best[0.125]
    assert f"{margin:+.2f} yes" in rows["1/8"]
    # the lite networks are ours: never the best rival of the full network
    assert "lite" not in _point_table(frame, "light")
    assert _lite(read_csv(results_file("reports/light")), "light") == ""
