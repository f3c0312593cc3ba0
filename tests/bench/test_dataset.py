"""bench.dataset: small datasets in both inferred layouts, simulated with exact ground truth, scored as
``neuspike.reconstruct`` scores the same recording and instant; and every bad input refused in one line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench import dataset as cmd
from bench.harness import manifest as mf
from bench.harness.results import read_csv
from neuspike.conditions import Condition
from neuspike.formats.images import write_png
from neuspike.formats.spike_npz import write_spike_npz
from neuspike.formats.vidar_dat import read_dat
from neuspike.reconstruct import ReconstructSpec, run as reconstruct
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulation.recording import SensorConfig
from neuspike.simulation.writing import write_sequence
from neuspike.streams import SpikeStream

W, H = 48, 32
RATE = 20_000.0
LIGHT = 0.5  # gain = L / threshold = 0.5 expected spikes per plane at intensity 1
SPIKE_METHODS = "tfp,tfi,snm"
EVENT_METHODS = "events-integrate,firenet-sim"


def _simulate(kind: str, out: Path, duration_s: float, modalities: tuple[str, ...], **scene) -> tuple[dict, object]:
    spec = SceneSpec(kind=kind, image="camera", size=(W, H), **scene)
    meta = write_sequence(make_scene(spec), Condition(light=LIGHT, effects=()), out, rng=np.random.default_rng(3),
                          start_s=0.0, duration_s=duration_s, sensor=SensorConfig(), modalities=modalities)
    return meta, make_scene(spec)


@pytest.fixture(scope="module")
def spike_gt(tmp_path_factory) -> Path:
    """``spike/still.dat`` + ``gt/still.png`` and ``spike/pan.npz`` + ``gt/pan.npy``: ground truth the scene
    rendered at the centre plane (a still scene is exact at every instant; the pan at its instant)."""
    root = tmp_path_factory.mktemp("spike_gt")
    work = tmp_path_factory.mktemp("sim")
    (root / "spike").mkdir()
    (root / "gt").mkdir()
    for name, kind, extra in (("still", "still", {}), ("pan", "pan", {"velocity_px_s": (400.0, 0.0)})):
        meta, scene = _simulate(kind, work / name, 96 / RATE, ("spikes",), **extra)
        planes = read_dat(work / name / "spikes.dat", height=H, width=W)
        key = planes.shape[0] // 2
        truth = np.clip(scene.render(np.array([(key + 0.5) / RATE]))[0], 0, 1).astype(np.float32)
        if name == "still":
            shutil.copyfile(work / name / "spikes.dat", root / "spike" / "still.dat")
            write_png(root / "gt" / "still.png", truth, clip=False)
        else:
            write_spike_npz(root / "spike" / "pan.npz", SpikeStream(planes, plane_rate_hz=RATE))
            np.save(root / "gt" / "pan.npy", truth)
    return root


@pytest.fixture(scope="module")
def events_frames(tmp_path_factory) -> Path:
    """``events.h5``, ``images/`` and ``images.txt`` (the Event-Camera Dataset's layout) of a panning scene:
    the frames are the scene rendered at their instants, every 256 planes."""
    root = tmp_path_factory.mktemp("events_frames")
    work = tmp_path_factory.mktemp("sim_ev") / "seq"
    _simulate("pan", work, 0.03, ("events",), velocity_px_s=(300.0, 0.0))
    shutil.copyfile(work / "events.h5", root / "events.h5")
    (root / "images").mkdir()
    lines = []
    for line in (work / "frames" / "timestamps.txt").read_text().splitlines():
        if line.startswith("#"):
            continue
        _, t_sensor, _, name = line.split()
        shutil.copyfile(work / "frames" / name, root / "images" / name)
        lines.append(f"{t_sensor} images/{name}")
    (root / "images.txt").write_text("\n".join(lines) + "\n")
    return root


def _run(args: list[str], capsys) -> tuple[int, str, str]:
    code = cmd.main([*args, "--threads", "1", "--no-progress", "--no-report"])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _scores(rows: pd.DataFrame) -> dict[str, float]:
    return dict(zip(rows["metric"], rows["value"]))


# ----------------------------------------------------------------------------------------------
# The two layouts, scored as neuspike.reconstruct scores them
# ----------------------------------------------------------------------------------------------

def test_spike_gt_layout_scores_equal_reconstruct(spike_gt, tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = _run([str(spike_gt), "--gain", str(LIGHT), "--methods", SPIKE_METHODS, "--out", str(out)], capsys)
    assert code == 0, err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["layout"] == "spike-gt"
    entries = {r["name"]: r for r in manifest["recordings"]}
    assert entries["still"]["instants"] == {"plane": 48} and entries["still"]["ground_truth"] == "gt/still.png"
    assert (entries["still"]["height"], entries["still"]["width"]) == (H, W)  # the .dat's size from its ground truth
    assert entries["pan"]["gain"] == LIGHT
    frame = read_csv(out / "results.csv")
    assert set(frame["status"]) == {"ok"}
    for name, files in (("still", {"spikes": spike_gt / "spike" / "still.dat", "height": H, "width": W}),
                        ("pan", {"spikes": spike_gt / "spike" / "pan.npz"})):
        gt = spike_gt / entries[name]["ground_truth"]
        expected = reconstruct(ReconstructSpec(methods=tuple(SPIKE_METHODS.split(",")), out=tmp_path / f"rec-{name}",
                                               plane=48, gain=LIGHT, gt=gt, **files), stream=open("/dev/null", "w"))
        for result in expected:
            rows = frame[(frame["scene"] == name) & (frame["method"] == result.name)]
            got = _scores(rows)
            assert set(got) == {"psnr", "ssim", "psnr_affine", "ssim_affine", "noise_sigma", "laplacian_var"}
            for metric, value in result.scores.items():
                assert got[metric] == value, (name, result.name, metric)
            assert rows["time_s"].iloc[0] == pytest.approx(48.5 / RATE)
            assert rows["reference"].iloc[0] == entries[name]["ground_truth"]
    # the still scene's ground truth is exact: TFP with the true gain is close to it
    tfp = _scores(frame[(frame["scene"] == "still") & (frame["method"] == "tfp")])
    assert tfp["psnr"] > 20


def test_events_frames_layout_scores_equal_reconstruct(events_frames, tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = _run([str(events_frames), "--methods", f"{EVENT_METHODS},tfp", "--out", str(out)], capsys)
    assert code == 0, err
    assert "frames lie outside the events" in err  # the frame at t = 0 has no events before it
    manifest = json.loads((out / "manifest.json").read_text())
    (entry,) = manifest["recordings"]
    assert manifest["layout"] == "events-frames" and entry["events"] == "events.h5"
    times, gts = entry["instants"]["times_s"], entry["ground_truth"]
    assert len(times) == len(gts) >= 2 and all(t > 0 for t in times)
    frame = read_csv(out / "results.csv")
    assert set(frame["method"]) == set(EVENT_METHODS.split(","))  # tfp reads spikes: not applicable, no rows
    assert sorted(pd.unique(frame["instant"])) == list(range(len(times)))  # one row per instant
    for index, (t, gt) in enumerate(zip(times, gts)):
        expected = reconstruct(ReconstructSpec(methods=tuple(EVENT_METHODS.split(",")), out=tmp_path / f"rec{index}",
                                               events=events_frames / "events.h5", at_s=t, gt=events_frames / gt),
                               stream=open("/dev/null", "w"))
        for result in expected:
            rows = frame[(frame["instant"] == index) & (frame["method"] == result.name)]
            assert rows["time_s"].iloc[0] == t and rows["reference"].iloc[0] == gt
            got = _scores(rows)
            for metric, value in result.scores.items():
                assert got[metric] == value, (index, result.name, metric)


def test_long_recording_gives_a_row_per_instant_and_resumes(spike_gt, tmp_path, capsys):
    """``every_planes`` over a 96-plane file with a 32-plane window: key planes 16, 40, 64 (the last whose
    window fits, 80 - 16 = 64 ... shown by the plane centres)."""
    manifest = {"manifest": 1, "recordings": [{"name": "long", "spikes": "spike/pan.npz", "gain": LIGHT,
                                              "window_planes": 32, "instants": {"every_planes": 24}}]}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(manifest))
    out = tmp_path / "run"
    code, printed, err = _run([str(spike_gt), "--manifest", str(path), "--methods", "tfp", "--out", str(out)], capsys)
    assert code == 0, err
    frame = read_csv(out / "results.csv")
    times = sorted(pd.unique(frame["time_s"]))
    assert times == pytest.approx([(k + 0.5) / RATE for k in (16, 40, 64)])
    assert set(frame["metric"]) == {"noise_sigma", "laplacian_var"}  # no ground truth named: no-reference only
    code, printed, _ = _run([str(spike_gt), "--manifest", str(path), "--methods", "tfp", "--out", str(out)], capsys)
    assert code == 0 and "0 computed now" in printed
    config = json.loads((out / "config.json").read_text())["dataset"]
    assert config["protocol"]["recordings"]["long"]["window_planes"] == 32
    assert config["protocol"]["ssim"]["gaussian_weights"] is True


def test_damaged_recording_fails_its_rows_and_the_others_run(spike_gt, tmp_path, capsys):
    root = tmp_path / "ds"
    shutil.copytree(spike_gt, root)
    with open(root / "spike" / "still.dat", "ab") as fh:  # a trailing partial plane
        fh.write(b"\x01\x02\x03")
    out = tmp_path / "run"
    code, _, err = _run([str(root), "--gain", str(LIGHT), "--methods", "tfp", "--out", str(out)], capsys)
    assert code == 1
    frame = read_csv(out / "results.csv")
    bad = frame[frame["scene"] == "still"]
    assert set(bad["status"]) == {"error"} and bad["error"].str.contains("reading the recording failed").all()
    assert set(frame.loc[frame["scene"] == "pan", "status"]) == {"ok"}
    code, _, _ = _run([str(root), "--gain", str(LIGHT), "--methods", "tfp", "--out", str(out), "--allow-failures"],
                      capsys)
    assert code == 0


def test_report_has_protocol_table_and_sheets(spike_gt, tmp_path):
    out = tmp_path / "run"
    code = cmd.main([str(spike_gt), "--gain", str(LIGHT), "--methods", "tfp,tfi", "--out", str(out),
                     "--threads", "1", "--no-progress"])
    assert code == 0
    table = pd.read_csv(out / "tables" / "dataset.csv")
    assert set(table["recording"]) == {"still", "pan"} and set(table["method"]) == {"tfp", "tfi"}
    assert (out / "figures" / "sheet_still.png").is_file() and (out / "report.pdf").stat().st_size > 0
    from bench.reporting.dataset_report import protocol_blocks

    text = " ".join(t for _, t in protocol_blocks(json.loads((out / "config.json").read_text())["dataset"]))
    assert "sigma=1.5" in text and "Data range: 1.0" in text
    assert "still: spikes, 48x32, 20000.0 planes/s, window 256 planes, gain 0.5 (given)" in text


# ----------------------------------------------------------------------------------------------
# Bad input: one line naming the recording, before any work
# ----------------------------------------------------------------------------------------------

def _manifest(tmp_path: Path, **entry) -> Path:
    base = {"name": "bad", "spikes": "spike/pan.npz", "gain": LIGHT}
    base.update(entry)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"manifest": 1, "recordings": [base]}))
    return path


@pytest.mark.parametrize("entry, message", [
    ({"spikes": "spike/missing.dat", "height": H, "width": W}, "recording bad: spike file spike/missing.dat does not exist"),
    ({"ground_truth": "gt/small.png"}, "recording bad: ground truth gt/small.png is 16x16, the sensor 48x32"),
    ({"instants": {"plane": 500}}, "recording bad: key instant: plane 500 is outside the spike file's 96 planes"),
    ({"instants": {"times_s": [1.0]}}, "recording bad: key instant: time 1.0 s is outside the spike recording"),
    ({"gain": 0}, "recording bad: gain is 0"),
    ({"plane_rate_hz": 0}, "recording bad: plane_rate_hz is 0"),
])
def test_bad_manifest_is_one_line_before_any_work(spike_gt, tmp_path, capsys, entry, message):
    root = tmp_path / "ds"
    shutil.copytree(spike_gt, root)
    write_png(root / "gt" / "small.png", np.zeros((16, 16), np.float32), clip=False)
    out = tmp_path / "run"
    code, _, err = _run([str(root), "--manifest", str(_manifest(tmp_path, **entry)), "--methods", "tfp",
                         "--out", str(out)], capsys)
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], err
    assert not (out / "results.csv").exists() and not (out / "parts").exists()


def test_unknown_layouts_are_refused(tmp_path, spike_gt, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = _run([str(empty), "--out", str(tmp_path / "o1")], capsys)
    assert code == 2 and "unknown layout" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run([str(spike_gt), "--layout", "kitti", "--out", str(tmp_path / "o2")], capsys)
    assert code == 2 and "unknown layout 'kitti'" in err
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"manifest": 1, "layout": "kitti", "recordings": [{"name": "a", "spikes": "a.dat"}]}))
    code, _, err = _run([str(spike_gt), "--manifest", str(path), "--out", str(tmp_path / "o3")], capsys)
    assert code == 2 and "unknown layout 'kitti'" in err


def test_inferred_manifest_reads_back_equal(spike_gt, events_frames, tmp_path):
    for root in (spike_gt, events_frames):
        inferred = mf.infer_manifest(root, gain=LIGHT if root == spike_gt else None)
        path = mf.write_manifest(tmp_path / f"{root.name}.json", inferred)
        assert mf.read_manifest(path).as_dict() == inferred.as_dict()
        resolved = mf.resolve(mf.read_manifest(path), root)
        assert all(r.damaged is None and r.instants for r in resolved)


def test_help_explains_the_layouts(capsys):
    with pytest.raises(SystemExit) as exc:
        cmd.main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for word in ("spike-gt", "events-frames", "manifest.json", "no-reference", "exit status"):
        assert word in text


def test_events_frames_picks_the_file_called_events(events_frames, tmp_path):
    """The Event-Camera Dataset keeps imu.txt and groundtruth.txt beside events.txt: the one called events is read."""
    root = tmp_path / "ds"
    shutil.copytree(events_frames, root)
    (root / "imu.txt").write_text("0.0 0 0 0 0 0 0\n")
    (entry,) = mf.infer_manifest(root).recordings
    assert entry.events == "events.h5"
    (root / "events.h5").rename(root / "dvs.h5")
    with pytest.raises(mf.InputError, match="exactly one event file beside images/, found dvs.h5, imu.txt"):
        mf.infer_manifest(root)


def test_a_folder_the_layout_does_not_read_is_said_not_skipped_silently(spike_gt, tmp_path):
    root = tmp_path / "data"
    shutil.copytree(spike_gt, root)
    (root / "video").mkdir()
    (root / "notes").mkdir()
    manifest = mf.infer_manifest(root)
    assert manifest.layout == "spike-gt" and len(manifest.recordings) == 2
    said = [n for n in manifest.notes if "is not read" in n]
    assert len(said) == 2 and said[1].startswith("video/") and "neuspike.simulate --video" in said[1]
    assert said[0] == "notes/ is not read by the spike-gt layout"


@pytest.mark.parametrize("name", [".", "..", "x" * 300, "a/b", ""])
def test_a_recording_name_that_cannot_be_a_file_name_is_refused(name):
    from neuspike.errors import InputError

    with pytest.raises(InputError, match="name: expected 1 to 120 letters"):
        mf.parse_recording({"name": name, "spikes": "spike/a.dat"}, 0)
    assert mf.parse_recording({"name": "x" * 120, "spikes": "spike/a.dat"}, 0).name == "x" * 120


@pytest.mark.parametrize("key", ["gain", "plane_rate_hz"])
def test_true_is_not_a_number(key):
    from neuspike.errors import InputError

    with pytest.raises(InputError, match=f"{key}: expected a positive number, got True"):
        mf.parse_recording({"name": "a", "spikes": "spike/a.dat", key: True}, 0)


def test_a_recording_replaced_by_one_of_the_same_size_is_scored_again(spike_gt, tmp_path, capsys):
    """Identity by content: a resume recomputes a recording whose file changed but kept its byte size,
    and keeps the rows of one that did not change."""
    root = tmp_path / "ds"
    shutil.copytree(spike_gt, root)
    out = tmp_path / "run"
    args = [str(root), "--methods", "tfp", "--out", str(out)]
    code, _, err = _run(args, capsys)
    assert code == 0, err
    before = read_csv(out / "results.csv")
    dat = root / "spike" / "still.dat"
    data = bytearray(dat.read_bytes())
    data[: len(data) // 2] = bytes(b ^ 0xFF for b in data[: len(data) // 2])  # other spikes, the same size
    dat.write_bytes(bytes(data))
    code, printed, err = _run(args, capsys)
    assert code == 0, err
    assert "1 computed now" in printed  # the still recording's one instant; the pan's rows resumed
    after = read_csv(out / "results.csv")
    psnr = lambda f, name: f[(f["scene"] == name) & (f["metric"] == "psnr")]["value"].iloc[0]  # noqa: E731
    assert psnr(after, "pan") == psnr(before, "pan") and psnr(after, "still") != psnr(before, "still")


def test_a_manifest_that_asks_for_millions_of_instants_is_refused_before_any_work(spike_gt, tmp_path, capsys):
    """every_planes 1 on an event recording of a long span: refused with the count and a step that fits."""
    manifest = {"manifest": 1, "recordings": [{"name": "long", "spikes": "spike/pan.npz", "gain": LIGHT,
                                              "window_planes": 32, "instants": {"every_planes": 1}}]}
    saved, mf.MAX_INSTANTS = mf.MAX_INSTANTS, 10
    try:
        path = tmp_path / "m.json"
        path.write_text(json.dumps(manifest))
        code, _, err = _run([str(spike_gt), "--manifest", str(path), "--methods", "tfp", "--out", str(tmp_path / "o")],
                            capsys)
    finally:
        mf.MAX_INSTANTS = saved
    assert code == 2 and "asks for 65 instants" in err and "take every_planes >= 7" in err
    assert not (tmp_path / "o" / "results.csv").exists()


def test_a_corrupt_ground_truth_image_is_named_as_the_cause(spike_gt, tmp_path):
    """A .dat takes its size from its ground truth: when that image cannot be read, the error names it
    (it had said the .dat needs a size)."""
    from neuspike.errors import InputError

    root = tmp_path / "ds"
    shutil.copytree(spike_gt, root)
    (root / "gt" / "still.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match=r"gt/still.png is not a readable image.*spike/still.dat"):
        mf.infer_manifest(root)


@pytest.mark.parametrize("where", ["absolute", "dotdot", "link"])
def test_a_manifest_cannot_read_files_outside_its_dataset_unless_told(spike_gt, tmp_path, capsys, where):
    """An 'event file' such as /proc/self/environ, a path with '..' or a link out of the folder is
    refused before any work, and nothing of the file reaches the outputs; --allow-outside reads it."""
    root = tmp_path / "ds"
    shutil.copytree(spike_gt, root)
    secret = tmp_path / "secret.txt"
    secret.write_text("TOKEN=do-not-quote-me\n")
    rel = {"absolute": str(secret), "dotdot": "../secret.txt", "link": "events.txt"}[where]
    if where == "link":
        (root / "events.txt").symlink_to(secret)
    manifest = {"manifest": 1, "recordings": [{"name": "x", "events": rel}]}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(manifest))
    out = tmp_path / "o"
    code, printed, err = _run([str(root), "--manifest", str(path), "--methods", "events-integrate", "--out", str(out)],
                              capsys)
    assert code == 2 and "leads out of the dataset folder" in err and "--allow-outside" in err
    assert not (out / "results.csv").exists()
    code, printed, err = _run([str(root), "--manifest", str(path), "--methods", "events-integrate", "--out", str(out),
                               "--allow-outside", "--allow-failures"], capsys)
    written = "".join(p.read_text(errors="replace") for p in out.rglob("*") if p.is_file() and p.suffix in (".csv", ".md", ".json", ".txt"))
    assert "do-not-quote-me" not in written + printed + err  # read as asked, but never quoted


def test_a_dat_sized_by_its_ground_truth_says_so_and_names_an_ambiguous_size(spike_gt, tmp_path):
    """A headerless .dat takes its size from its ground truth: the manifest's notes say which size it was
    read at; where the file is also a whole number of the Vidar's 400x250 planes (a downsized ground
    truth of a Vidar recording), the note says so and how to read it at the sensor's size."""
    import numpy as np

    from neuspike.formats.vidar_dat import write_dat

    manifest = mf.infer_manifest(spike_gt)
    note = next(n for n in manifest.notes if n.startswith("spike/still.dat"))
    assert f"read at {W}x{H}, the size of gt/still.png" in note
    assert "Vidar" not in note  # (the file is not a whole number of 12,500-byte Vidar planes)
    root = tmp_path / "ds"
    (root / "spike").mkdir(parents=True)
    (root / "gt").mkdir()
    write_dat(root / "spike" / "v.dat", np.zeros((16, 250, 400), bool))  # 16 Vidar planes
    cv2 = pytest.importorskip("cv2")
    cv2.imwrite(str(root / "gt" / "v.png"), np.zeros((125, 200), np.uint8))  # a ground truth at half size
    note = next(n for n in mf.infer_manifest(root).notes if n.startswith("spike/v.dat"))
    assert "read at 200x125" in note and "give --height 250 --width 400" in note
