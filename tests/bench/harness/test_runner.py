"""The benchmark harness: grids, cells, the recording cache, tidy results, resuming, executors."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.harness import grid as grids
from neuspike.simulation.cache import load_recording, save_recording
from bench.harness.cells import METRICS
from neuspike.methods.plugins import forget_plugin, load_plugins
from bench.harness.results import COLUMNS, TIMING_COLUMNS, drop_timing, read_csv
from bench.harness.runner import ConfigMismatch, Execution, SweepSpec, run_sweep
from bench.sweep import main
from neuspike import methods as registry
from neuspike.errors import InputError
from neuspike.simulation.recording import SensorConfig

PLANES = 32
SIZE = (32, 24)

# Tiny methods, registered by a plug-in module so that subprocesses and Dask workers see them too.
PLUGIN = textwrap.dedent('''
    import os
    import time

    import numpy as np

    from neuspike.methods import Method, MethodUnavailable, register


    class MeanRate(Method):
        """Spike count over the window divided by planes and gain (TFP over the whole window)."""

        inputs = frozenset({"spikes"})

        def _reconstruct(self, sample):
            delay = float(os.environ.get("HT_SLEEP_S", "0"))
            if delay:
                time.sleep(delay)
            s = sample.spikes
            rate = s.planes.mean(axis=0, dtype=np.float64) / s.gain * self.params.get("scale", 1.0)
            return np.clip(rate, 0.0, 1.0).astype(np.float32), "gain"


    class Failing(Method):
        inputs = frozenset({"spikes"})

        def _reconstruct(self, sample):
            if os.environ.get("HT_FIXED"):
                return np.zeros((sample.height, sample.width), np.float32), "none"
            raise RuntimeError("deliberate failure")


    class Unavailable(Method):
        inputs = frozenset({"events"})

        def __init__(self, name=None, **params):
            raise MethodUnavailable("weights not given (test)")

        def _reconstruct(self, sample):
            raise AssertionError("never called")


    NAMES = ("ht-mean", "ht-mean-x2", "ht-fail", "ht-unavailable")
    register("ht-mean", MeanRate)
    register("ht-mean-x2", MeanRate, params={"scale": 2.0})
    register("ht-fail", Failing)
    register("ht-unavailable", Unavailable)
''')


@pytest.fixture
def plugin(tmp_path):
    """Path of the plug-in file, imported here too; its methods are unregistered afterwards."""
    path = tmp_path / "ht_plugin.py"
    path.write_text(PLUGIN)
    load_plugins((str(path),))
    yield str(path)
    for name in ("ht-mean", "ht-mean-x2", "ht-fail", "ht-unavailable"):
        registry.unregister(name)
    forget_plugin(str(path))


def test_plugin_named_by_relative_and_absolute_path_loads_once(plugin, monkeypatch):
    """The CLI names a plug-in as typed, workers by its resolved path: one file, registered once."""
    path = Path(plugin)
    monkeypatch.chdir(path.parent)
    assert load_plugins((path.name,)) == []  # already loaded under its absolute path
    assert load_plugins((str(path),)) == []
    assert registry.entry("ht-mean").params == {}


def tiny_grid(lights=(0.25, 0.5), motions=(8, 16), seeds=(0,)):
    return grids.Grid(
        scenes=(grids.scene_entry("pan:camera", SIZE),), lights=lights, motions=motions,
        noises=("none",), seeds=seeds, effects=grids.DEFAULT_EFFECTS,
    )


def tiny_spec(methods, **grid_kw):
    return SweepSpec(name="tiny", grid=tiny_grid(**grid_kw), methods=tuple(methods),
                     sensor=SensorConfig(planes=PLANES))


def quiet(plugin, **kw):
    return Execution(plugins=(plugin,), progress=False, report=False, **kw)


def same_numbers(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Equal in every column except the timing columns (which measure each run anew)."""
    pd.testing.assert_frame_equal(drop_timing(a), drop_timing(b), check_exact=True)


# ----------------------------------------------------------------------------------------------
# Grids
# ----------------------------------------------------------------------------------------------

def test_presets_match_the_paper_axes():
    light = grids.preset("light")
    assert light.lights == (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2) and light.motions == (128,)
    motion = grids.preset("motion")
    assert motion.motions == (16, 32, 64, 128, 256) and motion.lights == (0.25,)
    noise = grids.preset("noise")
    assert noise.noises == ("small", "medium", "high") and noise.lights == (0.25,) and noise.motions == (128,)
    cells = light.cells()
    assert len(cells) == len(grids.QUICK_SCENES) * 5
    assert [c.condition.light for c in cells[:5]] == list(light.lights)
    assert {c.scene.spec.size for c in cells} == {grids.QUICK_SIZE}
    full = grids.preset("light", full=True)
    assert {c.scene.spec.size for c in full.cells()} == {(400, 250)}
    assert {s.kind for s in full.scenes} == {"pan", "zoom", "fan", "still"}
    from neuspike.scenes import TEST_PHOTOS

    assert {s.image for s in full.scenes} <= set(TEST_PHOTOS)


def test_grid_rejects_bad_axes():
    with pytest.raises(InputError, match="divide"):
        grids.preset("motion").check_planes(100)
    with pytest.raises(InputError, match="kind"):
        grids.scene_entry("spin:camera", SIZE)
    with pytest.raises(InputError, match="repeats"):
        tiny_grid(lights=(0.25, 0.25))
    with pytest.raises(InputError, match="fraction"):
        grids.parse_fraction("1/0")
    assert grids.parse_fraction("1/32") == 1 / 32 and grids.parse_size("346x260") == (346, 260)


# ----------------------------------------------------------------------------------------------
# A sweep end to end
# ----------------------------------------------------------------------------------------------

def _unpack_cached(cache_dir: Path) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(mean-rate image, ground truth, gain) of every cached recording, read with NumPy alone."""
    out = []
    for path in sorted(cache_dir.glob("*.npz")):
        with np.load(path) as z:
            t, h, w = z["spike_shape"]
            planes = np.unpackbits(z["spike_bits"], axis=-1, count=int(w), bitorder="little")
            spike_info = json.loads(z["spike_json"].tobytes())
            gt = np.clip(z["ground_truth"], 0, 1)
        rate = planes.reshape(t, h, w).mean(axis=0, dtype=np.float64) / spike_info["gain"]
        out.append((np.clip(rate, 0, 1).astype(np.float32), gt, spike_info["gain"]))
    return out


def test_tiny_sweep_runs_end_to_end(plugin, tmp_path):
    spec = tiny_spec(["ht-mean", "ht-unavailable"])
    outcome = run_sweep(spec, tmp_path / "run", quiet(plugin))
    assert outcome.exit_code == 0 and (outcome.n_ok, outcome.n_failed, outcome.n_missing) == (4, 0, 0)
    frame = read_csv(outcome.results_path)
    assert list(frame.columns) == list(COLUMNS)
    assert len(frame) == 4 * 2 * len(METRICS)  # cells x methods x metrics
    assert sorted(frame["metric"].unique()) == ["psnr", "psnr_affine", "specks", "ssim", "ssim_affine", "static_texture"]
    # a pan has no static region: the measure is left empty, not made up
    assert frame.loc[frame["metric"] == "static_texture", "value"].isna().all()
    assert set(zip(frame["light"], frame["motion"])) == {(0.25, 8), (0.25, 16), (0.5, 8), (0.5, 16)}

    # the skipped method: rows with the reason, not a failure; its modality is not simulated
    skipped = frame[frame["method"] == "ht-unavailable"]
    assert (skipped["status"] == "skipped").all() and skipped["value"].isna().all()
    assert skipped["error"].str.contains("weights not given").all()
    assert "ht-unavailable" in outcome.skipped
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["sweep"]["resolved"]["modalities"] == ["spikes"]

    mean = frame[frame["method"] == "ht-mean"]
    assert (mean["status"] == "ok").all() and (mean["normalisation"] == "gain").all()
    assert (mean["ms_per_frame"] > 0).all() and (mean["sim_seconds"] > 0).all()
    assert mean["effects"].str.contains("spikes:initial_charge").all()
    assert not mean["effects"].str.contains("events:").any()

    # independent check of the plumbing: PSNR from the cached recordings, read with NumPy alone
    expected = sorted(10 * np.log10(1.0 / np.mean((img.astype(np.float64) - gt) ** 2))
                      for img, gt, _ in _unpack_cached(tmp_path / "run" / "cache"))
    got = sorted(mean[mean["metric"] == "psnr"]["value"])
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    gains = sorted({g for _, _, g in _unpack_cached(tmp_path / "run" / "cache")})
    assert gains == [0.25, 0.5]
    # the last lines answer the question: what the accuracy cost, the mean PSNR and SSIM beside the time
    line = next(x for x in outcome.summary().splitlines() if x.strip().startswith("ht-mean"))
    psnr, ssim, ms = (float(v) for v in line.split()[1:])
    assert psnr == pytest.approx(np.mean(expected), abs=0.005)
    assert ssim == pytest.approx(mean[mean["metric"] == "ssim"]["value"].mean(), abs=5e-5)
    assert ms == pytest.approx(mean[mean["metric"] == "psnr"]["ms_per_frame"].median(), abs=0.05)

    meta = json.loads((tmp_path / "run" / "metadata.json").read_text())
    for key in ("source", "versions", "machine", "threads_per_worker", "start", "end", "executor"):
        assert key in meta
    assert meta["end"] >= meta["start"] and meta["versions"]["numpy"] == np.__version__


def test_failing_method_gives_error_rows_and_nonzero_exit(plugin, tmp_path, monkeypatch):
    args = ["--axis", "light", "--lights", "1/4", "--motions", "16", "--planes", str(PLANES),
            "--size", "32x24", "--scenes", "pan:camera", "--methods", "ht-mean,ht-fail",
            "--plugin", plugin, "--no-report", "--no-progress"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 1
    frame = read_csv(tmp_path / "a" / "results.csv")
    failed = frame[frame["method"] == "ht-fail"]
    assert len(failed) == len(METRICS) and (failed["status"] == "error").all() and failed["value"].isna().all()
    assert failed["error"].str.contains("RuntimeError: deliberate failure").all()
    assert (frame[frame["method"] == "ht-mean"]["status"] == "ok").all()
    assert "deliberate failure" in next((tmp_path / "a" / "errors").glob("*.txt")).read_text()
    # allowed failures exit 0; the rerun finds the cell finished and computes nothing
    assert main(args + ["--out", str(tmp_path / "a"), "--allow-failures"]) == 0
    # once the method is fixed, --retry-failed runs the failed cell again
    monkeypatch.setenv("HT_FIXED", "1")
    assert main(args + ["--out", str(tmp_path / "a"), "--retry-failed"]) == 0
    assert (read_csv(tmp_path / "a" / "results.csv")["status"] == "ok").all()
    assert not list((tmp_path / "a" / "errors").glob("*.txt"))
    # a skipped method alone is not a failure
    ok_args = [a if a != "ht-mean,ht-fail" else "ht-mean,ht-unavailable" for a in args]
    assert main(ok_args + ["--out", str(tmp_path / "b")]) == 0


def test_same_seed_same_numbers_and_seeds_differ(plugin, tmp_path):
    spec = tiny_spec(["ht-mean"], seeds=(0, 1))
    a = read_csv(run_sweep(spec, tmp_path / "a", quiet(plugin, use_cache=False)).results_path)
    b = read_csv(run_sweep(spec, tmp_path / "b", quiet(plugin, use_cache=False)).results_path)
    same_numbers(a, b)
    psnr = a[a["metric"] == "psnr"].set_index(["light", "motion", "seed"])["value"]
    # the random initial charge differs between seeds, so the numbers do
    assert (psnr.xs(0, level="seed") != psnr.xs(1, level="seed")).all()


def test_adding_a_method_reuses_the_cached_recordings(plugin, tmp_path):
    cache = tmp_path / "cache"
    first = run_sweep(tiny_spec(["ht-mean"]), tmp_path / "a", quiet(plugin, cache_dir=cache))
    assert first.n_cache_hits == 0
    stamps = {p.name: p.stat().st_mtime_ns for p in cache.glob("*.npz")}
    assert len(stamps) == 4
    second = run_sweep(tiny_spec(["ht-mean", "ht-mean-x2"]), tmp_path / "b", quiet(plugin, cache_dir=cache))
    assert second.n_cache_hits == 4 and second.n_computed == 4
    assert {p.name: p.stat().st_mtime_ns for p in cache.glob("*.npz")} == stamps
    a, b = read_csv(first.results_path), read_csv(second.results_path)
    b_mean = b[b["method"] == "ht-mean"].reset_index(drop=True)
    same_numbers(a.drop(columns="cell"), b_mean.drop(columns="cell"))
    # a damaged cache file is simulated again (and replaced), with the same numbers
    victim = sorted(cache.glob("*.npz"))[0]
    victim.write_bytes(victim.read_bytes()[:100])
    third = run_sweep(tiny_spec(["ht-mean"]), tmp_path / "c", quiet(plugin, cache_dir=cache))
    assert third.n_cache_hits == 3 and victim.stat().st_size > 100
    same_numbers(a, read_csv(third.results_path))


def test_changed_config_is_refused_unless_forced(plugin, tmp_path):
    run_sweep(tiny_spec(["ht-mean"], lights=(0.5,), motions=(16,)), tmp_path / "a", quiet(plugin))
    other = tiny_spec(["ht-mean"], lights=(0.25,), motions=(16,))
    with pytest.raises(ConfigMismatch, match="lights"):
        run_sweep(other, tmp_path / "a", quiet(plugin))
    outcome = run_sweep(other, tmp_path / "a", quiet(plugin, force=True))
    frame = read_csv(outcome.results_path)
    assert set(frame["light"]) == {0.25} and len(list((tmp_path / "a" / "parts").glob("*.csv"))) == 1


def test_cache_round_trip_is_bit_exact(tmp_path):
    from neuspike.utils.rng import derive_rng
    from neuspike.scenes import make_scene
    from neuspike.simulation.window import simulate_window

    cell = tiny_grid(lights=(0.25,), motions=(8,)).cells()[0]
    rec = simulate_window(make_scene(cell.scene.spec), cell.condition, rng=derive_rng(0, "t"),
                          sensor=SensorConfig(planes=PLANES), history_s=0.002)
    back = load_recording(save_recording(tmp_path / "r.npz", rec))
    np.testing.assert_array_equal(back.spikes.planes, rec.spikes.planes)
    assert back.spikes.gain == rec.spikes.gain and back.spikes.plane_rate_hz == rec.spikes.plane_rate_hz
    for field in ("t_s", "x", "y", "p"):
        a, b = getattr(back.events, field), getattr(rec.events, field)
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert len(rec.events) > 0 and rec.events.t_s.min() < 0  # the history is kept
    np.testing.assert_array_equal(back.ground_truth, rec.ground_truth)
    assert (back.key_time_s, back.window_start_s, back.window_end_s) == (
        rec.key_time_s, rec.window_start_s, rec.window_end_s)
    assert not list(tmp_path.glob(".*.tmp"))


# ----------------------------------------------------------------------------------------------
# Resuming after a kill, and executors
# ----------------------------------------------------------------------------------------------

DRIVER = textwrap.dedent('''
    import sys
    from bench.harness import grid as grids
    from bench.harness.runner import Execution, SweepSpec, run_sweep
    from neuspike.simulation.recording import SensorConfig

    plugin, out = sys.argv[1], sys.argv[2]
    grid = grids.Grid(scenes=(grids.scene_entry("pan:camera", (32, 24)),), lights=(0.25, 0.5, 1.0),
                      motions=(8, 16), seeds=(0,), effects=grids.DEFAULT_EFFECTS)
    spec = SweepSpec(name="tiny", grid=grid, methods=("ht-mean",), sensor=SensorConfig(planes=32))
    run_sweep(spec, out, Execution(plugins=(plugin,), progress=False, report=False))
''')


def test_kill_midway_then_rerun_equals_an_uninterrupted_run(plugin, tmp_path):
    driver = tmp_path / "driver.py"
    driver.write_text(DRIVER)
    out = tmp_path / "killed"
    env = {**os.environ, "HT_SLEEP_S": "0.3"}
    proc = subprocess.Popen([sys.executable, str(driver), plugin, str(out)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    parts = out / "parts"
    while time.monotonic() < deadline and proc.poll() is None and not list(parts.glob("*.csv")):
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    _, err = proc.communicate()
    assert proc.returncode == -signal.SIGKILL, err.decode()[-2000:]
    before = len(list(parts.glob("*.csv")))
    assert 1 <= before < 6, "the kill must land midway"
    for part in parts.glob("*.csv"):  # nothing half-written: every part parses, with all its rows
        assert len(read_csv(part)) == len(METRICS)
    assert not (out / "results.csv").exists()

    grid = grids.Grid(scenes=(grids.scene_entry("pan:camera", SIZE),), lights=(0.25, 0.5, 1.0),
                      motions=(8, 16), seeds=(0,), effects=grids.DEFAULT_EFFECTS)
    spec = SweepSpec(name="tiny", grid=grid, methods=("ht-mean",), sensor=SensorConfig(planes=PLANES))
    resumed = run_sweep(spec, out, quiet(plugin))
    assert resumed.n_computed == 6 - before and resumed.n_missing == 0
    reference = run_sweep(spec, tmp_path / "whole", quiet(plugin))
    assert reference.n_computed == 6
    a, b = read_csv(resumed.results_path), read_csv(reference.results_path)
    same_numbers(a, b)
    assert set(TIMING_COLUMNS) <= set(a.columns)
    meta = json.loads((out / "metadata.json").read_text())
    assert len(meta["previous_runs"]) == 1 and meta["previous_runs"][0]["end"] is None


def test_dask_gives_the_local_results(plugin, tmp_path):
    pytest.importorskip("distributed")
    from bench.harness.executors import DaskExecutor

    spec = tiny_spec(["ht-mean", "ht-fail"])
    local = run_sweep(spec, tmp_path / "local", quiet(plugin))
    dask = run_sweep(spec, tmp_path / "dask",
                     quiet(plugin, executor=DaskExecutor(workers=1, processes=False), cache_dir=tmp_path / "c2"))
    assert dask.n_computed == 4 and dask.n_cache_hits == 0 and dask.n_failed == 4
    same_numbers(read_csv(local.results_path), read_csv(dask.results_path))
    meta = json.loads((tmp_path / "dask" / "metadata.json").read_text())
    assert meta["executor"]["executor"] == "dask"


def test_worker_processes_give_the_in_process_results(plugin, tmp_path):
    spec = tiny_spec(["ht-mean", "ht-fail"])
    inline = run_sweep(spec, tmp_path / "inline", quiet(plugin))
    pool = run_sweep(spec, tmp_path / "pool", quiet(plugin, workers=2, cache_dir=tmp_path / "c2"))
    assert pool.n_computed == 4 and pool.n_failed == 4 and pool.n_missing == 0
    same_numbers(read_csv(inline.results_path), read_csv(pool.results_path))
    meta = json.loads((tmp_path / "pool" / "metadata.json").read_text())
    assert meta["timing_contended"] is True and meta["threads_per_worker"] >= 1
    assert meta["threads_observed"] == [meta["threads_per_worker"]]


def test_dask_missing_gives_a_clear_error(monkeypatch):
    from bench.harness.executors import DaskExecutor

    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the extra were not installed
    with pytest.raises(InputError, match=r"neuspike-bench\[dask\]"):
        with DaskExecutor():
            pass


def test_reconstructions_of_the_swept_axis_are_saved_for_the_report(plugin, tmp_path):
    from bench.harness import images as report
    import matplotlib.image as mpimg

    spec = SweepSpec(name="tiny", grid=tiny_grid(seeds=(0, 1)), methods=("ht-mean", "ht-fail"),
                     sensor=SensorConfig(planes=PLANES), axis="light")
    out = tmp_path / "run"
    run_sweep(spec, out, quiet(plugin))
    # one image set per light value: first seed, first motion (8), never the other cells
    folders = sorted(p.name for p in (out / "images" / "pan_camera").iterdir())
    assert folders == ["light=0.25", "light=0.5"]
    for light in (0.25, 0.5):
        names = sorted(p.name for p in report.image_path(out / "images", "pan:camera", "light", light, "gt").parent.iterdir())
        assert names == ["gt.png", "ht-mean.png"]  # the failed method has no image
    # the saved ground truth is the scene at the key instant, as cached (8-bit PNG: 2/255 tolerance)
    gts = [gt for _, gt, _ in _unpack_cached(out / "cache")]
    saved = np.asarray(mpimg.imread(report.image_path(out / "images", "pan:camera", "light", 0.5, "gt")))
    saved = saved[..., 0] if saved.ndim == 3 else saved
    assert saved.shape == gts[0].shape and np.abs(saved - gts[0]).max() <= 2 / 255


# ----------------------------------------------------------------------------------------------
# Merging sweeps of the same cells
# ----------------------------------------------------------------------------------------------

def test_merged_sweeps_equal_one_sweep_of_all_methods(plugin, tmp_path):
    from bench.merge import main as merge_main, merge_sweeps

    import dataclasses

    cache = str(tmp_path / "cache")

    def spec(methods, **kw):  # a light sweep, so that images are kept
        return dataclasses.replace(tiny_spec(methods, **kw), axis="light")

    one = run_sweep(spec(["ht-mean", "ht-mean-x2"]), tmp_path / "one", quiet(plugin, cache_dir=cache))
    a = run_sweep(spec(["ht-mean"]), tmp_path / "a", quiet(plugin, cache_dir=cache))
    b = run_sweep(spec(["ht-mean-x2"]), tmp_path / "b", quiet(plugin, cache_dir=cache))
    assert one.exit_code == a.exit_code == b.exit_code == 0
    merged = merge_sweeps(tmp_path / "m", [tmp_path / "a", tmp_path / "b"])
    whole = read_csv(one.results_path)
    # the cell id hashes the sweep's method list, so it differs; every number is the same
    same_numbers(merged.drop(columns="cell"), whole.drop(columns="cell"))
    assert read_csv(tmp_path / "m" / "results.csv").equals(merged)
    images = {p.relative_to(tmp_path / "m" / "images").as_posix() for p in (tmp_path / "m" / "images").rglob("*.png")}
    singles = {p.relative_to(tmp_path / "one" / "images").as_posix() for p in (tmp_path / "one" / "images").rglob("*.png")}
    assert images == singles and any(p.endswith("ht-mean-x2.png") for p in images)
    config = json.loads((tmp_path / "m" / "config.json").read_text())
    assert config["sweep"]["methods"] == ["ht-mean", "ht-mean-x2"] and len(config["merged_from"]) == 2

    # what does not fit is refused, naming the problem, and nothing is written
    assert merge_main([str(tmp_path / "x"), str(tmp_path / "a"), str(tmp_path / "a"), "--no-report"]) == 2
    other = run_sweep(spec(["ht-mean-x2"], lights=(0.5,)), tmp_path / "c", quiet(plugin, cache_dir=cache))
    assert other.exit_code == 0
    with pytest.raises(InputError, match="different sweep.*grid"):
        merge_sweeps(tmp_path / "y", [tmp_path / "a", tmp_path / "c"])
    with pytest.raises(InputError, match="not a finished sweep"):
        merge_sweeps(tmp_path / "y", [tmp_path / "a", tmp_path / "nothing"])
    # results computed on another device are not the same sweep (a folder without the field ran on the CPU)
    import shutil

    shutil.copytree(tmp_path / "b", tmp_path / "b-gpu")
    gpu = json.loads((tmp_path / "b-gpu" / "config.json").read_text())
    gpu["sweep"]["device"] = "cuda:0"
    (tmp_path / "b-gpu" / "config.json").write_text(json.dumps(gpu))
    with pytest.raises(InputError, match="different sweep.*device"):
        merge_sweeps(tmp_path / "y", [tmp_path / "a", tmp_path / "b-gpu"])
    # each method's precision comes with its rows
    gpu["sweep"]["device"], gpu["sweep"]["precision"] = "cpu", {"ht-mean-x2": "bfloat16"}
    (tmp_path / "b-gpu" / "config.json").write_text(json.dumps(gpu))
    merge_sweeps(tmp_path / "z", [tmp_path / "a", tmp_path / "b-gpu"])
    assert json.loads((tmp_path / "z" / "config.json").read_text())["sweep"]["precision"] == {"ht-mean-x2": "bfloat16"}
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    # a committed report keeps its results gzipped: it merges as the folder it was
    import gzip

    shutil.copytree(tmp_path / "a", tmp_path / "a-committed")
    raw = (tmp_path / "a-committed" / "results.csv").read_bytes()
    (tmp_path / "a-committed" / "results.csv.gz").write_bytes(gzip.compress(raw))
    (tmp_path / "a-committed" / "results.csv").unlink()
    again = merge_sweeps(tmp_path / "g", [tmp_path / "a-committed", tmp_path / "b"])
    same_numbers(again, merged)


def test_merge_with_replace_takes_a_methods_rows_from_the_last_folder_that_holds_it(plugin, tmp_path):
    """A method retrained and rerun alone replaces its old rows (and keeps its place in the method list)."""
    from bench.merge import main as merge_main, merge_sweeps
    from bench.harness.results import to_csv_text

    import dataclasses

    cache = str(tmp_path / "cache")

    def spec(methods):
        return dataclasses.replace(tiny_spec(methods), axis="light")

    one = run_sweep(spec(["ht-mean", "ht-mean-x2"]), tmp_path / "one", quiet(plugin, cache_dir=cache))
    new = run_sweep(spec(["ht-mean"]), tmp_path / "new", quiet(plugin, cache_dir=cache))
    assert one.exit_code == new.exit_code == 0
    # mark the later folder's numbers, so that where each row came from shows
    rows = read_csv(tmp_path / "new" / "results.csv")
    rows["value"] = rows["value"] + 1000.0
    (tmp_path / "new" / "results.csv").write_text(to_csv_text(rows))
    with pytest.raises(InputError, match="--replace"):
        merge_sweeps(tmp_path / "m", [tmp_path / "one", tmp_path / "new"])
    assert merge_main([str(tmp_path / "m"), str(tmp_path / "one"), str(tmp_path / "new"), "--replace", "--no-report"]) == 0
    merged = read_csv(tmp_path / "m" / "results.csv")
    old = read_csv(tmp_path / "one" / "results.csv")
    mean = merged[merged["method"] == "ht-mean"]
    assert len(mean) == len(rows) and mean["value"].notna().any()
    assert (mean["value"].dropna() >= 1000.0).all()  # NaN: metrics undefined for the cell
    x2 = merged[merged["method"] == "ht-mean-x2"].reset_index(drop=True)
    same_numbers(x2, old[old["method"] == "ht-mean-x2"].reset_index(drop=True))
    assert len(merged) == len(old)
    config = json.loads((tmp_path / "m" / "config.json").read_text())
    assert config["sweep"]["methods"] == ["ht-mean", "ht-mean-x2"]


def test_merge_take_reads_only_the_named_methods_from_later_folders(plugin, tmp_path):
    """``--take``: a rerun that also computed another method rejoins only the named one; the other
    keeps the first folder's rows and place, and a method no later folder holds is refused by name."""
    from bench.merge import main as merge_main, merge_sweeps
    from bench.harness.results import to_csv_text

    import dataclasses

    cache = str(tmp_path / "cache")

    def spec(methods):
        return dataclasses.replace(tiny_spec(methods), axis="light")

    assert run_sweep(spec(["ht-mean", "ht-mean-x2"]), tmp_path / "one", quiet(plugin, cache_dir=cache)).exit_code == 0
    assert run_sweep(spec(["ht-mean", "ht-mean-x2"]), tmp_path / "new", quiet(plugin, cache_dir=cache)).exit_code == 0
    rows = read_csv(tmp_path / "new" / "results.csv")
    rows["value"] = rows["value"] + 1000.0  # where each row came from shows
    (tmp_path / "new" / "results.csv").write_text(to_csv_text(rows))
    with pytest.raises(InputError, match="ht-median"):
        merge_sweeps(tmp_path / "m", [tmp_path / "one", tmp_path / "new"], replace=True, take=["ht-median"])
    assert merge_main([str(tmp_path / "m"), str(tmp_path / "one"), str(tmp_path / "new"), "--replace",
                       "--take", "ht-mean", "--no-report"]) == 0
    merged, old = read_csv(tmp_path / "m" / "results.csv"), read_csv(tmp_path / "one" / "results.csv")
    assert (merged.loc[merged["method"] == "ht-mean", "value"].dropna() >= 1000.0).all()
    x2 = merged[merged["method"] == "ht-mean-x2"].reset_index(drop=True)
    same_numbers(x2, old[old["method"] == "ht-mean-x2"].reset_index(drop=True))
    assert len(merged) == len(old)
    assert json.loads((tmp_path / "m" / "config.json").read_text())["sweep"]["methods"] == ["ht-mean", "ht-mean-x2"]


def test_progress_on_a_log_file_is_a_plain_line_now_and_then():
    """No terminal, no bar: a line at most every N seconds and one at the end, with the time left."""
    import io

    from bench.harness.runner import ProgressLines

    stream = io.StringIO()
    lines = ProgressLines("light", 10, 2, every_s=3600.0, stream=stream)
    for finished in range(3, 10):
        lines.update(finished, 0)
    assert stream.getvalue() == ""  # within the interval: quiet
    lines.update(10, 1)
    assert stream.getvalue() == "light: 10 of 10 cells finished (1 failed)\n"
    eager = ProgressLines("noise", 4, 0, every_s=0.0, stream=stream)
    eager.update(1, 0)
    assert stream.getvalue().splitlines()[-1].startswith("noise: 1 of 4 cells finished (0 failed), about ")


def test_merge_refuses_damaged_or_doubled_results_and_a_file_as_out_in_one_line(plugin, tmp_path, capsys):
    from bench.merge import main as merge_main

    cache = str(tmp_path / "cache")
    a = run_sweep(tiny_spec(["ht-mean"]), tmp_path / "a", quiet(plugin, cache_dir=cache))
    b = run_sweep(tiny_spec(["ht-mean-x2"]), tmp_path / "b", quiet(plugin, cache_dir=cache))
    assert a.exit_code == b.exit_code == 0
    capsys.readouterr()  # the sweeps' own notes
    (tmp_path / "afile").write_text("x")
    results = tmp_path / "b" / "results.csv"
    good = results.read_bytes()
    cases = [("file-out", lambda: None, str(tmp_path / "afile"), "exists and is not a folder"),
             ("garbage", lambda: results.write_bytes(b"\x00\xff garbage"), str(tmp_path / "m1"), "not a results table"),
             ("columns", lambda: results.write_text("cell,value\n1,2\n"), str(tmp_path / "m2"), "missing the columns"),
             ("doubled", lambda: results.write_bytes(good + good.split(b"\n", 1)[1]), str(tmp_path / "m3"),
              "repeat a (cell, method, metric)")]
    for name, damage, out, message in cases:
        results.write_bytes(good)
        damage()
        assert merge_main([out, str(tmp_path / "a"), str(tmp_path / "b"), "--no-report"]) == 2, name
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (name, err)


def test_a_second_run_on_the_same_out_is_refused_while_the_first_writes(plugin, tmp_path):
    """The folder is locked for the run (the kernel's flock, released when the process ends)."""
    from bench.harness.runner import out_lock

    out = tmp_path / "run"
    with out_lock(out):
        with pytest.raises(InputError, match="another run is writing to this folder"):
            run_sweep(tiny_spec(["ht-mean"]), out, quiet(plugin))
        assert not (out / "parts").exists() and not (out / "results.csv").exists()
    assert run_sweep(tiny_spec(["ht-mean"]), out, quiet(plugin)).exit_code == 0  # released
