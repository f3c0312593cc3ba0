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
from neuspike.errors import InputError
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


def _events_sample(ev, key_s):
    """An events-only sample at ``key_s`` holding every event before it (window: the last 1 ms)."""
    from neuspike.sample import Sample

    return Sample(height=ev.height, width=ev.width, key_time_s=key_s, window_start_s=key_s - 1e-3,
                  window_end_s=key_s, events=ev.between(float(ev.t_s[0]), key_s))


def test_streamed_state_equals_a_from_scratch_run_over_the_same_windows():
    """Video streaming (reconstruct_next) carries the state: frame 2 steps only the two windows
    completed since frame 1 and frame 3 its full windows plus a partial one; stepping the module by
    hand over the same voxel grids, from a reset, gives the same images."""
    from neuspike.methods.representations import event_windows, voxel_grid
    from neuspike.streams import EventStream

    rng = np.random.default_rng(5)
    h, w, n = 24, 32, 12_000
    ev = EventStream(np.sort(rng.uniform(0.0, 0.05, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                     rng.choice(np.array([-1, 1], np.int8), n), w, h)
    method = create("e2vid", precision="float32", max_windows=6)
    per = int(round(0.35 * h * w))
    t = ev.t_s
    k1 = float(t[8 * per] + t[8 * per + 1]) / 2
    i1 = int(np.searchsorted(t, k1))
    k2 = float(t[i1 + 2 * per])  # exactly two full windows after frame 1, none partial
    k3 = float(t[i1 + 3 * per + per // 2])  # one full window and half of the next
    images = [method.reconstruct(_events_sample(ev, k1))]
    assert method.last_steps == 6
    images.append(method.reconstruct_next(_events_sample(ev, k2), previous_s=k1))
    assert method.last_steps == 2
    images.append(method.reconstruct_next(_events_sample(ev, k3), previous_s=k2))
    assert method.last_steps == 2  # one committed, one partial

    def grid(a, b, t0, t1):
        chunk = EventStream.trusted(t[a:b], ev.x[a:b], ev.y[a:b], ev.p[a:b], w, h)
        g = voxel_grid(chunk, bins=5, t0_s=t0, t1_s=t1, height=h, width=w, normalize=True)
        return torch.from_numpy(g)[None]

    module, state = method.module, None
    with torch.inference_mode():
        first = event_windows(t[:i1], events_per_window=per, end_s=k1, max_windows=6)
        for a, b, t0, t1 in first:
            out, state = module(grid(a, b, t0, t1), state)
        np.testing.assert_array_equal(images[0], out[0, 0].numpy())
        out, state = module(grid(i1, i1 + per, k1, float(t[i1 + per])), state)
        out, state = module(grid(i1 + per, i1 + 2 * per, float(t[i1 + per]), k2), state)
        np.testing.assert_array_equal(images[1], out[0, 0].numpy())
        j = i1 + 2 * per
        out, state = module(grid(j, j + per, k2, float(t[j + per])), state)
        out, _ = module(grid(j + per, j + per + per // 2, float(t[j + per]), k3), state)
        np.testing.assert_array_equal(images[2], out[0, 0].numpy())


def test_read_out_at_the_last_full_window_steps_only_the_completed_windows():
    """read_out="window": a streamed frame steps only the windows completed since the previous frame
    and shows the last one's output (the "key" read-out's image before its partial step), says how
    far before the key instant it is, repeats the last image when no window completed, and is the
    same as "key" when a frame ends on a window's end; a bad value is refused."""
    from neuspike.streams import EventStream

    rng = np.random.default_rng(7)
    h, w, n = 24, 32, 12_000
    ev = EventStream(np.sort(rng.uniform(0.0, 0.05, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                     rng.choice(np.array([-1, 1], np.int8), n), w, h)
    per = int(round(0.35 * h * w))
    t = ev.t_s
    k1 = float(t[8 * per] + t[8 * per + 1]) / 2
    i1 = int(np.searchsorted(t, k1))
    k2 = float(t[i1 + 2 * per])                    # two full windows after frame 1, none partial
    k3 = float(t[i1 + 3 * per + per // 2])         # one full window and half of the next
    k4 = float(t[i1 + 3 * per + 3 * per // 4])     # no window completed since frame 3
    frames = [(k1, None), (k2, k1), (k3, k2), (k4, k3)]
    out = {}
    for read_out in ("key", "window"):
        method = create("e2vid", precision="float32", max_windows=6, read_out=read_out)
        images, steps, labels = [], [], []
        for key, prev in frames:
            s = _events_sample(ev, key)
            images.append(method.reconstruct(s) if prev is None else method.reconstruct_next(s, previous_s=prev))
            steps.append(method.last_steps)
            labels.append(method.last_normalisation)
        out[read_out] = images, steps, labels
    (key_img, key_steps, _), (win_img, win_steps, win_labels) = out["key"], out["window"]
    assert key_steps == [6, 2, 2, 1] and win_steps == [6, 2, 1, 0]
    np.testing.assert_array_equal(win_img[0], key_img[0])  # a fresh frame ends on the key instant
    np.testing.assert_array_equal(win_img[1], key_img[1])  # so does a frame on a window's end
    assert "read out at the last full window, 0 ms" in win_labels[1]
    # frame 3: the full window's output, which "key" computed and then stepped past
    reference = create("e2vid", precision="float32", max_windows=6)
    reference.reconstruct(_events_sample(ev, k1))
    reference.reconstruct_next(_events_sample(ev, k2), previous_s=k1)
    k_full = float(t[i1 + 3 * per])
    np.testing.assert_array_equal(win_img[2], reference.reconstruct_next(_events_sample(ev, k_full), previous_s=k2))
    assert not np.array_equal(win_img[2], key_img[2])
    lag_ms = 1e3 * (k3 - float(t[i1 + 3 * per]))
    assert f"{lag_ms:.3g} ms before the key instant" in win_labels[2]
    np.testing.assert_array_equal(win_img[3], win_img[2])  # nothing completed: the same image, no step
    with pytest.raises(InputError, match="read_out"):
        create("e2vid", precision="float32", read_out="partial")


def test_a_short_history_is_said_in_the_label():
    """Too few events for max_windows windows before the first frame: the label says on how many
    windows the state rests, fresh and carried, until the state has seen max_windows."""
    from neuspike.streams import EventStream

    rng = np.random.default_rng(6)
    h, w, n = 24, 32, 3_000
    ev = EventStream(np.sort(rng.uniform(0.0, 0.05, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                     rng.choice(np.array([-1, 1], np.int8), n), w, h)
    method = create("e2vid", precision="float32", max_windows=8)
    method.reconstruct(_events_sample(ev, 0.01))
    windows = -(-int(np.searchsorted(ev.t_s, 0.01)) // int(round(0.35 * h * w)))  # the oldest one partial
    assert windows < 8
    assert f"short history: warmed up on {windows} of 8 windows" in method.last_normalisation
    method.reconstruct_next(_events_sample(ev, 0.045), previous_s=0.01)
    assert method.windows_seen >= 8 and "short history" not in method.last_normalisation
