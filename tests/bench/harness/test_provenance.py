"""What a run records of its command: no absolute path of the machine that made it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from bench.harness.provenance import command_line
from neuspike.utils.jsonio import portable_path


def test_paths_inside_or_beside_the_current_folder_become_relative(tmp_path, monkeypatch):
    work = tmp_path / "repo"
    (work / "runs").mkdir(parents=True)
    monkeypatch.chdir(work)
    assert portable_path(str(work / "runs" / "light")) == os.path.join("runs", "light")
    assert portable_path(str(tmp_path / "shared" / "weights")) == os.path.join("..", "shared", "weights")
    assert portable_path("relative/as/typed") == "relative/as/typed"
    far = "/var/lib/somewhere/deep/cache"
    assert portable_path(far) == os.path.join("...", "deep", "cache")


def test_the_command_names_the_module_and_no_absolute_path(tmp_path):
    # run as `python -m` from another folder, with absolute paths as arguments
    code = ("import json, sys; from bench.harness.provenance import command_line; print(json.dumps(command_line()))")
    module = tmp_path / "probe_cmd.py"
    module.write_text(code)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[3]), str(tmp_path)])}
    out = subprocess.run([sys.executable, "-m", "probe_cmd", "--out", str(tmp_path / "runs"),
                          f"--weights={tmp_path / 'w'}", "--seeds", "0,1"],
                         capture_output=True, text=True, cwd=tmp_path, env=env, check=True).stdout
    import json

    cmd = json.loads(out)
    assert cmd == ["python", "-m", "probe_cmd", "--out", "runs", "--weights=w", "--seeds", "0,1"]
    assert not any(str(tmp_path) in part for part in cmd)


def test_a_script_run_by_path_is_named_without_its_folder(monkeypatch):
    import types

    monkeypatch.setitem(sys.modules, "__main__", types.SimpleNamespace(__spec__=None))
    assert command_line(["/abs/path/to/script.py", "--x", "1"]) == ["python", "script.py", "--x", "1"]


def test_a_sweeps_config_names_its_weights_folder_without_the_machines_path(tmp_path, monkeypatch):
    from bench.harness import grid as grids
    from bench.harness.runner import SweepSpec

    (tmp_path / "repo").mkdir()
    (tmp_path / "shared" / "weights").mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "repo")
    spec = SweepSpec(name="light", grid=grids.preset("light", full=False), methods=("tfp",),
                     weights=str(tmp_path / "shared" / "weights"), axis="light")
    assert os.path.isabs(spec.weights)  # the cells' identity keeps the resolved folder
    assert spec.as_dict()["weights"] == os.path.join("..", "shared", "weights")


def test_other_jobs_load_marks_timings_as_contended(monkeypatch):
    from bench.harness import provenance

    loads = iter([0.1, 1.2, 1.3, 2.9])  # before; then this run's one thread, then another job joins
    monkeypatch.setattr(provenance.os, "getloadavg", lambda: (next(loads), 0.0, 0.0))
    monkeypatch.setattr(provenance, "others_busy_cpus", lambda: 0)  # nothing else running at the start
    watch = provenance.LoadWatch(1)
    for _ in range(3):
        watch.read()
    summary = watch.summary()
    assert summary["other_load"] == 2.9 - 1
    assert summary["timing_contended"] is True and "other jobs" in summary["contention"][0]
    assert summary["load_1min"] == {"before": 0.1, "max": 2.9, "last": 2.9}
    quiet = iter([0.05, 0.9, 1.1])
    monkeypatch.setattr(provenance.os, "getloadavg", lambda: (next(quiet), 0.0, 0.0))
    watch = provenance.LoadWatch(1)
    watch.read()
    watch.read()
    assert watch.summary()["timing_contended"] is False  # 0.1 beyond its own thread: noise, not a job
    monkeypatch.setattr(provenance.os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    assert provenance.LoadWatch(1, side_by_side=True).summary()["timing_contended"] is True


def test_workers_times_threads_beyond_the_cpus_is_refused(tmp_path):
    import pytest

    from bench.harness import grid as grids
    from bench.harness.runner import Execution, SweepSpec, run_sweep
    from neuspike.utils.resources import usable_cpus
    from neuspike.errors import InputError

    spec = SweepSpec(name="light", grid=grids.preset("light", full=False), methods=("tfp",), axis="light")
    cpus = usable_cpus()
    with pytest.raises(InputError, match=f"--workers 2 x --threads {cpus} = {2 * cpus} threads exceed"):
        run_sweep(spec, tmp_path / "out", Execution(workers=2, threads=cpus, progress=False, report=False))
    assert not (tmp_path / "out" / "config.json").exists()


def test_more_workers_than_cpus_is_refused_with_the_default_threads(tmp_path):
    import pytest

    from bench.harness import grid as grids
    from bench.harness.runner import Execution, SweepSpec, run_sweep
    from neuspike.errors import InputError
    from neuspike.utils.resources import usable_cpus

    spec = SweepSpec(name="light", grid=grids.preset("light", full=False), methods=("tfp",), axis="light")
    workers = usable_cpus() + 1
    with pytest.raises(InputError, match=f"--workers {workers} x --threads 1 = {workers} threads exceed"):
        run_sweep(spec, tmp_path / "out", Execution(workers=workers, progress=False, report=False))
    assert not (tmp_path / "out" / "config.json").exists()


def test_a_job_running_at_the_start_marks_timings_contended_before_the_load_average_sees_it(monkeypatch):
    """The load average lags by about a minute: a job started just before the run reads as quiet
    there, but the runnable tasks counted at the start see it."""
    from bench.harness import provenance

    monkeypatch.setattr(provenance.os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    monkeypatch.setattr(provenance, "others_busy_cpus", lambda: 2)
    summary = provenance.LoadWatch(1).summary()
    assert summary["timing_contended"] is True and summary["others_busy_cpus_before"] == 2
    assert "2 CPU(s) busy" in summary["contention"][0]
    monkeypatch.setattr(provenance, "others_busy_cpus", lambda: 0)
    assert provenance.LoadWatch(1).summary()["timing_contended"] is False


def test_a_job_that_just_ended_does_not_mark_a_quiet_run_contended(monkeypatch):
    """A job that finished just before the run leaves the lagging load average high while nothing runs:
    with no runnable task at the start and the readings within the run's own threads, the run is quiet
    (the reading before is still recorded). Where something runs at the start, or the system does not
    say, the reading before counts."""
    from bench.harness import provenance

    decaying = iter([1.29, 1.4, 1.9, 1.45])  # the previous 2-thread benchmark's tail, then this run's 2 threads
    monkeypatch.setattr(provenance.os, "getloadavg", lambda: (next(decaying), 0.0, 0.0))
    monkeypatch.setattr(provenance, "others_busy_cpus", lambda: 0)
    watch = provenance.LoadWatch(2)
    for _ in range(3):
        watch.read()
    summary = watch.summary()
    assert summary["timing_contended"] is False and summary["other_load"] == 0.0
    assert summary["load_1min"] == {"before": 1.29, "max": 1.9, "last": 1.45}
    for busy in (1, None):
        monkeypatch.setattr(provenance.os, "getloadavg", lambda: (1.29, 0.0, 0.0))
        monkeypatch.setattr(provenance, "others_busy_cpus", lambda busy=busy: busy)
        summary = provenance.LoadWatch(2).summary()
        assert summary["other_load"] == 1.29 and summary["timing_contended"] is True
        assert any("load 1.29" in r for r in summary["contention"])


def test_default_threads_leave_the_cpus_other_processes_keep_busy(monkeypatch):
    """Threads per worker default to the idle usable CPUs shared by the workers (at least one), with a
    note naming the busy CPUs; where the system reports nothing, every usable CPU counts."""
    from neuspike.utils import resources

    monkeypatch.setattr(resources, "usable_cpus", lambda: 8)
    for busy, workers, expected in ((0, 1, 8), (0, 2, 4), (3, 1, 5), (3, 2, 2), (8, 1, 1), (12, 4, 1), (None, 2, 4)):
        monkeypatch.setattr(resources, "others_busy_cpus", lambda busy=busy: busy)
        threads, note = resources.default_threads(workers)
        assert threads == expected, (busy, workers)
        assert (note is not None) == bool(busy)
        if busy:  # never "12 of 8 CPUs": a load beyond the CPUs is said as such
            assert (f"{busy} of the 8 usable CPUs busy" in note) if busy < 8 else (
                f"all 8 usable CPUs (their load is {busy}) busy" in note)


def test_commands_announce_a_reduced_thread_default_on_stderr(monkeypatch, capsys):
    """The commands' shared default: the thread count, and the note with its override only when other
    processes keep CPUs busy."""
    from neuspike.utils import resources

    monkeypatch.setattr(resources, "usable_cpus", lambda: 4)
    monkeypatch.setattr(resources, "others_busy_cpus", lambda: 1)
    assert resources.announce_default_threads(1) == 3
    err = capsys.readouterr().err
    assert "1 of the 4 usable CPUs busy" in err and "(--threads overrides)" in err
    monkeypatch.setattr(resources, "others_busy_cpus", lambda: 0)
    assert resources.announce_default_threads(2) == 2
    assert capsys.readouterr().err == ""


def test_others_busy_cpus_reads_the_runnable_tasks_less_the_reader(monkeypatch, tmp_path):
    """``procs_running`` counts the process reading it: one running task means nothing else runs; the
    median of the readings ignores a one-off spike."""
    import builtins
    import io

    from neuspike.utils import resources

    values = iter([1, 3, 3, 9, 3])
    real_open = builtins.open

    def fake_open(path, *args, **kwargs):
        if str(path) == "/proc/stat":
            return io.StringIO(f"cpu  1 2 3\nprocs_running {next(values)}\nprocs_blocked 0\n")
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)
    assert resources.others_busy_cpus(readings=5, interval_s=0.0) == 2
