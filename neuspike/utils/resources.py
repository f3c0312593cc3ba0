"""Whether requested work fits this machine: memory, free disk, the file size limit, the CPUs other
processes leave idle (:func:`default_threads`); and what the machine is (:func:`cpu_model`).

Commands estimate what a job needs before starting it and refuse, in one line naming the sizes,
what cannot fit, rather than failing partway (an allocation error after minutes of work, a disk
filled with temporary files, ``OSError: File too large``).
"""

from __future__ import annotations

import os
import platform
import shutil
import sys
import time
from pathlib import Path

from neuspike.errors import InputError

__all__ = ["announce_default_threads", "available_memory_bytes", "check_disk", "check_file_size_limit", "check_memory", "cpu_model",
           "default_threads", "format_bytes", "free_cpus", "others_busy_cpus", "usable_cpus"]


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity where the system reports one), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - platforms without affinity
        return max(1, os.cpu_count() or 1)


def others_busy_cpus(readings: int = 5, interval_s: float = 0.02) -> int | None:
    """CPUs other processes keep busy now: the runnable tasks the kernel counts (``procs_running`` of
    ``/proc/stat``) less the one reading it, the median of a few readings ``interval_s`` apart.

    Unlike the load average, which lags by about a minute, this sees a job that started a moment ago.
    Threads of this process that are running count as others' (call it before starting work). ``None``
    where the system does not report it.
    """
    values = []
    for i in range(max(1, int(readings))):
        if i:
            time.sleep(interval_s)
        try:
            with open("/proc/stat") as f:
                for line in f:
                    if line.startswith("procs_running"):
                        values.append(max(0, int(line.split()[1]) - 1))
                        break
        except (OSError, ValueError, IndexError):
            return None
    if not values:
        return None
    return sorted(values)[len(values) // 2]


def free_cpus() -> tuple[int, int | None]:
    """The usable CPUs that other processes leave idle now (at least 1), and how many they keep busy
    (``None`` where unknown: then every usable CPU counts as free)."""
    usable = usable_cpus()
    busy = others_busy_cpus()
    if busy is None:
        return usable, None
    return max(1, usable - busy), busy


def default_threads(workers: int = 1) -> tuple[int, str | None]:
    """Torch threads per worker for ``workers`` workers on the CPUs other processes leave idle now
    (at least 1), and a note saying so when other processes are running (``None`` otherwise).

    Oversubscribed threads wait on each other (a 2-thread FireNet beside another job took 5.1 s per
    frame against 0.5-0.7 s with 1 thread), so the default leaves busy CPUs to their jobs.
    """
    free, busy = free_cpus()
    threads = max(1, free // max(1, int(workers)))
    note = None
    if busy:
        usable = usable_cpus()
        held = (f"{busy} of the {usable} usable CPUs" if busy < usable
                else f"all {usable} usable CPUs (their load is {busy})")
        note = (f"other processes keep {held} busy: {threads} torch thread(s)"
                + (" per worker" if workers > 1 else ""))
    return threads, note


def announce_default_threads(workers: int = 1) -> int:
    """:func:`default_threads` for a command whose ``--threads`` was not given: the thread count,
    with the note (when there is one) printed on stderr, naming ``--threads`` as the override."""
    threads, note = default_threads(workers)
    if note:
        print(f"{note} (--threads overrides)", file=sys.stderr)
    return threads


def cpu_model() -> str | None:
    """The CPU's model name (``/proc/cpuinfo``, else what the platform says; ``None`` if nothing)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None

_UNITS = ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB")


def format_bytes(n: float) -> str:
    """``6.34 TiB``: a byte count in binary units, three significant digits."""
    n = float(n)
    for unit in _UNITS:
        if abs(n) < 1024 or unit == _UNITS[-1]:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def available_memory_bytes() -> int | None:
    """Memory the system can give a new allocation without swapping (``MemAvailable``); None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes: float, what: str, detail: str = "") -> None:
    """Raise :class:`InputError` when ``nbytes`` exceed the memory available now.

    ``what`` names the work (``"the simulation"``), ``detail`` what the bytes are (``"frames 1.2 GiB, ..."``).
    """
    available = available_memory_bytes()
    if available is not None and nbytes > available:
        raise InputError(f"{what} would need about {format_bytes(nbytes)} of memory"
                         f"{f' ({detail})' if detail else ''}; {format_bytes(available)} is available")


def _existing(folder: str | os.PathLike) -> Path:
    path = Path(folder).absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def check_disk(folder: str | os.PathLike, nbytes: float, what: str, detail: str = "") -> None:
    """Raise :class:`InputError` when ``nbytes`` exceed the free space of the file system of ``folder``."""
    try:
        free = shutil.disk_usage(_existing(folder)).free
    except OSError:
        return
    if nbytes > free:
        raise InputError(f"{what} would need about {format_bytes(nbytes)} on disk"
                         f"{f' ({detail})' if detail else ''}; {format_bytes(free)} is free in {_existing(folder)}")


def check_file_size_limit(nbytes: float, what: str) -> None:
    """Raise :class:`InputError` when a file of ``nbytes`` exceeds this process's file size limit (``ulimit -f``)."""
    try:
        import resource
    except ImportError:  # not on this system
        return
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY and nbytes > soft:
        raise InputError(f"{what} would be about {format_bytes(nbytes)}, over this process's file size limit "
                         f"of {format_bytes(soft)} (ulimit -f)")
