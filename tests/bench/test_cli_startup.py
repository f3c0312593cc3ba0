"""``--help`` and usage errors of the benchmark commands answer at once: torch, pandas, matplotlib and
OpenCV (seconds to import together) load only after the arguments are parsed."""

from __future__ import annotations

import pytest

from tests.cli_probe import probe

HEAVY = ("torch", "pandas", "matplotlib", "cv2", "numba")

COMMANDS = ("bench.sweep", "bench.noise", "bench.timing", "bench.report", "bench.merge", "bench.video",
            "bench.method_speed", "bench.simulator_speed", "bench.fast_motion", "bench.dataset")


@pytest.mark.parametrize("module", COMMANDS)
@pytest.mark.parametrize("argv, code", [(["--help"], 0), (["--no-such-option"], 2)])
def test_help_and_usage_errors_import_nothing_heavy(module, argv, code):
    last, output = probe(module, argv, HEAVY)
    assert last == f"exit {code} heavy []", output
