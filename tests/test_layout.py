"""The import graph of the three packages, function-level imports and modules named by string (lazy
exports, ``importlib``) included, imports under ``if TYPE_CHECKING:`` (which never run) left out: no
cycle, and no upward import (``neuspike`` never imports ``baselines`` or ``bench``; ``baselines`` never
imports ``bench``)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("neuspike", "baselines", "bench")
RANK = {"neuspike": 0, "baselines": 1, "bench": 2}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _imports(path: Path, modules: dict[str, Path]) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    skipped = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.dump(node.test):
            skipped.update(id(n) for child in node.body for n in ast.walk(child))
    found = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in modules:
            names = [node.value]  # a module named by string (importlib, a lazy export table)
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name:
                found.add(name)
    return found


def test_no_package_imports_upward():
    modules = _modules()
    bad = []
    for name, path in modules.items():
        for target in _imports(path, modules):
            if RANK[target.split(".")[0]] > RANK[name.split(".")[0]]:
                bad.append(f"{name} imports {target}")
    assert not bad, bad


def test_imports_have_no_cycle():
    modules = _modules()
    graph = {name: _imports(path, modules) - {name} for name, path in modules.items()}
    # a package's __init__ importing its own submodules is how packages re-export; not a cycle of concern
    for name in graph:
        graph[name] = {t for t in graph[name] if not t.startswith(name + ".")}
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, cycles


def test_bench_has_two_wings_and_its_top_level_holds_commands_only():
    """``bench/*.py`` are the commands users type (each has ``main``); the libraries live in
    ``bench.harness`` and ``bench.reporting``, and no harness module imports the reporting wing."""
    modules = _modules()
    bad = [f"{name} imports {target}" for name, path in modules.items() if name.startswith("bench.harness")
           for target in _imports(path, modules) if target.startswith("bench.reporting")]
    assert not bad, bad
    for path in (ROOT / "bench").glob("*.py"):
        if path.stem == "__init__":
            continue
        tree = ast.parse(path.read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body), \
            f"bench/{path.name} is not a command (no main): libraries go into bench/harness or bench/reporting"


def test_the_condition_axes_are_declared_once():
    """Titles, labels, scales and the images' folders of the axes come from bench.harness.axes: no other
    module of bench spells an axis title, nor lists axis names to pick a scale."""
    import re

    from bench.harness.axes import AXIS

    offenders = []
    for path in (ROOT / "bench").rglob("*.py"):
        if path.name == "axes.py":
            continue
        text = path.read_text()
        for a in AXIS.values():
            if f'"{a.title}"' in text:
                offenders.append(f"{path.relative_to(ROOT)} spells {a.title!r}")
        if re.search(r'axis in \("(?:light|motion|noise)", "(?:light|motion|noise)"\)', text):
            offenders.append(f"{path.relative_to(ROOT)} picks a scale by axis names")
    assert not offenders, offenders
