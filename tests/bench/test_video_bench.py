"""The video benchmark on a tiny version of its standard recording."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from bench import video as vb
from neuspike.methods import create
from neuspike.metrics import psnr
from neuspike.scenes import SceneSpec, make_scene
from neuspike.video import frame_times, open_recording, reconstruct_video
from neuspike.video.truth import ground_truth_for


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("video-bench")
    cache, out = root / "recording", root / "out"
    argv = ["--size", "48x32", "--duration", "0.005", "--fps", "2000", "--methods", "tfp,events-highpass,zz-none",
            "--cache", str(cache), "--out", str(out), "--no-progress"]
    assert vb.main(argv) == 0
    return argv, cache, out


def test_rows_columns_and_failing_method(bench_run):
    _, _, out = bench_run
    frame = pd.read_csv(out / "results.csv")
    assert list(frame.columns) == list(vb.COLUMNS)
    reads = [f"{vb.READ_ONLY} events", f"{vb.READ_ONLY} spikes"]
    assert list(frame["method"]) == [*reads, vb.SINGLE_FRAME, "tfp", "events-highpass", "zz-none"]
    bad = frame.set_index("method").loc["zz-none"]
    assert bad["status"] == "error" and "unknown method" in bad["error"]
    ok = frame[frame["status"] == "ok"].set_index("method")
    assert (ok.loc[["tfp", "events-highpass"], "frames"] == 10).all()
    # real-time factor: sensor seconds per method second = frames/s divided by the output rate
    assert np.allclose(ok["real_time_factor"], ok["frames_per_s"] / 2000.0)
    assert np.allclose(ok["frames_per_s"], ok["frames"] / ok["method_s"])
    for f in ("README.md", "metadata.json", "accuracy_vs_speed.png"):
        assert (out / f).is_file()
    assert "| tfp | spikes |" in (out / "README.md").read_text()
    spec = json.loads((out / "metadata.json").read_text())["spec"]
    assert spec["duration_s"] == 0.005 and spec["device"] == "cpu"
    assert frame["device"].isna().all()  # no row of this run ran on a torch device


def test_accuracy_matches_an_independent_scoring(bench_run):
    """Mean PSNR of TFP equals PSNR against the scene rendered at each instant, computed here; the
    instants start half a spike window (128 planes) in, so that every window is centred on its frame."""
    _, cache, out = bench_run
    scene = make_scene(SceneSpec(kind="fan", size=(48, 32), rpm=2600.0))
    times = frame_times(128 / 20_000, 128 / 20_000 + 0.005, 2000)
    with open_recording(cache) as rec:
        scores = [psnr(img, np.clip(scene.render(np.array([t]))[0], 0, 1), data_range=1.0)
                  for t, img in reconstruct_video(create("tfp"), rec, times)]
    row = pd.read_csv(out / "results.csv").set_index("method").loc["tfp"]
    assert row["mean_psnr_db"] == pytest.approx(np.mean(scores), abs=1e-4)


def test_cached_recording_is_reused(bench_run):
    argv, cache, out = bench_run
    stamp = (cache / "meta.json").stat().st_mtime_ns
    assert vb.main([a if a != "tfp,events-highpass,zz-none" else "tfp" for a in argv]) == 0
    assert (cache / "meta.json").stat().st_mtime_ns == stamp
    assert list(pd.read_csv(out / "results.csv")["method"])[2:] == [vb.SINGLE_FRAME, "tfp"]


def test_a_learned_methods_row_names_the_device_it_ran_on(bench_run):
    _, cache, _ = bench_run
    spec = vb.VideoBenchSpec(duration_s=0.005, fps=2000.0, width=48, height=32)
    times = frame_times(vb.MARGIN_S, vb.MARGIN_S + spec.duration_s, spec.fps)
    with open_recording(cache) as rec:
        truth = ground_truth_for(cache, rec.meta, height=rec.height, width=rec.width, tolerance_s=0.5 / spec.fps)
        rows = {name: vb.measure_method(name, rec, times, truth, spec, None) for name in ("firenet-sim", "tfp")}
    assert rows["firenet-sim"]["status"] == "ok" and rows["firenet-sim"]["device"] == "cpu"
    assert rows["tfp"]["status"] == "ok" and rows["tfp"]["device"] is None  # a classical method has none


def test_other_jobs_load_marks_the_timings_contended(bench_run, tmp_path, monkeypatch):
    """With other jobs' load beyond the run's own threads (a load average read as 3 on a run of 1
    thread) the run is marked contended in its metadata and on its page; a quiet reading is not."""
    import bench.harness.provenance as provenance

    argv, _, _ = bench_run
    for load, contended in ((3.0, True), (0.0, False)):
        monkeypatch.setattr(provenance, "load_1min", lambda load=load: load)
        monkeypatch.setattr(provenance, "others_busy_cpus", lambda: 0)
        out = tmp_path / f"out-{load:g}"
        args = list(argv)
        args[args.index("--methods") + 1] = "tfp"
        args[args.index("--out") + 1] = str(out)
        assert vb.main(args + ["--threads", "1"]) == 0
        run = json.loads((out / "metadata.json").read_text())["run"]
        page = (out / "README.md").read_text()
        assert run["timing_contended"] is contended
        assert ("Timings contended" in page) is contended
        if not contended:
            assert "Timings uncontended" in page


def test_compile_runs_two_untimed_frames_first_and_changes_no_image(bench_run, tmp_path, monkeypatch):
    """``--compile``: the method's module goes through torch.compile (replaced here by a recorder that
    returns the module itself, so the plumbing is tested without the minutes of a real compile; the
    compiled image itself is tested in tests/neuspike/test_compiled.py); two frames run untimed first,
    the timed stream starts afresh and its scores are the eager run's."""
    import torch

    _, cache, _ = bench_run
    calls = []
    monkeypatch.setattr(torch, "compile", lambda module, **kw: calls.append(kw) or module)
    rows = {}
    for flag in ([], ["--compile"]):
        out = tmp_path / ("c" if flag else "e")
        argv = ["--size", "48x32", "--duration", "0.005", "--fps", "2000", "--methods", "firenet-sim",
                "--precision", "float32", "--cache", str(cache), "--out", str(out), "--no-progress", *flag]
        assert vb.main(argv) == 0
        rows[bool(flag)] = pd.read_csv(out / "results.csv").set_index("method").loc["firenet-sim"]
    assert len(calls) == 1 and calls[0]["options"] == {"freezing": True}
    eager, compiled = rows[False], rows[True]
    assert np.isnan(eager["compile_s"]) and compiled["compile_s"] > 0
    assert compiled["frames"] == eager["frames"] == 10
    for column in ("mean_psnr_db", "mean_ssim", "mean_flicker_rmse", "steps_per_frame"):
        assert compiled[column] == eager[column]
    readme = (tmp_path / "c" / "README.md").read_text()
    assert "`python -m bench.video --precision float32 --compile`" in readme and "compiled (torch.compile;" in readme


def test_read_out_window_reaches_the_event_networks_only_and_costs_fewer_steps(bench_run, tmp_path):
    """``--read-out window``: firenet-sim's row takes fewer network steps per frame than with the
    default read-out (no partial window stepped) and says so in its note; tfp beside it runs as before;
    the regeneration command names the flag."""
    _, cache, _ = bench_run
    rows = {}
    for flag in ([], ["--read-out", "window"]):
        out = tmp_path / ("w" if flag else "k")
        argv = ["--size", "48x32", "--duration", "0.005", "--fps", "2000", "--methods", "firenet-sim,tfp",
                "--precision", "float32", "--cache", str(cache), "--out", str(out), "--no-progress", *flag]
        assert vb.main(argv) == 0
        rows[bool(flag)] = pd.read_csv(out / "results.csv").set_index("method")
    key, window = rows[False], rows[True]
    assert (key["status"] == "ok").all() and (window["status"] == "ok").all()
    assert window.loc["firenet-sim", "steps_per_frame"] < key.loc["firenet-sim", "steps_per_frame"]
    assert "read out at the last full window" in window.loc["firenet-sim", "normalisation"]
    assert "read out" not in key.loc["firenet-sim", "normalisation"]
    assert window.loc["firenet-sim", "read_out"] == "window" and key.loc["firenet-sim", "read_out"] == "key"
    assert pd.isna(window.loc["tfp", "read_out"])
    assert window.loc["tfp", "mean_psnr_db"] == key.loc["tfp", "mean_psnr_db"]
    readme = (tmp_path / "w" / "README.md").read_text()
    assert "--read-out window`" in readme and "frames read out at the last full event window" in readme


def test_full_writes_its_own_report_folder_unless_told(tmp_path, monkeypatch):
    """``--full`` without ``--out`` goes to bench-full, the default run to bench: neither overwrites the other."""
    import shutil
    from pathlib import Path

    quick, full = tmp_path / "bench", tmp_path / "bench-full"
    for folder in (quick, full):
        folder.mkdir()
        shutil.copy(Path(vb.__file__).resolve().parents[1] / "reports" / "video" / "bench-full" / "results.csv",
                    folder / "results.csv")
    monkeypatch.setattr(vb, "DEFAULT_OUT", quick)
    monkeypatch.setattr(vb, "DEFAULT_OUT_FULL", full)
    assert vb.main(["--full", "--plot-only"]) == 0
    assert (full / "accuracy_vs_speed.png").exists() and not (quick / "accuracy_vs_speed.png").exists()
    assert vb.main(["--plot-only"]) == 0
    assert (quick / "accuracy_vs_speed.png").exists()


def test_a_plug_in_files_method_runs_beside_the_registered_ones(bench_run, tmp_path):
    """--plugin (as the sweeps take it): the plug-in's variant of TFP scores as TFP on the same recording."""
    from neuspike.methods import unregister
    from neuspike.methods.plugins import forget_plugin

    argv, cache, _ = bench_run
    plugin = tmp_path / "zz_bench_plugin.py"
    plugin.write_text("from baselines.tfp import TFP\n\n\n"
                      "def register_methods(register):\n    register('zz-bench-tfp', TFP, params={'window': None})\n")
    out = tmp_path / "out"
    try:
        assert vb.main(["--size", "48x32", "--duration", "0.005", "--fps", "2000", "--methods", "tfp,zz-bench-tfp",
                        "--plugin", str(plugin), "--cache", str(cache), "--out", str(out), "--no-progress"]) == 0
    finally:
        unregister("zz-bench-tfp")
        forget_plugin(str(plugin))
    rows = pd.read_csv(out / "results.csv").set_index("method")
    assert rows.loc["zz-bench-tfp", "status"] == "ok"
    assert rows.loc["zz-bench-tfp", "mean_psnr_db"] == pytest.approx(rows.loc["tfp", "mean_psnr_db"])
