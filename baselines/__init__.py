"""Every reconstruction method other than the fusion network, behind the common interface.

Each method module defines ``register_methods(register)``, which adds its methods and variants to
the registry; :func:`register_methods` (the ``neuspike.methods`` entry point) calls them all once.
Modules are discovered, not listed: every module of this package either registers methods or is
named in :data:`HELPER_MODULES`, and one that does neither is an error rather than a method that
silently vanishes from every sweep.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Callable

from neuspike.errors import one_line

#: Modules of this package that hold shared code and register no method.
HELPER_MODULES: frozenset[str] = frozenset({"snm_kernels", "tfstp_kernels"})


def method_modules() -> list[str]:
    """Dotted names of this package's method modules, sorted."""
    names = sorted(f"{__name__}.{m.name}" for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
    return [n for n in names if n.rsplit(".", 1)[1] not in HELPER_MODULES]


_DONE = False


def register_methods(register: Callable[..., object] | None = None) -> None:
    """Register the suite's baselines with ``register`` (default :func:`neuspike.methods.register`; idempotent).

    Every module is tried; if some fail to import, lack ``register_methods`` or fail to register,
    the others still register and one error naming all failures is raised afterwards.
    """
    global _DONE
    if _DONE:
        return
    _DONE = True
    if register is None:
        from neuspike.methods import register
    problems = []
    for name in method_modules():
        try:
            module = importlib.import_module(name)
            hook = getattr(module, "register_methods", None)
            if not callable(hook):
                raise ImportError("defines no register_methods(register) and is not in HELPER_MODULES")
            hook(register)
        except Exception as exc:
            problems.append(f"{name}: {one_line(exc)}")
    if problems:
        raise ImportError("some baselines could not be registered: " + "; ".join(problems))

