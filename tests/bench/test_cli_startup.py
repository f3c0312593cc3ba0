"""``--help`` and usage errors of the benchmark commands answer at once: torch, pandas, matplotlib and
OpenCV (seconds to import together) load only after the arguments are parsed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("torch", "pandas", "matplotlib", "cv2", "numba")
PROBE = """
import runpy, sys
sys.argv = [{module!r}, *{argv!r}]
try:
    runpy.run_module({module!r}, run_name="__main__")
except SystemExit as exc:
    code = exc.code
print("exit", code, "heavy", sorted(m for m in {heavy!r} if m in sys.modules))
"""

COMMANDS = ("bench.sweep", "bench.noise", "bench.timing", "bench.report", "bench.merge", "bench.video",
            "bench.method_speed", "bench.simulator_speed")


@pytest.mark.parametrize("module", COMMANDS)
@pytest.mark.parametrize("argv, code", [(["--help"], 0), (["--no-such-option"], 2)])
def test_help_and_usage_errors_import_nothing_heavy(module, argv, code):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    probe = PROBE.format(module=module, argv=argv, heavy=HEAVY)
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=120)
    assert done.stdout.strip().splitlines()[-1] == f"exit {code} heavy []", (done.stdout, done.stderr)
