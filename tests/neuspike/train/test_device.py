"""The training device: a spec field that round-trips (old files mean the CPU), a missing device refused
before anything is written, an explicit CPU run equal to the default one, "auto" precision timed where
the device computes bfloat16, and (on a machine with a GPU) a run begun on CUDA that resumes on the CPU."""

from __future__ import annotations

from neuspike.train.checkpoint import read_checkpoint_file

import csv
import dataclasses
import json
from pathlib import Path

import pytest
import torch

from neuspike.errors import InputError
from neuspike.train.__main__ import build_parser, main, spec_from_args
from neuspike.train.loop import Trainer, train
from neuspike.train.spec import load_spec, spec_from_dict
from tests.neuspike.train.test_run_folder import _tiny_sequences, _tiny_windows

pytestmark = pytest.mark.usefixtures("one_torch_thread")
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="torch sees no CUDA device")


def _args(line: str):
    return spec_from_args(build_parser().parse_args(line.split()))


def test_the_device_round_trips_and_is_not_part_of_a_runs_identity(tmp_path):
    spec = dataclasses.replace(_tiny_windows(tmp_path, "run"), device="cuda:1")
    assert spec.as_dict()["device"] == "cuda:1"
    (tmp_path / "spec.json").write_text(json.dumps(spec.as_dict()))
    assert load_spec(tmp_path / "spec.json") == spec
    # a run checkpointed on one device resumes on another: the folder's spec still matches
    assert spec.identity() == dataclasses.replace(spec, device="cpu").identity()
    for bad in ("", "  ", None, 0):
        with pytest.raises(InputError, match="device"):
            dataclasses.replace(spec, device=bad)


def test_spec_files_without_a_device_mean_the_cpu(tmp_path):
    current = _tiny_sequences(tmp_path, "run").as_dict()
    del current["device"]
    assert spec_from_dict(current).device == "cpu"


def test_the_command_takes_a_device_also_over_a_spec_file(tmp_path):
    assert _args("e2vid").device == "cpu" and _args("neuspike-net --quick").device == "cpu"
    assert _args("e2vid --device cuda:1").device == "cuda:1"  # parsed, resolved only when training starts
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(dataclasses.replace(_tiny_windows(tmp_path, "run"), device="cuda").as_dict()))
    assert _args(f"neuspike-net --spec {path}").device == "cuda"
    assert _args(f"neuspike-net --spec {path} --device cpu").device == "cpu"


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA device")
@pytest.mark.parametrize("device", ["cuda", "cuda:0"])
def test_a_missing_cuda_device_is_one_line_naming_it_and_nothing_is_written(tmp_path, capsys, device):
    run, shard = tmp_path / "run", tmp_path / "shard"
    code = main(["neuspike-net", "--quick", "--device", device, "--out", str(run), "--shard", str(shard),
                 "--workers", "1", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and f"'{device}'" in err[0] and "no CUDA device" in err[0], err
    assert list(tmp_path.iterdir()) == []  # no run folder, no shard
    with pytest.raises(InputError, match="no CUDA device"):  # the Python call refuses it as well
        Trainer(dataclasses.replace(_tiny_windows(tmp_path, "run"), device=device), quiet=True)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("make", [_tiny_windows, _tiny_sequences])
def test_an_explicit_cpu_run_equals_the_default_run_bit_for_bit(tmp_path, make):
    default = make(tmp_path, "default")
    explicit = dataclasses.replace(make(tmp_path, "explicit"), device="cpu")
    assert default.device == "cpu" and dataclasses.replace(explicit, out_dir=default.out_dir) == default
    a, b = train(default, quiet=True), train(explicit, quiet=True)
    assert a["step"] == b["step"] == default.steps and a["best"] == b["best"]
    ca = read_checkpoint_file(Path(default.out_dir) / "checkpoint.pt")
    cb = read_checkpoint_file(Path(explicit.out_dir) / "checkpoint.pt")
    assert ca["module"].keys() == cb["module"].keys()
    for k in ca["module"]:
        assert torch.equal(ca["module"][k], cb["module"][k]), k
    for i, state in ca["optimizer"]["state"].items():
        for k, v in state.items():
            assert torch.equal(v, cb["optimizer"]["state"][i][k]), (i, k)
    losses = [[r["loss"] for r in csv.DictReader(open(Path(s.out_dir) / "train_log.csv")) if r["kind"] == "train"]
              for s in (default, explicit)]
    assert losses[0] == losses[1] and len(losses[0]) == default.steps
    cards = [json.loads(p.read_text()) for p in sorted(Path(explicit.out_dir).glob("*.json"))
             if p.name not in ("spec.json", "precision.json")]
    assert cards and all(c["training"]["device"] == "cpu" for c in cards)


@needs_cuda
def test_a_run_begun_on_cuda_resumes_on_the_cpu(tmp_path):
    """Two steps on the GPU, killed; the same run then resumes on the CPU from the GPU's checkpoint
    (CPU tensors in the file) and ends where a CPU run does, to the rounding of the GPU's arithmetic."""
    cpu = _tiny_windows(tmp_path, "cpu")
    gpu = dataclasses.replace(_tiny_windows(tmp_path, "gpu"), device="cuda")
    straight = Trainer(cpu, quiet=True)
    straight.run()
    first = Trainer(gpu, quiet=True)
    assert first.run(until=2)["step"] == 2
    assert next(first.module.parameters()).device.type == "cuda"
    state = read_checkpoint_file(Path(gpu.out_dir) / "checkpoint.pt")  # on the CPU, no map_location needed
    assert all(v.device.type == "cpu" for v in state["module"].values())
    assert all(v.device.type == "cpu" for s in state["optimizer"]["state"].values() for v in s.values())
    card = json.loads((Path(gpu.out_dir) / "neuspike-net.json").read_text())
    assert card["training"]["device"].startswith("cuda") and card["training"]["device_name"]
    resumed = Trainer(dataclasses.replace(gpu, device="cpu"), quiet=True)
    assert resumed.run()["resumed"] and resumed.step == cpu.steps
    assert next(resumed.module.parameters()).device.type == "cpu"
    rows = [list(csv.DictReader(open(Path(s.out_dir) / "train_log.csv"))) for s in (cpu, gpu)]
    losses = [[float(r["loss"]) for r in rs if r["kind"] == "train"] for rs in rows]
    assert len(losses[1]) == cpu.steps
    # step 1 starts from the same weights on the same batch: the losses differ only by rounding
    assert losses[1][0] == pytest.approx(losses[0][0], rel=2e-2)
    for k, v in straight.module.state_dict().items():
        w = resumed.module.state_dict()[k]
        if v.is_floating_point():  # Adam moves each weight by at most about lr per step
            assert torch.allclose(v, w, rtol=0, atol=4 * cpu.steps * cpu.lr), k


def test_auto_precision_measures_a_sequence_step_where_the_device_computes_bfloat16(tmp_path):
    """On a GPU (or a CPU with native bfloat16) "auto" times a training step before the first one: the
    sequence task's shard is loaded by then."""
    spec = dataclasses.replace(_tiny_sequences(tmp_path, "run"), precision="auto", steps=1)
    trainer = Trainer(spec, quiet=True)
    trainer.precision = "bfloat16"  # what "auto" resolves to on such a device
    timed = trainer._step_ms
    trainer._step_ms = lambda precision, repeats=3: timed(precision, repeats=1)  # emulated bfloat16 is slow here
    assert trainer.run()["step"] == 1
    record = json.loads((tmp_path / "run" / "precision.json").read_text())
    assert record["measured"] and record["device"] == "cpu" and set(record["ms_per_step"]) == {"float32", "bfloat16"}
    assert record["choice"] == trainer.precision == trainer.task.precision
