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


# -- the local Wiener filter ----------------------------------------------------------------------

def _flat_with_noise(sigma: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    clean = np.full((60, 80), 0.3, np.float32)
    noisy = clean + np.random.default_rng(seed).normal(0.0, sigma, clean.shape).astype(np.float32)
    return clean, noisy


def test_noise_level_reads_the_deviation_of_white_noise_and_nothing_on_clean_shading():
    """The mean absolute Laplacian of white noise of deviation s is 6 sqrt(2 / pi) s: the median of the 7x7
    means reads s within a few per cent, the 5th percentile about 0.65 s (the boxes that happen to vary least); a clean ramp or flat image reads 0."""
    from neuspike.methods.readout import noise_level

    clean, noisy = _flat_with_noise(0.03)
    assert noise_level(noisy, 50.0) == pytest.approx(0.03, rel=0.04)
    assert 0.5 * 0.03 < noise_level(noisy, 5.0) < 0.8 * 0.03  # the least-varying boxes: about 0.65 s
    ramp = np.add.outer(np.linspace(0, 0.5, 60), np.linspace(0, 0.3, 80)).astype(np.float32)
    assert noise_level(ramp, 5.0) < 1e-6 and noise_level(clean, 5.0) == 0.0


def test_wiener_takes_white_noise_off_a_flat_image_by_about_the_box():
    """On a flat image with white noise every neighbourhood varies about as noise does, so each pixel takes
    its 7x7 mean: the error's standard deviation falls by up to sqrt(49) = 7 (at least 3 here, leaving the
    neighbourhoods whose sample variance exceeds the noise estimate)."""
    from neuspike.methods.readout import wiener

    clean, noisy = _flat_with_noise(0.03)
    out = wiener(noisy, 5.0)
    before, after = np.std(noisy - clean), np.std(out - clean)
    assert after < before / 3
    assert abs(float(out.mean()) - float(noisy.mean())) < 1e-3  # the level is kept


def test_wiener_leaves_a_clean_piecewise_flat_image_as_it_was():
    """A clean image with flat regions: its least-varying neighbourhoods do not vary at all, so the noise
    estimate is zero and nothing is smoothed (the edges keep their values)."""
    from neuspike.methods.readout import wiener

    image = np.full((40, 60), 0.2, np.float32)
    image[:, 30:] = 0.7
    image[10:20, 5:15] = 0.9
    assert np.array_equal(wiener(image, 2.0), image)


def test_wiener_keeps_an_edge_far_above_the_noise():
    """A step of 0.5 under noise of 0.02: the flat sides are smoothed, the step stays a step (the pixels beside
    it keep their side's level within the noise)."""
    from neuspike.methods.readout import wiener

    rng = np.random.default_rng(3)
    clean = np.full((50, 50), 0.2, np.float32)
    clean[:, 25:] = 0.7
    noisy = clean + rng.normal(0.0, 0.02, clean.shape).astype(np.float32)
    out = wiener(noisy, 2.0)
    assert np.all(np.abs(out[:, 24] - 0.2) < 0.08) and np.all(np.abs(out[:, 25] - 0.7) < 0.08)
    assert np.std(out[:, :20] - clean[:, :20]) < np.std(noisy[:, :20] - clean[:, :20]) / 2


def test_wiener_commutes_with_an_offset_and_a_gain():
    """The local mean, the local variance and the noise estimate move together: filtering a * x + b gives a
    times the filtered x plus b (the filter has no scale of its own)."""
    from neuspike.methods.readout import wiener

    _, noisy = _flat_with_noise(0.05, seed=1)
    noisy[20:40, 30:60] += 0.3
    base = wiener(noisy, 2.0).astype(np.float64)
    moved = wiener((0.5 * noisy + 0.1).astype(np.float32), 2.0).astype(np.float64)
    np.testing.assert_allclose(moved, 0.5 * base + 0.1, atol=2e-6)


def test_wiener_refuses_what_it_cannot_filter():
    from neuspike.methods.readout import wiener

    image = np.zeros((8, 8), np.float32)
    for bad in (0.0, -1.0, float("nan"), True):
        with pytest.raises(InputError, match="scale"):
            wiener(image, bad)
    with pytest.raises(InputError, match="window"):
        wiener(image, 2.0, window=4)
    with pytest.raises(InputError, match="quantile"):
        wiener(image, 2.0, quantile=100)
    with pytest.raises(InputError, match="shape"):
        wiener(np.zeros((2, 8, 8), np.float32), 2.0)
    small = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(wiener(small, 2.0), small)  # smaller than the box: left as it was
    assert wiener(image, 2.0) is not image


def test_the_registered_networks_smooth_their_read_out():
    import torch

    from neuspike.methods import entry
    from neuspike.nets import WIENER
    from neuspike.nets.method import NeuSpikeNetMethod
    from neuspike.methods.readout import wiener
    from neuspike.sample import Sample
    from neuspike.streams import SpikeStream

    for name in ("neuspike-net", "neuspike-net-spike"):
        assert entry(name).params["wiener"] == WIENER
    params = {**entry("neuspike-net-spike").params, "level": "network", "despeckle": 0.0}
    method = NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **params)
    _, noisy = _flat_with_noise(0.03, seed=2)
    output = torch.from_numpy(noisy)[None, None]
    spikes = SpikeStream(planes=np.zeros((4, *noisy.shape), bool), plane_rate_hz=20_000.0, start_s=0.0)
    sample = Sample(height=noisy.shape[0], width=noisy.shape[1], key_time_s=1e-4, window_start_s=0.0,
                    window_end_s=2e-4, spikes=spikes)
    np.testing.assert_array_equal(method.to_image(output, sample), np.clip(wiener(noisy, WIENER), 0, 1))
    with pytest.raises(InputError, match="wiener"):
        NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **{**params, "wiener": -1.0})
    off = NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **{**params, "wiener": 0.0})
    assert "wiener" not in off.params
    np.testing.assert_array_equal(off.to_image(output, sample), np.clip(noisy, 0, 1))
