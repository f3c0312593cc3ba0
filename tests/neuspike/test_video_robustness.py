"""``python -m neuspike.video`` under kills, file size limits and recordings too small to score.

The output folder is staged whole (:func:`neuspike.formats.staging.staged_folder`): after a kill or
a failed write it is entirely the old run's; a written video is checked to read back whole.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from neuspike.formats.vidar_dat import write_dat
from neuspike.video.cli import main

H, W = 24, 32
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def finished(tmp_path):
    """A .dat recording and a finished video folder made from it (tfp, frames as PNG)."""
    rng = np.random.default_rng(5)
    planes = rng.random((400, H, W)) < np.linspace(0.05, 0.6, W)[None, None, :]
    write_dat(tmp_path / "spikes.dat", planes)
    out = tmp_path / "out"
    args = ["--spikes", str(tmp_path / "spikes.dat"), "--height", str(H), "--width", str(W), "--fps", "1000",
            "--no-progress", "--out", str(out)]
    assert main(args + ["--method", "tfp"]) == 0
    return args, out, _snapshot(out)


def _snapshot(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (hidden ones included) and the sha256 of its bytes."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _child(script: str, *, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(script)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_a_kill_during_a_rerun_leaves_the_old_folder_whole(finished, tmp_path):
    args, out, before = finished
    marker = tmp_path / "started"
    child = _child(f"""
        import sys, time
        import numpy as np
        from neuspike.methods import Method, register
        from neuspike.video.cli import main

        class Slow(Method):
            inputs = frozenset({{"spikes"}})
            def _reconstruct(self, sample):
                open({str(marker)!r}, "w").close()
                time.sleep(0.2)
                return np.zeros((sample.height, sample.width), np.float32), "none"

        register("zz-slow", Slow)
        sys.exit(main({args!r} + ["--method", "tfp,zz-slow"]))
    """, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not marker.exists():
            assert child.poll() is None, child.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        time.sleep(0.5)  # several frames into the rerun: new videos and frames are being written
        staged = [p for p in out.parent.glob(f".{out.name}.*.staging") if any(p.rglob("*"))]
        assert staged, "the rerun had not started writing: the kill would test nothing"
        child.send_signal(signal.SIGKILL)
    finally:
        child.communicate()
    assert _snapshot(out) == before  # entirely old: no new tfp.mp4 beside the old frames
    # the next run clears what the killed one left beside the folder and publishes a whole new folder
    assert main(args + ["--method", "tfp,tfi"]) == 0
    assert {"tfp.mp4", "tfi.mp4", "video.json", "compare.mp4"} <= set(_snapshot(out))
    assert not list(tmp_path.glob(".out.*"))
    # nothing the killed run was writing is carried into the new folder
    assert not [p for p in out.rglob("*") if ".partial" in p.name or p.name.endswith(".tmp")]


def test_a_killed_runs_partial_files_are_its_own_not_the_users():
    """The staging's carry keeps a user's files in --out and drops any killed run's temporaries."""
    from neuspike.formats.staging import _is_ours

    ours = frozenset({"tfp", "tfp.mp4", "video.json"})
    for name in (".tfp.partial.mp4", ".tfp.partial", ".video.json.1a2b.tmp", "tfp.mp4",
                 ".other.partial.mp4", ".other.mp4.x9y8.tmp"):  # a killed run's, whatever it wrote
        assert _is_ours(name, ours), name
    for name in ("notes.txt", ".hidden", "other.mp4", "partial_results.csv"):
        assert not _is_ours(name, ours), name


def test_a_file_size_limit_fails_in_one_line_and_keeps_the_old_folder(finished, tmp_path):
    args, out, before = finished
    rerun = ["--method", "tfp,tfi", "--frames", "none"]
    # the same rerun without a limit, elsewhere: a limit that only compare.mp4 (the largest file) passes,
    # which OpenCV's writer would otherwise truncate silently
    ref = tmp_path / "ref"
    assert main([a if a != str(out) else str(ref) for a in args] + rerun) == 0
    sizes = sorted((p.stat().st_size, p.name) for p in ref.iterdir())
    assert sizes[-1][1] == "compare.mp4", sizes
    limit = (sizes[-1][0] + sizes[-2][0]) // 2
    child = _child(f"""
        import resource, signal, sys
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
        from neuspike.video.cli import main
        sys.exit(main({args!r} + {rerun!r}))
    """, cwd=tmp_path)
    stdout, stderr = child.communicate(timeout=300)
    assert child.returncode == 2, (stdout, stderr)
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    assert f"{out / 'compare.mp4'}: the video was not written completely" in lines[0], lines[0]
    assert _snapshot(out) == before
    assert not list(tmp_path.glob(".out.*"))


def test_a_truncated_video_is_refused_not_published(tmp_path, monkeypatch):
    """The check behind the file size limit: a video cut short is never published."""
    from neuspike.errors import SourceError
    from neuspike.video import writers

    writer = writers.Mp4Writer(tmp_path / "v.mp4", fps=25, width=W, height=H)
    for k in range(20):
        writer.write(np.full((H, W), 10 * k, np.uint8))
    writer._writer.release()  # the whole file, then cut short as a full disk would
    data = writer.tmp.read_bytes()
    assert writers.mp4_complete(writer.tmp)
    writer.tmp.write_bytes(data[: len(data) - 50])
    assert not writers.mp4_complete(writer.tmp)
    monkeypatch.setattr(writer, "_writer", _Released())
    with pytest.raises(SourceError, match=r"v\.mp4: the video was not written completely \(20 frames"):
        writer.close()
    assert list(tmp_path.iterdir()) == []


class _Released:
    def release(self):
        pass


def test_a_recording_smaller_than_the_ssim_window_is_written_without_scores(tmp_path, capsys):
    from neuspike.simulate import main as simulate_main

    assert simulate_main(["--size", "8x8", "--out", str(tmp_path / "sim")]) == 0
    capsys.readouterr()
    assert main([str(tmp_path / "sim"), "--method", "tfp", "--out", str(tmp_path / "v"), "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "not used: 8x8 is smaller than the 11x11 SSIM window" in captured.out
    assert "error" not in captured.err
    assert (tmp_path / "v" / "tfp.mp4").is_file() and not (tmp_path / "v" / "metrics.csv").exists()


def test_a_rerun_replaces_the_earlier_runs_outputs_and_keeps_other_files(finished):
    args, out, before = finished
    assert main(args + ["--method", "tfp,tfi"]) == 0
    (out / "notes.txt").write_text("mine")
    assert main(args + ["--method", "tfi"]) == 0
    names = {p.name for p in out.iterdir()}
    assert "tfp.mp4" not in names and "tfp" not in names  # no video of a method this run did not make
    assert {"tfi.mp4", "tfi", "video.json", "notes.txt"} <= names and (out / "notes.txt").read_text() == "mine"
