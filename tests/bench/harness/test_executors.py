"""Executors: worker processes do not outlive the sweep that started them; a bad scheduler address is refused."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from bench.harness.executors import PARENT_CHECK_S

REPO = Path(__file__).resolve().parents[3]

SCRIPT = textwrap.dedent('''
    import os, sys, time
    from pathlib import Path

    def task(folder):
        (Path(folder) / f"worker-{os.getpid()}").write_text("")
        time.sleep(120)  # a long cell
        return os.getpid()

    if __name__ == "__main__":
        from bench.harness.executors import LocalExecutor
        with LocalExecutor(2) as ex:
            for _ in ex.run(task, [sys.argv[1]] * 2):
                pass
''')


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "\nState:\tZ" not in state  # a zombie has exited; only its parent has not reaped it


def test_workers_exit_when_the_main_process_is_killed(tmp_path):
    script = tmp_path / "sweep_like.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    main = subprocess.Popen([sys.executable, str(script), str(tmp_path)], cwd=tmp_path, env=env)
    try:
        deadline = time.monotonic() + 120
        while len(list(tmp_path.glob("worker-*"))) < 2:
            assert main.poll() is None, "the main process ended early"
            assert time.monotonic() < deadline, "the workers never started"
            time.sleep(0.05)
        workers = [int(p.name.split("-")[1]) for p in tmp_path.glob("worker-*")]
        assert all(_alive(pid) for pid in workers)
        main.send_signal(signal.SIGKILL)
        main.wait(10)
        killed = time.monotonic()
        while any(_alive(pid) for pid in workers) and time.monotonic() - killed < 5 + 4 * PARENT_CHECK_S:
            time.sleep(0.05)
        survivors = [pid for pid in workers if _alive(pid)]
        assert not survivors, f"workers {survivors} outlived the main process by {time.monotonic() - killed:.1f} s"
    finally:
        if main.poll() is None:
            main.kill()
        for p in tmp_path.glob("worker-*"):
            try:
                os.kill(int(p.name.split("-")[1]), signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_a_scheduler_address_that_is_not_one_is_refused_in_one_line_before_any_work(tmp_path, capsys):
    from bench.harness.executors import check_scheduler_address
    from bench.sweep import main
    from neuspike.errors import InputError

    for good in ("tcp://10.0.0.5:8786", "localhost:8786", "tls://[::1]:8786"):
        assert check_scheduler_address(good) == good
    for bad in ("not an address", "tcp://host", "host:port", ""):
        with pytest.raises(InputError, match="--scheduler"):
            check_scheduler_address(bad)
    out = tmp_path / "run"
    assert main(["--executor", "dask", "--scheduler", "not an address", "--methods", "tfp", "--lights", "1/4",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --scheduler") and not out.exists()
