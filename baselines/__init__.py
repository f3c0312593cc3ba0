"""Every reconstruction method other than the fusion network, behind the common interface.

Each module defines ``register_methods(register)``, which adds its methods and variants to the
registry; :func:`register_all` (the ``neuspike.methods`` entry point) calls them all once.
"""

from __future__ import annotations

import importlib

from neuspike.methods import register

_MODULES = (
    "baselines.tfp",
    "baselines.tfi",
    "baselines.tfstp",
    "baselines.snm",
    "baselines.event_integration",
    "baselines.firenet",
    "baselines.fusion_complementary",
)
_DONE = False


def register_all() -> None:
    """Register the suite's baselines (idempotent).

    Every module is tried; if some fail to import or register, the others still register and
    one error naming all failures is raised afterwards.
    """
    global _DONE
    if _DONE:
        return
    _DONE = True
    problems = []
    for name in _MODULES:
        try:
            importlib.import_module(name).register_methods(register)
        except Exception as exc:
            problems.append(f"{name}: {type(exc).__name__}: {exc}")
    if problems:
        raise ImportError("some baselines could not be registered: " + "; ".join(problems))
