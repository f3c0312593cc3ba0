"""The loss terms of single-window training as registered components (:mod:`neuspike.train.terms`)."""

from __future__ import annotations

import json

import pytest
import torch

from neuspike.errors import InputError
from neuspike.methods.weights import PACKAGE_WEIGHTS
from neuspike.train import TrainSpec, WindowData
from neuspike.train.spec import apply_settings, spec_from_dict
from neuspike.train.terms import TERMS, LossTerm, register_term, resolve_losses


def test_a_spec_names_its_terms_with_their_parameters_and_defaults():
    assert WindowData().losses == {"l1": {"weight": 1.0}, "ssim": {"weight": 1.0, "window": 11, "noise_weights": None}}
    got = resolve_losses({"spike_floor": 2, "l1": 1, "offset": {"weight": 0.5}})
    assert list(got) == ["l1", "offset", "spike_floor"]  # the registry's order, whatever the spec's
    assert got["spike_floor"] == {"weight": 2.0, "noise_weights": None, "terms": "both", "network": None, "emphasis": None}
    assert resolve_losses({"offset": 0}) == {}  # weight 0 with its defaults: as if not named
    with pytest.raises(InputError, match=r"unknown terms \['wobble'\]; the registered ones: l1, ssim"):
        resolve_losses({"wobble": 1})
    with pytest.raises(InputError, match=r"losses.ssim: unknown parameters \['size'\]; it takes weight, window, noise_weights"):
        resolve_losses({"ssim": {"size": 7}})
    with pytest.raises(InputError, match="losses.ssim.window"):
        resolve_losses({"ssim": {"window": 4}})


def test_set_reaches_a_term_and_its_parameters():
    spec = apply_settings(TrainSpec(), ["data.losses.offset=0.5", "data.losses.ssim.window=7",
                                        'data.losses.spike_floor={"weight": 2, "noise_weights": {"high": 16}}'])
    assert spec.data.losses["offset"] == {"weight": 0.5}
    assert spec.data.losses["ssim"] == {"weight": 1.0, "window": 7, "noise_weights": None}
    assert spec.data.losses["spike_floor"] == {"weight": 2.0, "noise_weights": {"high": 16.0}, "terms": "both", "network": None, "emphasis": None}
    assert spec_from_dict(json.loads(json.dumps(spec.as_dict()))) == spec


def test_the_earlier_fields_read_into_the_terms_and_every_shipped_spec_loads():
    earlier = TrainSpec().as_dict()
    earlier["data"].pop("losses")
    earlier["data"].update(ssim_weight=1.0, ssim_window=11, offset_weight=0.0, spike_floor_weight=2.0,
                           spike_floor_noise_weights={"high": 16.0, "medium": 8.0}, spike_floor_terms="both",
                           gate_targets=None, gate_target_weight=0.0, gate_forcing=False)
    earlier.update(teacher="neuspike/trained/neuspike-net.safetensors", distill_weight=1.0)
    losses = spec_from_dict(earlier).data.losses
    assert losses == {"l1": {"weight": 1.0}, "ssim": {"weight": 1.0, "window": 11, "noise_weights": None},
                      "distill": {"weight": 1.0, "teacher": "neuspike/trained/neuspike-net.safetensors"},
                      "spike_floor": {"weight": 2.0, "noise_weights": {"medium": 8.0, "high": 16.0}, "terms": "both", "network": None, "emphasis": None}}
    cards = sorted(PACKAGE_WEIGHTS.glob("*.json"))
    assert cards
    for card in cards:  # the spec behind every shipped network still reads (and round-trips)
        spec = spec_from_dict(json.loads(card.read_text())["training"]["spec"], where=card.name)
        assert spec_from_dict(spec.as_dict()) == spec
    sequences = TrainSpec(method="e2vid").as_dict()
    sequences["data"] = {"kind": "sequences"}
    sequences["teacher"], sequences["distill_weight"] = "t.safetensors", 1.0
    with pytest.raises(InputError, match="distillation trains on single windows"):
        spec_from_dict(sequences)


@pytest.fixture
def clean_registry():
    before = dict(TERMS)
    yield
    TERMS.clear()
    TERMS.update(before)


def test_a_new_experiment_is_one_registered_term(clean_registry):
    """A term registered here (twice the mean image, weighted) is named by a spec and added to the loss,
    and logged, with nothing else to change."""
    from neuspike.methods import create
    from neuspike.train.windows import WindowTask

    def brightness(step, *, weight, scale):
        value = scale * step.image.mean()
        return weight * value, {"brightness": value.item()}

    register_term(LossTerm("brightness", brightness, defaults={"scale": 2.0}, weight=0.0, image_only=True))
    with pytest.raises(InputError, match="registered already"):
        register_term(LossTerm("brightness", brightness))
    data = WindowData(losses={"l1": 1, "brightness": {"weight": 0.25}})
    task = WindowTask(TrainSpec(data=data), create("neuspike-net-spike", precision="float32"))
    image, target = torch.full((1, 1, 16, 16), 0.6), torch.full((1, 1, 16, 16), 0.5)
    loss, parts = task.loss(image, target)
    assert float(loss) == pytest.approx(0.1 + 0.25 * 2.0 * 0.6) and parts["brightness"] == pytest.approx(1.2)


def test_sequence_specs_name_their_own_terms_and_read_the_earlier_fields():
    from neuspike.train.spec import SequenceData

    assert SequenceData().losses == {"l1": {"weight": 1.0}, "ssim": {"weight": 1.0},
                                     "temporal": {"weight": 1.0, "occlusion_alpha": 50.0}}
    with pytest.raises(InputError, match=r"unknown terms \['offset'\]; the registered ones: l1, ssim, temporal, "
                                         r"history, empty"):
        SequenceData(losses={"offset": 1})
    with pytest.raises(InputError, match="at least 2 windows"):
        SequenceData(length=1, warmup_windows=0, losses={"history": 1})
    earlier = TrainSpec(method="e2vid", data=SequenceData()).as_dict()
    earlier["data"].pop("losses")
    earlier["data"].update(l1=1.0, ssim=1.0, temporal=0.5, occlusion_alpha=20.0, history=0.3, empty=0.0)
    assert spec_from_dict(earlier).data.losses == {"l1": {"weight": 1.0}, "ssim": {"weight": 1.0},
                                                   "temporal": {"weight": 0.5, "occlusion_alpha": 20.0},
                                                   "history": {"weight": 0.3}}


def test_the_earlier_data_fields_read_into_the_data_terms_with_the_same_shard_keys():
    """The shipped cards' specs name sweep_fraction, sweep_grid, sweep_scenes, sweep_scene_weights and
    broad_fraction (or, written by this trainer, the mixture's terms): they read into the sweep and broad data
    terms, and the shard key is the one those fields made (their names and values, reconstructed here from the
    card itself)."""
    from neuspike.train.mixture import DATA_TERMS, resolve_mixture

    assert list(DATA_TERMS) == ["sweep", "broad", "smooth", "fast_pans"]
    cards = sorted(PACKAGE_WEIGHTS.glob("neuspike-net*.json"))
    assert cards
    for card in cards:
        written = json.loads(card.read_text())["training"]["spec"]["data"]
        if "mixture" in written:  # the current form: the earlier fields' values, read back from the terms
            terms = written["mixture"]
            written = {"sweep_fraction": terms["sweep"]["fraction"], "sweep_scenes": terms["sweep"]["scenes"],
                       "sweep_scene_weights": terms["sweep"]["scene_weights"], "sweep_grid": terms["sweep"]["grid"],
                       "broad_fraction": terms.get("broad", {}).get("fraction", 0.0)}
        data = spec_from_dict(json.loads(card.read_text())["training"]["spec"]).data
        key = data.key(0)
        sweep = data.mixture["sweep"]
        assert sweep["fraction"] == written["sweep_fraction"] == key["sweep_fraction"] > 0
        assert sweep["scenes"] is written["sweep_scenes"] is key["sweep_scenes"] is True
        assert list(sweep["scene_weights"]) == written["sweep_scene_weights"] == key["sweep_scene_weights"]
        assert sweep["grid"] == written.get("sweep_grid", "sweeps") == key.get("sweep_grid", "sweeps")
        assert "broad" not in data.mixture and "broad_fraction" not in key and not written.get("broad_fraction")
    assert resolve_mixture({"broad": 0, "sweep": {"fraction": 0}}) == {}  # fraction 0 at the defaults: nothing
    with pytest.raises(InputError, match=r"mixture: unknown terms \['wobble'\]; the registered ones"):
        resolve_mixture({"wobble": 0.5})
    with pytest.raises(InputError, match=r"mixture.sweep: unknown parameters \['points'\]; it takes fraction, grid"):
        resolve_mixture({"sweep": {"fraction": 0.5, "points": 3}})
    spec = apply_settings(TrainSpec(), ['data.mixture.sweep={"fraction": 0.5, "grid": "light-noise"}'])
    assert spec.data.mixture == {"sweep": {"fraction": 0.5, "grid": "light-noise", "scenes": False,
                                           "scene_weights": None}}
    assert spec_from_dict(json.loads(json.dumps(spec.as_dict()))) == spec
