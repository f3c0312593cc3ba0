"""NeuSpike-Net behind the method interface: representations (closed forms), registry, strict weights, bad input."""

import numpy as np
import pytest
import torch

from neuspike.errors import FormatError, InputError
from neuspike.methods import create, entry
from neuspike.nets import DEFAULT_DESIGN, NeuSpikeNetMethod, event_representation, spike_representation
from neuspike.methods.normalisation import DARK_RATE_CAP
from neuspike.nets.method import count_level
from neuspike.nets.representations import interval_rate, spike_quantum
from neuspike.sample import Sample
from neuspike.streams import EventStream, SpikeStream
from neuspike.methods.weights import save_safetensors

H, W, T = 12, 20, 256


def regular_spikes(period: int, *, gain: float | None) -> SpikeStream:
    """An ideal sensor's regular trains; its dark rate is unknown (as a bare file's)."""
    planes = np.zeros((T, H, W), bool)
    planes[period - 1::period] = True
    return SpikeStream(planes=planes, plane_rate_hz=20_000.0, start_s=0.0, gain=gain)


def make_sample(*, events: bool = True, gain: float | None = 0.25, period: int = 4, seed: int = 0) -> Sample:
    rng = np.random.default_rng(seed)
    spikes = regular_spikes(period, gain=gain)
    end = T / 20_000.0
    ev = None
    if events:
        n = 500
        ev = EventStream(t_s=np.sort(rng.uniform(0, end, n)), x=rng.integers(0, W, n), y=rng.integers(0, H, n),
                         p=rng.choice(np.array([-1, 1], np.int8), n), width=W, height=H)
    return Sample(height=H, width=W, key_time_s=end / 2, window_start_s=0.0, window_end_s=end, spikes=spikes,
                  events=ev, event_threshold=0.2, ground_truth=np.zeros((H, W), np.float32))


@pytest.mark.parametrize("period", [2, 4, 8, 16])
def test_spike_counts_of_a_regular_train_are_its_radiance(period):
    gain = 0.25
    rep = spike_representation(make_sample(period=period, gain=gain), "counts")
    assert rep.shape == (32, H, W) and rep.dtype == np.float32
    # one spike every `period` planes is a rate 1/period, radiance rate / gain, in every 8-plane group
    assert np.allclose(rep.mean(axis=0), 1 / period / gain)


def test_interval_of_a_regular_train_is_its_period():
    planes = regular_spikes(4, gain=1.0).planes
    centres = np.array([16, 100, 200])
    assert np.allclose(interval_rate(planes, centres), 0.25)
    rep = spike_representation(make_sample(period=4, gain=0.5), "counts_interval")
    assert np.allclose(rep[:16], 0.5) and np.allclose(rep[16:], 0.5)  # (1/4) / 0.5 both ways


def brute_force_interval(planes, centres):
    t = planes.shape[0]
    idx = np.arange(t)[:, None, None]
    out = []
    for c in centres:
        prev = np.where(planes[:c], idx[:c], -t).max(axis=0) if c > 0 else np.full(planes.shape[1:], -t)
        nxt = np.where(planes[c:], idx[c:], 2 * t).min(axis=0)
        out.append(1.0 / (nxt - prev))
    return np.array(out, np.float32)


@pytest.mark.parametrize("p", [0.002, 0.05, 0.5])
@pytest.mark.parametrize("centres", [np.arange(16) * 16 + 8, np.array([0, 5, 100, 255])])
def test_interval_matches_a_brute_force_search(p, centres, rng):
    planes = rng.random((256, 5, 7)) < p
    assert np.allclose(interval_rate(planes, centres), brute_force_interval(planes, centres))


def test_contrast_representation_sums_to_threshold_times_net_polarity():
    s = make_sample()
    rep = event_representation(s, "contrast")
    ev = s.window_events()
    net = np.zeros((H, W))
    np.add.at(net, (ev.y, ev.x), ev.p.astype(float))
    assert np.allclose(rep.sum(axis=0), 0.2 * net, atol=1e-5)


def test_voxel_representation_is_normalised():
    rep = event_representation(make_sample(), "voxel")
    nz = rep[rep != 0]
    assert rep.shape == (32, H, W) and abs(nz.mean()) < 1e-4 and abs(nz.std() - 1) < 1e-3


@pytest.mark.parametrize("kind", ["counts", "counts_interval"])
def test_a_window_of_another_length_keeps_the_radiance_scale(kind):
    planes = np.zeros((200, H, W), bool)  # a real recording's 200 planes: groups of 12 or 13
    planes[1::2] = True
    s = Sample(height=H, width=W, key_time_s=0.005, window_start_s=0.0, window_end_s=0.01,
               spikes=SpikeStream(planes=planes, plane_rate_hz=20_000.0, start_s=0.0, gain=0.5))
    rep = spike_representation(s, kind)
    assert rep.shape == (32, H, W)
    # rate 1/2 over gain 1/2: 1 on average; a group of 6 or 7 planes holds 3 or 4 spikes
    assert abs(rep.mean() - 1.0) < 0.02 and np.allclose(rep, 1.0, atol=0.15)


def test_unknown_gain_is_estimated_from_the_data():
    known = spike_representation(make_sample(gain=0.5), "counts")
    estimated = spike_representation(make_sample(gain=None), "counts")
    assert np.allclose(estimated, 1.0)  # the brightest pixels map to radiance 1
    assert not np.allclose(known, estimated)


@pytest.fixture
def weights_dir(tmp_path):
    torch.manual_seed(0)
    for name in ("neuspike-net", "neuspike-net-spike"):
        params = dict(entry(name).params)  # the registered design (the fusion network's has the motion gate)
        module = NeuSpikeNetMethod(name, precision="float32", **params).module
        save_safetensors(module, tmp_path / f"{name}.safetensors", card={"model": {"params": params}})
    return tmp_path


def test_both_methods_are_registered_with_their_inputs():
    assert entry("neuspike-net").inputs == {"spikes", "events"}
    assert entry("neuspike-net-spike").inputs == {"spikes"}
    assert entry("neuspike-net").weights.file == "neuspike-net.safetensors"


def test_reconstruct_returns_an_image_of_the_sample_size(weights_dir, one_torch_thread):
    for name in ("neuspike-net", "neuspike-net-spike"):
        method = create(name, weights_dir=weights_dir, precision="float32")
        image = method.reconstruct(make_sample())
        assert image.shape == (H, W) and image.dtype == np.float32
        assert 0.0 <= image.min() and image.max() <= 1.0
        assert method.last_normalisation == ("clamp; mean level counted from the spikes, dark rate estimated; "
                                             "despeckled (margin 0.1); Wiener-smoothed (noise 5x)")
    spike = create("neuspike-net-spike", weights_dir=weights_dir, precision="float32")
    spike.reconstruct(make_sample(gain=None))
    assert "gain estimated" in spike.last_normalisation


def test_the_counted_level_is_the_radiance_of_a_regular_train():
    """A pixel firing every p planes over T planes holds T / p spikes: radiance (1 / p) / gain; the
    half spike left in the integrator and the dark rate are accounted for."""
    sample = make_sample(gain=0.25, period=4)
    # dark rate unknown: estimated from the window, which holds no black, so the estimate stops at its cap
    assert count_level(sample) == pytest.approx((1 / 4 + 0.5 / T - DARK_RATE_CAP) / 0.25)
    spikes = sample.spikes
    known = Sample(**{**sample.__dict__, "spikes": SpikeStream(spikes.planes, gain=0.25, dark_rate=0.0)})
    assert count_level(known) == pytest.approx((1 / 4 + 0.5 / T) / 0.25)
    dark = Sample(**{**sample.__dict__, "spikes": SpikeStream(spikes.planes, gain=0.25, dark_rate=1 / 180)})
    assert count_level(dark) == pytest.approx((1 / 4 + 0.5 / T - 1 / 180) / 0.25)
    unknown_gain = Sample(**{**sample.__dict__, "spikes": SpikeStream(spikes.planes, dark_rate=0.0)})
    assert count_level(unknown_gain) is None


def test_counts_level_shifts_the_image_until_it_predicts_the_spikes(weights_dir, one_torch_thread):
    """A window cut from a running sensor holds T (gain x + d) spikes on average (its starting charge
    is spread evenly over a threshold): 64 spikes in 256 planes at gain 0.5 is radiance 0.5. A
    simulation's first window with Algorithm 1's random charge holds half a spike fewer once bright:
    radiance 64.5 / 128."""
    base = make_sample(gain=0.5, period=4)
    sample = Sample(**{**base.__dict__, "spikes": SpikeStream(base.spikes.planes, gain=0.5, dark_rate=0.0)})
    # (the read-out's despeckling and smoothing off: the level alone is under test)
    off = dict(despeckle=0.0, wiener=0.0)
    network = create("neuspike-net-spike", weights_dir=weights_dir, precision="float32", level="network", **off)
    counts = create("neuspike-net-spike", weights_dir=weights_dir, precision="float32", **off)
    as_made, shifted = network.reconstruct(sample), counts.reconstruct(sample)
    assert 0 < as_made.min() and as_made.max() < 1 and 0 < shifted.min() and shifted.max() < 1  # nothing clipped
    assert float(shifted.mean(dtype=np.float64)) == pytest.approx(0.5, abs=1e-5)
    np.testing.assert_allclose(shifted - as_made, 0.5 - float(as_made.mean(dtype=np.float64)), atol=1e-5)
    assert counts.last_normalisation == "clamp; mean level counted from the spikes"
    assert network.last_normalisation == "clamp"
    first = SpikeStream(base.spikes.planes, gain=0.5, dark_rate=0.0,
                        meta={"stages": [{"name": "initial_charge"}, {"name": "integrate_and_fire"}]})
    started = counts.reconstruct(Sample(**{**base.__dict__, "spikes": first}))
    assert float(started.mean(dtype=np.float64)) == pytest.approx(64.5 / 128, abs=1e-5)
    # without the dark rate it is estimated from the window (capped here: no black in view) and said so
    estimated = counts.reconstruct(base)
    assert float(estimated.mean(dtype=np.float64)) == pytest.approx((0.25 - DARK_RATE_CAP) / 0.5, abs=1e-5)
    assert counts.last_normalisation == "clamp; mean level counted from the spikes, dark rate estimated"
    with pytest.raises(InputError, match="level"):
        create("neuspike-net-spike", weights_dir=weights_dir, level="mean")


def test_a_sample_without_events_is_refused_by_the_fusion_network(weights_dir):
    method = create("neuspike-net", weights_dir=weights_dir, precision="float32")
    with pytest.raises(InputError, match="events"):
        method.reconstruct(make_sample(events=False))
    with pytest.raises(InputError, match="no events"):
        NeuSpikeNetMethod("neuspike-net", precision="float32", **DEFAULT_DESIGN, spike_only=False).encode(
            make_sample(events=False))
    spike = create("neuspike-net-spike", weights_dir=weights_dir, precision="float32")
    assert spike.reconstruct(make_sample(events=False)).shape == (H, W)


def test_weights_of_the_wrong_shape_are_a_format_error(tmp_path):
    params = dict(entry("neuspike-net").params)
    state = NeuSpikeNetMethod("neuspike-net", precision="float32", **params).module.state_dict()
    state["predict.weight"] = torch.zeros(1, 10, 3, 3)
    save_safetensors(state, tmp_path / "neuspike-net.safetensors")
    with pytest.raises(FormatError, match="predict.weight"):
        create("neuspike-net", weights_dir=tmp_path)


def test_a_truncated_weights_file_is_a_format_error(weights_dir):
    path = weights_dir / "neuspike-net.safetensors"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    from neuspike.methods.weights import WeightsMismatch

    with pytest.raises(FormatError), pytest.warns(WeightsMismatch):  # its card's sha256 is the whole file's
        create("neuspike-net", weights_dir=weights_dir)


def test_weights_trained_for_another_design_are_refused(weights_dir):
    import json

    card = weights_dir / "neuspike-net.json"
    data = json.loads(card.read_text())
    data["model"]["params"]["fusion"] = "attention"
    card.write_text(json.dumps(data))
    with pytest.raises(FormatError, match="trained for"):
        create("neuspike-net", weights_dir=weights_dir)


def test_weights_of_another_head_are_refused_and_old_cards_mean_the_tanh_head(tmp_path):
    params = {**DEFAULT_DESIGN, "spike_only": False, "head": "tanh"}
    module = NeuSpikeNetMethod("neuspike-net", precision="float32", **params).module
    old_card = {k: v for k, v in params.items() if k != "head"}  # a card written before heads and gates existed
    save_safetensors(module, tmp_path / "neuspike-net.safetensors", card={"model": {"params": old_card}})
    old = {"weights_dir": tmp_path, "key_estimates": "none"}  # and no key estimates
    assert create("neuspike-net", **old, head="tanh", motion_gate="none").module.head == "tanh"
    with pytest.raises(FormatError, match="trained for"):
        create("neuspike-net", **old, head="support", motion_gate="none")
    with pytest.raises(FormatError, match="motion_gate"):  # an old card means no gate
        create("neuspike-net", **old, head="tanh")
    assert DEFAULT_DESIGN["head"] == "support-count" == create("neuspike-net").module.head  # the shipped weights


def test_cards_without_a_transformer_mean_the_fixed_representations(tmp_path):
    """The shipped weights use the fixed representations (``transformer="fixed"``) and are refused by a
    method built with learned transformers (whose tensors they lack)."""
    assert create("neuspike-net").params["transformer"] == "fixed"
    with pytest.raises(FormatError, match="transformer"):
        create("neuspike-net", transformer="learned")
    with pytest.raises(InputError, match="transformer"):
        create("neuspike-net", transformer="learnt")


def test_the_quantum_is_the_radiance_of_one_spike_in_a_group():
    """support-count's last input: 16 / (T * gain), the smallest step of the 16 group rates."""
    sample = make_sample(gain=0.25, period=7)
    rates = spike_representation(sample, "counts_interval")[:16]
    q = spike_quantum(sample)
    assert q == pytest.approx(16 / (T * 0.25))
    counts = rates / q  # each group's spike count
    assert np.allclose(counts, np.round(counts), atol=1e-5) and counts.max() > 1
    design = {**DEFAULT_DESIGN, "spike_only": False}
    method = NeuSpikeNetMethod("neuspike-net", precision="float32", **{**design, "head": "support-count"})
    inputs = method.encode(sample)[0]
    assert len(inputs) == 3 and inputs[-1].shape == (1, 1, H, W)
    assert torch.all(inputs[-1] == torch.tensor(q, dtype=torch.float32))
    support = NeuSpikeNetMethod("neuspike-net", precision="float32", **{**design, "head": "support"})
    assert len(support.encode(sample)[0]) == 2  # the support head takes none


def brute_force_key_intervals(planes, centre, side=2):
    """The interval sequence around ``centre`` pixel by pixel, from the list of spike planes."""
    t = planes.shape[0]
    out = np.zeros((2 * side + 1, *planes.shape[1:]), np.float32)
    for y, x in np.ndindex(*planes.shape[1:]):
        spikes = np.flatnonzero(planes[:, y, x])
        before, after = list(spikes[spikes < centre][::-1]), list(spikes[spikes >= centre])
        b, a = before + [-t], after + [2 * t]  # the first missing spike: a window length outside
        seq = {0: 1.0 / (a[0] - b[0])}
        for k in range(1, side + 1):
            seq[-k] = 1.0 / (b[k - 1] - b[k]) if len(before) >= k else seq[-k + 1]
            seq[k] = 1.0 / (a[k] - a[k - 1]) if len(after) >= k else seq[k - 1]
        out[:, y, x] = [seq[k] for k in range(-side, side + 1)]
    return out


@pytest.mark.parametrize("p", [0.0, 0.004, 0.05, 0.5])
def test_key_intervals_match_a_brute_force_search_and_the_interval_at_the_centre(p, rng):
    """Both the NumPy reference and the compiled kernel: the intervals pixel by pixel, the middle one
    :func:`interval_rate` at the centre, and the kernel equal to the reference bit for bit."""
    from neuspike.nets.representations import key_intervals

    planes = rng.random((256, 6, 9)) < p
    planes[:, 0, 0] = False  # a silent pixel, and one with a single spike before the centre
    planes[:, 0, 1] = False
    planes[40, 0, 1] = True
    ref = key_intervals(planes, 128)
    assert np.allclose(ref, brute_force_key_intervals(planes, 128))
    assert np.array_equal(ref[2], interval_rate(planes, [128])[0])
    assert np.allclose(ref[:, 0, 0], 1 / (3 * 256)) and np.allclose(ref[:2, 0, 1], 1 / (40 + 256))
    try:
        from neuspike.nets import representation_kernels as kernels
    except ImportError:  # pragma: no cover - numba missing
        return
    out = np.empty_like(ref)
    kernels.key_window(planes.view(np.uint8), 128, np.float32(0.3), out)
    assert np.array_equal(out, ref / np.float32(0.3))


def test_key_estimates_of_a_regular_train_are_its_radiance_and_extend_the_spike_input():
    """Every interval of a regular train is its period: the five channels are (1 / period) / gain,
    appended after the 32 by ``encode``; bad names are refused, and weights trained with them are
    refused by a method built without them."""
    from neuspike.nets.representations import key_representation

    sample = make_sample(gain=0.5, period=4)
    assert key_representation(sample, "none") is None
    key = key_representation(sample, "isi-sequence")
    assert key.shape == (5, H, W) and np.allclose(key, 0.25 / 0.5)
    assert np.array_equal(key_representation(sample, "isi-sequence", backend="numpy"), key)
    design = {**DEFAULT_DESIGN, "spike_only": False, "head": "support-count", "motion_gate": "stats"}
    method = NeuSpikeNetMethod("neuspike-net", precision="float32", **{**design, "key_estimates": "isi-sequence"})
    spikes = method.encode(sample)[0][0]
    assert spikes.shape == (1, 37, H, W)
    assert torch.equal(spikes[0, :32], torch.from_numpy(spike_representation(sample, "counts_interval")))
    assert torch.equal(spikes[0, 32:], torch.from_numpy(key))
    with pytest.raises(InputError, match="key_estimates"):
        NeuSpikeNetMethod("neuspike-net", precision="float32", **{**design, "key_estimates": "isi"})
    with pytest.raises(InputError, match="support-count"):
        NeuSpikeNetMethod("neuspike-net", precision="float32", **{**design, "head": "support", "key_estimates": "isi-sequence"})
    for name in ("neuspike-net", "neuspike-net-spike"):  # the shipped weights (stages 25 and 38) use them
        assert create(name).params["key_estimates"] == "isi-sequence"
        with pytest.raises(FormatError, match="key_estimates"):
            create(name, key_estimates="none")
