"""The spike-count model behind a counted level, against the spike camera itself."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from neuspike.conditions import effect
from neuspike.methods.counting import expected_count, initial_state, level_shift
from neuspike.sensors.spike_camera import SpikeCamera

T = 256


def capture(frame: np.ndarray, *, light: float, random_start: bool, seed: int = 0):
    effects = (effect("initial_charge"),) if random_start else ()
    cam = SpikeCamera(frame.shape[1], frame.shape[0], light=light, effects=effects, rng=np.random.default_rng(seed))
    return cam.capture(frame[None], hold_planes=T)


def test_a_dark_pixel_fires_the_charge_it_started_with():
    """Closed form at mu = 0: sum_k Phi(-k) = 0.1833 spikes; far from 0 the count is mu - 1/2."""
    assert expected_count(np.array([0.0]), "normal")[0] == pytest.approx(sum(norm.cdf(-k) for k in range(1, 12)), abs=1e-6)
    np.testing.assert_allclose(expected_count(np.array([20.0, 100.0]), "normal"), [19.5, 99.5], atol=1e-6)
    np.testing.assert_allclose(expected_count(np.array([0.2, 3.0]), "running"), [0.2, 3.0])
    np.testing.assert_allclose(expected_count(np.array([0.2, 3.0]), "rest"), [0.0, 2.5])
    with pytest.raises(ValueError, match="state"):
        expected_count(np.zeros(1), "warm")


@pytest.mark.parametrize("radiance", [0.0, 0.02, 0.1, 0.6])
def test_the_model_predicts_what_the_camera_counts(radiance):
    """Mean count of 40,000 pixels of one radiance with Algorithm 1's random start, at L = 1/32."""
    frame = np.full((200, 200), radiance, np.float32)
    stream = capture(frame, light=1 / 32, random_start=True)
    counted = stream.planes.sum(axis=0).mean()
    predicted = expected_count(np.array([T * stream.gain * radiance]), "normal")[0]
    assert counted == pytest.approx(predicted, abs=0.01)
    assert initial_state(stream) == "normal"
    assert initial_state(capture(frame, light=1 / 32, random_start=False)) == "rest"


def test_level_shift_undoes_an_offset_of_a_dim_image_where_the_linear_rule_cannot():
    """A dim frame (most of it black) and its truth shifted up by 0.05: the shift that predicts the
    spikes brings it back to within 0.005; the linear rule (mean count + 1/2) misses by 0.08."""
    rng = np.random.default_rng(1)
    frame = np.zeros((120, 160), np.float32)
    frame[30:60, 40:100] = 0.6
    frame += rng.uniform(0, 0.03, frame.shape).astype(np.float32)
    stream = capture(frame, light=1 / 32, random_start=True)
    counts = stream.planes.sum(axis=0)
    shift = level_shift(frame + 0.05, counts, planes=T, gain=stream.gain, dark_rate=0.0, state="normal")
    assert shift == pytest.approx(-0.05, abs=0.005)
    linear = (counts.mean() + 0.5) / (T * stream.gain) - float(frame.mean())
    assert linear > 0.06  # the rule it replaces
    # nothing can explain an empty window but black: the shift stops at -1
    assert level_shift(frame, np.zeros_like(counts), planes=T, gain=stream.gain, dark_rate=0.0,
                       state="running") == -1.0
