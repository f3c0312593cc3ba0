"""``--set KEY=VALUE``: a field of the spec (dotted into a section) set on a spec file or on the flags' spec,
checked as a spec file is, and recorded in the run folder so that the same command resumes."""

import json

import pytest

from neuspike.errors import InputError
from neuspike.train.__main__ import build_parser, spec_from_args
from neuspike.train.spec import apply_settings, load_spec

from .test_train import tiny_spec


def _spec(argv):
    return spec_from_args(build_parser().parse_args(argv))


def test_set_changes_nested_fields_of_a_spec_file_and_nothing_else(tmp_path):
    base = tiny_spec(tmp_path)
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(base.as_dict()))
    spec = _spec(["neuspike-net", "--spec", str(path), "--set", "lr=1e-4", "--set", "data.speed_range=[2000, 24000]",
                  "--set", "params.width=0.45", "--set", "init_from=runs/a b/w.safetensors"])
    assert spec.lr == 1e-4 and spec.data.speed_range == (2000.0, 24000.0)
    assert spec.params == {"width": 0.45} and spec.init_from == "runs/a b/w.safetensors"
    changed = {"lr", "params", "init_from", "export", "data"}
    before, after = load_spec(path).as_dict(), spec.as_dict()
    assert {k for k in after if after[k] != before[k]} <= changed
    assert {k for k in after["data"] if after["data"][k] != before["data"][k]} == {"speed_range"}


def test_set_applies_to_the_flags_spec_too(tmp_path):
    spec = _spec(["neuspike-net", "--quick", "--out", str(tmp_path / "r"), "--set", "data.noise_levels=[\"high\"]"])
    assert spec.data.noise_levels == ("high",)


def test_unknown_keys_bad_values_and_bad_forms_are_refused_by_name(tmp_path):
    base = tiny_spec(tmp_path)
    with pytest.raises(InputError, match=r"unknown spec keys \['speed'\]"):
        apply_settings(base, ["data.speed=3"])
    with pytest.raises(InputError, match=r"unknown spec keys \['lrr'\]"):
        apply_settings(base, ["lrr=1"])
    with pytest.raises(InputError, match="expected KEY=VALUE"):
        apply_settings(base, ["lr"])
    with pytest.raises(InputError, match="lr: expected a positive number"):
        apply_settings(base, ["lr=-1"])
    with pytest.raises(InputError, match="steps is not a section"):
        apply_settings(base, ["steps.x=1"])
    with pytest.raises(InputError, match="data kind follows from the method"):
        apply_settings(base, ["data.kind=\"sequences\""])
    with pytest.raises(InputError, match="test photographs"):
        apply_settings(base, ["data.photos=[\"camera\"]"])


def test_a_set_run_resumes_with_the_same_command_and_refuses_another(tmp_path, one_torch_thread):
    from neuspike.train.loop import Trainer

    path = tmp_path / "spec.json"
    path.write_text(json.dumps(tiny_spec(tmp_path, steps=2).as_dict()))
    argv = ["neuspike-net", "--spec", str(path), "--set", "lr=2e-4"]
    Trainer(_spec(argv), quiet=True).run()
    Trainer(_spec(argv), quiet=True).run()  # the same spec: resumes (finished), no refusal
    with pytest.raises(InputError, match="spec"):
        Trainer(_spec(["neuspike-net", "--spec", str(path), "--set", "lr=3e-4"]), quiet=True).run()
