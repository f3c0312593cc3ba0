"""Where cells run: in this process, in local worker processes, or on a Dask cluster.

Every executor runs the same function (:func:`bench.harness.cells.run_cell`) on the same tasks and yields
``(task, result)`` pairs as they complete, where ``result`` is a
:class:`~bench.harness.cells.CellResult` or, when the infrastructure failed (a worker process died, a Dask
worker was lost), the exception. Results never depend on the executor: each cell is a pure function
of its task. Only the timing columns do, and running cells in parallel on few cores slows each one
down (the sweep records the executor, the worker count and the threads in ``metadata.json``).

``local``
    ``workers == 1``: cells run one after another in this process (methods registered in-process
    are visible). ``workers > 1``: a :class:`concurrent.futures.ProcessPoolExecutor` with the
    ``spawn`` start method (safe with torch's thread pools); workers import plug-ins themselves.
    Each worker watches its parent and exits within :data:`PARENT_CHECK_S` seconds of the parent's
    death (a killed sweep leaves no orphaned workers computing for nobody).
``dask``
    ``scheduler`` given: connect to that Dask scheduler (``tcp://host:8786``); the workers need
    this package installed, and plug-ins importable or given as paths they can read. No
    scheduler: a ``distributed.LocalCluster`` of ``workers`` processes with one thread each.
    Dask is an optional extra: ``pip install 'neuspike-bench[dask]'``.
"""

from __future__ import annotations

import re

import multiprocessing
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterable, Iterator

from neuspike.utils.checks import check_positive_int
from neuspike.errors import InputError

EXECUTORS = ("local", "dask")
#: Seconds between a worker's checks that its parent is still alive.
PARENT_CHECK_S = 0.5


def _exit_with_parent(parent_pid: int) -> None:
    """Worker initializer: a daemon thread ends this process once ``parent_pid`` is gone.

    When the parent dies its children are adopted by another process, so the parent id changes.
    """

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_CHECK_S)
        os._exit(70)  # no cleanup: the results would go nowhere

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


class LocalExecutor:
    """Cells in this process (``workers == 1``) or in ``workers`` spawned processes."""

    name = "local"

    def __init__(self, workers: int = 1) -> None:
        self.workers = check_positive_int("workers", workers)
        self._pool: ProcessPoolExecutor | None = None

    def describe(self) -> dict[str, Any]:
        return {"executor": self.name, "workers": self.workers,
                "mode": "in-process" if self.workers == 1 else "process pool (spawn)"}

    def __enter__(self) -> "LocalExecutor":
        if self.workers > 1:
            self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_exit_with_parent, initargs=(os.getpid(),))
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def run(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        tasks = list(tasks)
        if self._pool is None:
            for task in tasks:
                try:
                    yield task, fn(task)
                except Exception as exc:  # run_cell catches method failures; this is a defect
                    yield task, exc
            return
        futures = {self._pool.submit(fn, task): task for task in tasks}
        try:
            for future in as_completed(futures):
                exc = future.exception()
                yield futures[future], (exc if exc is not None else future.result())
        finally:
            for future in futures:
                future.cancel()


class DaskExecutor:
    """Cells on a Dask cluster: an existing one (``scheduler``) or a local one."""

    name = "dask"

    def __init__(self, scheduler: str | None = None, workers: int = 1, processes: bool = True) -> None:
        self.scheduler = scheduler
        self.workers = check_positive_int("workers", workers)
        self.processes = processes
        self._client = None
        self._cluster = None

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"executor": self.name, "scheduler": self.scheduler}
        if self.scheduler is None:
            out.update(workers=self.workers, mode="LocalCluster", processes=self.processes)
        elif self._client is not None:
            try:
                out["workers"] = len(self._client.scheduler_info().get("workers", {}))
            except Exception:  # information only
                pass
        return out

    def __enter__(self) -> "DaskExecutor":
        try:
            import distributed
        except ImportError:
            raise InputError(
                "the dask executor needs the optional extra: pip install 'neuspike-bench[dask]' "
                "(or use --executor local)"
            ) from None
        if self.scheduler:
            try:
                self._client = distributed.Client(self.scheduler, timeout="30s")
            except (OSError, ValueError) as exc:  # unreachable, or an address distributed cannot parse
                raise InputError(f"cannot reach the Dask scheduler at {self.scheduler!r}: {exc}") from exc
        else:
            self._cluster = distributed.LocalCluster(
                n_workers=self.workers, threads_per_worker=1, processes=self.processes,
                dashboard_address=None,
            )
            self._client = distributed.Client(self._cluster)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def run(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        import distributed

        if self._client is None:
            raise RuntimeError("DaskExecutor.run outside its 'with' block")
        futures = {}
        for task in tasks:
            future = self._client.submit(fn, task, pure=False, key=f"neuspike-cell-{task.cell_id}")
            futures[future.key] = (future, task)
        try:
            for future, result in distributed.as_completed(
                [f for f, _ in futures.values()], with_results=True, raise_errors=False
            ):
                yield futures[future.key][1], result
        finally:
            for future, _ in futures.values():
                future.cancel()


_ADDRESS = re.compile(r"^(?:[a-z][a-z0-9+.-]*://)?(?:\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.-]+):\d{1,5}$")


def check_scheduler_address(address: str) -> str:
    """``address`` when it reads as a Dask scheduler address (``[scheme://]host:port``); an
    :class:`InputError` naming the expected form otherwise, before anything starts."""
    if not isinstance(address, str) or not _ADDRESS.match(address.strip()):
        raise InputError(f"--scheduler: expected an address such as tcp://10.0.0.5:8786 (host and port), got {address!r}")
    return address.strip()


def make_executor(name: str, *, workers: int = 1, scheduler: str | None = None):
    """The executor called ``name`` (``"local"`` or ``"dask"``)."""
    if name == "local":
        if scheduler:
            raise InputError("--scheduler applies to --executor dask only")
        return LocalExecutor(workers)
    if name == "dask":
        if scheduler is not None:
            check_scheduler_address(scheduler)
        return DaskExecutor(scheduler, workers)
    raise InputError(f"executor must be one of {', '.join(EXECUTORS)}, got {name!r}")
