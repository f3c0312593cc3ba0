"""NeuSpike-Net module: shapes, parameter counts (closed form), padding, fusion identities, spike-only subset."""

import math

import pytest
import torch

from neuspike.errors import InputError
from neuspike.nets import FUSIONS, PAPER_PARAMETERS, NeuSpikeNet, make_fusion, pad_to_multiple


def conv(cin, cout, k=3, bias=True):
    return k * k * cin * cout + (cout if bias else 0)


def norm(c):
    return 2 * c


def expected_parameters(fusion: str, spike_only: bool, c_in: int = 32) -> int:
    """The architecture of REFERENCE §1.1 counted by hand."""
    enc = conv(c_in, 64) + norm(64) + conv(64, 128) + norm(128) + conv(128, 256) + norm(256)
    res = 2 * 2 * (conv(256, 256) + norm(256))
    dec = conv(256, 128) + norm(128) + conv(256, 64) + norm(64) + conv(128, 32) + norm(32)
    pred = conv(32 + c_in, 1)
    total = enc + res + dec + pred
    if spike_only:
        return total
    if fusion == "gate":
        fuse = conv(128, 64) + conv(256, 128)
    else:
        fuse = sum(2 * c * (c // 4) + c // 4 + (c // 4) * c + c + conv(c, c, bias=False) for c in (64, 128))
    return total + enc + fuse


@pytest.mark.parametrize("fusion", FUSIONS)
@pytest.mark.parametrize("spike_only", [False, True])
def test_parameter_count_matches_the_hand_count(fusion, spike_only):
    net = NeuSpikeNet(fusion=fusion, spike_only=spike_only)
    n = sum(p.numel() for p in net.parameters())
    assert n == expected_parameters(fusion, spike_only)
    print(f"NeuSpike-Net fusion={fusion} spike_only={spike_only}: {n:,} parameters "
          f"(paper {PAPER_PARAMETERS:,}, {n - PAPER_PARAMETERS:+,})")


@pytest.mark.parametrize("hw", [(37, 53), (8, 8), (25, 40)])
def test_any_size_is_padded_and_cropped_back(hw, one_torch_thread):
    torch.manual_seed(0)
    net = NeuSpikeNet().eval()
    x = torch.rand(2, 32, *hw)
    with torch.no_grad():
        y = net(x, torch.randn(2, 32, *hw))
    assert y.shape == (2, 1, *hw)
    assert float(y.min()) >= 0.0 and float(y.max()) <= 1.0


def test_padding_is_zero_at_bottom_right_to_multiples_of_8():
    x = torch.ones(1, 2, 250, 401)
    p = pad_to_multiple(x)
    assert p.shape == (1, 2, 256, 408)
    assert torch.equal(p[..., :250, :401], x)
    assert float(p[..., 250:, :].abs().sum()) == 0.0 and float(p[..., :, 401:].abs().sum()) == 0.0


@pytest.mark.parametrize("fusion", FUSIONS)
def test_fusion_with_a_silent_motion_feature_is_the_texture_feature(fusion):
    torch.manual_seed(1)
    f = make_fusion(fusion, 64)
    t = torch.randn(2, 64, 8, 8)
    assert torch.allclose(f(t, torch.zeros_like(t)), t)
    assert not torch.allclose(f(t, torch.randn_like(t)), t)


def test_spike_only_network_is_the_full_network_with_the_motion_path_silenced(one_torch_thread):
    torch.manual_seed(2)
    full = NeuSpikeNet().eval()
    spike = NeuSpikeNet(spike_only=True).eval()
    subset = {k: v for k, v in full.state_dict().items() if not k.startswith(("motion.", "fuse1.", "fuse2."))}
    spike.load_state_dict(subset, strict=True)  # the spike-only tensors are a subset of the full ones
    x = torch.rand(1, 32, 24, 40)
    with torch.no_grad():
        assert torch.allclose(spike(x), full.forward_texture_only(x), atol=1e-6)
        assert not torch.allclose(spike(x), full(x, torch.randn_like(x)), atol=1e-3)


def test_bad_inputs_are_typed_errors():
    net = NeuSpikeNet()
    x = torch.rand(1, 32, 16, 16)
    with pytest.raises(InputError, match="needs the event"):
        net(x)
    with pytest.raises(InputError, match="32"):
        net(torch.rand(1, 5, 16, 16), x)
    with pytest.raises(InputError, match="differ"):
        net(x, torch.rand(1, 32, 16, 24))
    with pytest.raises(InputError, match="takes no events"):
        NeuSpikeNet(spike_only=True)(x, x)
    with pytest.raises(InputError, match="fusion"):
        NeuSpikeNet(fusion="concat")


def test_support_head_starts_as_the_mean_of_the_spike_estimates(one_torch_thread):
    """Zero-initialised, the head is the plain mean of the 32 radiance estimates (TFP and TFI over the window)."""
    torch.manual_seed(3)
    for spike_only in (False, True):
        net = NeuSpikeNet(head="support", spike_only=spike_only).eval()
        x = torch.rand(2, 32, 21, 30) * 3.0
        with torch.no_grad():
            y = net(x) if spike_only else net(x, torch.randn_like(x))
        assert y.shape == (2, 1, 21, 30)
        assert torch.allclose(y, x.mean(dim=1, keepdim=True), atol=1e-6)


def test_support_head_is_a_convex_choice_among_the_estimates_plus_a_correction(one_torch_thread):
    torch.manual_seed(4)
    net = NeuSpikeNet(head="support", spike_only=True).eval()
    with torch.no_grad():
        net.predict.weight.normal_(0.0, 0.5)  # logits depend on the features
        net.predict.weight[0].zero_()
        net.predict.bias.zero_()
        x = torch.rand(1, 32, 16, 24) * 2.0
        y = net(x)
        lo, hi = x.min(dim=1, keepdim=True).values, x.max(dim=1, keepdim=True).values
        assert bool(((y >= lo - 1e-5) & (y <= hi + 1e-5)).all())  # the absolute scale is the data's
        assert not torch.allclose(y, x.mean(dim=1, keepdim=True), atol=1e-3)  # and it chooses per pixel
        net.predict.bias[0] = 0.25  # the first channel adds a correction in radiance units
        assert torch.allclose(net(x), y + 0.25, atol=1e-5)


def test_support_count_head_counts_its_correction_in_spikes(one_torch_thread):
    """The correction is multiplied by the quantum (the radiance of one spike per group), per sample."""
    torch.manual_seed(5)
    for spike_only in (False, True):
        net = NeuSpikeNet(head="support-count", spike_only=spike_only).eval()
        x = torch.rand(2, 32, 19, 26) * 2.0
        q = torch.tensor([0.5, 2.0]).view(2, 1, 1, 1)
        args = (x,) if spike_only else (x, torch.randn_like(x))
        with torch.no_grad():
            base = net(*args, q)
            assert torch.allclose(base, x.mean(dim=1, keepdim=True), atol=1e-6)  # zero head: the mean
            net.predict.bias[0] = 0.5  # half a spike per group
            y = net(*args, q)
            assert torch.allclose(y - base, 0.5 * q.expand_as(base), atol=1e-5)
            # the quantum as a map (what the method passes, so crops keep it) gives the same image
            assert torch.equal(net(*args, q.expand(2, 1, 19, 26)), y)
            if not spike_only:  # the motion path silenced equals the spike-only network with these weights
                alone = NeuSpikeNet(head="support-count", spike_only=True).eval()
                alone.load_state_dict({k: v for k, v in net.state_dict().items()
                                       if not k.startswith(("motion.", "fuse1.", "fuse2."))})
                assert torch.allclose(net.forward_texture_only(x, q), alone(x, q), atol=1e-6)


def test_parts_return_the_image_and_the_convex_part_it_adds_the_correction_to(one_torch_thread):
    """``parts=True`` gives ``(image, convex)``: the same image as without it, ``convex`` the softmax-weighted
    estimates (inside their per-pixel range), their difference the correction; the tanh head refuses."""
    torch.manual_seed(6)
    net = NeuSpikeNet(head="support-count").eval()
    x = torch.rand(2, 32, 17, 22) * 2.0
    e = torch.randn_like(x)
    q = torch.tensor([0.5, 2.0]).view(2, 1, 1, 1)
    with torch.no_grad():
        net.predict.weight.normal_(0.0, 0.5)
        net.predict.bias[0] = 0.5  # half a spike per group of correction
        image, convex = net(x, e, q, parts=True)
        assert torch.equal(image, net(x, e, q))
        lo, hi = x.min(dim=1, keepdim=True).values, x.max(dim=1, keepdim=True).values
        assert bool(((convex >= lo - 1e-5) & (convex <= hi + 1e-5)).all())
        assert not torch.allclose(convex, x.mean(dim=1, keepdim=True), atol=1e-3)
        net.predict.weight[0].zero_()  # a correction of exactly half a spike: image - convex = 0.5 q
        image, convex = net(x, e, q, parts=True)
        assert torch.allclose(image - convex, 0.5 * q.expand_as(image), atol=1e-5)
        alone, alone_convex = net.forward_texture_only(x, q, parts=True)
        assert torch.equal(alone, net.forward_texture_only(x, q))
        assert alone_convex.shape == (2, 1, 17, 22)
    with pytest.raises(InputError, match="parts"):
        NeuSpikeNet(head="tanh")(x, e, parts=True)
    with pytest.raises(InputError, match="parts"):
        NeuSpikeNet(head="tanh").forward_texture_only(x, parts=True)


def test_support_count_head_inputs_are_checked():
    x = torch.rand(1, 32, 16, 16)
    count, support = NeuSpikeNet(head="support-count", spike_only=True), NeuSpikeNet(head="support", spike_only=True)
    with pytest.raises(InputError, match="quantum"):
        count(x)
    with pytest.raises(InputError, match="quantum"):
        count(x, torch.ones(1, 1, 8, 8))
    with pytest.raises(InputError, match="no quantum"):
        support.forward_texture_only(x, torch.ones(1, 1, 1, 1))
    with pytest.raises(InputError, match="quantum"):
        NeuSpikeNet(head="support-count")(x, torch.randn_like(x))


def test_parameter_count_of_the_support_head():
    tanh, support = NeuSpikeNet(), NeuSpikeNet(head="support")
    extra = sum(p.numel() for p in support.parameters()) - sum(p.numel() for p in tanh.parameters())
    assert extra == conv(32 + 32, 1 + 32) - conv(32 + 32, 1)
    with pytest.raises(InputError, match="head"):
        NeuSpikeNet(head="sigmoid")


def test_motion_gate_adds_a_small_mlp_and_starts_as_the_ungated_network(one_torch_thread):
    """Weights trained without the gate load into a gated network (``may_lack``) and give the same image:
    the gate's last layer starts at zero, so every gain is exactly 1."""
    from neuspike.methods.weights import load_state_strict

    torch.manual_seed(3)
    plain = NeuSpikeNet(head="support-count").eval()
    gated = NeuSpikeNet(head="support-count", motion_gate="stats").eval()
    extra = sum(p.numel() for p in gated.parameters()) - sum(p.numel() for p in plain.parameters())
    assert extra == (4 * 32) * 32 + 32 + 32 * 4 + 4
    load_state_strict(gated, plain.state_dict(), "plain", may_lack=gated.STARTS_AS_IDENTITY)
    x, m, q = torch.rand(2, 32, 24, 40), torch.randn(2, 32, 24, 40), torch.full((2, 1, 1, 1), 0.02)
    with torch.no_grad():
        assert torch.equal(gated.motion_gate(x, m), torch.ones(2, 4))
        assert torch.equal(gated(x, m, q), plain(x, m, q))
    with pytest.raises(Exception, match="missing tensors"):  # without may_lack the file is incomplete
        load_state_strict(gated, plain.state_dict(), "plain")
    with pytest.raises(Exception, match="missing tensors"):  # may_lack covers the gate only
        state = {k: v for k, v in plain.state_dict().items() if not k.startswith("predict.")}
        load_state_strict(gated, state, "plain", may_lack=gated.STARTS_AS_IDENTITY)


def test_motion_gate_scales_each_level_of_the_motion_path(one_torch_thread):
    """A gain of 0 at every level is the spike-only network; gains stay in (0, 2)."""
    torch.manual_seed(4)
    net = NeuSpikeNet(head="support-count", motion_gate="stats").eval()
    x, m, q = torch.rand(1, 32, 24, 40), torch.randn(1, 32, 24, 40), torch.full((1, 1, 1, 1), 0.02)
    with torch.no_grad():
        net.motion_gate.mlp[2].bias.fill_(-1e4)  # sigmoid -> 0: the motion path silenced
        assert torch.allclose(net(x, m, q), net.forward_texture_only(x, q), atol=1e-6)
        net.motion_gate.mlp[2].bias.fill_(1e4)
        g = net.motion_gate(x, m)
    assert torch.equal(g, torch.full_like(g, 2.0))
    with pytest.raises(InputError, match="motion_gate"):
        NeuSpikeNet(motion_gate="global")
    with pytest.raises(InputError, match="spike-only"):
        NeuSpikeNet(spike_only=True, motion_gate="stats")


def test_local_gate_starts_as_the_stats_gate_and_loads_its_weights(one_torch_thread):
    """``"stats-local"`` adds 188 parameters whose last layer is zero: ``"stats"`` weights load
    (``may_lack``) and give the same image bit for bit, on a frame whose sides are not multiples of 8."""
    from neuspike.methods.weights import load_state_strict

    torch.manual_seed(6)
    stats = NeuSpikeNet(head="support-count", motion_gate="stats").eval()
    with torch.no_grad():  # a gate that is not the identity, so the comparison covers it
        stats.motion_gate.mlp[2].bias.copy_(torch.tensor([0.3, -0.2, 0.1, -0.4]))
    local = NeuSpikeNet(head="support-count", motion_gate="stats-local").eval()
    extra = sum(p.numel() for p in local.parameters()) - sum(p.numel() for p in stats.parameters())
    assert extra == (2 * 9 * 8 + 8) + (8 * 4 + 4)
    load_state_strict(local, stats.state_dict(), "stats", may_lack=local.STARTS_AS_IDENTITY)
    x, m, q = torch.rand(2, 32, 27, 43), torch.randn(2, 32, 27, 43), torch.full((2, 1, 1, 1), 0.02)
    with torch.no_grad():
        assert torch.equal(local(x, m, q), stats(x, m, q))
        logits = local.local_gate(m)
    assert logits.shape == (2, 4, 27, 43) and torch.equal(logits, torch.zeros_like(logits))
    with pytest.raises(InputError, match="spike-only"):
        NeuSpikeNet(spike_only=True, motion_gate="stats-local")


def test_noise_gate_starts_as_the_stats_gate_and_multiplies_its_gains(one_torch_thread):
    """``"stats-noise"`` adds an MLP on 4C + 20 inputs whose last layer is zero: ``"stats"`` weights load
    (``may_lack``) and give the same image bit for bit (a frame whose sides are not multiples of 8); a
    noise gain of 0 at every level is the spike-only network whatever the stats gate says."""
    from neuspike.methods.weights import load_state_strict
    from neuspike.nets.network import NoiseGate

    torch.manual_seed(8)
    stats = NeuSpikeNet(head="support-count", motion_gate="stats").eval()
    with torch.no_grad():  # a stats gate that is not the identity, so the comparison covers it
        stats.motion_gate.mlp[2].bias.copy_(torch.tensor([0.3, -0.2, 0.1, -0.4]))
    noisy = NeuSpikeNet(head="support-count", motion_gate="stats-noise").eval()
    extra = sum(p.numel() for p in noisy.parameters()) - sum(p.numel() for p in stats.parameters())
    assert extra == (4 * 32 + 4 * 5) * 32 + 32 + 32 * 4 + 4
    load_state_strict(noisy, stats.state_dict(), "stats", may_lack=noisy.STARTS_AS_IDENTITY)
    x, m, q = torch.rand(2, 32, 27, 43), torch.randn(2, 32, 27, 43), torch.full((2, 1, 1, 1), 0.02)
    with torch.no_grad():
        assert torch.equal(noisy.noise_gate(x, m), torch.ones(2, 4))
        assert torch.equal(noisy(x, m, q), stats(x, m, q))
        noisy.noise_gate.mlp[2].bias.fill_(-1e4)  # the noise gate shuts every level
        assert torch.allclose(noisy(x, m, q), noisy.forward_texture_only(x, q), atol=1e-6)
    assert NoiseGate.statistics(x, m).shape == (2, 4 * 32 + 20)
    with pytest.raises(InputError, match="spike-only"):
        NeuSpikeNet(spike_only=True, motion_gate="stats-noise")


def test_noise_gate_quantiles_are_those_of_the_strided_per_pixel_energies():
    """The 20 numbers after the stats gate's 128 are, in order, the 10-90 % quantiles (NumPy's linear rule)
    of log(eps + e) over every 4th row and column, e the events' channel-mean energy, the same for their
    3x3 mean, the difference of those two logarithms, and the spikes' channel-mean (s - box3 s)^2, all
    computed here with NumPy; dense independent events sit at the closed-form coherence of noise."""
    import numpy as np

    from neuspike.nets.network import MotionGate, NoiseGate

    gen = torch.Generator().manual_seed(5)
    spikes, events = torch.rand(1, 3, 21, 34, generator=gen), torch.randn(1, 3, 21, 34, generator=gen)
    got = NoiseGate.statistics(spikes, events)[0].numpy()
    assert np.allclose(got[:12], MotionGate.statistics(spikes, events)[0].numpy())
    s, eps, qs = NoiseGate.STRIDE, NoiseGate.EPS, list(NoiseGate.QUANTILES)

    def box3(a):  # (C, H, W): mean over the neighbours inside the image
        c, h, w = a.shape
        out = np.zeros_like(a)
        for i in range(h):
            for j in range(w):
                out[:, i, j] = a[:, max(i - 1, 0):i + 2, max(j - 1, 0):j + 2].mean(axis=(1, 2))
        return out

    e, sp = events[0].double().numpy(), spikes[0].double().numpy()
    energy = np.log(eps + (e ** 2).mean(0)[::s, ::s]).ravel()
    coherent = np.log(eps + (box3(e) ** 2).mean(0)[::s, ::s]).ravel()
    detail = np.log(eps + ((sp - box3(sp)) ** 2).mean(0)[::s, ::s]).ravel()
    want = np.concatenate([np.quantile(v, qs) for v in (energy, coherent, coherent - energy, detail)])
    assert np.allclose(got[12:], want, atol=1e-5)
    for hw in ((21, 34), (27, 43), (4, 8), (5, 9), (1, 1)):  # the strided 3x3 mean: the full one's strided rows
        field = torch.rand(2, 3, *hw, generator=gen)
        assert torch.allclose(NoiseGate.strided_box3(field), MotionGate.box3(field)[..., ::s, ::s], atol=1e-6)
    # the median coherence: 0 for events that cover a region alike; about log(1/9) for dense independent
    # +-1 events (the 3x3 mean of nine of them has mean square 1/9), averaged over eight channels
    region = torch.ones(1, 8, 64, 64)
    noise = torch.randint(0, 2, (1, 8, 64, 64), generator=gen).float() * 2 - 1
    median = [float(NoiseGate.statistics(torch.zeros_like(x), x)[0, 32 + 12]) for x in (region, noise)]
    assert median[0] == 0.0 and median[1] == pytest.approx(math.log(1 / 9), abs=0.3)


def test_local_gate_statistics_tell_isolated_events_from_edges_and_regions():
    """At the centre of an analytic pattern of unit events (two channels alike), the energy is the 3x3
    mean of x^2 and the coherence the 3x3 mean of box3(x)^2 over it: an isolated event 1/9 and
    (1/81) / (1/9) = 1/9, a straight line 1/3 and (1/9) / (1/3) = 1/3, a uniform region 1 and 1."""
    from neuspike.nets.network import LocalGate

    h = w = 31
    point, line, region = torch.zeros(3, 1, 2, h, w)
    point[..., 15, 15] = 1.0
    line[..., :, 15] = 1.0
    region[...] = 1.0
    eps = LocalGate.EPS
    expected = {"point": (1 / 9, 1 / 81), "line": (1 / 3, 1 / 9), "region": (1.0, 1.0)}
    for name, events in (("point", point), ("line", line), ("region", region)):
        energy, coherent = expected[name]
        c = LocalGate.statistics(events)[0, :, 15, 15]
        assert float(c[0]) == pytest.approx(math.log(eps + energy), abs=1e-5), name
        assert float(c[1]) == pytest.approx(math.log(eps + coherent) - math.log(eps + energy), abs=1e-5), name
    # the coherence orders noise < edge < region whatever the events' scale (eps aside)
    scaled = [float(LocalGate.statistics(10.0 * e)[0, 1, 15, 15]) for e in (point, line, region)]
    assert scaled[0] < scaled[1] < scaled[2]
    assert scaled[0] == pytest.approx(math.log(1 / 9), abs=0.01) and scaled[1] == pytest.approx(math.log(1 / 3), abs=0.01)


def test_local_gate_scales_each_level_by_its_blocks_mean(one_torch_thread):
    """Saturated logits give gains of 2 everywhere; the gains of a level are the block means of the
    full-resolution map, and the padding around the frame has a gain of 1."""
    from neuspike.nets.network import LocalGate

    logits = torch.full((1, 4, 5, 6), -1e4)
    gains = LocalGate.level_gains(logits, (8, 8))
    assert [tuple(g.shape[-2:]) for g in gains] == [(8, 8), (4, 4), (2, 2), (1, 1)]
    assert torch.equal(gains[0][..., :5, :6], torch.zeros(1, 1, 5, 6))
    assert torch.equal(gains[0][..., 5:, :], torch.ones(1, 1, 3, 8))
    assert float(gains[3]) == pytest.approx(1.0 - 30 / 64)  # 30 of 64 pixels shut, the rest padding
    torch.manual_seed(7)
    net = NeuSpikeNet(head="support-count", motion_gate="stats-local").eval()
    x, m, q = torch.rand(1, 32, 24, 40), torch.randn(1, 32, 24, 40), torch.full((1, 1, 1, 1), 0.02)
    with torch.no_grad():
        net.local_gate.out.bias.fill_(-1e4)  # every map 0 inside the frame: the motion path silenced there
        silenced = net(x, m, q)
    assert torch.allclose(silenced, net.forward_texture_only(x, q), atol=1e-6)


def test_learned_input_transformers_start_as_the_fixed_network_and_keep_the_fixed_basis(one_torch_thread):
    """``transformer="learned"`` adds x + conv1x1(relu(conv3x3(x))) on each path (10,304 parameters a
    path, the 1x1 layer zero), so fixed weights load and give the same images; once it is not zero it
    changes the encoders' input, while the support head still weighs the fixed rates (the output
    stays a convex combination of them plus the correction)."""
    from neuspike.methods.weights import load_state_strict

    torch.manual_seed(5)
    fixed = NeuSpikeNet(head="support-count", motion_gate="stats").eval()
    learned = NeuSpikeNet(head="support-count", motion_gate="stats", transformer="learned").eval()
    per_path = (9 * 32 * 32 + 32) + (32 * 32 + 32)
    count = lambda net: sum(p.numel() for p in net.parameters())  # noqa: E731
    assert count(learned) - count(fixed) == 2 * per_path == 20_608
    spike = NeuSpikeNet(head="support-count", spike_only=True, transformer="learned")
    assert count(spike) - count(NeuSpikeNet(head="support-count", spike_only=True)) == per_path
    assert not hasattr(spike, "event_transformer")
    load_state_strict(learned, fixed.state_dict(), "fixed", may_lack=learned.STARTS_AS_IDENTITY)
    x, m, q = torch.rand(2, 32, 20, 36), torch.randn(2, 32, 20, 36), torch.full((2, 1, 1, 1), 0.02)
    with torch.no_grad():
        for net in (fixed, learned):  # the support head's prediction layer starts at zero: give it weights
            torch.manual_seed(6)
            net.predict.weight.normal_(0, 0.05)
        assert torch.equal(learned(x, m, q), fixed(x, m, q))
        assert torch.equal(learned.forward_texture_only(x, q), fixed.forward_texture_only(x, q))
        learned.spike_transformer.out.weight.normal_(0, 0.1)
        assert not torch.allclose(learned(x, m, q), fixed(x, m, q))
        # the prediction layer silenced: the support head gives the mean of the fixed rates, whatever T does
        learned.predict.weight.zero_()
        learned.predict.bias.zero_()
        assert torch.allclose(learned(x, m, q), x.mean(dim=1, keepdim=True), atol=1e-6)
    with pytest.raises(InputError, match="transformer"):
        NeuSpikeNet(transformer="attention")


def test_support_cue_starts_as_the_network_without_it_and_reaches_the_support_softmax(one_torch_thread):
    """``support_cue="spread"`` adds conv3x3(2 -> 16) + conv1x1(16 -> 33) (865 parameters) whose last
    layer is zero: weights trained without it load and give the same images, for the fusion network
    and its spike-only variant. Once it is not zero it moves the support; with the prediction layer
    and the cue's output at zero the image is the mean of the estimates again."""
    from neuspike.methods.weights import load_state_strict

    torch.manual_seed(7)
    count = lambda net: sum(p.numel() for p in net.parameters())  # noqa: E731
    for spike_only, gate in ((False, "stats"), (True, "none")):
        plain = NeuSpikeNet(head="support-count", motion_gate=gate, spike_only=spike_only).eval()
        cued = NeuSpikeNet(head="support-count", motion_gate=gate, spike_only=spike_only, support_cue="spread").eval()
        assert count(cued) - count(plain) == conv(2, 16) + conv(16, 33, k=1) == 865
        load_state_strict(cued, plain.state_dict(), "plain", may_lack=cued.STARTS_AS_IDENTITY)
        x, q = torch.rand(2, 32, 20, 36), torch.full((2, 1, 1, 1), 0.02)
        inputs = (x, q) if spike_only else (x, torch.randn(2, 32, 20, 36), q)
        with torch.no_grad():
            for net in (plain, cued):
                torch.manual_seed(8)
                net.predict.weight.normal_(0, 0.05)
            assert torch.equal(cued(*inputs), plain(*inputs))
            cued.support_cue.out.weight.normal_(0, 0.5)
            assert not torch.allclose(cued(*inputs), plain(*inputs))
            cued.predict.weight.zero_()
            cued.predict.bias.zero_()
            cued.support_cue.out.weight.zero_()
            assert torch.allclose(cued(*inputs), x.mean(dim=1, keepdim=True), atol=1e-6)
    with pytest.raises(InputError, match="support_cue"):
        NeuSpikeNet(head="support", support_cue="spread")
    with pytest.raises(InputError, match="support_cue"):
        NeuSpikeNet(head="support-count", support_cue="edges")


def test_support_cue_statistics_in_closed_form():
    """Counts ``n_g = rate_g / q``: constant counts give no dispersion and no change; counts a in the
    first half of the window and b in the second (an edge passing at its centre) give
    log1p(((a - b) / 2)^2 / ((a + b) / 2 + 1)) and log1p(|b - a| / sqrt((a + b) / 2 + 1))."""
    import math

    from neuspike.nets.network import SupportCue

    q = torch.full((1, 1, 1, 1), 0.05)
    flat = torch.full((1, 16, 3, 4), 6 * 0.05)
    assert torch.allclose(SupportCue.statistics(flat, q), torch.zeros(1, 2, 3, 4), atol=1e-6)
    a, b = 2.0, 10.0
    step = torch.cat([torch.full((1, 8, 3, 4), a), torch.full((1, 8, 3, 4), b)], dim=1) * 0.05
    got = SupportCue.statistics(step, q)
    mean = (a + b) / 2
    assert torch.allclose(got[:, 0], torch.full((1, 3, 4), math.log1p(((a - b) / 2) ** 2 / (mean + 1))), atol=1e-5)
    assert torch.allclose(got[:, 1], torch.full((1, 3, 4), math.log1p(abs(b - a) / math.sqrt(mean + 1))), atol=1e-5)
    # a per-pixel quantum map counts each pixel in its own units
    qmap = torch.full((1, 1, 3, 4), 0.05)
    qmap[..., 0, 0] = 0.1
    got = SupportCue.statistics(step, qmap)
    assert torch.allclose(got[:, 0, 0, 0], torch.tensor([math.log1p(2.0 ** 2 / (3.0 + 1))]), atol=1e-5)


def test_motion_gate_statistics_tell_incoherent_events_from_an_edge():
    """The 3x3 mean keeps 1/sqrt(3) of a straight edge's rms (three columns of 1/3) and about 1/3 of
    sparse isolated events' (nine pixels of 1/9)."""
    from neuspike.nets.network import MotionGate

    g = torch.Generator().manual_seed(5)
    h = w = 64
    noise = torch.zeros(1, 32, h, w)
    mask = torch.rand(1, 32, h, w, generator=g) < 0.01
    noise[mask] = torch.where(torch.rand(int(mask.sum()), generator=g) < 0.5, -1.0, 1.0)
    edge = torch.zeros(1, 32, h, w)
    edge[..., w // 2] = 1.0
    spikes = torch.rand(1, 32, h, w, generator=g)
    s_noise, s_edge = MotionGate.statistics(spikes, noise), MotionGate.statistics(spikes, edge)

    def kept(s):  # rms of box3(events) over rms of events
        return (s[:, 96:].exp() - MotionGate.EPS) / (s[:, 64:96].exp() - MotionGate.EPS)

    assert torch.allclose(kept(s_edge), torch.full((1, 32), 3 ** -0.5), atol=0.01)  # top and bottom rows: 1/2
    assert abs(float(kept(s_noise).mean()) - 1.0 / 3.0) < 0.03
    spike_stats = torch.cat([spikes.abs().mean(dim=(2, 3)), spikes.std(dim=(2, 3), correction=0)], dim=1)
    assert torch.allclose(s_noise[:, :64], torch.log(MotionGate.EPS + spike_stats))


@pytest.mark.parametrize("hw", [(1, 1), (1, 6), (2, 2), (5, 7), (250, 400)])
def test_gate_box_mean_is_the_3x3_mean_inside_the_image(hw):
    from neuspike.nets.network import MotionGate

    x = torch.randn(2, 3, *hw, generator=torch.Generator().manual_seed(0))
    expect = torch.nn.functional.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)
    assert torch.allclose(MotionGate.box3(x), expect, atol=1e-6)


def test_key_refinement_starts_as_the_network_without_it_and_can_replace_the_support(one_torch_thread):
    """``key_estimates="isi-sequence"`` adds conv3x3(32 + 10 -> 16) + conv1x1(16 -> 5) (6,149 parameters)
    whose last layer is zero: weights trained without it load and give the same images from the same
    32 channels, for the fusion network and its spike-only variant; the encoders never see the five
    extra channels. With ``a_k = 1`` for one estimate the image is that estimate plus the correction."""
    from neuspike.methods.weights import load_state_strict
    from neuspike.nets.network import KeyRefine

    torch.manual_seed(9)
    count = lambda net: sum(p.numel() for p in net.parameters())  # noqa: E731
    for spike_only, gate in ((False, "stats"), (True, "none")):
        plain = NeuSpikeNet(head="support-count", motion_gate=gate, spike_only=spike_only).eval()
        keyed = NeuSpikeNet(head="support-count", motion_gate=gate, spike_only=spike_only,
                            key_estimates="isi-sequence").eval()
        assert count(keyed) - count(plain) == conv(32 + 10, 16) + conv(16, 5, k=1) == 6149
        with torch.no_grad():
            plain.predict.weight.normal_(0, 0.05)
        load_state_strict(keyed, plain.state_dict(), "plain", may_lack=keyed.STARTS_AS_IDENTITY)
        x, key, q = torch.rand(2, 32, 20, 36), torch.rand(2, 5, 20, 36), torch.full((2, 1, 1, 1), 0.02)
        events = () if spike_only else (torch.randn(2, 32, 20, 36),)
        with torch.no_grad():
            base, convex = plain(x, *events, q, parts=True)
            assert torch.equal(keyed(torch.cat([x, key], 1), *events, q), base)
            keyed.key_refine.out.bias[2] = 1.0  # a_0 = 1: the interval at the key instant replaces the support
            image, same_convex = keyed(torch.cat([x, key], 1), *events, q, parts=True)
            assert torch.equal(same_convex, convex)
            assert torch.allclose(image, key[:, 2:3] + (base - convex), atol=1e-6)
            with pytest.raises(InputError, match="37"):
                keyed(x, *events, q)
    stats = KeyRefine.statistics(torch.full((1, 5, 2, 2), 9 * 0.02), torch.full((1, 1, 2, 2), 4 * 0.02),
                                 torch.full((1, 1, 1, 1), 0.02))
    assert torch.allclose(stats[:, :5], torch.full((1, 5, 2, 2), (9 - 4) / 5 ** 0.5))  # counts 9 against 4
    assert torch.allclose(stats[:, 5:], torch.full((1, 5, 2, 2), float(torch.log1p(torch.tensor(9.0)))))
    with pytest.raises(InputError, match="key_estimates"):
        NeuSpikeNet(head="support", key_estimates="isi-sequence")
    with pytest.raises(InputError, match="key_estimates"):
        NeuSpikeNet(head="support-count", key_estimates="isi")
