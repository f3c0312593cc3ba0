"""Output folders change in one step: entirely old or entirely new, even when the writer is killed."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.formats.staging import check_writable_folder, remove_stale_temporaries, staged_folder

OURS = ("a.bin", "meta.json")
REPO = Path(__file__).resolve().parents[3]


def _write_run(folder: Path, tag: str) -> None:
    (folder / "a.bin").write_text(tag)
    (folder / "meta.json").write_text(tag)


def test_a_staged_folder_replaces_ours_and_keeps_the_users_files(tmp_path):
    out = tmp_path / "rec"
    with staged_folder(out, ours=OURS) as staging:
        _write_run(staging, "old")
    (out / "notes.txt").write_text("mine")
    with staged_folder(out, ours=OURS) as staging:
        (staging / "meta.json").write_text("new")  # the new run writes no a.bin
    assert sorted(p.name for p in out.iterdir()) == ["meta.json", "notes.txt"]
    assert (out / "meta.json").read_text() == "new" and (out / "notes.txt").read_text() == "mine"
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]  # no staging folder left


def test_a_failed_run_leaves_the_folder_as_it_was(tmp_path):
    out = tmp_path / "rec"
    with staged_folder(out, ours=OURS) as staging:
        _write_run(staging, "old")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(RuntimeError, match="disk on fire"):
        with staged_folder(out, ours=OURS) as staging:
            _write_run(staging, "new")
            raise RuntimeError("disk on fire")
    assert {p.name: p.read_text() for p in out.iterdir()} == {"a.bin": "old", "meta.json": "old", "notes.txt": "mine"}
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]


def test_a_killed_runs_staging_folder_is_cleaned_and_its_carried_files_given_back(tmp_path):
    out = tmp_path / "rec"
    with staged_folder(out, ours=OURS) as staging:
        _write_run(staging, "old")
    # what a run killed while carrying the user's files over leaves behind
    stale = tmp_path / ".rec.0123456789ab.staging"
    stale.mkdir()
    _write_run(stale, "half")
    (stale / "notes.txt").write_text("mine")
    with staged_folder(out, ours=OURS) as staging:
        _write_run(staging, "new")
    assert {p.name: p.read_text() for p in out.iterdir()} == {"a.bin": "new", "meta.json": "new", "notes.txt": "mine"}
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]


def test_unwritable_output_folders_are_one_line_input_errors(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="exists and is not a folder"):
        check_writable_folder(tmp_path / "file")
    with pytest.raises(InputError, match=r"cannot write there \(Not a directory\)"):
        check_writable_folder(tmp_path / "file" / "sub")
    with pytest.raises(InputError, match=r"file is not a folder"):
        check_writable_folder(tmp_path / "file" / "sub", create=False)
    assert check_writable_folder(tmp_path / "later" / "deeper", create=False) == tmp_path / "later" / "deeper"
    assert not (tmp_path / "later").exists()
    assert check_writable_folder(tmp_path / "new" / "deeper").is_dir()
    assert list((tmp_path / "new" / "deeper").iterdir()) == []  # the probe file is gone


def test_stale_temporaries_are_removed(tmp_path):
    for name in (".x.png.k3j2.tmp", ".results.csv.abc.tmp", "keep.tmp", "x.png"):
        (tmp_path / name).write_text("")
    assert remove_stale_temporaries(tmp_path) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.tmp", "x.png"]


# --------------------------------------------------------------------------- the simulate command, killed
def _simulate(out: Path, seed: int) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "neuspike.simulate", "--mode", "continuous", "--size", "64x48",
           "--duration", "0.06", "--seed", str(seed), "--noise", "medium", "--no-progress", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _state(folder: Path) -> tuple:
    """What identifies a run's output: the bytes of its data files and its meta.json's counts."""
    if not (folder / "meta.json").is_file():
        return ("no meta.json", sorted(p.name for p in folder.iterdir()) if folder.is_dir() else None)
    meta = json.loads((folder / "meta.json").read_text())
    digest = {name: hashlib.sha256((folder / name).read_bytes()).hexdigest()
              for name in ("spikes.dat", "frames/timestamps.txt") if (folder / name).is_file()}
    frames = sorted(p.name for p in (folder / "frames").iterdir()) if (folder / "frames").is_dir() else []
    return (meta["seed"], meta.get("spike_count"), meta.get("event_count"), digest, frames,
            (folder / "events.h5").is_file())


def _stagings(out: Path) -> set[str]:
    return {p.name for p in out.parent.glob(f".{out.name}.*.staging")}


def _writing_started(out: Path, proc: subprocess.Popen, before: set[str], timeout_s: float = 120.0) -> float:
    """Wait until the run creates a new staging folder beside ``out``; return that instant."""
    end = time.perf_counter() + timeout_s
    while time.perf_counter() < end and proc.poll() is None:
        if _stagings(out) - before:
            return time.perf_counter()
        time.sleep(0.005)
    raise AssertionError(f"the run never started writing (status {proc.poll()})")


def test_a_killed_simulation_leaves_the_folder_entirely_old_or_entirely_new(tmp_path):
    out, ref = tmp_path / "rec", tmp_path / "ref"
    old = _simulate(out, seed=1)
    new = _simulate(ref, seed=2)
    started = _writing_started(ref, new, set())
    assert new.wait(120) == 0 and old.wait(120) == 0, new.stderr.read().decode()
    write_s = time.perf_counter() - started  # simulating and writing, after the imports
    states = {"old": _state(out), "new": _state(ref)}
    assert states["old"] != states["new"]
    (out / "notes.txt").write_text("the user's own file")
    # kill at random instants while the new run simulates and writes, up to just after it finished
    for delay in np.random.default_rng(13).uniform(0.0, 1.1, 2) * write_s:
        before = _stagings(out)  # a killed run's staging folder stays until the next run finishes
        proc = _simulate(out, seed=2)
        time.sleep(max(0.0, _writing_started(out, proc, before) + delay - time.perf_counter()))
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        now = _state(out)
        assert now in (states["old"], states["new"]), f"killed {delay:.2f} s into writing: a mixed folder {now}"
        assert (out / "notes.txt").read_text() == "the user's own file"
    done = _simulate(out, seed=2)
    assert done.wait(120) == 0
    assert _state(out) == states["new"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec", "ref"]  # the killed runs' leftovers are gone
    assert not list(out.rglob("*.tmp"))


# --------------------------------------------------------------------------- commands refuse before working
def test_commands_report_an_unwritable_out_in_one_line_before_any_work(tmp_path, capsys):
    from neuspike import reconstruct, simulate
    from neuspike.formats import write_spike_npz
    from neuspike.streams import SpikeStream

    (tmp_path / "file").write_text("x")
    bad = str(tmp_path / "file" / "out")
    assert simulate.main(["--size", "48x32", "--motion", "16", "--no-progress", "--out", bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --out") and "not a folder" in err[0]

    spikes = write_spike_npz(tmp_path / "s.npz", SpikeStream(np.zeros((8, 16, 16), bool), gain=0.25))
    assert reconstruct.main(["--method", "tfp-w8", "--spikes", str(spikes), "--out", bad]) == 2
    captured = capsys.readouterr()
    assert "sample:" not in captured.out  # nothing was loaded or computed
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --out") and "is not a folder" in err[0]
    assert not (tmp_path / "nothing").exists()
    assert reconstruct.main(["--method", "no-such-method", "--spikes", str(spikes),
                             "--out", str(tmp_path / "nothing" / "o")]) == 2
    assert not (tmp_path / "nothing").exists()  # a failed command creates no folder


def test_a_ground_truth_below_the_ssim_window_is_refused_before_any_method_runs(tmp_path):
    from neuspike.formats import write_spike_npz
    from neuspike.formats.samples import load_sample
    from neuspike.streams import SpikeStream

    spikes = write_spike_npz(tmp_path / "s.npz", SpikeStream(np.zeros((8, 8, 10), bool), gain=0.25))
    np.save(tmp_path / "truth.npy", np.zeros((8, 10), np.float32))
    with pytest.raises(InputError, match=r"10x8 is smaller than the 11x11 SSIM window"):
        load_sample(spikes=spikes, gt=tmp_path / "truth.npy")
    assert load_sample(spikes=spikes).ground_truth is None


def test_a_linked_output_folder_is_replaced_behind_its_link(tmp_path):
    real = tmp_path / "real"
    with staged_folder(real, ours=OURS) as staging:
        _write_run(staging, "old")
    (tmp_path / "link").symlink_to(real)
    with staged_folder(tmp_path / "link", ours=OURS) as staging:
        _write_run(staging, "new")
    assert (tmp_path / "link").is_symlink() and (real / "a.bin").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]
