"""Which implementation a sensor simulator runs: compiled (numba) kernels or the plain NumPy path.

Both give the same output bit for bit; the NumPy path is the reference and the fallback where
numba cannot be imported. ``backend="auto"`` picks numba when it is available. Compiled kernels run
on ``numba.get_num_threads()`` threads (set it with ``numba.set_num_threads``).
"""

from __future__ import annotations

from neuspike.errors import InputError

__all__ = ["BACKENDS", "NUMBA_AVAILABLE", "resolve_backend"]

#: Accepted values of a simulator's ``backend`` argument.
BACKENDS: tuple[str, ...] = ("auto", "numba", "numpy")

try:  # numba is a dependency, but the simulators must still run where it cannot be imported
    import numba  # noqa: F401
except ImportError:  # pragma: no cover - exercised only without numba
    NUMBA_AVAILABLE = False
else:
    NUMBA_AVAILABLE = True


def resolve_backend(backend: str) -> str:
    """``"numba"`` or ``"numpy"`` for a requested backend.

    Raises
    ------
    InputError
        For an unknown name, or ``"numba"`` requested where numba cannot be imported.
    """
    if backend not in BACKENDS:
        raise InputError(f"backend: expected one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "numba" if NUMBA_AVAILABLE else "numpy"
    if backend == "numba" and not NUMBA_AVAILABLE:
        raise InputError("backend 'numba': numba cannot be imported here; use backend='numpy' or 'auto'")
    return backend
