"""Timing: median and spread on a fake timer, per-step figures of recurrent methods, Table 2 rows, the
accuracy-versus-time join, and the speed targets of bench.method_speed."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pandas as pd
import pytest

from bench import method_speed, timing
from bench.harness import timer
from bench.reporting import accuracy
from bench.reporting import tables as tb
from bench.harness.results import base_row, rows_frame, to_csv_text
from neuspike import methods as registry
from neuspike.errors import InputError
from tests.doubles import Failing, MeanRate, Unavailable
from neuspike.sample import Sample
from neuspike.streams import SpikeStream


def fake_timer(ns_values):
    values = iter(ns_values)
    return lambda: next(values)


# ----------------------------------------------------------------------------------------------
# Median and spread
# ----------------------------------------------------------------------------------------------

def test_time_callable_on_a_fake_timer():
    calls, setups = [], []
    # five timed calls lasting 5, 1, 3, 9 and 7 ms (the timer is read before and after each)
    ticks = []
    t = 1_000
    for ms in (5, 1, 3, 9, 7):
        ticks += [t, t + ms * 1_000_000]
        t += 50_000_000
    stats = timer.time_callable(lambda: calls.append(1), repeats=5, warmup=2, setup=lambda: setups.append(1),
                                 timer=fake_timer(ticks))
    assert stats.samples_ms == (5.0, 1.0, 3.0, 9.0, 7.0)
    assert len(calls) == 7 and len(setups) == 7  # warm-up calls are made, set up, and not timed
    s = stats.summary()
    # sorted 1, 3, 5, 7, 9: median 5; quartiles at positions 1 and 3 (linear interpolation)
    assert (s["median_ms"], s["min_ms"], s["max_ms"], s["q1_ms"], s["q3_ms"], s["n"]) == (5.0, 1.0, 9.0, 3.0, 7.0, 5)


def test_summary_of_an_even_count_interpolates():
    s = timer.summarize_ms([4.0, 1.0, 2.0, 3.0])
    assert s["median_ms"] == 2.5 and s["q1_ms"] == 1.75 and s["q3_ms"] == 3.25


@pytest.mark.parametrize("bad", [[], [1.0, -0.5], [float("nan")]])
def test_summary_rejects_bad_timings(bad):
    with pytest.raises(InputError):
        timer.summarize_ms(bad)


@pytest.mark.parametrize("kw", [{"repeats": 0, "warmup": 0}, {"repeats": 2, "warmup": -1}, {"repeats": 1.5, "warmup": 0}])
def test_time_callable_rejects_bad_counts(kw):
    with pytest.raises(InputError):
        timer.time_callable(lambda: None, **kw)


class FakeRecurrent:
    """Stands in for a recurrent method that steps through four event windows per call."""

    recurrent = True
    inputs = frozenset({"events"})

    def __init__(self):
        self.resets = 0
        self.last_steps = 0

    def reset(self):
        self.resets += 1

    def reconstruct(self, sample):
        self.last_steps = 4
        return sample


def test_time_method_divides_recurrent_calls_by_their_steps():
    method = FakeRecurrent()
    ticks = [0, 8_000_000, 10_000_000, 22_000_000, 30_000_000, 40_000_000]  # 8, 12, 10 ms
    result = timer.time_method(method, "sample", repeats=3, warmup=1, timer=fake_timer(ticks))
    assert method.resets == 4 and result.steps == 4
    row = result.row()
    assert row["median_ms"] == 10.0 and row["ms_per_frame"] == 2.5
    assert row["min_frame_ms"] == 2.0 and row["max_frame_ms"] == 3.0 and row["steps"] == 4


# ----------------------------------------------------------------------------------------------
# Samples
# ----------------------------------------------------------------------------------------------

def test_cut_spike_window_keeps_the_planes_around_the_key_plane():
    rng = np.random.default_rng(3)
    planes = rng.random((10, 3, 4)) < 0.3
    spikes = SpikeStream(planes, plane_rate_hz=100.0, start_s=0.0, gain=0.5, threshold=1.0)
    sample = Sample(height=3, width=4, key_time_s=0.05, window_start_s=0.0, window_end_s=0.1, spikes=spikes)
    assert sample.key_plane == 5
    cut = timer.cut_spike_window(sample, 4)
    np.testing.assert_array_equal(cut.spikes.planes, planes[3:7])
    assert cut.spikes.start_s == pytest.approx(0.03) and cut.window_end_s == pytest.approx(0.07)
    assert cut.key_plane == 2 and cut.spikes.gain == 0.5
    with pytest.raises(InputError):
        timer.cut_spike_window(sample, 12)


# ----------------------------------------------------------------------------------------------
# Table 2 rows with methods that work, fail and are unavailable
# ----------------------------------------------------------------------------------------------

NAMES = {"tt-mean": MeanRate, "tt-fail": Failing, "tt-unavailable": Unavailable}


@pytest.fixture
def test_methods():
    for name, cls in NAMES.items():
        registry.register(name, cls)
    yield tuple(NAMES)
    for name in NAMES:
        registry.unregister(name)


def test_measure_gives_a_row_per_method_and_size(test_methods):
    frame = timer.measure(test_methods, [(32, 24), (16, 12)], repeats=2, warmup=1, history_windows=0.0)
    assert list(frame.columns) == list(timer.TIMING_COLUMNS) and len(frame) == 6
    by = frame.set_index(["method", "resolution"])
    ok = by.loc[("tt-mean", "32x24")]
    assert ok["status"] == "ok" and ok["repeats"] == 2 and ok["min_ms"] <= ok["median_ms"] <= ok["max_ms"]
    assert ok["ms_per_frame"] == ok["median_ms"] and ok["threads"] >= 1 and ok["family"] == "spike"
    assert by.loc[("tt-fail", "16x12")]["status"] == "error"
    assert "deliberate failure" in by.loc[("tt-fail", "16x12")]["error"]
    skipped = by.loc[("tt-unavailable", "32x24")]
    assert skipped["status"] == "skipped" and "weights not given (test)" in skipped["error"]
    md = tb.timing_markdown(frame)
    assert "| tt-mean | spike | - |" in md and "tt-unavailable (skipped)" in md and "| FireNet | CPU | 38,000 |" in md


def results_for(method_psnr: dict[str, float], size=(32, 24)) -> pd.DataFrame:
    rows = []
    for method, p in method_psnr.items():
        for metric, value in (("psnr", p), ("ssim", p / 40)):
            rows.append(base_row(cell="c", scene="pan:camera", kind="pan", image="camera", width=size[0],
                                 height=size[1], planes=256, light=0.25, motion=128, noise="none", seed=0,
                                 method=method, inputs="spikes", parameters=0, metric=metric, value=value,
                                 status="ok", ms_per_frame=1.0))
    return rows_frame(rows)


def test_join_accuracy_takes_the_sweeps_resolution_or_the_closest():
    timing_rows = pd.DataFrame([
        {"method": "a", "resolution": "32x24", "width": 32, "height": 24, "status": "ok", "ms_per_frame": 1.0},
        {"method": "a", "resolution": "400x250", "width": 400, "height": 250, "status": "ok", "ms_per_frame": 9.0},
        {"method": "b", "resolution": "240x180", "width": 240, "height": 180, "status": "ok", "ms_per_frame": 3.0},
        {"method": "b", "resolution": "640x480", "width": 640, "height": 480, "status": "ok", "ms_per_frame": 30.0},
        {"method": "c", "resolution": "32x24", "width": 32, "height": 24, "status": "skipped", "ms_per_frame": math.nan},
    ])
    joined = accuracy.join_accuracy(results_for({"a": 20.0, "b": 25.0, "c": 10.0}), timing_rows, "runs/x").set_index("method")
    assert joined.loc["a", "ms_per_frame"] == 1.0 and joined.loc["a", "resolution"] == "32x24"
    assert joined.loc["b", "ms_per_frame"] == 3.0 and joined.loc["b", "resolution"] == "240x180"
    assert math.isnan(joined.loc["c", "ms_per_frame"]) and joined.loc["b", "psnr"] == 25.0


def test_timing_command_writes_table_2_chart_and_report(test_methods, tmp_path):
    results = tmp_path / "sweep"
    results.mkdir()
    (results / "results.csv").write_text(to_csv_text(results_for({"tt-mean": 20.0})))
    out = tmp_path / "timing"
    code = timing.main(["--methods", "tt-mean,tt-unavailable", "--sizes", "32x24", "--repeats", "2", "--warmup", "0",
                        "--history-windows", "0", "--results", str(results), "--out", str(out)])
    assert code == 0
    frame = pd.read_csv(out / "timing.csv")
    assert set(frame["status"]) == {"ok", "skipped"}
    assert "tt-unavailable (skipped): MethodUnavailable: weights not given (test)" in (out / "tables" / "timing.md").read_text()
    acc = pd.read_csv(out / "accuracy_vs_time.csv")
    assert acc["method"].tolist() == ["tt-mean"] and acc["psnr"].iloc[0] == 20.0
    # times are paired with accuracy at the sweep's own resolution, timed in addition to --sizes
    sweep_w, sweep_h = accuracy.sweep_resolution(results_for({"tt-mean": 20.0}))
    assert acc["resolution"].iloc[0] == f"{sweep_w}x{sweep_h}"
    assert {"32x24", f"{sweep_w}x{sweep_h}"} <= set(frame["resolution"])
    meta = json.loads((out / "metadata.json").read_text())
    assert set(meta["load_1min"]) == {"before", "max", "last"} and isinstance(meta["timing_contended"], bool)
    assert (out / "figures" / "accuracy_vs_time.png").exists() and (out / "report.pdf").read_bytes().startswith(b"%PDF")
    for name in ("config.json", "metadata.json"):
        assert (out / name).stat().st_size > 0
    # the report rebuilds Table 2 from timing.csv alone, byte for byte
    before = {n: (out / "tables" / n).read_bytes() for n in ("timing.md", "timing.csv", "accuracy_vs_time.md")}
    from bench.reporting.build import build_report

    build_report(out)
    assert {n: (out / "tables" / n).read_bytes() for n in before} == before


# ----------------------------------------------------------------------------------------------
# bench.method_speed
# ----------------------------------------------------------------------------------------------

def test_speed_targets_cover_variants_and_nothing_else():
    assert method_speed.target_of("tfp-w8").name == "tfp"
    assert method_speed.target_of("firenet-plus").name == "firenet"
    assert method_speed.target_of("tfstp").name == "tfstp"  # not caught by the tfp prefix
    assert method_speed.target_of("events-integrate") is None
    assert method_speed.target_of("tfi").limit_ms == 1.99


def test_method_speed_rows_and_verdicts(test_methods, monkeypatch):
    monkeypatch.setattr(method_speed, "WIDTH", 32)
    monkeypatch.setattr(method_speed, "HEIGHT", 24)
    frame = method_speed.measure(["tt-mean", "tt-fail", "tt-unavailable"], repeats=2, warmup=1)
    by = frame.set_index("method")
    assert by.loc["tt-mean", "status"] == "ok" and by.loc["tt-mean", "ms_41_median"] > 0
    assert by.loc["tt-mean", "verdict"] == "-" and by.loc["tt-fail", "status"] == "error"
    assert by.loc["tt-unavailable", "status"] == "skipped"
    text = method_speed.markdown(frame, 2, 1, "cpu")
    assert "| tt-mean |" in text and "tt-unavailable (skipped): MethodUnavailable" in text


@pytest.mark.parametrize("methods, device, cause", [
    ("tfi,tfp-w32", "cuda:7", "device 'cuda:7': none of the methods (tfi, tfp-w32) runs on a torch device"),
    ("tfi,tfi", "cpu", "--methods repeats a name"),
])
def test_timing_command_refuses_before_writing_anything(tmp_path, capsys, methods, device, cause):
    code = timing.main(["--methods", methods, "--device", device, "--sizes", "32x24", "--results", "none",
                        "--no-report", "--out", str(tmp_path / "t")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert code == 2 and len(err) == 1 and cause in err[0], err
    assert not (tmp_path / "t" / "config.json").exists()


def test_flops_are_counted_against_a_closed_form_and_a_network_is_read_against_the_matmul_rate():
    import torch

    # a 3x3 convolution, 2 -> 3 channels, on 8x8: 2 FLOP per multiply-add, 3*8*8 outputs of 2*3*3 terms
    conv = torch.nn.Conv2d(2, 3, 3, padding=1, bias=False)
    assert timer.count_module_gflop(conv, (torch.zeros(1, 2, 8, 8),)) * 1e9 == 2 * (3 * 8 * 8) * (2 * 3 * 3)
    frame = timer.measure(["firenet-sim", "tfi"], [(32, 24)], repeats=1, warmup=0, history_windows=1)
    net, classical = frame.set_index("method").loc["firenet-sim"], frame.set_index("method").loc["tfi"]
    assert net["gflop_per_step"] > 0 and net["matmul_gflop_s"] > 0
    assert net["flop_bound_ms"] == pytest.approx(net["gflop_per_step"] / net["matmul_gflop_s"] * 1000)
    assert net["gflop_s"] == pytest.approx(net["gflop_per_step"] / net["ms_per_frame"] * 1000)
    assert math.isnan(classical["gflop_per_step"])  # no network, nothing counted
    assert net["encode_ms"] > 0 and math.isnan(classical["encode_ms"])  # the inputs' time: learned methods only
    md = tb.timing_markdown(frame)
    assert "FLOP-bound ms" in md and "inputs ms" in md and "| firenet-sim | 32x24 |" in md
    old = frame.drop(columns=["encode_ms"])  # a timing.csv from before the column still renders
    assert "| firenet-sim | 32x24 |" in tb.timing_markdown(old)


def test_the_inputs_time_is_per_step_for_a_recurrent_method(monkeypatch):
    """``encode_ms`` divides a recurrent method's encoding of the whole history by its step count
    (its time per frame is per step), and leaves a feed-forward method's whole. The clock is a fixed
    8 ms per call, so the result does not depend on the machine's load."""

    class Fake:
        def __init__(self, recurrent):
            self.recurrent = recurrent

        def encode(self, sample):
            return [None] * 4

    ticks = iter(range(0, 10**12, 8_000_000))  # each reading 8 ms after the previous: 8 ms per call
    real = timer.time_callable
    monkeypatch.setattr(timer, "time_callable", lambda fn, **kw: real(fn, timer=lambda: next(ticks), **kw))
    whole = timer.encode_ms(Fake(False), None, repeats=3, warmup=0)
    per_step = timer.encode_ms(Fake(True), None, repeats=3, warmup=0)
    assert whole == 8.0 and per_step == 2.0
    assert whole >= 4.0 and per_step >= 1.0 and per_step < whole / 2


class FakeStreaming(FakeRecurrent):
    """A recurrent method that steps four windows cold and one per new frame of a video."""

    def reconstruct_next(self, sample, *, previous_s):
        assert previous_s < sample.key_time_s
        self.last_steps = 1
        return sample


def test_time_streaming_times_new_frames_after_an_untimed_cold_start():
    frames = [Sample(height=2, width=2, key_time_s=k * 1e-3, window_start_s=k * 1e-3 - 1e-4,
                     window_end_s=k * 1e-3 + 1e-4, spikes=SpikeStream(np.zeros((2, 2, 2), bool), plane_rate_hz=1e4,
                                                                        start_s=k * 1e-3 - 1e-4)) for k in range(5)]
    method = FakeStreaming()
    assert timer.streams(method) and not timer.streams(FakeRecurrent())
    # frame 1 (warm-up) 1 ms, then 3, 5, 4 ms; the cold start on frame 0 is not timed
    ticks = [0, 1_000_000, 1_000_000, 4_000_000, 4_000_000, 9_000_000, 9_000_000, 13_000_000]
    row = timer.time_streaming(method, frames, warmup=1, timer=fake_timer(ticks))
    assert method.resets == 1
    assert row == {"stream_ms": 4.0, "stream_min_ms": 3.0, "stream_max_ms": 5.0, "stream_steps": 1.0}
    with pytest.raises(InputError, match="none to time"):
        timer.time_streaming(method, frames[:2], warmup=1)


def test_table_2_and_the_chart_label_the_cold_start_and_the_streaming_cost():
    row = {c: math.nan for c in timer.TIMING_COLUMNS}
    row.update(method="e2vid", family="event", resolution="32x24", width=32, height=24, status="ok", error="",
               parameters=10, median_ms=400.0, ms_per_frame=25.0, min_frame_ms=24.0, max_frame_ms=26.0, steps=16,
               cold_ms=400.0, stream_ms=50.0, stream_min_ms=45.0, stream_max_ms=60.0, stream_steps=2.0)
    frame = pd.DataFrame([row], columns=list(timer.TIMING_COLUMNS))
    md = tb.timing_markdown(frame)
    assert "**cold start**" in md and "| e2vid | 32x24 | 400 (16 steps) | 50 [45-60] (2.0 steps) | 8.0x |" in md
    joined = accuracy.join_accuracy(results_for({"e2vid": 12.0}), frame, "runs/x").set_index("method")
    assert joined.loc["e2vid", "ms_per_frame"] == 400.0 and joined.loc["e2vid", "stream_ms"] == 50.0
    # the chart: the streaming cost drawn hollow at 50 ms beside the filled cold start at 400, and a key
    # below the panels that says which is which
    from bench.reporting import figures

    points = tb.with_fronts(joined.reset_index()[["method", "family", "ms_per_frame", "psnr", "ssim", "stream_ms"]])
    fig = figures.accuracy_time_figure(points, note="a note " * 40)
    try:
        texts = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
        assert any(t.startswith("filled: cold start") for t in texts)
        assert any(t.startswith("hollow: streaming") for t in texts)
        hollow = [c for c in fig.axes[0].collections if len(c.get_offsets()) == 1
                  and len(c.get_facecolors()) == 0]
        assert [float(c.get_offsets()[0][0]) for c in hollow] == [50.0]
        assert max(len(line) for line in fig._suptitle.get_text().splitlines()) <= 170  # the long note wraps
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_measure_runs_learned_methods_in_the_precision_asked_and_says_so(test_methods):
    """``precision`` reaches every learned method and none of the others; each row names what ran."""
    frame = timer.measure(["neuspike-net-spike", "tt-mean"], [(32, 24)], repeats=1, warmup=0, history_windows=0.0,
                          precision="bfloat16")
    by = frame.set_index("method")
    assert by.loc["neuspike-net-spike", "status"] == "ok", by.loc["neuspike-net-spike", "error"]
    assert by.loc["neuspike-net-spike", "precision"] == "bfloat16" and by.loc["neuspike-net-spike", "device"] == "cpu"
    assert by.loc["tt-mean", "precision"] == "" and by.loc["tt-mean", "device"] == ""
    assert re.search(r"\| neuspike-net-spike \| spike \| [\d,]+ \| bfloat16 \|", tb.timing_markdown(frame))
    made = registry.create_many(["neuspike-net-spike"], precision="float32")
    assert made["neuspike-net-spike"].method.params["precision"] == "float32"
    with pytest.raises(InputError, match="precision: expected one of auto, float32, bfloat16, got 'half'"):
        registry.create_many(["neuspike-net-spike", "tt-mean"], precision="half")


def test_timing_command_times_a_method_a_plug_in_file_registers(tmp_path):
    """Table 2 takes --plugin as the sweeps do: the file's method is timed and the plug-in recorded."""
    from neuspike.methods.plugins import forget_plugin

    plugin = tmp_path / "tt_plugin.py"
    plugin.write_text("from tests.doubles import MeanRate\n\n\n"
                      "def register_methods(register):\n    register('tt-plugged', MeanRate)\n")
    out = tmp_path / "timing"
    try:
        assert timing.main(["--plugin", str(plugin), "--methods", "tt-plugged", "--sizes", "32x24", "--repeats", "1",
                            "--warmup", "0", "--history-windows", "0", "--results", "none", "--no-report",
                            "--out", str(out)]) == 0
    finally:
        registry.unregister("tt-plugged")
        forget_plugin(str(plugin))
    frame = pd.read_csv(out / "timing.csv")
    assert frame["method"].tolist() == ["tt-plugged"] and frame["status"].tolist() == ["ok"]
    assert json.loads((out / "config.json").read_text())["timing"]["plugins"] == [str(plugin)]


def test_timing_command_refuses_a_plug_in_file_that_does_not_exist(tmp_path, capsys):
    code = timing.main(["--plugin", str(tmp_path / "absent.py"), "--methods", "snm", "--results", "none",
                        "--out", str(tmp_path / "timing")])
    err = capsys.readouterr().err
    assert code != 0 and "plug-in file" in err and "does not exist" in err and not (tmp_path / "timing").exists()
