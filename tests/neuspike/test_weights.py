"""Weights: the registry entry's configuration reaches the resolver, the constructor builds then
loads with no ordering for subclasses to work around, and a file that no longer matches its card warns."""

from __future__ import annotations

import json
import shutil
import warnings

import pytest
import torch

from baselines.firenet import FireNet, FireNetModule
from neuspike.errors import InputError
from neuspike.methods import MethodUnavailable, WeightsConfig, create, entry, register, unregister
from neuspike.methods.weights import PACKAGE_WEIGHTS, WeightsMismatch, file_sha256, save_safetensors


@pytest.fixture
def copied(tmp_path):
    """The shipped firenet-sim weights and card, copied into a user's folder."""
    for suffix in (".safetensors", ".json"):
        shutil.copy(PACKAGE_WEIGHTS / f"firenet-sim{suffix}", tmp_path / f"firenet-sim{suffix}")
    return tmp_path


def test_the_shipped_weights_match_their_cards():
    for card in sorted(PACKAGE_WEIGHTS.glob("*.json")):
        assert json.loads(card.read_text())["sha256"] == file_sha256(card.with_suffix(".safetensors")), card.name


def test_weights_that_no_longer_match_their_card_warn(copied):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same = create("firenet-sim", weights_dir=copied, precision="float32")  # matching: silent
    assert same.weights_path == copied / "firenet-sim.safetensors"
    torch.manual_seed(1)
    save_safetensors(FireNetModule(), copied / "firenet-sim.safetensors", dtype=None)  # retrained; old card kept
    with pytest.warns(WeightsMismatch, match="differs from its card"):
        changed = create("firenet-sim", weights_dir=copied, precision="float32")
    assert changed.weights_sha256 == file_sha256(copied / "firenet-sim.safetensors") != same.weights_sha256


def test_the_entry_carries_the_weights_configuration(tmp_path):
    firenet = entry("firenet")
    assert firenet.weights == WeightsConfig("firenet.pt", subdirs=("firenet",))
    assert entry("e2vid").weights == WeightsConfig("e2vid.safetensors")
    (tmp_path / "firenet").mkdir()
    torch.manual_seed(2)
    save_safetensors(FireNetModule(), tmp_path / "firenet" / "firenet-sim.safetensors", dtype=None)
    # the sub-folder comes from the entry, not from the class
    assert create("firenet-sim", weights_dir=tmp_path).weights_path == tmp_path / "firenet" / "firenet-sim.safetensors"
    with pytest.raises(InputError, match="weights"):
        register("test-bad-weights", FireNet, weights=3)
    register("test-string-weights", FireNet, params={"normalize": True}, weights="firenet-sim.safetensors")
    try:
        assert entry("test-string-weights").weights == WeightsConfig("firenet-sim.safetensors")
    finally:
        unregister("test-string-weights")


def test_create_builds_untrained_then_loads_through_the_one_loader():
    """``create(trained=False)`` is the constructor's fresh module (torch's generator); loading the shipped
    file into it with ``load_file`` gives what ``create`` gives, identity included."""
    torch.manual_seed(0)
    fresh = create("firenet-sim", trained=False, precision="float32")
    torch.manual_seed(0)
    again = FireNetModule()
    assert fresh.weights_path is None and fresh.layout is None and "weights_file" not in fresh.params
    for k, v in again.state_dict().items():
        assert torch.equal(fresh.module.state_dict()[k], v), k
    shipped = create("firenet-sim", precision="float32")
    assert shipped.layout == "safetensors" and shipped.params["weights_file"] == "firenet-sim.safetensors"
    assert shipped.module.encoder.weight.is_contiguous(memory_format=torch.channels_last)
    assert fresh.load_file(shipped.weights_path) is fresh
    assert fresh.describe() == shipped.describe()
    for k, v in shipped.module.state_dict().items():
        assert torch.equal(fresh.module.state_dict()[k], v), k


def test_the_trainer_gets_its_method_from_create_in_the_default_layout():
    from neuspike.train.method import training_method
    from neuspike.train.spec import SequenceData, TrainSpec

    spec = TrainSpec(method="firenet-sim", data=SequenceData(size=40, windows=4, length=4, warmup_windows=1),
                     out_dir="unused", crop=24, batch=1, steps=1, precision="float32", threads=None)
    method = training_method(spec)
    torch.manual_seed(spec.seed)
    assert method.weights_path is None and method.module.encoder.weight.is_contiguous()
    for k, v in FireNetModule().state_dict().items():  # the seed's fresh module
        assert torch.equal(method.module.state_dict()[k], v), k


def test_a_missing_file_is_refused_before_anything_is_built(tmp_path):
    built = []

    class Counting(FireNet):
        def build_module(self):
            built.append(1)
            return super().build_module()

    register("test-missing-weights", Counting, params={"normalize": True}, weights="absent.safetensors")
    try:
        with pytest.raises(MethodUnavailable, match="absent.safetensors"):
            create("test-missing-weights", weights_dir=tmp_path)
        assert built == []
        assert create("test-missing-weights", trained=False, precision="float32").weights_path is None
        assert built == [1]
    finally:
        unregister("test-missing-weights")


def test_an_entry_declaring_weights_needs_a_method_that_loads_them(tmp_path):
    from neuspike.errors import NeuSpikeError
    from neuspike.methods import Method

    class NoLoader(Method):
        inputs = frozenset({"spikes"})

        def __init__(self, name=None, *, device="cpu"):
            super().__init__(name)

        def _reconstruct(self, sample):
            raise AssertionError("not called")

    (tmp_path / "w.safetensors").write_bytes(b"")
    register("test-no-loader", NoLoader, weights="w.safetensors")
    try:
        with pytest.raises(NeuSpikeError, match="load_file"):
            create("test-no-loader", weights_dir=tmp_path)
    finally:
        unregister("test-no-loader")


class _NotATensor:
    pass


def test_a_pickle_that_is_not_tensors_is_refused_in_one_line_without_torchs_unsafe_advice(tmp_path):
    """torch's message is many lines and advises weights_only=False (which runs the file's code):
    the error keeps one line, names what is wrong, and never passes that advice on."""
    from neuspike.errors import FormatError
    from neuspike.methods.weights import load_torch_state

    objects, garbage = tmp_path / "objects.pt", tmp_path / "garbage.pt"
    torch.save({"state_dict": {"w": _NotATensor()}}, objects)
    garbage.write_bytes(b"not a torch file at all")
    for path in (objects, garbage):
        with pytest.raises(FormatError) as err:
            load_torch_state(path)
        text = str(err.value)
        assert "\n" not in text and "weights_only=False" not in text and "weights_only` set to `False" not in text
        assert str(path) in text and "only tensors are loaded" in text
    with pytest.raises(FormatError, match="_NotATensor"):
        load_torch_state(objects)


def test_a_weights_card_that_is_not_an_object_is_one_line(copied):
    """A card that is a JSON list (or garbage) is a FormatError naming the card, not a traceback."""
    from neuspike.errors import FormatError
    from neuspike.methods.weights import read_card

    card = copied / "firenet-sim.json"
    card.write_text("[1, 2, 3]")
    with pytest.raises(FormatError, match="a weights card is a JSON object, got a list"):
        read_card(copied / "firenet-sim.safetensors")
    card.write_text("{not json")
    with pytest.raises(FormatError, match="not a readable JSON card"):
        read_card(copied / "firenet-sim.safetensors")
