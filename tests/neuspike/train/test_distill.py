"""Distillation (the ``distill`` loss term, its ``teacher`` and weight): the term is the student's crop losses against the
teacher's image, zero when the student is the teacher, and a compact student learns from a full one."""

import csv
import json

import pytest
import torch

from neuspike.errors import InputError
from neuspike.nets import LITE_DESIGN
from neuspike.train.loop import Trainer

from .test_train import tiny_spec


@pytest.fixture(scope="module")
def teacher(tmp_path_factory):
    """A trained (4-step) fusion network with its JSON card, and the shard it trained on."""
    root = tmp_path_factory.mktemp("teacher")
    torch.set_num_threads(1)
    Trainer(tiny_spec(root), quiet=True).run()
    return root / "run" / "neuspike-net.safetensors", str(root / "shard")


def test_the_spec_refuses_half_a_distillation(tmp_path):
    with pytest.raises(InputError, match="weight > 0"):
        tiny_spec(tmp_path, teacher=str(tmp_path / "t.safetensors"))
    with pytest.raises(InputError, match="give its teacher"):
        tiny_spec(tmp_path, distill_weight=1.0)
    with pytest.raises(InputError, match="teacher: expected a .safetensors"):
        tiny_spec(tmp_path, teacher=str(tmp_path / "t.pt"), distill_weight=1.0)
    with pytest.raises(InputError, match="no such file"):
        Trainer(tiny_spec(tmp_path, teacher=str(tmp_path / "gone.safetensors"), distill_weight=1.0), quiet=True)


def test_the_term_is_the_crop_losses_against_the_teacher_and_zero_for_the_teacher_itself(
        tmp_path, teacher, one_torch_thread):
    weights, shard = teacher
    same = Trainer(tiny_spec(tmp_path / "same", shard_dir=shard, teacher=str(weights), distill_weight=0.5,
                             init_from=str(weights)), quiet=True)
    same.task.prepare(same._bar)
    task = same.task
    with torch.no_grad():
        for step in range(4):  # fusion and spike-only steps: the teacher answers in the step's variant
            _, parts = task.step_loss(step, same.autocast)
            assert parts["distill"] == pytest.approx(0.0, abs=2e-3), (step, task.step_variant(step))
    lite = Trainer(tiny_spec(tmp_path / "lite", shard_dir=shard, teacher=str(weights), distill_weight=0.5,
                             params=dict(LITE_DESIGN)), quiet=True)
    lite.task.prepare(lite._bar)
    task = lite.task
    plain = Trainer(tiny_spec(tmp_path / "plain", shard_dir=shard, params=dict(LITE_DESIGN)), quiet=True)
    plain.module.load_state_dict(lite.module.state_dict())
    plain.task.train_paths = task.train_paths
    with torch.no_grad():
        for step in range(2):
            variant = task.step_variant(step)
            inputs, target = task.batch(step)
            by_hand = task.crop_losses(task.forward(inputs, variant),
                                       task.teacher_image(inputs, variant)).mean()
            loss, parts = task.step_loss(step, lite.autocast)
            base, _ = plain.task.step_loss(step, plain.autocast)
            assert parts["distill"] == pytest.approx(float(by_hand), rel=1e-5)
            assert float(by_hand) > 1e-3
            assert float(loss - base) == pytest.approx(0.5 * float(by_hand), rel=1e-4, abs=1e-6)


def test_a_compact_student_trains_from_a_full_teacher_and_logs_the_term(tmp_path, teacher, one_torch_thread):
    weights, shard = teacher
    spec = tiny_spec(tmp_path, shard_dir=shard, teacher=str(weights), distill_weight=1.0, params=dict(LITE_DESIGN))
    run = Trainer(spec, quiet=True)
    run.run()
    rows = [r for r in csv.DictReader(open(tmp_path / "run" / "train_log.csv")) if r["kind"] == "train"]
    assert len(rows) == 4 and all(float(r["distill"]) > 0 for r in rows)
    card = json.loads((tmp_path / "run" / "neuspike-net.json").read_text())
    assert card["model"]["params"]["width"] == LITE_DESIGN["width"]
    assert "despeckle" not in card["model"]["params"]  # the read-out is the registry entry's, not the design
    assert card["training"]["spec"]["data"]["losses"]["distill"] == {"weight": 1.0, "teacher": str(weights)}


def test_a_spike_only_teacher_cannot_teach_a_fusion_student(tmp_path, teacher, one_torch_thread):
    weights, shard = teacher
    spike = weights.with_name("neuspike-net-spike.safetensors")
    assert spike.is_file()
    with pytest.raises(InputError, match="spike-only network cannot teach"):
        Trainer(tiny_spec(tmp_path, shard_dir=shard, teacher=str(spike), distill_weight=1.0), quiet=True)


def test_the_spike_floor_against_a_held_spike_only_network(tmp_path, teacher, one_torch_thread):
    """losses.spike_floor.network: the floor is a trained spike-only network's image (held, no gradient), so
    the term is mean(relu(l_fusion - l_floor)) with l_floor that network's crop losses (computed by hand here);
    the teacher's own spike-only export is its fusion file's spike-only self, so from the teacher's weights the
    held floor gives the term the network's own floor gives. A fusion file as the floor, a file that is not a
    .safetensors and a missing file are refused by name."""
    weights, shard = teacher
    spike = weights.with_name("neuspike-net-spike.safetensors")
    with pytest.raises(InputError, match="spike_floor.network: expected a spike-only"):
        tiny_spec(tmp_path, losses={"spike_floor": {"weight": 1.0, "network": "floor.pt"}})
    with pytest.raises(InputError, match="spike_floor.network .*a fusion network"):
        Trainer(tiny_spec(tmp_path, shard_dir=shard, losses={"spike_floor": {"weight": 1.0, "network": str(weights)}}),
                quiet=True)
    with pytest.raises(InputError, match="no such file"):
        Trainer(tiny_spec(tmp_path, shard_dir=shard,
                          losses={"spike_floor": {"weight": 1.0, "network": str(tmp_path / "gone.safetensors")}}),
                quiet=True)
    runs = {}
    for name, network in (("own", None), ("held", str(spike))):
        floor = {"weight": 2.0} if network is None else {"weight": 2.0, "network": network}
        run = Trainer(tiny_spec(tmp_path / name, shard_dir=shard, init_from=str(weights),
                                losses={"l1": 1.0, "ssim": 1.0, "spike_floor": floor}), quiet=True)
        run.task.prepare(run._bar)
        runs[name] = run
    held = runs["held"].task
    assert held.floor_network is not None and not any(p.requires_grad for p in held.floor_network.parameters())
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():  # move the student away from the floor's weights: the two floors now differ
        for p in runs["held"].module.parameters():
            p.add_(0.05 * torch.randn(p.shape, generator=gen))
    steps = [k for k in range(40) if held.step_variant(k) == "fusion"][:3]
    with torch.no_grad():
        for step in steps:
            inputs, target = held.batch(step)
            floor = held.floor_network(inputs[0], *inputs[2:])
            by_hand = (held.crop_losses(held.forward(inputs, "fusion"), target)
                       - held.crop_losses(floor, target)).clamp_min(0).mean()
            _, parts = held.step_loss(step, runs["held"].autocast)
            assert parts["spike_floor"] == pytest.approx(float(by_hand), rel=1e-5, abs=1e-7)
            own_floor = held.forward(inputs, "spike")
            assert not torch.allclose(own_floor, floor, atol=1e-4)  # (the held floor is not the moving self)
        own, ref = runs["own"].task, runs["held"].task
        for step in steps:  # unmoved student: its own floor is the held export's image
            inputs, _ = own.batch(step)
            assert torch.allclose(own.forward(inputs, "spike"), ref.floor_network(inputs[0], *inputs[2:]), atol=1e-5)
