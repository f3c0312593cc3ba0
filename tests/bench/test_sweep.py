"""Sweep command: requests that cannot give results are refused before the first cell."""

from __future__ import annotations

import re

import pytest

from bench.sweep import main


@pytest.mark.parametrize("args, message", [
    (["--size", "7x5"], r"size 7x5: both sides must be at least 11 pixels"),
    (["--scenes", "pan:missing.png"], r"scene pan:missing.png: .*missing.png"),
    (["--methods", ""], r"expected a comma-separated list, got ''"),  # not "every method"
    (["--cache", "/dev/null"], r"--cache /dev/null: exists and is not a folder"),  # not a failure in every cell
])
def test_bad_requests_are_refused_before_any_cell_runs(tmp_path, capsys, args, message):
    out = tmp_path / "run"
    code = main(["--axis", "light", "--methods", "tfp-w32", "--lights", "1/4", "--seeds", "0",
                 "--no-report", "--no-progress", "--out", str(out), *args])
    err = capsys.readouterr().err
    assert code == 2
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and re.search(message, lines[0]), err
    assert not (out / "parts").exists() and not (out / "results.csv").exists()


def test_an_unwritable_out_is_one_line_before_any_work(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    code = main(["--axis", "light", "--methods", "tfp-w32", "--no-report", "--no-progress",
                 "--out", str(tmp_path / "file" / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    # nothing is created on the way, so the first thing in the path that cannot hold a folder is named
    assert err[-1].startswith("error: --out") and f"{tmp_path / 'file'} is not a folder" in err[-1]
    assert not any("sweep:" in line for line in err)  # nothing started


def test_sweeps_take_a_precision_for_every_learned_method(tmp_path):
    """``--precision`` reaches every worker's method creation; an unknown one is a usage error."""
    from bench.harness.cells import WorkerSetup, instances
    from bench.sweep import build_parser, execution_from_args

    args = build_parser().parse_args(["--precision", "float32", "--out", str(tmp_path)])
    assert execution_from_args(args).precision == "float32"
    assert execution_from_args(build_parser().parse_args([])).precision is None  # each method's own
    made = instances(("neuspike-net-spike", "tfp"), WorkerSetup(precision="float32"))
    assert made["neuspike-net-spike"][1].method.params["precision"] == "float32"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--precision", "float16"])
