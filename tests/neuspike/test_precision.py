"""``"auto"`` precision: bfloat16 only where a measured step is faster, measured once per machine and module."""

from __future__ import annotations

import json

import pytest

from neuspike.methods import create
from neuspike.methods import learned, precision


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NEUSPIKE_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "precision.json"


def _fake_steps(monkeypatch, f32_ms: float, bf16_ms: float) -> None:
    """Every measurement times float32 first, then bfloat16: give them these medians (the steps run)."""
    answers = iter([f32_ms, bf16_ms])
    monkeypatch.setattr(precision, "_median_ms", lambda step: (step(), next(answers))[1])


@pytest.mark.parametrize("f32_ms, bf16_ms, chosen", [(100.0, 60.0, "bfloat16"), (100.0, 95.0, "float32"),
                                                      (100.0, 180.0, "float32")])
def test_bfloat16_only_where_the_measured_step_is_faster(monkeypatch, cache, f32_ms, bf16_ms, chosen):
    monkeypatch.setattr(learned, "native_bfloat16", lambda: True)
    _fake_steps(monkeypatch, f32_ms, bf16_ms)
    method = create("firenet-sim")
    assert method.params["precision"] == chosen and method.describe()["params"]["precision"] == chosen
    record = method.precision_measurement
    assert (record["float32_ms"], record["bfloat16_ms"], record["cached"]) == (f32_ms, bf16_ms, False)
    # remembered: the next creation measures nothing and gives the same choice
    monkeypatch.setattr(precision, "_median_ms", lambda step: pytest.fail("measured again"))
    again = create("firenet-sim")
    assert again.params["precision"] == chosen and again.precision_measurement["cached"] is True
    assert len(json.loads(cache.read_text())) == 1


def test_without_native_bfloat16_auto_is_float32_unmeasured(monkeypatch, cache):
    monkeypatch.setattr(learned, "native_bfloat16", lambda: False)
    monkeypatch.setattr(precision, "_median_ms", lambda step: pytest.fail("measured"))
    method = create("neuspike-net")
    assert method.params["precision"] == "float32" and method.precision_measurement is None
    assert not cache.exists()


@pytest.mark.parametrize("name", ["neuspike-net", "e2vid", "firenet-sim"])
def test_every_network_can_be_probed_in_both_precisions(monkeypatch, cache, name):
    # a real measurement (bfloat16 emulated here if the CPU lacks it): one step each way, on the probe
    monkeypatch.setattr(learned, "native_bfloat16", lambda: True)
    monkeypatch.setattr(precision, "REPEATS", 1)
    monkeypatch.setattr(precision, "PROBE_SIZE", (64, 48))
    method = create(name)
    record = method.precision_measurement
    assert "error" not in record, record
    assert record["float32_ms"] > 0 and record["bfloat16_ms"] > 0
    assert method.params["precision"] == record["choice"]
