"""The switching-median read-out (:func:`neuspike.methods.readout.despeckle`) on analytic images."""

from __future__ import annotations

import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.methods.readout import despeckle
from neuspike.metrics import isolated_outliers


def test_an_isolated_pixel_becomes_its_neighbourhood_median_and_nothing_else_moves():
    image = np.full((7, 9), 0.4, np.float32)
    image[:, 5:] = 0.6  # a step edge: no pixel is beyond all of its neighbours
    image[3, 2] = 0.9  # a bright speck on the flat side
    image[1, 7] = 0.05  # a dark speck on the bright side
    out = despeckle(image, 0.1)
    assert out[3, 2] == np.float32(0.4) and out[1, 7] == np.float32(0.6)
    untouched = np.ones_like(image, bool)
    untouched[3, 2] = untouched[1, 7] = False
    assert np.array_equal(out[untouched], image[untouched])
    assert isolated_outliers(out, np.where(untouched, image, out), data_range=1.0) == 0.0


def test_ramps_texture_and_pixels_within_the_margin_are_left_exactly():
    y, x = np.mgrid[0:32, 0:40]
    ramp = (0.01 * x + 0.005 * y).astype(np.float32)
    assert np.array_equal(despeckle(ramp, 0.1), ramp)
    rng = np.random.default_rng(0)
    texture = rng.uniform(0.3, 0.35, (32, 40)).astype(np.float32)  # every local extremum within 0.05
    assert np.array_equal(despeckle(texture, 0.1), texture)
    bump = np.full((5, 5), 0.5, np.float32)
    bump[2, 2] = 0.59  # beyond its neighbours by 0.09, not 0.1
    assert np.array_equal(despeckle(bump, 0.1), bump)


def test_specks_injected_into_a_photograph_are_removed():
    from skimage import data, filters

    # a photograph without specks of its own (a real isolated pixel would be taken as one, by design)
    clean = filters.gaussian(data.camera()[::4, ::4] / 255.0, sigma=1.0).astype(np.float32)
    assert isolated_outliers(clean, np.zeros_like(clean), data_range=1.0) == 0.0
    rng = np.random.default_rng(1)
    noisy = clean.copy()
    ys, xs = np.mgrid[2:126:6, 2:126:6]  # specks three pixels apart or more: no two share a neighbourhood
    pick = rng.random(ys.shape) < 0.3
    noisy[ys[pick], xs[pick]] = np.where(rng.random(int(pick.sum())) < 0.5, 0.0, 1.0)
    before = isolated_outliers(noisy, clean, data_range=1.0)
    after = isolated_outliers(despeckle(noisy, 0.1), clean, data_range=1.0)
    # a replaced pixel is its neighbourhood's median, inside its neighbours' range: no speck is left
    assert before > 50 / noisy.size and after == 0.0
    err = lambda a: float(np.abs(a - clean).mean())  # noqa: E731
    assert err(despeckle(noisy, 0.1)) < err(noisy)


def test_bad_arguments_are_refused():
    with pytest.raises(InputError, match="margin"):
        despeckle(np.zeros((4, 4), np.float32), 0.0)
    with pytest.raises(InputError, match="shape"):
        despeckle(np.zeros((2, 4, 4), np.float32), 0.1)
    assert despeckle(np.zeros((2, 5), np.float32), 0.1).shape == (2, 5)


def test_the_registered_networks_despeckle_their_read_out():
    import torch

    from neuspike.methods import entry
    from neuspike.nets import DESPECKLE
    from neuspike.nets.method import NeuSpikeNetMethod
    from neuspike.sample import Sample

    for name in ("neuspike-net", "neuspike-net-spike"):
        assert entry(name).params["despeckle"] == DESPECKLE
    params = {**entry("neuspike-net-spike").params, "level": "network"}
    method = NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **params)
    output = torch.full((1, 1, 6, 6), 0.3)
    output[0, 0, 2, 3] = 0.8
    from neuspike.streams import SpikeStream

    spikes = SpikeStream(planes=np.zeros((4, 6, 6), bool), plane_rate_hz=20_000.0, start_s=0.0)
    sample = Sample(height=6, width=6, key_time_s=1e-4, window_start_s=0.0, window_end_s=2e-4, spikes=spikes)
    image = method.to_image(output, sample)
    assert image[2, 3] == np.float32(0.3) and np.all(image == np.float32(0.3))
    with pytest.raises(InputError, match="despeckle"):
        NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **{**params, "despeckle": -0.1})
    off = NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **{**params, "despeckle": 0.0})
    assert "despeckle" not in off.params and off.to_image(output, sample)[2, 3] == np.float32(0.8)


def test_a_speck_left_beside_a_replaced_one_goes_in_a_further_pass():
    """1.0 beside 0.85 on a flat 0.4: the first pass replaces the 1.0 (beyond its brightest neighbour,
    the 0.85, by 0.15); the 0.85, no longer below a brighter neighbour, is an outlier then and goes next."""
    image = np.full((7, 7), 0.4, np.float32)
    image[3, 3], image[3, 4] = 1.0, 0.85
    out = despeckle(image, 0.1)
    assert np.all(out == np.float32(0.4))
    assert image[3, 3] == np.float32(1.0)  # the caller's image is left as it was
