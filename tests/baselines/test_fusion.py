"""``fusion-complementary`` against the per-event recursion, its spike estimate and a simulated pan."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import baselines.fusion_complementary as fusion_module
from baselines.event_integration import EventIntegration, log_to_image
from baselines.fusion_complementary import (
    DARK_FLOOR_SPIKES,
    ComplementaryFusion,
    causal_planes,
    causal_spike_rate,
    complementary_filter,
    matched_cutoff_hz,
)
from neuspike.methods.normalisation import rate_to_image
from baselines.tfp import TFP
from neuspike.conditions import Condition
from neuspike.errors import InputError
from neuspike.metrics import ssim
from neuspike.sample import Sample
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulation.window import simulate_window
from neuspike.streams import EventStream, SpikeStream

RATE_HZ = 20_000.0


def spikes(planes: np.ndarray, gain: float | None = 0.25) -> SpikeStream:
    return SpikeStream(planes, plane_rate_hz=RATE_HZ, gain=gain, dark_rate=0.0)


def random_events(rng: np.random.Generator, n: int, height: int, width: int, t0: float, t1: float) -> EventStream:
    t = np.sort(rng.uniform(t0, t1, n))
    return EventStream(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice(np.array([-1, 1]), n),
                       width, height)


def sample_of(stream: SpikeStream, events: EventStream, *, key_plane: int | None = None,
              threshold: float | None = 0.2) -> Sample:
    """Key instant at the start of ``key_plane`` (default the middle plane), as for simulated data."""
    t = stream.num_planes
    key = (t // 2 if key_plane is None else key_plane) / RATE_HZ
    return Sample(height=stream.height, width=stream.width, key_time_s=key, window_start_s=0.0,
                  window_end_s=t / RATE_HZ, spikes=stream, events=events, event_threshold=threshold)


# --- the spike estimate --------------------------------------------------------------------------


def test_causal_planes_are_those_centred_before_the_key_instant():
    # Simulated windows: key at the start of plane 128 of 256 -> planes 0..127.
    assert causal_planes(256, RATE_HZ, 0.0, 128 / RATE_HZ) == (0, 128)
    # Real recordings: key at the centre of plane K -> planes 0..K.
    assert causal_planes(200, RATE_HZ, 1.5, 1.5 + 99.5 / RATE_HZ) == (0, 100)
    # Newest planes only, and never nothing.
    assert causal_planes(256, RATE_HZ, 0.0, 128 / RATE_HZ, 32) == (96, 128)
    assert causal_planes(256, RATE_HZ, 0.0, 0.0) == (0, 1)
    assert causal_planes(8, RATE_HZ, 0.0, 1.0) == (0, 8)
    with pytest.raises(InputError):
        causal_planes(8, RATE_HZ, 0.0, 1e-4, 0)


def test_matched_cutoff_equals_the_mean_age_of_the_planes():
    # 128 planes before the key instant: mean age 64 planes = 3.2 ms -> 1 / (2 pi 3.2 ms) = 49.7 Hz.
    assert matched_cutoff_hz(RATE_HZ, 0.0, 128 / RATE_HZ, 0, 128) == pytest.approx(1 / (2 * math.pi * 3.2e-3))
    assert matched_cutoff_hz(RATE_HZ, 0.0, 40 / RATE_HZ, 8, 40) == pytest.approx(1 / (2 * math.pi * 16 / RATE_HZ))
    # floored at half a plane
    assert matched_cutoff_hz(RATE_HZ, 0.0, 0.5 / RATE_HZ, 0, 1) == pytest.approx(RATE_HZ / math.pi)


def test_no_events_gives_the_spike_estimate_exactly():
    rng = np.random.default_rng(0)
    planes = rng.random((32, 6, 7)) < 0.3
    planes[:, 0, 0] = False  # a dark pixel: the floor of half a spike in 16 planes
    expected_rate = np.maximum(planes[:16].mean(axis=0), DARK_FLOOR_SPIKES / 16)
    for events in (EventStream.empty(7, 6), random_events(rng, 50, 6, 7, 17 / RATE_HZ, 32 / RATE_HZ)):
        method = ComplementaryFusion()
        image = method.reconstruct(sample_of(spikes(planes), events))
        np.testing.assert_array_equal(image, rate_to_image(expected_rate, 0.25, dark_rate=0.0)[0])
        assert image[0, 0] == np.float32(0.5 / 16 / 0.25)
        assert method.last_planes == (0, 16) and method.last_normalisation == "gain"
        robust = ComplementaryFusion().reconstruct(sample_of(spikes(planes, gain=None), events))
        np.testing.assert_array_equal(robust, log_to_image(np.log(expected_rate))[0])


def filter_by_recursion(events: EventStream, frame_log: np.ndarray, threshold: float, alpha: float,
                        time_s: float) -> np.ndarray:
    """The complementary filter one event at a time from L(t0) = L_F, then decayed to ``time_s``."""
    level = frame_log.astype(np.float64).copy()
    t0 = events.t_s[0] if len(events) else time_s
    last = np.full(frame_log.shape, t0)
    for t, x, y, p in zip(events.t_s, events.x, events.y, events.p):
        beta = math.exp(-alpha * (t - last[y, x]))
        level[y, x] = beta * level[y, x] + (1 - beta) * frame_log[y, x] + p * threshold
        last[y, x] = t
    beta = np.exp(-alpha * (time_s - last))
    return beta * level + (1 - beta) * frame_log


@pytest.mark.parametrize("seed", range(6))
def test_closed_form_equals_the_recursion(seed):
    rng = np.random.default_rng(seed)
    h, w = 3, 4
    events = random_events(rng, int(rng.integers(0, 300)), h, w, -0.03, 0.0)
    frame_log = rng.normal(-2.0, 1.0, (h, w))
    cutoff_hz = float(rng.uniform(5.0, 300.0))
    threshold = float(rng.uniform(0.05, 0.5))
    expected = filter_by_recursion(events, frame_log, threshold, 2 * math.pi * cutoff_hz, 0.002)
    got = complementary_filter(events, frame_log=frame_log, threshold=threshold, cutoff_hz=cutoff_hz, time_s=0.002)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)


def test_method_is_the_filter_read_out_at_the_key_instant():
    rng = np.random.default_rng(4)
    h, w = 8, 9
    planes = rng.random((64, h, w)) < 0.2
    events = random_events(rng, 2000, h, w, -0.01, 64 / RATE_HZ)
    method = ComplementaryFusion(threshold=0.15)
    image = method.reconstruct(sample_of(spikes(planes, gain=0.5), events))
    key = 32 / RATE_HZ
    frame = np.maximum(planes[:32].mean(axis=0), DARK_FLOOR_SPIKES / 32)
    cutoff = 1 / (2 * math.pi * 16 / RATE_HZ)
    assert method.last_cutoff_hz == pytest.approx(cutoff)
    assert (method.last_threshold, method.last_threshold_source) == (0.15, "parameter")
    fused = complementary_filter(events.between(-1.0, key), frame_log=np.log(frame), threshold=0.15,
                                 cutoff_hz=cutoff, time_s=key)
    np.testing.assert_allclose(image, np.clip(np.exp(fused) / 0.5, 0, 1), rtol=1e-6, atol=1e-7)
    # a fixed crossover and a shorter spike window are honoured
    method = ComplementaryFusion(cutoff_hz=100.0, spike_planes=8)
    method.reconstruct(sample_of(spikes(planes), events))
    assert method.last_cutoff_hz == 100.0 and method.last_planes == (24, 32)


def test_invalid_parameters_and_inputs_raise():
    for kwargs in ({"cutoff_hz": 0.0}, {"cutoff_hz": -5.0}, {"spike_planes": 0}, {"spike_planes": 2.5},
                   {"threshold": 0.0}):
        with pytest.raises(InputError):
            ComplementaryFusion(**kwargs)
    events = EventStream(np.array([1.0]), np.array([0]), np.array([0]), np.array([1]), 2, 2)
    with pytest.raises(InputError, match="after the output time"):
        complementary_filter(events, frame_log=np.zeros((2, 2)), threshold=0.2, cutoff_hz=10.0, time_s=0.0)
    with pytest.raises(InputError, match="finite"):
        complementary_filter(events, frame_log=np.full((2, 2), -np.inf), threshold=0.2, cutoff_hz=10.0, time_s=2.0)
    with pytest.raises(InputError):
        complementary_filter(events, frame_log=np.zeros((3, 2)), threshold=0.2, cutoff_hz=10.0, time_s=2.0)
    with pytest.raises(InputError):
        causal_spike_rate(np.zeros((4, 2, 2), bool), 2, 2)
    only_events = Sample(height=2, width=2, key_time_s=0.0, window_start_s=0.0, window_end_s=0.0, events=events)
    with pytest.raises(InputError, match="lacks"):
        ComplementaryFusion().reconstruct(only_events)


def test_registered_as_one_entry_needing_both_inputs():
    entries = {}
    fusion_module.register_methods(lambda name, factory, **kw: entries.setdefault(name, (factory, kw)))
    factory, kw = entries["fusion-complementary"]
    method = factory(name="fusion-complementary", **kw["params"])
    assert method.inputs == frozenset({"spikes", "events"}) and method.params["cutoff_hz"] is None


# --- spike hard cases ----------------------------------------------------------------------------


@pytest.mark.parametrize("case", ["no spikes", "every plane", "single plane", "tiny gain", "no gain"])
def test_spike_hard_cases_give_a_clean_image(case):
    rng = np.random.default_rng(9)
    h, w = 10, 12
    planes = {"no spikes": np.zeros((256, h, w), bool), "every plane": np.ones((256, h, w), bool),
              "single plane": rng.random((1, h, w)) < 0.5}.get(case, rng.random((256, h, w)) < 0.01)
    gain = {"tiny gain": 1e-6, "no gain": None}.get(case, 1 / 32)
    events = random_events(rng, 5000, h, w, -0.02, planes.shape[0] / RATE_HZ)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = ComplementaryFusion().reconstruct(sample_of(spikes(planes, gain), events))
    assert image.dtype == np.float32 and np.isfinite(image).all() and 0 <= image.min() and image.max() <= 1
    if case == "every plane":
        assert image.max() == 1.0


# --- a simulated fast pan ------------------------------------------------------------------------


def test_beats_both_parents_on_a_fast_textured_pan():
    """A held-out textured photograph panning fast (S = 256: 11 px per window) at L = 1/8, no noise.

    (On smooth pictures such as ``clock`` the window-centred TFP, which averages twice as many planes,
    stays ahead: the fusion's gain is in texture under motion.)
    """
    scene = make_scene(SceneSpec(kind="pan", image="gravel", size=(160, 100), velocity_px_s=(1000.0, 300.0)))
    sample = simulate_window(scene, Condition(light=1 / 8, motion=256), rng=np.random.default_rng(0),
                             history_s=4 * 0.0128).to_sample()
    gt = sample.ground_truth
    fused = ssim(ComplementaryFusion().reconstruct(sample), gt, data_range=1.0)
    spikes_only = ssim(TFP().reconstruct(sample), gt, data_range=1.0)
    events_only = ssim(EventIntegration().reconstruct(sample), gt, data_range=1.0)
    assert fused > max(spikes_only, events_only) + 0.1, (fused, spikes_only, events_only)
