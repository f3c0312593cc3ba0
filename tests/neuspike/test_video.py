"""Video streaming: equality with single-frame reconstructions, bounded memory, ground truth, the command."""

from __future__ import annotations

import json
import math
import tracemalloc

import cv2
import h5py
import numpy as np
import pytest

from neuspike import methods as registry
from neuspike.errors import InputError
from neuspike.formats.event_readers import read_events
from neuspike.formats.event_writers import write_events_h5, write_events_npz
from neuspike.formats.spike_npz import write_spike_npz
from neuspike.formats.vidar_dat import write_dat
from neuspike.methods import Method
from neuspike.formats.samples import load_sample
from neuspike.streams import EventStream, SpikeStream
from neuspike.video import check_fps, frame_times, open_recording, reconstruct_video, stream_samples
from neuspike.video.cli import main
from neuspike.video.truth import FlickerMeter, ground_truth_for
from neuspike.formats.images import to_uint8

H, W = 24, 32
RATE = 20_000.0
STATELESS = ("tfp", "tfp-w8", "tfi", "events-integrate", "events-highpass", "fusion-complementary")


def _events(rng, n, t0, t1, width=W, height=H):
    t = np.sort(rng.uniform(t0, t1, n))
    return EventStream(t, rng.integers(0, width, n), rng.integers(0, height, n),
                       rng.choice(np.array([-1, 1]), n), width, height)


@pytest.fixture
def recording(tmp_path, rng):
    """A 600-plane .dat with a spatial rate pattern and events over the same 30 ms (plus earlier)."""
    rate = np.linspace(0.05, 0.6, W)[None, :] * np.linspace(0.5, 1.0, H)[:, None]
    planes = rng.random((600, H, W)) < rate
    write_dat(tmp_path / "spikes.dat", planes)
    write_events_h5(tmp_path / "events.h5", _events(rng, 20_000, -0.01, 600 / RATE))
    return tmp_path, planes


def _single(name, spikes, events, t, **kw):
    sample = load_sample(spikes=spikes, events=events, at_s=t, **kw)
    m = registry.create(name)
    m.reset()
    return m.reconstruct(sample)


@pytest.mark.parametrize("name", STATELESS)
def test_stream_equals_single_frame(recording, name):
    folder, _ = recording
    spikes, events = folder / "spikes.dat", folder / "events.h5"
    m = registry.create(name)
    # edges (windows shifted inside the file), the middle, a repeated instant and a step back in time
    times = [0.0, 2e-5, 0.004, 0.0151, 0.0151, 0.012, 0.0299, 0.03]
    with open_recording(spikes=spikes, events=events, height=H, width=W) as rec:
        got = list(reconstruct_video(m, rec, times))
    assert [t for t, _ in got] == times
    for t, img in got:
        ref = _single(name, spikes, events, t, height=H, width=W)
        if name in ("events-highpass", "fusion-complementary"):  # streamed decayed sums agree to rounding
            np.testing.assert_allclose(img, ref, rtol=0, atol=1e-6, err_msg=f"{name} at {t}")
        else:
            assert np.array_equal(img, ref), (name, t)


@pytest.mark.parametrize("name", ["events-integrate", "events-highpass", "fusion-complementary"])
def test_event_sums_stream_through_a_short_history(recording, name):
    """With a 2 ms history, each frame drops events and adds new ones: the updated image equals the
    one summed afresh (integration bit for bit, the decayed sums within 1e-6), every frame after the
    first is an update (for the fusion: where its crossover, matched to the spike planes, is unchanged;
    near the recording's ends the spike window shifts and it changes), and a step back in time sums
    afresh."""
    folder, _ = recording
    kw = dict(spikes=folder / "spikes.dat", events=folder / "events.h5", height=H, width=W)
    times = list(frame_times(0.006, 0.024, 2000)) + [0.01]
    m = registry.create(name)
    streamed, cutoffs = [], []
    with open_recording(**kw) as rec, open_recording(**kw) as rec2:
        for t, img in reconstruct_video(m, rec, times, event_history_s=0.002):
            streamed.append(m.last_streamed)
            cutoffs.append(getattr(m, "last_cutoff_hz", None) or 0.0)
            ref = registry.create(name).reconstruct(next(stream_samples(rec2, [t], event_history_s=0.002)))
            if name == "events-integrate":
                assert np.array_equal(img, ref), t
            else:
                np.testing.assert_allclose(img, ref, rtol=0, atol=1e-6, err_msg=str(t))
    same_cutoff = [math.isclose(a, b, rel_tol=1e-9) for a, b in zip(cutoffs, cutoffs[1:])]
    assert streamed == [False] + same_cutoff[:-1] + [False]
    assert sum(streamed) >= len(times) - 4


def test_stream_events_only_and_npz_sources(tmp_path, rng):
    ev = _events(rng, 5000, 0.1, 0.2)
    write_events_npz(tmp_path / "ev.npz", ev)
    write_events_h5(tmp_path / "ev.h5", ev)
    planes = rng.random((300, H, W)) < 0.3
    write_spike_npz(tmp_path / "sp.npz", SpikeStream(planes, plane_rate_hz=RATE, start_s=0.25, gain=0.5))
    times = frame_times(0.11, 0.19, 200)
    for path in (tmp_path / "ev.npz", tmp_path / "ev.h5"):
        with open_recording(path) as rec:
            assert rec.modalities == {"events"}
            for t, img in reconstruct_video(registry.create("events-highpass"), rec, times):
                assert np.array_equal(img, _single("events-highpass", None, path, t))
    with open_recording(tmp_path / "sp.npz") as rec:
        assert rec.gain == 0.5 and rec.start_s == 0.25
        for t, img in reconstruct_video(registry.create("tfp-w16"), rec, frame_times(0.25, 0.265, 2000)):
            assert np.array_equal(img, _single("tfp-w16", tmp_path / "sp.npz", None, t))


def test_pku_layout_read_by_range_matches_whole_file(tmp_path, rng):
    n = 3000
    rec = np.zeros(n, dtype=[("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
    rec["timestamp"] = np.sort(rng.integers(2_890_000, 2_990_000, n))
    rec["x"], rec["y"], rec["polarity"] = rng.integers(0, 346, n), rng.integers(0, 260, n), rng.integers(0, 2, n)
    path = tmp_path / "pku.hdf5"
    with h5py.File(path, "w") as f:
        f.create_dataset("events", data=rec)
    whole = read_events(path)
    with open_recording(path) as vr:
        assert (vr.width, vr.height) == (346, 260)
        for t in (2.895, 2.9, 2.95, 2.98):
            s = next(stream_samples(vr, [t], window_planes=400, event_history_s=0.004))
            ref = whole.between(t - 0.01 - 0.004, t + 0.01)
            for a in ("t_s", "x", "y", "p"):
                assert np.array_equal(getattr(s.events, a), getattr(ref, a))


def test_memory_bounded_by_window_not_recording(tmp_path, rng):
    """A 40,000-plane 64x64 .dat (164 MB unpacked, 20 MB on disk) streams with a peak of a few windows."""
    h = w = 64
    path = tmp_path / "long.dat"
    path.write_bytes(rng.integers(0, 256, 40_000 * h * w // 8, dtype=np.uint8).tobytes())  # any bytes are planes
    window_bytes = 256 * h * w  # one unpacked bool window: 1 MB
    m = registry.create("tfp")
    with open_recording(spikes=path, height=h, width=w) as rec:
        times = frame_times(0.0, rec.span_s()[1], 40)  # 80 frames spread over the whole 2 s
        tracemalloc.start()
        try:
            n = sum(1 for _ in reconstruct_video(m, rec, times))
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert n == 80
    assert peak < 10 * window_bytes, f"peak {peak / 1e6:.1f} MB for a {window_bytes / 1e6:.1f} MB window"


def test_event_memory_bounded_by_history(tmp_path, rng):
    """2M events over 2 s (26 MB in memory) stream with 10 ms of history in a small fraction of that
    (what stays is the window, the history and one block read ahead, not the recording)."""
    write_events_h5(tmp_path / "ev.h5", _events(rng, 2_000_000, 0.0, 2.0))
    m = registry.create("events-highpass")
    with open_recording(tmp_path / "ev.h5") as rec:
        times = frame_times(0.05, 1.95, 100)
        tracemalloc.start()
        try:
            n = sum(1 for _ in reconstruct_video(m, rec, times, event_history_s=0.01))
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert n == 190
    assert peak < 4e6, f"peak {peak / 1e6:.2f} MB"


def test_frame_times_and_fps_rules(recording):
    folder, _ = recording
    t = frame_times(0.0, 0.001, RATE)
    assert np.allclose(t, (np.arange(20) + 0.5) / RATE)  # one frame per plane, at plane centres
    with pytest.raises(InputError, match="not before"):
        frame_times(0.02, 0.01, 100)
    with pytest.raises(InputError, match="shorter than one frame"):
        frame_times(0.0, 0.001, 100)
    with open_recording(spikes=folder / "spikes.dat", events=folder / "events.h5", height=H, width=W) as rec:
        with pytest.raises(InputError, match="plane rate"):
            check_fps(2 * RATE, rec, {"spikes"})
        assert check_fps(2 * RATE, rec, {"events"}) == 2 * RATE
        with pytest.raises(InputError, match="outside"):
            next(stream_samples(rec, [0.05]))


def test_flicker_closed_forms(rng):
    gt = [rng.random((8, 8)) for _ in range(4)]
    biased = FlickerMeter()
    assert math.isnan(biased.update(gt[0] + 0.1, gt[0]))
    assert all(abs(biased.update(g + 0.1, g)) < 1e-12 for g in gt[1:])  # a constant error does not flicker
    alt = FlickerMeter()
    vals = [alt.update(g + (0.05 if k % 2 else -0.05), g) for k, g in enumerate(gt)]
    assert np.allclose(vals[1:], 0.1)  # +-d alternation: consecutive-difference error 2d
    assert math.isnan(alt.update(gt[0], None)) and math.isnan(alt.update(gt[1], gt[1]))  # a gap breaks the chain


def test_scene_ground_truth_follows_time_scale(tmp_path):
    from neuspike.conditions import Condition
    from neuspike.utils.rng import derive_rng
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.writing import write_sequence

    scene = make_scene(SceneSpec(kind="pan", size=(48, 32), velocity_px_s=(2000.0, 0.0)))
    write_sequence(scene, Condition(light=0.25, motion=128), tmp_path, rng=derive_rng(0, "t"), start_s=0.3,
                   duration_s=0.002, time_scale=0.5, modalities=("spikes",))
    meta = json.loads((tmp_path / "meta.json").read_text())
    truth = ground_truth_for(tmp_path, meta, height=32, width=48, tolerance_s=1e-4)
    assert truth.source == "scene"
    t = 0.0031
    t_gt, img = truth.at(t)
    assert t_gt == t
    expected = np.clip(scene.render(np.array([0.3 + 0.5 * t]))[0], 0, 1)
    assert np.array_equal(img, expected)
    assert not np.array_equal(img, np.clip(scene.render(np.array([0.3 + t]))[0], 0, 1))


# --------------------------------------------------------------------------- the command
class _FailAt(Method):
    inputs = frozenset({"spikes"})

    def _reconstruct(self, sample):
        if sample.key_time_s > 0.01:
            raise InputError("deliberate failure mid-run")
        return np.zeros((sample.height, sample.width), np.float32), "none"


def _run(*argv):
    return main([str(a) for a in argv])


def test_command_writes_videos_frames_and_metrics(tmp_path, rng):
    from neuspike.conditions import Condition
    from neuspike.utils.rng import derive_rng
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.writing import write_sequence

    sim = tmp_path / "sim"
    scene = make_scene(SceneSpec(kind="fan", size=(48, 32), rpm=2600.0))
    write_sequence(scene, Condition(light=0.25, motion=128), sim, rng=derive_rng(0, "v"), start_s=0.0,
                   duration_s=0.01)
    out = tmp_path / "out"
    assert _run(sim, "--method", "tfp-w32,events-highpass", "--fps", 2000, "--frames", "png,npy",
                "--out", out, "--no-progress") == 0
    for f in ("tfp-w32.mp4", "events-highpass.mp4", "compare.mp4", "contact_sheet.png", "metrics.csv",
              "metrics.png", "video.json"):
        assert (out / f).is_file(), f
    assert not list(out.glob(".*partial*"))
    summary = json.loads((out / "video.json").read_text())
    assert summary["frames"] == 20 and summary["ground_truth"] == "scene"
    assert summary["recording"]["dark_rate"] == 0.0  # written by the simulation: a camera without dark current
    # the record names no absolute folder of this machine (the command got absolute paths)
    assert str(tmp_path) not in (out / "video.json").read_text()
    cap = cv2.VideoCapture(str(out / "compare.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 20 and int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)) == 3 * 48 + 8
    # the saved frames are the streamed frames
    with open_recording(sim) as rec:
        streamed = list(reconstruct_video(registry.create("tfp-w32"), rec, frame_times(0.0, 0.01, 2000)))
    k = 7
    assert np.array_equal(np.load(out / "tfp-w32" / f"frame_{k:06d}.npy"), streamed[k][1])
    png = cv2.imread(str(out / "tfp-w32" / f"frame_{k:06d}.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(png, to_uint8(streamed[k][1], clip=True))
    import csv

    rows = list(csv.DictReader(open(out / "metrics.csv")))
    assert len(rows) == 40 and {r["method"] for r in rows} == {"tfp-w32", "events-highpass"}
    from neuspike.metrics import psnr

    row = next(r for r in rows if r["method"] == "tfp-w32" and r["frame"] == str(k))
    gt = np.clip(scene.render(np.array([streamed[k][0]]))[0], 0, 1)
    assert float(row["psnr_db"]) == pytest.approx(psnr(streamed[k][1], gt, data_range=1.0), abs=1e-3)


@pytest.mark.parametrize("argv, message", [
    (["--start", "0.02", "--end", "0.01"], "not before"),
    (["--start", "0.01", "--end", "0.01001"], "shorter than one frame"),
    (["--end", "0.5"], "not inside the recording"),
    (["--fps", "40000"], "above the spike plane rate"),
])
def test_command_bad_input_is_one_line_and_writes_nothing(recording, tmp_path, capsys, argv, message):
    folder, _ = recording
    out = tmp_path / "out"
    code = _run("--spikes", folder / "spikes.dat", "--height", H, "--width", W, "--method", "tfp", "--fps", 1000,
                *argv, "--out", out, "--no-progress")
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error:") and message in err[0], err
    assert not out.exists() or not any(out.iterdir())


def test_command_event_method_may_exceed_plane_rate(recording, tmp_path):
    folder, _ = recording
    out = tmp_path / "out"
    assert _run("--events", folder / "events.h5", "--method", "events-integrate", "--fps", 40_000, "--start", 0, "--end",
                "0.0003", "--frames", "none", "--out", out, "--no-progress") == 0
    assert json.loads((out / "video.json").read_text())["frames"] == 12


def test_command_unwritable_output_and_failure_mid_run(recording, tmp_path, capsys):
    folder, _ = recording
    blocker = tmp_path / "file"
    blocker.write_text("x")
    args = ("--spikes", folder / "spikes.dat", "--height", H, "--width", W, "--fps", 1000, "--no-progress")
    assert _run(*args, "--method", "tfp", "--out", blocker / "sub") == 2
    assert "is not a folder" in capsys.readouterr().err
    registry.register("zz-video-fail", _FailAt)
    try:
        out = tmp_path / "out"
        assert _run(*args, "--method", "tfp,zz-video-fail", "--out", out) == 2
        assert "deliberate failure" in capsys.readouterr().err
        assert not out.exists() and list(tmp_path.glob(".out*")) == []  # nothing published, nothing left behind
    finally:
        registry.unregister("zz-video-fail")


def test_firenet_carries_its_state_between_frames(tmp_path, one_torch_thread):
    """The first frame is a fresh reconstruction; later frames step only the new windows (plus one
    partial window) and stay close to fresh reconstructions (differing window tiling and longer warm-up)."""
    from tests.shared_data import SHARED

    weights = SHARED / "weights"
    if not (weights / "firenet" / "firenet.pt").is_file():
        pytest.skip("FireNet weights not available")
    from neuspike.conditions import Condition
    from neuspike.metrics import ssim
    from neuspike.utils.rng import derive_rng
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.writing import write_sequence

    scene = make_scene(SceneSpec(kind="pan", size=(64, 48), velocity_px_s=(400.0, 0.0)))
    write_sequence(scene, Condition(light=0.25, motion=128), tmp_path, rng=derive_rng(0, "f"), start_s=0.0,
                   duration_s=0.06, modalities=("events",))
    m = registry.create("firenet", weights_dir=weights)
    fresh = registry.create("firenet", weights_dir=weights)
    per_window = round(0.35 * 64 * 48)
    with open_recording(tmp_path) as rec:
        times = frame_times(0.04, 0.06, 400)
        previous = None
        for k, (t, img) in enumerate(reconstruct_video(m, rec, times)):
            if k:
                new = rec.event_index(t) - rec.event_index(previous)
                assert m.last_steps <= new // per_window + 2  # the windows pending since the last commit, + 1 partial
            if k in (0, 2, 7):
                ref = fresh.reconstruct(load_sample(events=tmp_path / "events.h5", at_s=t))
                if k == 0:
                    assert np.array_equal(img, ref) and m.last_steps == fresh.last_steps == 24
                else:
                    assert ssim(img, ref, data_range=1.0) > 0.9
            previous = t


@pytest.mark.parametrize("name", ["tfp", "tfp-w32"])
def test_tfp_sliding_count_equals_a_full_count(recording, name):
    """At one frame per plane (and every 10 planes) TFP updates its count by the planes entering and
    leaving the window; every frame equals the single-frame reconstruction."""
    folder, _ = recording
    spikes = folder / "spikes.dat"
    times = np.concatenate([frame_times(0.006, 0.0085, RATE), frame_times(0.0085, 0.02, 2000)])
    with open_recording(spikes=spikes, height=H, width=W) as rec:
        got = list(reconstruct_video(registry.create(name), rec, times))
    for t, img in got[::3]:
        assert np.array_equal(img, _single(name, spikes, None, t, height=H, width=W)), t


def test_command_precision_and_compile_reach_the_learned_method(recording, tmp_path, monkeypatch):
    """``--precision`` sets the learned method's precision and ``--compile`` sends its network through
    torch.compile (replaced by a recorder returning the module itself, so the plumbing is tested without
    a real compile; the compiled image is tested in test_compiled.py): both are recorded in video.json,
    and a pass-through compile changes no frame."""
    import torch

    folder, _ = recording
    calls = []
    monkeypatch.setattr(torch, "compile", lambda module, **kw: calls.append(kw) or module)
    runs = {}
    for flags in ([], ["--compile"]):
        out = tmp_path / ("compiled" if flags else "eager")
        assert _run("--events", folder / "events.h5", "--method", "firenet-sim", "--precision", "float32",
                    "--fps", 10_000, "--start", 0, "--end", "0.0005", "--frames", "npy", "--out", out,
                    "--no-progress", *flags) == 0
        runs[bool(flags)] = out
    assert len(calls) == 1 and calls[0]["options"] == {"freezing": True}
    for compiled, out in runs.items():
        summary = json.loads((out / "video.json").read_text())
        assert summary["spec"]["precision"] == "float32" and summary["spec"]["compiled"] is compiled
        assert summary["methods"]["firenet-sim"]["precision"] == "float32"
        assert summary["methods"]["firenet-sim"]["compiled"] is compiled
    frames = sorted((runs[False] / "firenet-sim").glob("frame_*.npy"))
    assert len(frames) == 5
    for f in frames:
        assert np.array_equal(np.load(f), np.load(runs[True] / "firenet-sim" / f.name))


def test_command_read_out_reaches_the_event_networks_and_is_refused_where_none_reads_windows(
        recording, tmp_path, capsys):
    """``--read-out window`` reaches firenet-sim (recorded in video.json, said in its label) and not a
    method without event windows run beside it; asked of such methods alone it is a one-line error
    before anything is written."""
    folder, _ = recording
    out = tmp_path / "window"
    assert _run("--events", folder / "events.h5", "--method", "firenet-sim,events-integrate", "--precision",
                "float32", "--read-out", "window", "--fps", 10_000, "--start", 0, "--end", "0.0005",
                "--frames", "none", "--out", out, "--no-progress") == 0
    summary = json.loads((out / "video.json").read_text())
    assert summary["spec"]["read_out"] == "window"
    assert summary["methods"]["firenet-sim"]["read_out"] == "window"
    assert "read out at the last full window" in summary["methods"]["firenet-sim"]["normalisation"]
    assert summary["methods"]["events-integrate"]["read_out"] is None
    capsys.readouterr()
    code = _run("--events", folder / "events.h5", "--method", "events-integrate", "--read-out", "window",
                "--out", tmp_path / "refused", "--no-progress")
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "read_out" in err[0] and "event windows" in err[0], err
    assert not (tmp_path / "refused").exists()


def test_command_refuses_an_unknown_precision(recording, tmp_path, capsys):
    folder, _ = recording
    code = _run("--events", folder / "events.h5", "--method", "firenet-sim", "--precision", "float16",
                "--out", tmp_path / "out", "--no-progress")
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--precision" in err[0] and "float16" in err[0], err
    assert not (tmp_path / "out").exists()


def test_command_runs_a_method_a_plug_in_file_registers(recording, tmp_path):
    """--plugin (as the benchmarks take it): a plug-in's variant of TFP streams the frames TFP-w32 streams."""
    from neuspike.methods.plugins import forget_plugin

    folder, _ = recording
    plugin = tmp_path / "zz_video_plugin.py"
    plugin.write_text("from baselines.tfp import TFP\n\n\n"
                      "def register_methods(register):\n    register('zz-video-w32', TFP, params={'window': 32})\n")
    common = ("--spikes", folder / "spikes.dat", "--height", H, "--width", W, "--fps", 1000, "--frames", "npy",
              "--no-progress")
    try:
        assert _run(*common, "--plugin", plugin, "--method", "zz-video-w32", "--out", tmp_path / "a") == 0
    finally:
        registry.unregister("zz-video-w32")
        forget_plugin(str(plugin))
    assert _run(*common, "--method", "tfp-w32", "--out", tmp_path / "b") == 0
    ours, theirs = sorted((tmp_path / "a" / "zz-video-w32").glob("*.npy")), sorted((tmp_path / "b" / "tfp-w32").glob("*.npy"))
    assert len(ours) == len(theirs) > 1
    assert all(np.array_equal(np.load(a), np.load(b)) for a, b in zip(ours, theirs))
