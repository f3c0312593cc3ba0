"""Run a command's ``main`` as ``python -m`` does, in a fresh interpreter, and report its exit status
and which of some heavy modules it imported (for the tests that ``--help`` and usage errors answer
before anything heavy is imported)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Sequence

ROOT = Path(__file__).resolve().parents[1]
_PROBE = """
import runpy, sys
sys.argv = [{module!r}, *{argv!r}]
try:
    runpy.run_module({module!r}, run_name="__main__")
except SystemExit as exc:
    code = exc.code
print("exit", code, "heavy", sorted(m for m in {heavy!r} if m in sys.modules))
"""


def probe(module: str, argv: Sequence[str], heavy: Sequence[str]) -> tuple[str, str]:
    """``("exit CODE heavy [...]", everything printed)`` of ``python -m MODULE ARGV``."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = _PROBE.format(module=module, argv=list(argv), heavy=tuple(heavy))
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    return done.stdout.strip().splitlines()[-1] if done.stdout.strip() else "", done.stdout + done.stderr
