"""The classical event methods against closed forms, and every event method on the hard cases.

``events-integrate`` must recover a linear log ramp (events built by hand at the exact crossing
times); ``events-highpass`` must equal a step-by-step per-event recursion written here. The hard
cases (no events, one event, a burst of a million events, sensor sizes that are not multiples of
8, a poisoned ground truth) run every event-consuming method: the two classical ones,
``fusion-complementary`` and, when the shared weights are present, ``firenet`` and ``firenet-plus``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import baselines.event_integration as event_module
import baselines.firenet as firenet_module
import baselines.fusion_complementary as fusion_module
from baselines.event_integration import (
    RunningEventSum,
    DEFAULT_THRESHOLD,
    EventHighPass,
    EventIntegration,
    highpass_events,
    integrate_events,
    log_to_image,
    resolve_threshold,
)
from neuspike.errors import InputError
from neuspike.methods.weights import resolve_weights
from neuspike.metrics import affine_fit
from neuspike.sample import Sample
from neuspike.streams import EventStream, SpikeStream
from tests.shared_data import SHARED

pytestmark = pytest.mark.usefixtures("one_torch_thread")

WEIGHTS = SHARED / "weights"
HAVE_WEIGHTS = (WEIGHTS / "firenet" / "firenet.pt").is_file() and (WEIGHTS / "firenet" / "firenet_plus.pt").is_file()

PLANE_RATE_HZ = 20_000.0
PLANES = 32
WINDOW_END_S = PLANES / PLANE_RATE_HZ
KEY_S = 0.5 * WINDOW_END_S


def local_registry() -> dict:
    entries: dict = {}

    def register(name, factory, *, params=None, inputs=None, description="", weights=None):
        assert name not in entries
        entries[name] = (factory, dict(params or {}), weights)

    for module in (event_module, firenet_module, fusion_module):
        module.register_methods(register)
    return entries


REGISTRY = local_registry()
CLASSICAL = ("events-integrate", "events-highpass", "fusion-complementary")
NETWORKS = ("firenet", "firenet-plus")


def create(name: str, **overrides):
    """As :func:`neuspike.methods.create` does: build, then load the entry's file from the user's folder."""
    factory, params, weights = REGISTRY[name]
    method = factory(name=name, **{**params, **overrides})
    if weights is not None:
        method.load_file(resolve_weights(weights.file, WEIGHTS, subdirs=weights.subdirs))
    return method


def method_params():
    for name in CLASSICAL:
        yield pytest.param(name, id=name)
    for name in NETWORKS:
        yield pytest.param(name, id=name, marks=pytest.mark.skipif(not HAVE_WEIGHTS, reason="shared weights absent"))


def make_sample(events: EventStream, *, key_time_s: float = KEY_S, spikes: SpikeStream | None = None,
                threshold: float | None = 0.2, ground_truth=None, window=(0.0, WINDOW_END_S)) -> Sample:
    return Sample(height=events.height, width=events.width, key_time_s=key_time_s, window_start_s=window[0],
                  window_end_s=window[1], spikes=spikes, events=events, event_threshold=threshold,
                  ground_truth=ground_truth)


def random_spikes(rng: np.random.Generator, height: int, width: int, rate: float = 0.2) -> SpikeStream:
    return SpikeStream(rng.random((PLANES, height, width)) < rate, plane_rate_hz=PLANE_RATE_HZ, gain=0.5)


def random_events(rng: np.random.Generator, n: int, height: int, width: int, t0: float, t1: float) -> EventStream:
    t = np.sort(rng.uniform(t0, t1, n))
    return EventStream(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice(np.array([-1, 1]), n),
                       width, height)


# --- events-integrate ----------------------------------------------------------------------------


def ramp_events(rates_per_s: np.ndarray, rows: int, start_s: float, duration_s: float, threshold: float):
    """Events of pixels whose log intensity changes linearly at ``rates_per_s`` (one rate per column).

    A pixel with rate ``a`` crosses its n-th level ``n * threshold`` at ``start + n * threshold / |a|``,
    with polarity ``sign(a)``: ``floor(|a| * duration / threshold)`` events by the end.
    """
    t, x, y, p = [], [], [], []
    for col, a in enumerate(rates_per_s):
        if a == 0:
            continue
        n = int(np.floor(abs(a) * duration_s / threshold + 1e-12))
        times = start_s + np.arange(1, n + 1) * threshold / abs(a)
        for row in range(rows):
            t.append(times)
            x.append(np.full(n, col))
            y.append(np.full(n, row))
            p.append(np.full(n, int(np.sign(a))))
    t = np.concatenate(t)
    order = np.argsort(t, kind="stable")
    cat = lambda parts: np.concatenate(parts)[order]  # noqa: E731
    return EventStream(t[order], cat(x), cat(y), cat(p), len(rates_per_s), rows)


def test_events_integrate_recovers_a_linear_log_ramp():
    threshold, duration = 0.2, 0.05
    rates = (np.arange(24) - 8) * 25.0  # log units per second, OFF ramps on the left
    events = ramp_events(rates, rows=3, start_s=-duration, duration_s=duration, threshold=threshold)
    change = rates * duration  # the true change of log intensity by the key instant
    counts = np.floor(np.abs(change) / threshold + 1e-12) * np.sign(change)
    log_image = integrate_events(events, threshold=threshold, height=3, width=24)
    np.testing.assert_allclose(log_image, np.broadcast_to(threshold * counts, (3, 24)), atol=1e-12)
    assert np.abs(log_image - change).max() < threshold  # within one threshold of the ramp
    # The method: exp(L - offset), so its log is affine in the ramp with slope 1.
    method = EventIntegration()
    image = method.reconstruct(make_sample(events, key_time_s=0.0, window=(-0.01, 0.0)))
    assert method.last_threshold == threshold and method.last_threshold_source == "sample"
    log_out = np.log(image.astype(np.float64))
    ramp = np.broadcast_to(change, (3, 24))
    slope, offset = affine_fit(ramp, log_out)
    assert slope == pytest.approx(1.0, abs=0.02)
    assert np.abs(slope * ramp + offset - log_out).max() < threshold


def test_events_integrate_ignores_events_after_the_key_instant():
    rng = np.random.default_rng(2)
    events = random_events(rng, 400, 5, 6, -0.01, WINDOW_END_S)
    before = events.between(-0.01, KEY_S)
    full = EventIntegration().reconstruct(make_sample(events))
    cut = EventIntegration().reconstruct(make_sample(before))
    np.testing.assert_array_equal(full, cut)
    assert not np.array_equal(full, EventIntegration().reconstruct(make_sample(events, key_time_s=WINDOW_END_S)))


def test_threshold_resolution_order():
    events = EventStream.empty(4, 3)
    assert resolve_threshold(make_sample(events, threshold=0.3), None) == (0.3, "sample")
    assert resolve_threshold(make_sample(events, threshold=None), None) == (DEFAULT_THRESHOLD, "default")
    assert resolve_threshold(make_sample(events, threshold=0.3), 0.1) == (0.1, "parameter")
    with pytest.raises(InputError):
        EventIntegration(threshold=-0.2)


# --- events-highpass -----------------------------------------------------------------------------


def highpass_by_recursion(events: EventStream, threshold: float, alpha: float, time_s: float) -> np.ndarray:
    """Scheerlinck's high-pass filter, one event at a time: L <- exp(-alpha dt) L + c, then a final decay."""
    level = np.zeros((events.height, events.width))
    last = np.full((events.height, events.width), np.nan)
    for t, x, y, p in zip(events.t_s, events.x, events.y, events.p):
        if not np.isnan(last[y, x]):
            level[y, x] *= math.exp(-alpha * (t - last[y, x]))
        level[y, x] += p * threshold
        last[y, x] = t
    for (y, x), t_last in np.ndenumerate(last):
        if not np.isnan(t_last):
            level[y, x] *= math.exp(-alpha * (time_s - t_last))
    return level


@pytest.mark.parametrize("seed", range(5))
def test_highpass_closed_form_equals_the_recursion(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    events = random_events(rng, n, 3, 4, -0.02, 0.0)
    cutoff_hz = float(rng.uniform(1.0, 200.0))
    threshold = float(rng.uniform(0.05, 0.5))
    expected = highpass_by_recursion(events, threshold, 2 * math.pi * cutoff_hz, 0.001)
    got = highpass_events(events, threshold=threshold, cutoff_hz=cutoff_hz, time_s=0.001, height=3, width=4)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("alpha", [0.0, 31.4])
def test_running_event_sum_equals_a_fresh_sum_along_a_stream(alpha):
    """Slices of one stream with timestamps on a coarse grid (many events share a time; instants and
    slice starts fall on events), empty slices, a gap longer than the history and a history that
    grows then shrinks: every update equals a fresh sum (exactly for alpha = 0), and the update is
    refused (a fresh sum) where the new slice reaches back before the previous one or time goes back."""
    rng = np.random.default_rng(7)
    h, w, n = 6, 5, 4000
    t = np.sort(rng.integers(0, 400, n)) * 1e-3  # 400 distinct times, ~10 events each
    t[(t > 0.15) & (t < 0.25)] = 0.3  # a quiet stretch, then a pile-up at one instant
    t = np.sort(t)
    stream = EventStream(t, rng.integers(0, w, n), rng.integers(0, h, n), rng.choice(np.array([-1, 1]), n), w, h)
    running = RunningEventSum()
    previous, prev_first, refused = None, None, 0
    #        (instant, history): instants on the grid; 0.2-0.26 sit in the quiet stretch (empty slices)
    plan = [(0.05, 0.02), (0.051, 0.02), (0.051, 0.02), (0.09, 0.02), (0.12, 0.06), (0.2, 0.02), (0.26, 0.02),
            (0.3, 0.02), (0.301, 0.02), (0.35, 0.06), (0.36, 0.01), (0.33, 0.01), (0.39, 0.01)]
    for key, history in plan:
        events = stream.between(key - history, key)
        got = running.at(events, time_s=key, alpha=alpha, height=h, width=w, previous_s=previous).copy()
        fresh = RunningEventSum().at(events, time_s=key, alpha=alpha, height=h, width=w)
        reaches_back = previous is not None and key >= previous and prev_first is not None and len(events) \
            and events.t_s[0] < prev_first
        expected_stream = previous is not None and key >= previous and not reaches_back
        assert running.last_streamed == expected_stream, (key, history)
        refused += bool(reaches_back)
        if alpha == 0.0:
            assert np.array_equal(got, fresh), key
        else:
            np.testing.assert_allclose(got, fresh, rtol=0, atol=1e-12, err_msg=str(key))
        previous, prev_first = key, (events.t_s[0] if len(events) else None)
    assert refused == 1
    assert not running.at(events, time_s=0.39, alpha=alpha, height=h, width=w).flags.writeable
    with pytest.raises(InputError, match="not before the output time"):
        running.at(stream.between(0.1, 0.2), time_s=float(stream.between(0.1, 0.2).t_s[-1]), alpha=alpha,
                   height=h, width=w)


def test_an_old_event_decays_exponentially():
    alpha = 2 * math.pi * 5.0
    for age in (0.0, 0.0128, 0.1, 1.0):
        events = EventStream(np.array([0.0]), np.array([1]), np.array([0]), np.array([-1]), 2, 1)
        got = highpass_events(events, threshold=0.25, cutoff_hz=5.0, time_s=age, height=1, width=2)
        np.testing.assert_allclose(got, [[0.0, -0.25 * math.exp(-alpha * age)]], rtol=1e-12)
    with pytest.raises(InputError, match="after the output time"):
        highpass_events(events, threshold=0.2, cutoff_hz=5.0, time_s=-1.0, height=1, width=2)


def test_highpass_method_reads_out_at_the_key_instant():
    rng = np.random.default_rng(7)
    events = random_events(rng, 300, 4, 5, -0.05, WINDOW_END_S)
    method = EventHighPass(cutoff_hz=20.0)
    image = method.reconstruct(make_sample(events))
    log_image = highpass_events(events.between(-0.05, KEY_S), threshold=0.2, cutoff_hz=20.0, time_s=KEY_S,
                                height=4, width=5)
    np.testing.assert_array_equal(image, log_to_image(log_image)[0])
    assert method.last_normalisation == "robust-p99"


# --- every event method on the hard cases -------------------------------------------------------


def burst(rng: np.random.Generator, n: int, height: int, width: int) -> EventStream:
    """``n`` events within one microsecond just before the key instant, anywhere on the sensor."""
    return random_events(rng, n, height, width, KEY_S - 2e-6, KEY_S - 1e-6)


def run_clean(method, sample: Sample) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = method.reconstruct(sample)
    assert image.dtype == np.float32 and image.shape == (sample.height, sample.width)
    assert np.isfinite(image).all() and image.min() >= 0.0 and image.max() <= 1.0
    return image


CASES = {
    "no events": lambda rng, h, w: EventStream.empty(w, h),
    "one event": lambda rng, h, w: EventStream(np.array([KEY_S - 1e-4]), np.array([w - 1]), np.array([h - 1]),
                                               np.array([1]), w, h),
    "one event after the key": lambda rng, h, w: EventStream(np.array([KEY_S + 1e-4]), np.array([0]), np.array([0]),
                                                             np.array([-1]), w, h),
    "history and window": lambda rng, h, w: random_events(rng, 20_000, h, w, -0.02, WINDOW_END_S),
    "a pixel with a million events": lambda rng, h, w: EventStream(
        np.linspace(KEY_S - 1e-3, KEY_S - 1e-6, 1_000_000), np.zeros(1_000_000, np.uint16),
        np.zeros(1_000_000, np.uint16), np.ones(1_000_000, np.int8), w, h),
}


@pytest.mark.parametrize("name", list(method_params()))
@pytest.mark.parametrize("case", list(CASES))
def test_hard_cases_give_a_clean_image(name, case):
    rng = np.random.default_rng(11)
    h, w = 180, 240
    sample = make_sample(CASES[case](rng, h, w), spikes=random_spikes(rng, h, w))
    run_clean(create(name), sample)


@pytest.mark.parametrize("name", list(method_params()))
def test_a_burst_of_a_million_events(name):
    rng = np.random.default_rng(12)
    h, w = 180, 240
    sample = make_sample(burst(rng, 1_000_000, h, w), spikes=random_spikes(rng, h, w))
    image = run_clean(create(name), sample)
    assert image.std() > 0  # the burst is seen


@pytest.mark.parametrize("name", list(method_params()))
@pytest.mark.parametrize("size", [(346, 260), (240, 180)], ids=["346x260", "240x180"])
def test_sensor_sizes_not_multiples_of_8(name, size):
    w, h = size
    rng = np.random.default_rng(13)
    sample = make_sample(random_events(rng, 40_000, h, w, -0.02, WINDOW_END_S), spikes=random_spikes(rng, h, w))
    run_clean(create(name), sample)


@pytest.mark.parametrize("name", list(method_params()))
def test_methods_never_read_the_ground_truth(name):
    rng = np.random.default_rng(14)
    h, w = 24, 30
    events = random_events(rng, 5_000, h, w, -0.02, WINDOW_END_S)
    spikes = random_spikes(rng, h, w)
    method = create(name)
    clean = method.reconstruct(make_sample(events, spikes=spikes))
    poisoned = method.reconstruct(make_sample(events, spikes=spikes, ground_truth=np.full((h, w), np.nan, np.float32)))
    np.testing.assert_array_equal(clean, poisoned)
