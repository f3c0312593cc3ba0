"""Which implementation runs (compiled numba kernels or a reference path), and guards for numba's
parallel kernels: one launch at a time, none where the runtime cannot start one.

Every module with compiled kernels resolves its ``backend`` argument through
:func:`resolve_backend`: ``"auto"`` takes the kernels where they can run, ``"numba"`` asks for them,
and the module's reference path (``"numpy"``, or ``"torch"`` for SNM) is the fallback.

Two facts of numba's threading layers that every compiled kernel with ``prange`` must respect:

* With GNU OpenMP (numba's ``"omp"`` layer), a child process forked after a parallel region ran in
  its parent cannot start one: the OpenMP runtime terminates it. Which kernel ran in the parent does
  not matter (the pool is process-wide), so this module records, at fork time, whether numba's
  threading layer had been started (``numba.np.ufunc.parallel._is_initialized``) and with which
  layer; :func:`parallel_usable` is False in such a child, and callers take their reference path
  (spawned processes start clean).
* numba's ``"workqueue"`` layer takes one parallel launch at a time: :data:`KERNEL_LOCK` serialises
  launches from several threads of one process.
"""

from __future__ import annotations

import importlib.util
import os
import threading
from typing import Any

from neuspike.utils.checks import check_positive_int
from neuspike.errors import InputError

__all__ = ["KERNEL_LOCK", "NUMBA_AVAILABLE", "parallel_usable", "resolve_backend", "set_threads"]

#: Whether numba is installed (a dependency, but every stage must still run where it is not). Found
#: without importing it, so that importing this module stays cheap.
NUMBA_AVAILABLE: bool = importlib.util.find_spec("numba") is not None

#: Held around every parallel kernel launch (numba's workqueue layer is not reentrant).
KERNEL_LOCK = threading.RLock()

_forked_after_parallel = False


def _layer_started() -> str | None:
    """The threading layer numba started in this process, or None if none was started."""
    try:
        from numba.np.ufunc import parallel
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    if not getattr(parallel, "_is_initialized", False):
        return None
    try:
        import numba

        return str(numba.threading_layer())
    except ValueError:  # pragma: no cover - initialised but no layer reported
        return None


def _note_fork() -> None:
    global _forked_after_parallel
    # workqueue and TBB are fork-safe; GNU OpenMP is not
    _forked_after_parallel = _forked_after_parallel or _layer_started() == "omp"


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_note_fork)


def parallel_usable() -> bool:
    """Whether a numba parallel kernel can run in this process (False in a child forked after a
    GNU OpenMP parallel region ran in its parent)."""
    return not _forked_after_parallel


def resolve_backend(backend: Any, *, compiled: bool | None = None, reference: str = "numpy") -> str:
    """``"numba"`` or ``reference`` for a requested backend.

    Parameters
    ----------
    backend : {"auto", "numba", reference}
        ``"auto"``: the compiled kernels where they can run, else the reference path.
    compiled : bool, optional
        Whether the caller's compiled kernels could be imported (default: whether numba can).
    reference : str
        The name of the caller's reference path (``"numpy"``; SNM's is ``"torch"``).

    A child forked after a GNU OpenMP parallel region cannot start one (:func:`parallel_usable`):
    there the reference runs even when ``"numba"`` was asked for (both give the same results).

    Raises
    ------
    InputError
        For an unknown name, or ``"numba"`` requested where the kernels cannot be imported.
    """
    choices = ("auto", "numba", reference)
    if not isinstance(backend, str) or backend not in choices:
        raise InputError(f"backend: expected one of {choices}, got {backend!r}")
    available = NUMBA_AVAILABLE if compiled is None else compiled
    if backend == "numba" and not available:
        raise InputError(f"backend 'numba': numba cannot be imported here; use backend={reference!r} or 'auto'")
    if backend == reference or not available or not parallel_usable():
        return reference
    return "numba"


def set_threads(threads: int, *, torch_pool: bool = True) -> int:
    """Give numba's pool and torch's intra-op pool ``threads`` threads each (numba: at most the
    count it was started with); return the count set (torch's, or numba's with ``torch_pool=False``,
    which leaves torch alone for work that runs only numba kernels).

    The one place that pins threads, in one order: numba first, because starting its OpenMP
    threading layer resets the OpenMP pool size that torch reads. numba's pool is left alone when
    already at the count (setting it is not free once its layer runs); torch's is always set.
    """
    threads = check_positive_int("threads", threads)
    if NUMBA_AVAILABLE:
        import numba

        wanted = min(threads, numba.config.NUMBA_NUM_THREADS)
        if numba.get_num_threads() != wanted:
            numba.set_num_threads(wanted)
    if not torch_pool:
        return wanted if NUMBA_AVAILABLE else 1
    import torch

    # always, even when torch already reports the count: a numba OpenMP region started since can
    # have shrunk the pool that torch's own count no longer describes
    torch.set_num_threads(threads)
    return int(torch.get_num_threads())
