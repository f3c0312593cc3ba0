"""``--help`` and usage errors of the recording commands answer at once: nothing heavy is imported first.

Importing torch takes seconds and numpy with OpenCV most of a second; the commands parse their
arguments before importing any of them, so help and usage errors cost a bare interpreter's start.
"""

from __future__ import annotations

import pytest

from tests.cli_probe import probe

HEAVY = ("torch", "numpy", "cv2", "h5py")


@pytest.mark.parametrize("module, argv, code", [
    ("neuspike.reconstruct", ["--help"], 0),
    ("neuspike.reconstruct", ["--spikes", "x.dat"], 2),  # no --method
    ("neuspike.reconstruct", ["--height", "ten"], 2),
    ("neuspike.video", ["--help"], 0),
    ("neuspike.video", ["x.dat", "--fps", "abc"], 2),
    ("neuspike.video", ["x.dat", "--method", "tfp"], 2),  # no --out
])
def test_help_and_usage_errors_import_nothing_heavy(module, argv, code):
    last, output = probe(module, argv, HEAVY)
    assert last == f"exit {code} heavy []", output
