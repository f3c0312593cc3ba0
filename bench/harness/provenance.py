"""Run metadata (``metadata.json``): what ran, where, with what, and when.

Recorded: the source commit (and whether the working tree had uncommitted changes to tracked
files), the versions of Python and of the packages that shape the numbers, the machine (host, OS,
CPU model, logical CPUs usable, memory), the executor with its worker count and the torch threads
per worker, the command line, and the start and end of every run that contributed to a results
folder (a resumed sweep appends a run). When more than one worker shares the machine, the timing
columns are marked as measured under contention (``timing_contended``): with two cores, cells
running side by side slow each other down (``null`` on a remote Dask cluster, where it depends on
how the cluster places its workers).
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
import sys
from importlib import metadata as _metadata
from pathlib import Path
from typing import Any

from neuspike.utils.jsonio import portable_path
from neuspike.utils.resources import cpu_model, others_busy_cpus, usable_cpus

#: Distributions whose versions are recorded (absent ones are recorded as ``None``).
PACKAGES = (
    "neuspike-bench", "numpy", "torch", "kornia", "scikit-image", "scipy", "opencv-contrib-python-headless",
    "pandas", "matplotlib", "h5py", "tqdm", "dask", "distributed",
)
REPO_ROOT = Path(__file__).resolve().parents[1]


def now_iso() -> str:
    """The current time, ISO 8601 with the UTC offset, to the second."""
    return _dt.datetime.now(_dt.timezone.utc).astimezone().isoformat(timespec="seconds")


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(REPO_ROOT), *args], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def source_state() -> dict[str, Any]:
    """``{"commit": sha or None, "dirty": bool or None}`` of the checkout this package runs from."""
    commit = _git("rev-parse", "HEAD")
    status = _git("status", "--porcelain", "--untracked-files=no") if commit else None
    return {"commit": commit, "dirty": None if status is None else bool(status)}


def package_versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = _metadata.version(name)
        except _metadata.PackageNotFoundError:
            out[name] = None
    return out


def _memory_bytes() -> int | None:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def machine() -> dict[str, Any]:
    usable = usable_cpus()
    return {
        "host": platform.node(),
        "system": platform.platform(),
        "machine": platform.machine(),
        "cpu_model": cpu_model(),
        "logical_cpus": os.cpu_count(),
        "usable_cpus": usable,
        "memory_bytes": _memory_bytes(),
        "gpus": _gpu_names(),
    }


def _gpu_names() -> list[str]:
    """The CUDA devices torch sees, by name (empty without one, or without torch imported)."""
    torch = sys.modules.get("torch")  # only a command that runs networks has imported it; importing costs seconds
    try:
        if torch is None or not torch.cuda.is_available():
            return []
        return [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
    except Exception:  # a broken driver must not stop the run that records it
        return []


def command_line(argv: list[str] | None = None) -> list[str]:
    """The command that started this process, without the machine's paths: ``python -m MODULE`` and
    the arguments, absolute paths among them (also in ``--opt=PATH``) made portable (:func:`portable_path`)."""
    argv = list(sys.argv if argv is None else argv)
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None and spec.name:
        head = ["python", "-m", spec.name.removesuffix(".__main__")]
    else:
        head = ["python", Path(argv[0]).name] if argv else ["python"]

    def portable(arg: str) -> str:
        name, eq, value = arg.partition("=")
        if eq and name.startswith("--") and os.path.isabs(value):
            return f"{name}={portable_path(value)}"
        return portable_path(arg) if os.path.isabs(arg) else arg

    return head + [portable(a) for a in argv[1:]]


#: Load of other jobs (1-minute load average beyond this run's own threads) from which timings are
#: marked as contended: half a core busy with something else.
OTHER_LOAD_CONTENDED = 0.5


def load_1min() -> float | None:
    """The 1-minute load average, or None where the system does not report it."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


class LoadWatch:
    """The machine's load around a run, and whether other jobs shared it.

    The 1-minute load average is read before the work starts (everything in it is other jobs) and
    after each finished piece of work, where up to ``own_threads`` of it is this run's own. A run is
    contended when its cells ran side by side (``side_by_side``) or when other jobs' load reached
    :data:`OTHER_LOAD_CONTENDED` at any reading (the average lags by about a minute, so a job that
    starts late in a short run may be missed; the readings are recorded), or when other processes
    were running at the start (:func:`~neuspike.utils.resources.others_busy_cpus`, which sees a job
    the average has not caught up with yet).

    The same lag works the other way: a job that ended just before the run (the previous benchmark of
    a series) leaves the average high for a minute while nothing else runs. So the reading before the
    start counts as other jobs' load only where something is running at the start (or where the
    system does not say); the readings during the run count either way, and every reading is recorded.
    """

    def __init__(self, own_threads: int, *, side_by_side: bool = False) -> None:
        self.own_threads = int(own_threads)
        self.side_by_side = bool(side_by_side)
        self.before = load_1min()
        # what runs right now: the load average misses a job that started within the last minute
        self.busy_before = others_busy_cpus()
        self.readings: list[float] = []

    def read(self) -> None:
        value = load_1min()
        if value is not None:
            self.readings.append(value)

    def other_load(self) -> float | None:
        """The largest load of other jobs seen: before the run (where something was running at its start),
        or beyond this run's threads during it."""
        if self.before is None:
            return None
        before = self.before if self.busy_before is None or self.busy_before > 0 else 0.0
        return max([before] + [max(0.0, r - self.own_threads) for r in self.readings])

    def summary(self) -> dict[str, Any]:
        """``load_1min`` (before, max, last), ``other_load``, ``timing_contended`` and its reasons."""
        other = self.other_load()
        reasons = []
        if self.side_by_side:
            reasons.append("cells ran side by side in several workers")
        if other is not None and other >= OTHER_LOAD_CONTENDED:
            reasons.append(f"other jobs loaded the machine (load {other:.2f} beyond this run's "
                           f"{self.own_threads} thread(s))")
        if self.busy_before:
            reasons.append(f"other processes kept {self.busy_before} CPU(s) busy when it started")
        return {
            "load_1min": {"before": self.before, "max": max(self.readings, default=None),
                          "last": self.readings[-1] if self.readings else None},
            "other_load": other,
            "others_busy_cpus_before": self.busy_before,
            "timing_contended": (bool(reasons) if other is not None or self.side_by_side or self.busy_before is not None
                                 else None),
            "contention": reasons,
        }


def collect(*, executor: dict[str, Any], threads_per_worker: int | None, start: str,
            contended: bool | None) -> dict[str, Any]:
    """Metadata of a run that starts now (``end`` is filled by :func:`finish`).

    ``contended``: whether cells run side by side on this machine (``None`` when unknown, e.g. on
    a remote Dask cluster).
    """
    return {
        "source": source_state(),
        "versions": package_versions(),
        "machine": machine(),
        "command": command_line(),
        "executor": executor,
        "threads_per_worker": threads_per_worker,
        "timing_contended": contended,
        "start": start,
        "end": None,
    }


def finish(run: dict[str, Any], **fields: Any) -> dict[str, Any]:
    """``run`` with its end time and ``fields`` (counts, observed threads) added."""
    return {**run, **fields, "end": now_iso()}
