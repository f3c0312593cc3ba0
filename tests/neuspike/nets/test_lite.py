"""The compact NeuSpike-Net design (LITE_DESIGN): at most a quarter of the full networks' FLOPs at the
sweeps' frame, the same inputs and output, and the full networks untouched by the new parameters."""

import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from neuspike.errors import InputError
from neuspike.nets import LITE_DESIGN, SHIPPED_DESIGN
from neuspike.nets.network import DECODER_CHANNELS, ENCODER_CHANNELS, NeuSpikeNet, scaled_channels


def _net(spike_only: bool, **kw) -> NeuSpikeNet:
    return NeuSpikeNet(head="support-count", spike_only=spike_only, motion_gate="none" if spike_only else "stats",
                       **SHIPPED_DESIGN, **kw).eval()


def _inputs(net: NeuSpikeNet, h: int, w: int) -> tuple[torch.Tensor, ...]:
    gen = torch.Generator().manual_seed(0)
    spikes = torch.rand(1, 32 + net.key_channels, h, w, generator=gen)
    quantum = torch.full((1, 1, 1, 1), 0.05)
    return (spikes, quantum) if net.spike_only else (spikes, torch.rand(1, 32, h, w, generator=gen), quantum)


def _gflop(net: NeuSpikeNet) -> float:
    with torch.no_grad(), FlopCounterMode(display=False) as counter:
        net(*_inputs(net, 250, 400))
    return counter.get_total_flops() / 1e9


@pytest.mark.parametrize("spike_only", [True, False])
def test_lite_is_at_most_a_quarter_of_the_full_networks_flops_at_400x250(spike_only, one_torch_thread):
    full, lite = _gflop(_net(spike_only)), _gflop(_net(spike_only, **LITE_DESIGN))
    assert lite <= full / 4, (lite, full)
    assert lite >= full / 10  # (a sanity bound: the same representations and levels, not a different network)


def test_default_width_builds_the_full_network_parameter_for_parameter():
    full = _net(False)
    assert scaled_channels(ENCODER_CHANNELS, 1.0) == ENCODER_CHANNELS
    assert full.predict.kernel_size == (3, 3)
    shapes = {k: tuple(v.shape) for k, v in full.state_dict().items()}
    again = {k: tuple(v.shape) for k, v in _net(False, width=1.0, head_kernel=3).state_dict().items()}
    assert shapes == again
    assert shapes["texture.layers.0.conv.weight"][0] == ENCODER_CHANNELS[0]


def test_lite_takes_the_same_inputs_and_gives_an_image_of_the_input_size():
    for spike_only in (True, False):
        net = _net(spike_only, **LITE_DESIGN)
        assert net.predict.kernel_size == (1, 1)
        assert net.up3.conv.out_channels == scaled_channels(DECODER_CHANNELS, LITE_DESIGN["width"])[2]
        with torch.no_grad():
            out = net(*_inputs(net, 37, 53))
        assert out.shape == (1, 1, 37, 53)
        assert torch.isfinite(out).all()


def test_bad_width_and_kernel_are_refused():
    for bad in (0.0, -1, 3.0, True, "half"):
        with pytest.raises(InputError, match="width"):
            NeuSpikeNet(width=bad)
    with pytest.raises(InputError, match="head_kernel"):
        NeuSpikeNet(head_kernel=5)


def test_the_method_keeps_full_parameters_as_they_were_and_records_the_lite_ones():
    from neuspike.methods import create
    from neuspike.nets.method import NeuSpikeNetMethod

    full = create("neuspike-net-spike")
    assert "width" not in full.params and "head_kernel" not in full.params
    params = {k: v for k, v in full.params.items() if k not in ("precision", "weights_file")}
    lite = NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **{**params, **LITE_DESIGN})
    assert lite.params["width"] == LITE_DESIGN["width"] and lite.params["head_kernel"] == 1
    assert lite.module.width == LITE_DESIGN["width"]


def test_weights_of_one_size_are_refused_by_a_method_of_another(tmp_path):
    """A card records the width; a full method refuses a compact file by its design, not by a shape error."""
    from neuspike.errors import FormatError
    from neuspike.methods import create
    from neuspike.methods.weights import save_safetensors
    from neuspike.nets.method import NeuSpikeNetMethod

    full = create("neuspike-net-spike")
    params = {k: v for k, v in full.params.items() if k not in ("precision", "weights_file")}
    lite = NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **{**params, **LITE_DESIGN})
    path = tmp_path / "lite.safetensors"
    save_safetensors(lite.module, path, card={"model": {"params": {**params, **LITE_DESIGN}}})
    with pytest.raises(FormatError, match="trained for .*'width': 0.45"):
        NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **params).load_file(path)
