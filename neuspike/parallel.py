"""Guards for numba's parallel kernels: one launch at a time, none where the runtime cannot start one.

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

import os
import threading

__all__ = ["KERNEL_LOCK", "parallel_usable"]

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
