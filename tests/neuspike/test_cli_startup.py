"""``--help`` and usage errors of the recording commands answer at once: nothing heavy is imported first.

Importing torch takes seconds and numpy with OpenCV most of a second; the commands parse their
arguments before importing any of them, so help and usage errors cost a bare interpreter's start.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("torch", "numpy", "cv2", "h5py")
PROBE = """
import runpy, sys
sys.argv = [{module!r}, *{argv!r}]
try:
    runpy.run_module({module!r}, run_name="__main__")
except SystemExit as exc:
    code = exc.code
print("exit", code, "heavy", sorted(m for m in {heavy!r} if m in sys.modules))
"""


@pytest.mark.parametrize("module, argv, code", [
    ("neuspike.reconstruct", ["--help"], 0),
    ("neuspike.reconstruct", ["--spikes", "x.dat"], 2),  # no --method
    ("neuspike.reconstruct", ["--height", "ten"], 2),
    ("neuspike.video", ["--help"], 0),
    ("neuspike.video", ["x.dat", "--fps", "abc"], 2),
    ("neuspike.video", ["x.dat", "--method", "tfp"], 2),  # no --out
])
def test_help_and_usage_errors_import_nothing_heavy(module, argv, code):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    probe = PROBE.format(module=module, argv=argv, heavy=HEAVY)
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=120)
    assert done.stdout.strip().splitlines()[-1] == f"exit {code} heavy []", (done.stdout, done.stderr)
