"""The baselines package: every module registers its methods or is declared a helper; nothing vanishes."""

from __future__ import annotations

import importlib

import baselines
from neuspike import methods as registry


def test_every_baseline_module_registers_or_is_declared_a_helper():
    import importlib

    import baselines

    for name in baselines.method_modules():
        assert callable(getattr(importlib.import_module(name), "register_methods", None)), name


def test_every_method_module_contributes_registered_methods():
    names = set(registry.available())
    for module_name in baselines.method_modules():
        added = []
        importlib.import_module(module_name).register_methods(lambda name, *a, **k: added.append(name))
        assert added and set(added) <= names, module_name
