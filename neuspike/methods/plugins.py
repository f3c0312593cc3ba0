"""Plug-ins: modules that register methods when imported, named on a command line (``--plugin``) or in the
``NEUSPIKE_PLUGINS`` environment variable, for methods that are not packaged with an entry point.

Every command that runs methods by name (the sweeps, Table 2's timing, the video benchmark, the dataset
runner, the reconstruction and video commands) loads them through :func:`load_requested` (the harness's
workers through :func:`load_plugins`), once per process.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
from pathlib import Path
from typing import Any, Sequence

from neuspike.errors import InputError, one_line
from neuspike.methods import registry

__all__ = ["PLUGINS_ENV", "forget_plugin", "load_plugins", "load_requested", "plugin_names"]

#: Environment variable listing plug-in modules (names or ``.py`` paths, comma-separated).
PLUGINS_ENV = "NEUSPIKE_PLUGINS"

_LOADED_PLUGINS: dict[str, Any] = {}


def plugin_names(extra: tuple[str, ...] = ()) -> tuple[str, ...]:
    """``extra`` followed by the modules in ``NEUSPIKE_PLUGINS``, without repeats."""
    env = tuple(p.strip() for p in os.environ.get(PLUGINS_ENV, "").split(",") if p.strip())
    return tuple(dict.fromkeys(extra + env))


def load_plugins(plugins: tuple[str, ...]) -> list[str]:
    """Import each plug-in once per process; return the names newly imported.

    A plug-in is a module that registers methods when imported, or that defines a function
    ``register_methods()`` (the same callable a ``neuspike.methods`` entry point names), which is
    then called once. It is named by its dotted module name (importable on the worker's
    ``sys.path``) or by a path to a ``.py`` file.

    Raises
    ------
    InputError
        A plug-in that cannot be found or whose import fails (the message carries the cause).
    """
    loaded = []
    for plugin in plugins:
        key = _plugin_key(plugin)
        if key in _LOADED_PLUGINS:
            continue
        try:
            if plugin.endswith(".py") or os.sep in plugin:
                path = Path(plugin).resolve()
                if not path.is_file():
                    raise InputError(f"plug-in file {plugin!r} does not exist")
                name = f"neuspike_plugin_{path.stem}_{hashlib.sha256(str(path).encode()).hexdigest()[:8]}"
                module = sys.modules.get(name)
                if module is None:
                    spec = importlib.util.spec_from_file_location(name, path)
                    module = importlib.util.module_from_spec(spec)
                    sys.modules[name] = module
                    try:
                        spec.loader.exec_module(module)
                    except BaseException:
                        del sys.modules[name]
                        raise
            else:
                module = importlib.import_module(plugin)
            hook = getattr(module, "register_methods", None)
            if callable(hook):
                hook(registry.register)
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"plug-in {plugin!r} failed to load: {one_line(exc)}") from exc
        _LOADED_PLUGINS[key] = module
        loaded.append(plugin)
    return loaded


def _plugin_key(plugin: str) -> str:
    """One name per plug-in: a file's resolved path (``a.py`` and ``/abs/a.py`` are one plug-in), else the module name."""
    return str(Path(plugin).resolve()) if plugin.endswith(".py") or os.sep in plugin else plugin


def forget_plugin(plugin: str) -> None:
    """Forget that ``plugin`` was imported (tests that unregister its methods use this)."""
    module = _LOADED_PLUGINS.pop(_plugin_key(plugin), None)
    if module is not None:
        sys.modules.pop(module.__name__, None)


def load_requested(named: Sequence[str] = ()) -> tuple[str, ...]:
    """Import the plug-ins a command names (its ``--plugin`` values) and those in ``NEUSPIKE_PLUGINS``;
    return them all, in that order (what a run records as its plug-ins)."""
    plugins = plugin_names(tuple(named))
    load_plugins(plugins)
    return plugins
