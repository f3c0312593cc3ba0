"""E2VID-style network: parameter count from the architecture's arithmetic, any input size, the
skips and padding, the registry entries with our own weights, the recurrent state reset between
sequences, and the output after warm-up independent of where the history started."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from baselines.e2vid import PARAMETERS, E2VID, E2VIDModule
from baselines.firenet import FireNet, FireNetModule
from neuspike.conditions import Condition
from neuspike.methods import create, entry
from neuspike.scenes import SceneSpec
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig
from neuspike.methods.weights import save_safetensors

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def conv(cin: int, cout: int, k: int) -> int:
    return cin * cout * k * k + cout


def test_parameter_count_follows_the_architecture():
    """Head 5x5, three 5x5 strided encoders + ConvLSTM(3x3 gates), two residual blocks, three 5x5 decoders, 1x1 head."""
    expected = (conv(5, 32, 5)
                + sum(conv(c, 2 * c, 5) + conv(4 * c, 8 * c, 3) for c in (32, 64, 128))  # LSTM: [x,h] -> 4 gates
                + 2 * 2 * conv(256, 256, 3)
                + sum(conv(2 * c, c, 5) for c in (128, 64, 32))
                + conv(32, 1, 1))
    count = sum(p.numel() for p in E2VIDModule().parameters())
    print(f"E2VID-style parameters: {count:,} (paper: 10,700k)")
    assert count == expected == PARAMETERS
    assert abs(count - 10_700_000) / 10_700_000 < 0.01


@pytest.mark.parametrize("hw", [(37, 53), (8, 8), (65, 31)])
def test_any_size_in_same_size_out_in_unit_range(hw):
    torch.manual_seed(0)
    m = E2VIDModule().eval()
    x = torch.randn(2, 5, *hw)
    with torch.no_grad():
        out, state = m(x, None)
        out2, _ = m(x, state)
    assert out.shape == (2, 1, *hw) and out2.shape == (2, 1, *hw)
    assert float(out.min()) >= 0 and float(out.max()) <= 1
    ph, pw = (-hw[0]) % 8 + hw[0], (-hw[1]) % 8 + hw[1]
    assert [tuple(h.shape[-2:]) for h, _ in state] == [(ph // 2, pw // 2), (ph // 4, pw // 4), (ph // 8, pw // 8)]


def test_padding_is_zeros_at_the_bottom_right():
    """An input already a multiple of 8 whose bottom/right part is zero gives, on the top-left, the
    output of the input cropped there (zero padding is what the crop's forward adds)."""
    torch.manual_seed(1)
    m = E2VIDModule().eval()
    small = torch.randn(1, 5, 21, 19)
    big = torch.zeros(1, 5, 24, 24)
    big[..., :21, :19] = small
    with torch.no_grad():
        a, _ = m(small)
        b, _ = m(big)
    torch.testing.assert_close(a, b[..., :21, :19])


def test_a_skip_carries_the_head_to_the_prediction():
    """With every decoder zeroed, the output is sigmoid(pred(head(x))) exactly: the last skip is a sum."""
    torch.manual_seed(2)
    m = E2VIDModule().eval()
    for d in m.decoders:
        torch.nn.init.zeros_(d.weight)
        torch.nn.init.zeros_(d.bias)
    x = torch.randn(1, 5, 16, 16)
    with torch.no_grad():
        out, _ = m(x)
        ref = torch.sigmoid(m.pred(torch.relu(m.head(x))))
    torch.testing.assert_close(out, ref)


@pytest.fixture(scope="module")
def weights_dir(tmp_path_factory):
    """Seeded, untrained e2vid and firenet-sim weights in a folder (the user's folder wins over the package's)."""
    folder = tmp_path_factory.mktemp("weights")
    torch.manual_seed(3)
    save_safetensors(E2VIDModule(), folder / "e2vid.safetensors", dtype=None)
    save_safetensors(FireNetModule(), folder / "firenet-sim.safetensors", dtype=None)
    return folder


@pytest.fixture(scope="module")
def pan_sample():
    spec = SceneSpec("pan", image="brick", size=(48, 40), velocity_px_s=(3000.0, 800.0))
    return simulate_sample(spec, Condition(light=0.25, motion=128), sensor=SensorConfig(), seed=5,
                           modalities={"events"}, history_s=0.03)


def test_registry_entries_load_our_weights_strictly(weights_dir):
    for name, cls in (("e2vid", E2VID), ("firenet-sim", FireNet)):
        assert entry(name).weights.file.endswith(".safetensors")
        m = create(name, weights_dir=weights_dir, precision="float32")
        assert type(m) is cls and m.weights_path.parent == weights_dir and m.layout == "safetensors"
    bad = weights_dir / "bad"
    bad.mkdir()
    save_safetensors(FireNetModule(), bad / "e2vid.safetensors", dtype=None)
    from neuspike.errors import FormatError

    with pytest.raises(FormatError, match="missing tensors"):
        create("e2vid", weights_dir=bad)


def test_state_is_reset_between_sequences(weights_dir, pan_sample):
    """reconstruct(B) after reconstruct(A) equals reconstruct(B) on a fresh method."""
    other = simulate_sample(SceneSpec("zoom", image="cat", size=(48, 40)), Condition(light=0.25, motion=128),
                            sensor=SensorConfig(), seed=6, modalities={"events"}, history_s=0.03)
    used = create("e2vid", weights_dir=weights_dir, precision="float32")
    used.reconstruct(other)
    fresh = create("e2vid", weights_dir=weights_dir, precision="float32")
    np.testing.assert_array_equal(used.reconstruct(pan_sample), fresh.reconstruct(pan_sample))
    assert used.last_steps == fresh.last_steps > 3


#: Largest mean absolute difference allowed between outputs warmed up on 20 windows and on 10 windows
#: (the last windows are the same; only the history before them differs).
HISTORY_TOLERANCE = 0.01


@pytest.mark.parametrize("name", ["e2vid", "firenet-sim"])
def test_output_after_warm_up_does_not_depend_on_where_history_started(name, pan_sample):
    """Shipped weights (seeded untrained ones when none are shipped): cutting the history to its last
    10 windows changes the image by at most :data:`HISTORY_TOLERANCE` on average."""
    from neuspike.methods.weights import PACKAGE_WEIGHTS

    if not (PACKAGE_WEIGHTS / entry(name).weights.file).is_file():
        pytest.skip(f"no shipped {name} weights")
    long = create(name, precision="float32", max_windows=20)
    short = create(name, precision="float32", max_windows=10)
    a, b = long.reconstruct(pan_sample), short.reconstruct(pan_sample)
    assert long.last_steps == 20 and short.last_steps == 10
    diff = float(np.abs(a - b).mean())
    print(f"{name}: mean |20-window - 10-window| = {diff:.4f}")
    assert diff < HISTORY_TOLERANCE
