"""bench.method_speed: the same-run references, the verdicts against them, and the pinned threads."""

from __future__ import annotations

import math

import numba
import numpy as np
import pandas as pd
import torch

from baselines.tfp import tfp_rate
from bench import method_speed


def test_spikezoo_style_tfp_is_the_windowed_mean_over_the_gain():
    rng = np.random.default_rng(1)
    planes = rng.random((41, 6, 7)) < rng.uniform(0.0, 0.5, (6, 7))
    for window in (8, 41):
        expected = np.clip(tfp_rate(planes, 20, window) / 0.25, 0.0, 1.0)
        np.testing.assert_allclose(method_speed.spikezoo_tfp(planes, 20, window, 0.25), expected, rtol=1e-6)
    # near an end the window is shifted inward and keeps its planes, as TFP's is
    np.testing.assert_allclose(method_speed.spikezoo_tfp(planes, 0, 8, 1.0), planes[:8].mean(axis=0), rtol=1e-6)


def row(method, **values):
    return {"method": method, "status": "ok", "error": "", **values}


def test_verdicts_against_fixed_limits_and_same_run_references():
    frame = pd.DataFrame([
        row("snm", ms_256_median=20.0),
        row("tfstp", ms_256_median=12.5),
        row("tfp-w8", ms_41_median=2.0, window_41=8),
        row("tfp", ms_41_median=0.5, window_41=41),
        row("events-integrate", ms_256_median=1.0),
        row("ref:spikezoo-tfp-w8", ms_41_median=1.0),
        row("ref:spikezoo-tfp-w41", ms_41_median=1.0),
        row("ref:snm-torch", ms_256_median=600.0),
        {"method": "firenet", "status": "skipped", "error": "no weights"},
    ])
    by = method_speed.judge(frame).set_index("method")
    assert by.loc["snm", "verdict"] == "met" and by.loc["snm", "ratio"] == 20.0 / 30.0
    assert "ref:snm-torch 600 ms" in by.loc["snm", "reference"]
    assert by.loc["tfstp", "verdict"] == "missed" and by.loc["tfstp", "ratio"] == 1.25
    assert by.loc["tfp-w8", "verdict"] == "missed" and by.loc["tfp-w8", "limit_ms"] == 1.0  # its own window's reference
    assert by.loc["tfp", "verdict"] == "met" and by.loc["tfp", "ratio"] == 0.5
    assert by.loc["events-integrate", "verdict"] == "-" and by.loc["ref:snm-torch", "verdict"] == "-"
    assert by.loc["firenet", "verdict"] == "not measured" and math.isnan(by.loc["firenet", "ratio"])
    lines = method_speed.verdict_lines(method_speed.judge(frame))
    assert len(lines) == 5 and any(line.startswith("tfstp: 12.5 ms (T=256)") and "missed (1.25x" in line
                                   for line in lines)


def test_threads_are_pinned_for_torch_and_numba():
    before = method_speed.thread_counts()
    try:
        assert method_speed.pin_threads(1) == {"torch_threads": 1, "numba_threads": 1}
        assert torch.get_num_threads() == 1 and numba.get_num_threads() == 1
    finally:
        torch.set_num_threads(before["torch_threads"])
        numba.set_num_threads(before["numba_threads"])
