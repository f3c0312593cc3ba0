"""Training where the device computes bfloat16: "auto" times a step of the task's data."""

from __future__ import annotations

import dataclasses
import json

import pytest

from neuspike.train.loop import Trainer
from tests.neuspike.train.test_run_folder import _tiny_sequences

pytestmark = pytest.mark.usefixtures("one_torch_thread")


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
    assert record["measured"] and set(record["ms_per_step"]) == {"float32", "bfloat16"}
    assert record["choice"] == trainer.precision == trainer.task.precision
