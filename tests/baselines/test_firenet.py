"""FireNet: strict loading of both published checkpoints, the network against a reference written from
the published layout, recurrent state, windows, and accuracy on a simulated textured pan.

Tests that need the published weights skip when the shared folder is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F

import baselines.event_integration as event_module
import baselines.firenet as firenet_module
from baselines.firenet import (
    NUM_BINS,
    FireNet,
    FireNetModule,
    load_firenet,
    map_state_dict,
)
from neuspike.conditions import Condition
from neuspike.errors import FormatError, InputError
from neuspike.methods import MethodUnavailable, create
from neuspike.methods.weights import PACKAGE_WEIGHTS, WEIGHTS_ENV, WeightsNotFound, resolve_weights
from neuspike.metrics import ssim
from neuspike.methods.representations import event_windows
from neuspike.sample import Sample
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulation.window import simulate_window
from neuspike.streams import EventStream
from tests.shared_data import SHARED

pytestmark = pytest.mark.usefixtures("one_torch_thread")

WEIGHTS = SHARED / "weights"
FILES = {"firenet.pt": "legacy", "firenet_plus.pt": "plus"}
needs_weights = pytest.mark.skipif(
    not all((WEIGHTS / "firenet" / f).is_file() for f in FILES), reason="shared FireNet weights absent"
)
PARAMETERS = 37_777


def published(file_name: str, **params) -> FireNet:
    """FireNet built untrained, then the published file loaded into it (what ``create`` does)."""
    return FireNet(**params).load_file(WEIGHTS / "firenet" / file_name)


def checkpoint(name: str) -> dict:
    return torch.load(WEIGHTS / "firenet" / name, map_location="cpu", weights_only=True)


def random_grid(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    grid = rng.standard_normal((NUM_BINS, height, width)).astype(np.float32)
    return grid * (rng.random(grid.shape) < 0.3)


# --- a reference forward pass written from the published description, in the file's own names ----

PREFIXES = {
    "legacy": {"head": "net.head.conv.conv2d", "G1": "net.head.recurrent_block", "R1": "net.resblocks.0.conv",
               "G2": "net.resblocks.0.recurrent_block", "R2": "net.resblocks.1", "pred": "net.pred.conv2d"},
    "plus": {"head": "head.conv2d", "G1": "G1", "R1": "R1", "G2": "G2", "R2": "R2", "pred": "pred.conv2d"},
}


def reference_step(sd: dict, layout: str, x: torch.Tensor, states):
    """One step of FireNet as the weights' README describes it, straight from the state dict."""
    name = PREFIXES[layout]

    def conv(inp, prefix, padding=1):
        return F.conv2d(inp, sd[prefix + ".weight"], sd[prefix + ".bias"], padding=padding)

    def gru(inp, s, prefix):
        z = torch.sigmoid(conv(torch.cat([inp, s], 1), prefix + ".update_gate"))
        r = torch.sigmoid(conv(torch.cat([inp, s], 1), prefix + ".reset_gate"))
        o = torch.tanh(conv(torch.cat([inp, s * r], 1), prefix + ".out_gate"))
        return s * (1 - z) + o * z

    def res(inp, prefix):
        return F.relu(conv(F.relu(conv(inp, prefix + ".conv1")), prefix + ".conv2") + inp)

    h = F.relu(conv(x, name["head"]))
    if states is None:
        states = (torch.zeros_like(h), torch.zeros_like(h))
    s1 = gru(h, states[0], name["G1"])
    s2 = gru(res(s1, name["R1"]), states[1], name["G2"])
    return conv(res(s2, name["R2"]), name["pred"], padding=0), (s1, s2)


# --- loading -------------------------------------------------------------------------------------


@needs_weights
@pytest.mark.parametrize("file_name", list(FILES))
def test_both_checkpoints_load_with_every_tensor_used(file_name):
    module, layout = load_firenet(WEIGHTS / "firenet" / file_name)
    assert layout == FILES[file_name]
    assert sum(p.numel() for p in module.parameters()) == PARAMETERS
    source = checkpoint(file_name)["state_dict"]
    assert sum(v.numel() for v in source.values()) == PARAMETERS
    # Every tensor of the file is in the module exactly once, and the module has nothing else.
    own = module.state_dict()
    mapped, _ = map_state_dict(source)
    assert set(mapped) == set(own) and len(mapped) == len(source)
    for key, value in mapped.items():
        assert torch.equal(own[key], value)


@needs_weights
@pytest.mark.parametrize("file_name", list(FILES))
def test_network_matches_the_published_description(file_name):
    sd = checkpoint(file_name)["state_dict"]
    module, layout = load_firenet(WEIGHTS / "firenet" / file_name)
    rng = np.random.default_rng(0)
    states = ref_states = None
    with torch.inference_mode():
        for _ in range(3):  # three steps, so that the recurrent paths are exercised
            x = torch.from_numpy(random_grid(rng, 13, 17))[None]
            out, states = module(x, states)
            ref, ref_states = reference_step(sd, layout, x, ref_states)
            torch.testing.assert_close(out, ref, rtol=1e-4, atol=1e-5)
            torch.testing.assert_close(states[1], ref_states[1], rtol=1e-4, atol=1e-5)


def write_checkpoint(path: Path, state_dict: dict) -> Path:
    torch.save({"arch": "FireNet", "model": None, "state_dict": state_dict}, path)
    return path


@needs_weights
def test_tampered_checkpoints_raise_format_error(tmp_path):
    sd = checkpoint("firenet_plus.pt")["state_dict"]
    dropped = dict(sd)
    del dropped["G2.update_gate.bias"]
    extra = {**sd, "G3.update_gate.bias": torch.zeros(16)}
    extra_same_prefix = {**sd, "R1.conv1.scale": torch.ones(16)}  # a known layer, an unknown tensor
    reshaped = {**sd, "R2.conv1.weight": torch.zeros(16, 16, 5, 5)}
    legacy = checkpoint("firenet.pt")["state_dict"]
    mixed = {**legacy, "G1.reset_gate.weight": sd["G1.reset_gate.weight"]}
    cases = {"dropped": (dropped, "missing"), "extra": (extra, "fit no part"),
             "extra-same-prefix": (extra_same_prefix, "unused"), "reshaped": (reshaped, "shapes differ"),
             "mixed": (mixed, "fit no part")}
    for name, (state_dict, message) in cases.items():
        path = write_checkpoint(tmp_path / f"{name}.pt", state_dict)
        with pytest.raises(FormatError, match=message):
            load_firenet(path)
    (tmp_path / "garbage.pt").write_bytes(b"not a torch file")
    with pytest.raises(FormatError):
        load_firenet(tmp_path / "garbage.pt")
    torch.save({"state_dict": [1, 2, 3]}, tmp_path / "list.pt")
    with pytest.raises(FormatError):
        load_firenet(tmp_path / "list.pt")


def test_missing_weights_make_the_method_unavailable(monkeypatch, tmp_path):
    monkeypatch.setenv(WEIGHTS_ENV, str(WEIGHTS))  # library code never reads the environment
    with pytest.raises(WeightsNotFound, match="--weights") as info:
        create("firenet")
    assert isinstance(info.value, MethodUnavailable)
    with pytest.raises(WeightsNotFound, match="not found") as info:
        create("firenet", weights_dir=tmp_path)
    # every path tried is named: the entry's sub-folder, the folder, the package's own weights
    for path in (tmp_path / "firenet" / "firenet.pt", tmp_path / "firenet.pt", PACKAGE_WEIGHTS / "firenet.pt"):
        assert str(path) in str(info.value)


@needs_weights
def test_weights_are_found_in_the_folder_or_its_firenet_subfolder():
    assert resolve_weights("firenet.pt", WEIGHTS, subdirs=("firenet",)) == WEIGHTS / "firenet" / "firenet.pt"
    assert resolve_weights("firenet_plus.pt", WEIGHTS / "firenet", subdirs=("firenet",)) == WEIGHTS / "firenet" / "firenet_plus.pt"
    assert published("firenet.pt", normalize=True).parameter_count() == PARAMETERS


def test_invalid_parameters_raise():
    for kwargs in ({"precision": "float16"}, {"normalize": 1}, {"events_per_pixel": 0.0}, {"max_windows": 0}):
        with pytest.raises(InputError):
            FireNet(**{"normalize": True, **kwargs})


# --- state and windows ---------------------------------------------------------------------------


@needs_weights
def test_state_resets_between_sequences():
    method = published("firenet.pt", normalize=True)
    rng = np.random.default_rng(1)
    grids = [random_grid(rng, 20, 24) for _ in range(4)]
    first = [method.step(g) for g in grids]
    carried = method.step(grids[0])
    method.reset()
    again = [method.step(g) for g in grids]
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(carried, first[0])  # without a reset the state carries over
    with pytest.raises(InputError, match="differs"):
        method.step(random_grid(rng, 21, 24))
    with pytest.raises(InputError):
        method.step(np.zeros((4, 20, 24), np.float32))


def test_event_windows_tile_time_backwards_from_the_end():
    t = np.arange(10, dtype=float)
    windows = event_windows(t, events_per_window=4, end_s=12.0, max_windows=10)
    assert windows == [(0, 2, 0.0, 2.0), (2, 6, 2.0, 6.0), (6, 10, 6.0, 12.0)]
    assert event_windows(t, events_per_window=4, end_s=12.0, max_windows=2) == windows[1:]
    assert event_windows(np.zeros(0), events_per_window=4, end_s=1.0, max_windows=3) == []
    same = event_windows(np.full(3, 5.0), events_per_window=3, end_s=5.0, max_windows=3)
    assert same[0][:3] == (0, 3, 5.0) and same[0][3] > 5.0


@needs_weights
def test_reconstruct_uses_fixed_count_windows_up_to_the_key_instant():
    h, w = 20, 30
    method = published("firenet_plus.pt", normalize=False, max_windows=50)
    rng = np.random.default_rng(2)
    n = 1000
    t = np.sort(rng.uniform(-0.01, 0.002, n))
    events = EventStream(t, rng.integers(0, w, n), rng.integers(0, h, n), rng.choice([-1, 1], n), w, h)
    sample = Sample(height=h, width=w, key_time_s=0.001, window_start_s=0.0, window_end_s=0.002, events=events)
    image = method.reconstruct(sample)
    before = int(np.searchsorted(t, 0.001))
    assert method.windows_used == -(-before // round(0.35 * h * w))
    # Events after the key instant do not matter.
    cut = Sample(height=h, width=w, key_time_s=0.001, window_start_s=0.0, window_end_s=0.002,
                 events=events.between(-1.0, 0.001))
    np.testing.assert_array_equal(image, method.reconstruct(cut))


# --- accuracy on a simulated textured pan --------------------------------------------------------


@pytest.fixture(scope="module")
def pan_sample():
    """A textured photograph panning at 160x100, L = 1/4, S = 128, with eight windows of history."""
    scene = make_scene(SceneSpec(kind="pan", image="camera", size=(160, 100), velocity_px_s=(1000.0, 300.0)))
    recording = simulate_window(scene, Condition(light=0.25, motion=128), rng=np.random.default_rng(0),
                                history_s=8 * 0.0128)
    return recording.to_sample()


@needs_weights
@pytest.mark.parametrize("file_name, normalize", [("firenet.pt", True), ("firenet_plus.pt", False)])
def test_after_warm_up_firenet_beats_event_integration(pan_sample, file_name, normalize):
    method = published(file_name, normalize=normalize)
    image = method.reconstruct(pan_sample)
    assert method.windows_used == 24  # warmed up on the full 24 windows of history
    baseline = event_module.EventIntegration().reconstruct(pan_sample)
    gt = pan_sample.ground_truth
    ours, theirs = ssim(image, gt, data_range=1.0), ssim(baseline, gt, data_range=1.0)
    assert ours > theirs + 0.1, (ours, theirs)
    # without warm-up (a single window) it is worse
    cold = published(file_name, normalize=normalize, max_windows=1)
    assert ssim(cold.reconstruct(pan_sample), gt, data_range=1.0) < ours


@needs_weights
def test_bfloat16_stays_close_to_float32(pan_sample):
    exact = published("firenet.pt", normalize=True, max_windows=8)
    fast = published("firenet.pt", normalize=True, max_windows=8,
                   precision="bfloat16")
    a, b = exact.reconstruct(pan_sample), fast.reconstruct(pan_sample)
    assert np.abs(a - b).mean() < 0.02
    assert ssim(b, a, data_range=1.0) > 0.95


def test_gradients_flow_and_match_the_inference_path():
    module = FireNetModule()
    rng = np.random.default_rng(3)
    x = torch.from_numpy(random_grid(rng, 9, 11))[None]
    with torch.inference_mode():
        expected, _ = module(x, module(x)[1])
    out, _ = module(x, module(x)[1])  # with autograd: the in-place shortcut must not be taken
    out.sum().backward()
    torch.testing.assert_close(out.detach(), expected)
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in module.parameters())


def test_module_has_the_published_parameter_count():
    assert sum(p.numel() for p in FireNetModule().parameters()) == PARAMETERS
    assert firenet_module.CHANNELS == 16


@needs_weights
@pytest.mark.parametrize("native, bf16_ms, expected", [(True, 50.0, "bfloat16"), (True, 150.0, "float32"),
                                                       (False, None, "float32")])
def test_auto_precision_follows_a_measured_step_and_is_recorded(monkeypatch, tmp_path, native, bf16_ms, expected):
    import neuspike.methods.learned as learned
    from neuspike.methods import precision

    monkeypatch.setenv("NEUSPIKE_CACHE", str(tmp_path))
    monkeypatch.setattr(learned, "native_bfloat16", lambda: native)
    answers = iter([100.0, bf16_ms])  # float32 is timed first
    monkeypatch.setattr(precision, "_median_ms", lambda step: next(answers))
    method = published("firenet.pt", normalize=True)
    assert method.params["precision"] == expected
