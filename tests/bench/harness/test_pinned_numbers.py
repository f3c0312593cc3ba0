"""The sweep's numbers do not move when the code around them is reorganised.

``PINNED`` holds PSNR and SSIM of a small sweep (48x32, two scenes, two light scales, 128 planes,
seed 3) computed with the harness as it was at commit ab3aa25, before the cell-to-sample path moved
into the core. A refactoring that changes any of them changed what the suite measures.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.harness import grid as grids
from bench.harness.cells import WorkerSetup
from bench.harness.results import read_csv
from bench.harness.runner import Execution, SweepSpec, resolve_methods, run_sweep
from neuspike import methods as registry
from tests.doubles import WithWeights
from neuspike.simulation.recording import SensorConfig

METHODS = ("tfp-w32", "tfi", "events-integrate", "fusion-complementary")
PINNED = {
    ("fan:coins", 0.125, "events-integrate", "psnr"): 10.293550729938863,
    ("fan:coins", 0.125, "events-integrate", "ssim"): 0.239550982866128,
    ("fan:coins", 0.125, "fusion-complementary", "psnr"): 17.564509282344183,
    ("fan:coins", 0.125, "fusion-complementary", "ssim"): 0.7951679358476658,
    ("fan:coins", 0.125, "tfi", "psnr"): 25.576650373978943,
    ("fan:coins", 0.125, "tfi", "ssim"): 0.9441199259306045,
    ("fan:coins", 0.125, "tfp-w32", "psnr"): 19.179680330291657,
    ("fan:coins", 0.125, "tfp-w32", "ssim"): 0.8160741124711813,
    ("fan:coins", 0.5, "events-integrate", "psnr"): 9.643970692078863,
    ("fan:coins", 0.5, "events-integrate", "ssim"): 0.09652124213328242,
    ("fan:coins", 0.5, "fusion-complementary", "psnr"): 27.261152418184558,
    ("fan:coins", 0.5, "fusion-complementary", "ssim"): 0.9645428450302161,
    ("fan:coins", 0.5, "tfi", "psnr"): 26.17687893320975,
    ("fan:coins", 0.5, "tfi", "ssim"): 0.9655787960549524,
    ("fan:coins", 0.5, "tfp-w32", "psnr"): 30.34537955285534,
    ("fan:coins", 0.5, "tfp-w32", "ssim"): 0.9802521706983068,
    ("pan:camera", 0.125, "events-integrate", "psnr"): 9.035471987202015,
    ("pan:camera", 0.125, "events-integrate", "ssim"): 0.3687678252884707,
    ("pan:camera", 0.125, "fusion-complementary", "psnr"): 18.285205885110837,
    ("pan:camera", 0.125, "fusion-complementary", "ssim"): 0.5203454852007863,
    ("pan:camera", 0.125, "tfi", "psnr"): 30.620611797194762,
    ("pan:camera", 0.125, "tfi", "ssim"): 0.8862651607686926,
    ("pan:camera", 0.125, "tfp-w32", "psnr"): 19.12388854908451,
    ("pan:camera", 0.125, "tfp-w32", "ssim"): 0.5159903456176852,
    ("pan:camera", 0.5, "events-integrate", "psnr"): 7.027706601836284,
    ("pan:camera", 0.5, "events-integrate", "ssim"): 0.34448671279825516,
    ("pan:camera", 0.5, "fusion-complementary", "psnr"): 28.614309455420603,
    ("pan:camera", 0.5, "fusion-complementary", "ssim"): 0.8508601651514427,
    ("pan:camera", 0.5, "tfi", "psnr"): 21.09863295103637,
    ("pan:camera", 0.5, "tfi", "ssim"): 0.7729299924125662,
    ("pan:camera", 0.5, "tfp-w32", "psnr"): 31.714262246026863,
    ("pan:camera", 0.5, "tfp-w32", "ssim"): 0.8844247841950914,
}


def test_small_sweep_reproduces_the_pinned_numbers(tmp_path):
    g = grids.preset("light", size=(48, 32), scenes=["pan:camera", "fan:coins"], seeds=[3], lights=[1 / 8, 1 / 2])
    spec = SweepSpec(name="pin", grid=g, methods=METHODS, sensor=SensorConfig(planes=128), history_windows=5.0,
                     axis="light")
    run_sweep(spec, tmp_path, Execution(progress=False))
    frame = read_csv(tmp_path / "results.csv")
    got = {(r.scene, r.light, r.method, r.metric): r.value
           for r in frame[frame.metric.isin(["psnr", "ssim"])].itertuples()}
    assert set(got) == set(PINNED)
    for key, value in PINNED.items():
        assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


class NeedsWeights(WithWeights):
    """A recurrent method whose weights come only from the user's folder (as FireNet)."""

    inputs = frozenset({"events"})
    recurrent = True

    def _reconstruct(self, sample):
        return np.zeros((sample.height, sample.width), np.float32), "none"


def test_the_weights_folder_reaches_the_resolution_of_the_event_history(tmp_path):
    name = "zz-needs-weights"
    registry.available()
    registry.register(name, NeedsWeights, weights="zz-needs-weights.safetensors")
    (tmp_path / "zz-needs-weights.safetensors").write_bytes(b"")
    try:
        g = grids.preset("light", size=(48, 32), scenes=["pan:camera"], seeds=[0], lights=[1 / 4])
        spec = SweepSpec(name="h", grid=g, methods=(name, "tfi"), sensor=SensorConfig(planes=128),
                         history_windows=2.0, axis="light", weights=str(tmp_path))
        resolved = resolve_methods(spec, WorkerSetup())
        assert resolved["recurrent"] == [name] and resolved["history_s"] == pytest.approx(2 * 128 / 20_000)
        without = resolve_methods(SweepSpec(name="h", grid=g, methods=(name, "tfi"), sensor=SensorConfig(planes=128),
                                            history_windows=2.0, axis="light"), WorkerSetup())
        assert name in without["unavailable"] and without["history_s"] == 0.0
    finally:
        registry.unregister(name)
