"""A very dark scene (a gain so small that a window's detection floor maps above white): TFI and the
complementary filter draw it dark, not white, and leave every brighter case as it was."""

import numpy as np
import pytest

from baselines.fusion_complementary import DARK_FLOOR_SPIKES, ComplementaryFusion
from baselines.tfi import TFI, tfi_rate
from neuspike.methods.normalisation import rate_to_image
from neuspike.sample import Sample
from neuspike.streams import EventStream, SpikeStream

RATE_HZ = 20_000.0
T, H, W = 256, 12, 10


def _sample(planes: np.ndarray, gain: float) -> Sample:
    stream = SpikeStream(planes, plane_rate_hz=RATE_HZ, gain=gain, dark_rate=0.0)
    return Sample(height=H, width=W, key_time_s=(T // 2) / RATE_HZ, window_start_s=0.0, window_end_s=T / RATE_HZ,
                  spikes=stream, events=EventStream.empty(W, H), event_threshold=0.2)


def _dark_planes(rate: float, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random((T, H, W)) < rate


@pytest.mark.parametrize("method", [TFI, ComplementaryFusion])
def test_a_scene_below_the_detection_floor_is_drawn_dark_not_white(method):
    gain = 1 / 1024  # radiance 0.25 fires 1/4096 spikes a plane: most pixels are silent in 256 planes
    image = method().reconstruct(_sample(_dark_planes(0.25 * gain), gain))
    assert float(np.median(image)) <= 1 / 256  # the silent majority is black (it was white: the floor / gain >= 1)
    assert float(image.mean()) < 0.5


def test_tfi_counts_a_side_without_a_spike_only_below_the_floor_and_says_so():
    planes = _dark_planes(0.05)
    gain = 1 / 1024
    method = TFI()
    image = method.reconstruct(_sample(planes, gain))
    assert "counted" in method.last_normalisation
    rate = tfi_rate(planes, T // 2)
    both = planes[: T // 2 + 1].any(axis=0) & planes[T // 2 + 1:].any(axis=0)
    rate[~both] = planes[:, ~both].sum(axis=0) / T
    np.testing.assert_array_equal(image, rate_to_image(rate, gain, dark_rate=0.0)[0])
    # at a gain whose floor maps below white the bound rule stands, bit for bit
    gain = 1 / 64
    method = TFI()
    image = method.reconstruct(_sample(planes, gain))
    np.testing.assert_array_equal(image, rate_to_image(tfi_rate(planes, T // 2), gain, dark_rate=0.0)[0])
    assert "counted" not in method.last_normalisation


def test_the_complementary_floor_changes_only_where_it_would_be_white():
    planes = _dark_planes(0.05)
    planes[:, 0, 0] = False
    n = T // 2
    for gain, floor in ((1 / 64, DARK_FLOOR_SPIKES / n), (1 / 1024, (1 / 1024) / 256)):
        image = ComplementaryFusion().reconstruct(_sample(planes, gain))
        expected = np.maximum(planes[:n].mean(axis=0), floor)
        np.testing.assert_allclose(image, rate_to_image(expected, gain, dark_rate=0.0)[0], rtol=0, atol=1e-7)
