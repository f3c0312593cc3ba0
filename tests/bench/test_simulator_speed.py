"""The simulator benchmark runs in quick mode, compares like with like, and judges its targets."""

from __future__ import annotations

import numpy as np

from bench import simulator_speed


def test_quick_mode_prints_every_row_and_a_verdict_per_target(capsys):
    assert simulator_speed.main(["--quick"]) == 0
    out = capsys.readouterr().out
    assert "load average" in out and "80x48" in out
    lines = out.split("verdicts:")[1].strip().splitlines()
    assert len(lines) == len(simulator_speed.TARGETS) + 1  # and the whole window's absolute rate
    assert "window 48x32" in out and "not measured" in lines[-1]  # quick mode runs a small window only
    assert all((" met (" in x) or (" missed (" in x) or ("not measured" in x) for x in lines)


def test_every_implementation_of_a_configuration_gives_the_same_output_count():
    rows = simulator_speed.run(width=24, height=16, repeats=1, frames=6, window_sizes=((24, 16),))
    by_config: dict[tuple[str, str], set[int]] = {}
    assert any(r["context"] for r in rows)  # the memory floor and the held-frame kernel
    for r in rows:
        if not r["context"]:
            by_config.setdefault((r["sensor"], r["config"]), set()).add(r["count"])
        assert r["rate"] > 0 and r["min"] <= r["seconds"] <= r["max"] and r["load_1min"] >= 0
    assert all(len(counts) == 1 for counts in by_config.values()), by_config
    assert by_config[("spike", "no effects")] != {0}
    assert by_config[("window", "24x16")] != {0}  # the reference paths give the same events as the compiled ones


def test_plain_reference_loop_fires_at_the_closed_form_rate():
    frames = np.full((64, 2, 8), 0.375, np.float32)  # dyadic: exact float32 arithmetic
    planes = simulator_speed.plain_integrate_and_fire(frames, light=0.5, threshold=1.0)
    assert (planes.sum(axis=0) == int(64 * 0.5 * 0.375)).all()


def test_verdicts_compare_the_named_rows():
    def row(sensor, config, impl, rate):
        return {"sensor": sensor, "config": config, "impl": impl, "rate": rate, "unit": "x/s"}

    rows = [row("spike", "no effects", "plain NumPy loop", 100.0), row("spike", "no effects", "numba, 2 threads", 350.0),
            row("spike", "no effects", "numba, 1 thread", 150.0),
            row("event", "no effects", "NumPy path (today's)", 10.0), row("event", "no effects", "numba, 1 thread", 15.0),
            row("event", "no effects", "numba + worker thread", 25.0)]
    lines = simulator_speed.verdicts(rows)
    assert "met (3.50x" in lines[0] and "missed (1.50x" in lines[1]
    assert "numba + worker thread" in lines[2] and "met (2.50x" in lines[2]
    assert "not measured" in lines[3]


def test_whole_window_verdicts_judge_the_ratio_and_the_absolute_rate():
    def row(config, impl, rate):
        return {"sensor": "window", "config": config, "impl": impl, "rate": rate, "unit": "windows/s"}

    rows = [row("400x250", "NumPy reference paths", 2.0), row("400x250", "compiled, 1 thread", 7.0),
            row("128x128", "NumPy reference paths", 20.0), row("128x128", "compiled, 1 thread", 45.0)]
    lines = simulator_speed.verdicts(rows)
    assert any("whole window, 400x250" in x and "met (3.50x" in x for x in lines)
    assert any("whole window, 128x128" in x and "missed (45.0 windows/s)" in x for x in lines)
