"""The device and the precision a sweep computes with are part of its identity; methods are created once."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.harness import cells
from bench.harness import grid as grids
from bench.harness.results import read_csv
from bench.harness.runner import ConfigMismatch, Execution, SweepSpec, cell_id, resolve_methods, run_sweep
from bench.sweep import main
from bench.harness.cells import WorkerSetup
from neuspike import methods as registry
from neuspike.errors import InputError
from neuspike.methods import MethodUnavailable, create_many
from neuspike.simulation.recording import SensorConfig
from tests.doubles import Unavailable, WithWeights

NAME = "zz-learned"
BUILT: list[str] = []


class FakeLearned(WithWeights):
    """Takes what a learned method takes (device, precision, a weights file) and counts its creations."""

    inputs = frozenset({"spikes"})

    def __init__(self, name=None, *, device="cpu", precision="float32"):
        BUILT.append(name)
        super().__init__(name, precision=precision)
        self.device = device

    def _reconstruct(self, sample):
        rate = sample.spikes.planes.mean(axis=0, dtype=np.float64) / sample.spikes.gain
        return np.clip(rate, 0, 1).astype(np.float32), "gain"


@pytest.fixture
def learned(tmp_path_factory, monkeypatch):
    """Register ``NAME`` with a precision, its weights file shipped (in a stand-in for the package's
    folder); the fixture's value re-registers it with another precision."""
    from neuspike.methods import weights

    shipped = tmp_path_factory.mktemp("trained")
    (shipped / "w.safetensors").write_bytes(b"")
    monkeypatch.setattr(weights, "PACKAGE_WEIGHTS", shipped)
    registry.available()

    def register(precision: str) -> None:
        if NAME in registry.available():
            registry.unregister(NAME)
        registry.register(NAME, FakeLearned, weights="w.safetensors", params={"precision": precision})

    register("float32")
    BUILT.clear()
    yield register
    registry.unregister(NAME)


def spec(methods=(NAME, "tfp-w32")) -> SweepSpec:
    g = grids.Grid(scenes=(grids.scene_entry("pan:camera", (32, 24)),), lights=(0.5,), motions=(16,),
                   noises=("none",), seeds=(0,), effects=grids.DEFAULT_EFFECTS)
    return SweepSpec(name="id", grid=g, methods=tuple(methods), sensor=SensorConfig(planes=32))


QUIET = Execution(progress=False, report=False)


def _strip_arithmetic(out) -> None:
    """Make ``out``'s config.json look like one written before the identity held the arithmetic."""
    config = json.loads((out / "config.json").read_text())
    del config["sweep"]["device"], config["sweep"]["precision"]
    (out / "config.json").write_text(json.dumps(config))


def test_the_config_records_the_device_and_each_learned_methods_precision(learned, tmp_path):
    outcome = run_sweep(spec(), tmp_path, QUIET)
    sweep = json.loads((tmp_path / "config.json").read_text())["sweep"]
    assert sweep["device"] == "cpu" and sweep["precision"] == {NAME: "float32"}  # tfp-w32 has none
    # each method is built once in this process (resolving the sweep and running its cell)
    assert BUILT == [NAME] and outcome.n_computed == 1


def test_a_resume_with_another_precision_is_refused_naming_it(learned, tmp_path):
    run_sweep(spec(), tmp_path, QUIET)
    learned("bfloat16")
    with pytest.raises(ConfigMismatch, match=rf"precision\.{NAME} float32 -> bfloat16"):
        run_sweep(spec(), tmp_path, QUIET)
    assert len(list((tmp_path / "parts").glob("*.csv"))) == 1  # nothing mixed, nothing lost


def test_a_resume_with_another_device_is_refused_naming_it(tmp_path, capsys):
    args = ["--axis", "light", "--lights", "1/2", "--motions", "16", "--planes", "32", "--size", "32x24",
            "--scenes", "pan:camera", "--seeds", "0", "--methods", "tfp-w32", "--no-report", "--no-progress",
            "--out", str(tmp_path)]
    assert main(args) == 0
    # the folder as a run on a GPU would have left it
    config = json.loads((tmp_path / "config.json").read_text())
    config["sweep"]["device"] = "cuda:0"
    (tmp_path / "config.json").write_text(json.dumps(config))
    capsys.readouterr()
    assert main(args) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and "device cuda:0 -> cpu" in err[0], err


def test_cell_ids_hold_the_arithmetic_except_the_cpu_in_float32(learned):
    s = spec()
    resolved = resolve_methods(s, WorkerSetup())
    cell = s.grid.cells()[0]
    base = cell_id(s, resolved, cell)
    assert cell_id(s, resolved, cell, {"device": "cpu", "precision": {NAME: "float32"}}) == base
    assert cell_id(s, resolved, cell, {"device": "cuda", "precision": {NAME: "float32"}}) != base
    assert cell_id(s, resolved, cell, {"device": "cpu", "precision": {NAME: "bfloat16"}}) != base


def test_a_folder_written_before_the_identity_is_refused_by_name_and_replaced_with_force(learned, tmp_path):
    """Every committed report's configuration names its device and precisions; a run folder from before
    they were part of the identity is not guessed at: the refusal names what it lacks, --force reruns it."""
    first = run_sweep(spec(), tmp_path, QUIET)
    before = read_csv(first.results_path)
    _strip_arithmetic(tmp_path)
    with pytest.raises(ConfigMismatch, match=r"device absent -> cpu.*--force"):
        run_sweep(spec(), tmp_path, QUIET)
    again = run_sweep(spec(), tmp_path, Execution(progress=False, report=False, force=True))
    assert read_csv(again.results_path)["value"].equals(before["value"])


# ----------------------------------------------------------------------------------------------
# create_many: the one way every front end creates methods
# ----------------------------------------------------------------------------------------------

class Broken(Unavailable):
    def __init__(self, name=None, **params):
        raise RuntimeError("cannot build (test)")


@pytest.fixture
def odd_methods():
    registry.available()
    registry.register("zz-unavailable", Unavailable)
    registry.register("zz-broken", Broken)
    yield
    registry.unregister("zz-unavailable")
    registry.unregister("zz-broken")


def test_create_many_checks_every_name_before_building_any(learned):
    with pytest.raises(InputError, match="unknown method 'no-such-method'"):
        create_many([NAME, "no-such-method"])
    with pytest.raises(InputError, match="repeat"):
        create_many(["tfi", "tfi"])
    assert BUILT == []


def test_create_many_skips_or_refuses_the_unavailable_and_keeps_or_raises_errors(odd_methods):
    made = create_many(["tfi", "zz-unavailable", "zz-broken"], keep_errors=True)
    assert list(made) == ["tfi", "zz-unavailable", "zz-broken"]
    assert made["tfi"].method is not None and made["tfi"].method.name == "tfi"
    assert made["zz-unavailable"].method is None and "weights not given" in str(made["zz-unavailable"].unavailable)
    assert isinstance(made["zz-broken"].error, RuntimeError) and "cannot build" in made["zz-broken"].traceback
    with pytest.raises(MethodUnavailable, match="method 'zz-unavailable' is unavailable: weights not given"):
        create_many(["tfi", "zz-unavailable"], skip_unavailable=False)
    with pytest.raises(RuntimeError, match="cannot build"):
        create_many(["zz-broken"])


def test_a_device_no_method_runs_on_is_refused_naming_it():
    with pytest.raises(InputError, match=r"device 'cuda:7': none of the methods \(tfi, tfp-w32\) runs on a torch"):
        create_many(["tfi", "tfp-w32"], device="cuda:7")


@pytest.mark.parametrize("kind", ["cuda", "mps", "xpu"])
def test_a_device_this_machine_lacks_is_refused_for_learned_methods(learned, kind):
    import torch

    if kind == "cuda":
        missing = f"cuda:{torch.cuda.device_count() + 7}"
    elif kind == "mps" and not torch.backends.mps.is_available():
        missing = "mps"
    elif kind == "xpu" and not (hasattr(torch, "xpu") and torch.xpu.is_available()):
        missing = "xpu"
    else:
        pytest.skip(f"this machine has a {kind} device")
    with pytest.raises(InputError, match=f"device: '{missing}' was asked for but this machine has"):
        create_many(["tfi", "e2vid"], device=missing)
    assert BUILT == []


def test_the_sweep_command_refuses_an_unusable_device_in_one_line(tmp_path, capsys):
    code = main(["--axis", "light", "--methods", "tfi", "--device", "cuda:7", "--no-report", "--no-progress",
                 "--out", str(tmp_path / "run")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert code == 2 and len(err) == 1 and "'cuda:7'" in err[0], err
    assert not (tmp_path / "run" / "parts").exists()


def test_instances_are_built_once_per_process(learned):
    setup = WorkerSetup()
    a = cells.instances((NAME, "tfi"), setup)
    b = cells.instances((NAME,), setup)
    assert a[NAME][1].method is b[NAME][1].method and BUILT == [NAME]
