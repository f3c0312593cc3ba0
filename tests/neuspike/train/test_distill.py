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
    assert card["training"]["spec"]["data"]["losses"]["distill"] == {"weight": 1.0, "teacher": str(weights)}


def test_a_spike_only_teacher_cannot_teach_a_fusion_student(tmp_path, teacher, one_torch_thread):
    weights, shard = teacher
    spike = weights.with_name("neuspike-net-spike.safetensors")
    assert spike.is_file()
    with pytest.raises(InputError, match="spike-only network cannot teach"):
        Trainer(tiny_spec(tmp_path, shard_dir=shard, teacher=str(spike), distill_weight=1.0), quiet=True)
