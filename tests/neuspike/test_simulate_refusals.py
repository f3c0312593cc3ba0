"""The simulate command refuses, before any work, what cannot be done or cannot fit; leftovers of killed runs never ship."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

import neuspike.simulation.window as window_module
from neuspike.conditions import parse_effects
from neuspike.errors import InputError
from neuspike.simulate import main

REPO = Path(__file__).resolve().parents[2]
SMALL = ["--size", "48x32", "--motion", "64"]


@pytest.fixture
def no_simulation(monkeypatch):
    """Any simulation started fails the test: refusals come before any work."""
    def forbidden(*args, **kwargs):
        raise AssertionError("the simulation started")

    monkeypatch.setattr(window_module, "simulate_window", forbidden)
    import neuspike.simulation.cell as cell
    import neuspike.simulation.writing as writing

    monkeypatch.setattr(cell, "simulate_window", forbidden)

    monkeypatch.setattr(writing, "simulate_sequence", forbidden)


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


@pytest.mark.parametrize("argv, expected", [
    (["--effects", "shot_noise:rate_hz=1e12"], r"would need about [\d.]+ PiB of memory \(noise events"),
    (["--size", "100000x100000"], r"would need about [\d.]+ TiB of memory \(frames [\d.]+ TiB"),
    (["--history", "1e4"], r"would need about [\d.]+ TiB of memory \(frames"),
    (["--mode", "continuous", "--duration", "1e9"], r"would need about [\d.]+ PiB on disk \(spikes.dat [\d.]+ PiB"),
    (["--mode", "continuous", "--size", "64x48", "--duration", "100", "--effects", "leak:rate_hz=1e6"],
     r"on disk \(events.h5 [\d.]+ TiB"),
])
def test_work_that_cannot_fit_is_refused_naming_its_size(tmp_path, capsys, no_simulation, argv, expected):
    out = tmp_path / "rec"
    assert main([*argv, "--out", str(out)]) == 2
    line = _one_line_error(capsys)
    assert pytest.importorskip("re").search(expected, line), line
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("text, expected", [
    ("leak,leak", "'leak' is declared twice"),
    ("shot_noise:rate_hz=5;shot_noise:rate_hz=7", "'shot_noise' is declared twice"),
    ("refractory:period_s=1e-3,period_s=2e-3", "period_s is given twice"),
    (",,", "an empty entry"),
    ("leak,,refractory", "an empty entry"),
    ("leak;", "an empty entry"),
])
def test_repeated_or_empty_effects_are_refused(tmp_path, capsys, no_simulation, text, expected):
    with pytest.raises(InputError, match=expected):
        parse_effects(text)
    assert main([*SMALL, "--effects", text, "--out", str(tmp_path / "rec")]) == 2
    assert expected in _one_line_error(capsys)
    assert parse_effects("leak;refractory") == parse_effects("leak,refractory")  # both separators still work


def test_an_existing_folder_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys, no_simulation,
                                                                               monkeypatch):
    out = tmp_path / "rec"
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    real = tempfile.mkstemp

    def read_only(*args, dir=None, **kwargs):  # as a read-only folder answers (the tests may run as root)
        if dir is not None and Path(dir) == out:
            raise PermissionError(13, "Permission denied")
        return real(*args, dir=dir, **kwargs)

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    assert main([*SMALL, "--out", str(out)]) == 2
    line = _one_line_error(capsys)
    assert f"--out {out}: cannot write there (Permission denied)" in line
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_is_refused_before_any_work(tmp_path, capsys, no_simulation):
    out = tmp_path / "rec"
    out.mkdir()
    out.chmod(0o555)
    try:
        assert main([*SMALL, "--out", str(out)]) == 2
        assert "cannot write there" in _one_line_error(capsys)
    finally:
        out.chmod(0o755)


# ----------------------------------------------------------------------------------------------
# The file size limit (ulimit -f), in a subprocess that ignores SIGXFSZ as a shell's ulimit may not
# ----------------------------------------------------------------------------------------------

LIMITED = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, resource.RLIM_INFINITY))
from neuspike.simulate import main
sys.exit(main(sys.argv[1:]))
"""


def _limited(limit: int, out: Path, *extra: str) -> subprocess.CompletedProcess:
    """The command under a file size limit of ``limit`` bytes."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-c", LIMITED.format(limit=limit), *SMALL, "--out", str(out), *extra],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)


def test_a_file_over_the_size_limit_is_refused_before_any_work(tmp_path):
    out = tmp_path / "rec"
    done = _limited(50_000, out, "--modalities", "spikes")  # spikes.dat: 48 x 32 x 256 / 8 = 49,152 bytes
    assert done.returncode == 0, done.stderr
    done = _limited(40_000, tmp_path / "small")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "spikes.dat" in lines[0] and "48 KiB" in lines[0] and "ulimit -f" in lines[0]
    assert not (tmp_path / "small").exists()
    assert not list(tmp_path.glob(".*"))


@pytest.mark.parametrize("mode, limit", [("window", 50_000), ("continuous", 250_000)])
def test_a_file_that_would_outgrow_the_limit_stops_the_run_in_one_line_and_leaves_the_old_folder(tmp_path, mode,
                                                                                                  limit):
    """The size of events.h5 is known only once simulated: it is checked before each write, never hit partway."""
    out = tmp_path / "rec"
    argv = ["--mode", mode] + (["--duration", "0.05", "--no-progress"] if mode == "continuous" else [])
    first = _limited(10 ** 9, out, "--seed", "1", *argv)
    assert first.returncode == 0, first.stderr
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert (out / "events.h5").stat().st_size > limit and (out / "spikes.dat").stat().st_size < limit
    done = _limited(limit, out, "--seed", "2", *argv)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "events.h5" in lines[0] and "file size limit" in lines[0], lines
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before  # entirely the old recording
    assert not list(tmp_path.glob(".*")) and not list(out.glob(".*"))


# ----------------------------------------------------------------------------------------------
# Leftovers of a killed run
# ----------------------------------------------------------------------------------------------

def test_leftovers_of_a_killed_run_are_removed_and_never_shipped(tmp_path, capsys):
    out = tmp_path / "rec"
    assert main([*SMALL, "--out", str(out)]) == 0
    (out / "notes.txt").write_text("the user's own")
    # what a run killed while writing leaves: its staging folder with temporaries, and (from earlier
    # versions, which carried them over) temporaries inside the folder itself
    staging = tmp_path / ".rec.0123456789ab.staging"
    staging.mkdir()
    for name in (".spikes.dat.k3j2x.tmp", ".events.h5.ab12c.tmp", "gt.png"):
        (staging / name).write_bytes(b"half")
    (out / ".spikes.dat.zzz.tmp").write_bytes(b"half")
    (out / ".meta.json.q1.tmp").write_bytes(b"half")
    assert main([*SMALL, "--seed", "3", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["events.h5", "gt.npy", "gt.png", "meta.json", "notes.txt",
                                                     "spikes.dat"]
    assert json.loads((out / "meta.json").read_text())["seed"] == 3
    assert (out / "gt.png").read_bytes() != b"half"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def test_a_simulation_killed_while_writing_leaves_no_temporary_in_the_next_run(tmp_path):
    out = tmp_path / "rec"
    assert main([*SMALL, "--out", str(out)]) == 0  # a finished recording, which the killed run was replacing
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "neuspike.simulate", "--mode", "continuous", "--size", "64x48", "--duration", "0.2",
           "--noise", "medium", "--no-progress", "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.perf_counter() + 120
    while time.perf_counter() < deadline and proc.poll() is None:
        if any(p.name.endswith(".tmp") for s in tmp_path.glob(".rec.*.staging") for p in s.iterdir()):
            break
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait(60)
    leftovers = [p.name for s in tmp_path.glob(".rec.*.staging") for p in s.iterdir()]
    assert any(name.endswith(".tmp") for name in leftovers), leftovers  # the case of the test happened
    assert main([*SMALL, "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["events.h5", "gt.npy", "gt.png", "meta.json", "spikes.dat"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


# ----------------------------------------------------------------------------------------------
# Answers at once
# ----------------------------------------------------------------------------------------------

def test_help_and_usage_errors_do_not_load_the_simulator():
    code = ("import sys\n"
            "from neuspike.simulate import main\n"
            "for argv in (['--help'], ['--light', 'x', '--out', 'o'], ['--effects', ',,', '--out', 'o']):\n"
            "    try:\n"
            "        main(argv)\n"
            "    except SystemExit:\n"
            "        pass\n"
            "heavy = sorted(m for m in ('torch', 'cv2', 'numba', 'h5py', 'kornia', 'neuspike.scenes',\n"
            "               'neuspike.sensors') if m in sys.modules)\n"
            "print('heavy:' + ','.join(heavy))\n")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "heavy:", f"imported before the arguments were checked: {done.stdout}"


def test_a_sweep_too_large_for_memory_is_refused_before_any_cell(tmp_path, capsys, no_simulation):
    from bench.sweep import main as sweep_main

    rc = sweep_main(["--axis", "light", "--lights", "1/4", "--size", "100000x100000", "--scenes", "pan:camera",
                     "--methods", "tfp-w32", "--no-progress", "--no-report", "--out", str(tmp_path / "sweep")])
    assert rc == 2
    stderr = capsys.readouterr().err
    err = [line for line in stderr.strip().splitlines() if line.startswith("error")]
    assert "Traceback" not in stderr
    assert len(err) == 1 and "at 100000x100000 would need about" in err[0] and "TiB of memory" in err[0], err
    assert not (tmp_path / "sweep" / "results.csv").exists()


@pytest.mark.parametrize("effects, modalities, message", [
    ("leak:rate_hz=1000", "spikes", "leak (event camera) would not run: --modalities spikes"),
    ("dark_current", "events", "dark_current (spike camera) would not run: --modalities events"),
    ("", "spikes,events", "--effects: empty"),
    ("  ", "spikes", "--effects: empty"),
])
def test_an_effect_no_requested_camera_runs_is_refused(tmp_path, capsys, no_simulation, effects, modalities, message):
    """Simulate only the effects a scene calls for, and say so: a declared stage that would do nothing."""
    out = tmp_path / "rec"
    assert main([*SMALL, "--effects", effects, "--modalities", modalities, "--out", str(out)]) == 2
    assert message in _one_line_error(capsys)
    assert not out.exists()
