"""Event camera: exact crossings, closed-form noise rates, stage isolation, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from neuspike.conditions import EVENT_PRESETS, effect
from neuspike.errors import InputError
from neuspike.sensors import event_capture
from neuspike.sensors.event_camera import EventCamera, log_intensity
from neuspike.streams import EventStream

ALL = (effect("threshold_mismatch", sigma=0.05), effect("bandwidth", cutoff_hz=30.0),
       effect("refractory", period_s=5e-4), effect("leak", rate_hz=0.1), effect("shot_noise", rate_hz=5.0))


def ln_radiance(level):
    """Radiance whose pixel log intensity is ``level`` (above the dark floor, light 1)."""
    return np.float32(math.exp(level) / 255.0)


def pixel_index(stream):
    return stream.y.astype(np.int64) * stream.width + stream.x


def same_stream(a, b):
    return (len(a) == len(b) and np.array_equal(a.t_s, b.t_s) and np.array_equal(a.x, b.x)
            and np.array_equal(a.y, b.y) and np.array_equal(a.p, b.p))


def reference_events(frames, times, theta_on, theta_off):
    """Ideal pixel written plainly in float64: (t, pixel, polarity) sorted by (t, pixel)."""
    k, h, w = frames.shape
    x8 = 255.0 * frames.reshape(k, -1).astype(np.float64)
    logs = np.where(x8 <= 20, x8 * math.log(20) / 20, np.log(np.maximum(x8, 20)))
    events = []
    for pix in range(h * w):
        mem = logs[0, pix]
        for i in range(1, k):
            a, b = logs[i - 1, pix], logs[i, pix]
            while True:
                if b - mem >= theta_on[pix]:
                    level, pol = mem + theta_on[pix], 1
                elif b - mem <= -theta_off[pix]:
                    level, pol = mem - theta_off[pix], -1
                else:
                    break
                events.append((times[i - 1] + (level - a) / (b - a) * (times[i] - times[i - 1]), pix, pol))
                mem = level
    events.sort()
    return events


# --------------------------------------------------------------------------- log response
def test_log_intensity_is_v2e_lin_log():
    x8 = np.array([0.0, 5.0, 20.0, 21.0, 255.0, 2550.0])
    got = log_intensity(x8 / 255.0)
    want = np.where(x8 <= 20, x8 * math.log(20) / 20, np.log(np.maximum(x8, 1e-9)))
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    assert got[0] == 0.0
    # continuous at the floor, linear below it
    below = log_intensity(np.array([10.0, 19.999]) / 255)
    np.testing.assert_allclose(below[1], math.log(20), rtol=1e-4)
    np.testing.assert_allclose(below[0] * 2, math.log(20), rtol=1e-5)


@pytest.mark.parametrize("bad", [[-0.1, 0.5], [np.nan], [np.inf]])
def test_log_intensity_rejects_bad_values(bad):
    with pytest.raises(InputError):
        log_intensity(np.array(bad))


# --------------------------------------------------------------------------- the ideal pixel
@settings(max_examples=200, deadline=None)
@given(
    theta=st.floats(0.02, 0.6),
    delta=st.floats(0.05, 3.0),
    rising=st.booleans(),
    start=st.floats(3.1, 7.0),
    offset=st.floats(-0.99, 0.99),
)
def test_linear_ramp_gives_floor_delta_over_theta_events_at_exact_crossings(theta, delta, rising, start, offset):
    """One pixel: initialise at ``start``, move to ``start + offset * theta`` (no event), then ramp
    linearly by ``delta`` over one interval; crossings are at levels ``k * theta`` above (or below)
    the memorised level ``start``."""
    sign = 1.0 if rising else -1.0
    d0 = offset * theta
    end = d0 + sign * delta
    count = math.floor(abs(end) / theta) if end * sign > 0 else 0
    assume(abs(abs(end) / theta - round(abs(end) / theta)) > 1e-4)  # float32 log: no boundary cases
    assume(start + min(d0, end) > math.log(20) + 0.01)  # stay in the logarithmic range
    t0, dt = 0.25, 1e-3
    frames = np.array([ln_radiance(start), ln_radiance(start + d0), ln_radiance(start + end)]).reshape(3, 1, 1)
    times = np.array([0.0, t0, t0 + dt])
    cam = EventCamera(1, 1, light=1.0, threshold_on=theta, threshold_off=theta)
    events = cam.capture(frames, times)
    assert len(events) == count
    k = np.arange(1, count + 1)
    expected = t0 + (sign * k * theta - d0) / (end - d0) * dt
    np.testing.assert_allclose(events.t_s, expected, rtol=0, atol=dt * 2e-5 / delta)
    assert (events.p == sign).all()


@pytest.mark.parametrize("effects", [(), (effect("threshold_mismatch", sigma=0.05),)])
def test_matches_plain_float64_reference(effects):
    rng = np.random.default_rng(7)
    frames = (rng.random((25, 6, 8)) ** 3 * 2.0).astype(np.float32)
    frames[10] = 0.0  # dark floor and large jumps (many crossings per interval)
    frames[11] = 3.0
    times = np.cumsum(rng.random(25) * 1e-3 + 1e-4) + 1.0
    cam = EventCamera(8, 6, light=1.0, effects=effects, rng=np.random.default_rng(1))
    got = cam.capture(frames, times)
    ref = reference_events(frames, times, cam.theta_on.ravel().astype(np.float64),
                           cam.theta_off.ravel().astype(np.float64))
    assert len(got) == len(ref)
    ref_t, ref_pix, ref_p = (np.array(c) for c in zip(*ref))
    a, b = np.lexsort((got.t_s, pixel_index(got))), np.lexsort((ref_t, ref_pix))
    np.testing.assert_array_equal(pixel_index(got)[a], ref_pix[b])
    np.testing.assert_array_equal(got.p[a], ref_p[b])
    np.testing.assert_allclose(got.t_s[a], ref_t[b], rtol=0, atol=1e-7)


def test_output_sorted_by_time_then_pixel_and_valid():
    # a uniform scene: every pixel crosses at the same instants (ties)
    frames = np.ones((4, 5, 7), np.float32) * np.array([0.2, 0.5, 1.3, 0.4], np.float32)[:, None, None]
    cam = EventCamera(7, 5, light=1.0)
    s = cam.capture(frames, np.array([0.0, 1e-3, 2e-3, 3e-3]))
    t, pix = s.t_s, pixel_index(s)
    assert (np.diff(t) >= 0).all()
    tie = np.diff(t) == 0
    assert tie.sum() > 100 and (np.diff(pix)[tie] > 0).all()
    EventStream(s.t_s, s.x, s.y, s.p, s.width, s.height)  # the validating constructor accepts it
    assert s.meta["event_count"] == len(s)
    assert [stage["name"] for stage in s.meta["stages"]] == ["dvs_pixel"]


def test_first_frame_only_initialises():
    cam = EventCamera(4, 3, light=1.0)
    s = cam.capture(np.full((1, 3, 4), 0.7, np.float32), np.array([0.5]))
    assert len(s) == 0 and cam.initialised and cam.last_time_s == 0.5
    s = cam.capture(np.full((1, 3, 4), 0.7 * math.exp(0.25), np.float32), np.array([0.6]))
    assert len(s) == 12 and (s.p == 1).all()  # one ON event per pixel, after the initialising frame


def test_light_scales_intensity():
    frames = np.array([0.2, 0.6], np.float32).reshape(2, 1, 1) * np.ones((1, 2, 2), np.float32)
    times = np.array([0.0, 1e-3])
    bright = EventCamera(2, 2, light=1.0).capture(frames, times)
    assert len(bright) == 4 * math.floor(math.log(3) / 0.2)
    # at light 1/32 the pixels sit below the dark floor: linear response, fewer events
    dark = EventCamera(2, 2, light=1 / 32).capture(frames, times)
    x8 = 255 / 32 * np.array([0.2, 0.6])
    assert len(dark) == 4 * math.floor((x8[1] - x8[0]) * math.log(20) / 20 / 0.2)
    assert len(dark) < len(bright)


# --------------------------------------------------------------------------- stage isolation
def _constant(k=20, h=8, w=10, value=0.3):
    return np.full((k, h, w), value, np.float32), np.arange(k) * 1e-3


@pytest.mark.parametrize("effects", [(), (effect("threshold_mismatch", sigma=0.05),),
                                     (effect("bandwidth", cutoff_hz=30.0),),
                                     (effect("refractory", period_s=1e-3),),
                                     EVENT_PRESETS["clean"]])
def test_no_event_without_a_declared_noise_stage(effects):
    frames, times = _constant()
    s = EventCamera(10, 8, light=1.0, effects=effects, rng=np.random.default_rng(0)).capture(frames, times)
    assert len(s) == 0
    assert [x["name"] for x in s.meta["stages"]] == ["dvs_pixel", *(e.name for e in effects)]


@pytest.mark.parametrize("effects", [(), (effect("bandwidth", cutoff_hz=30.0), effect("refractory", period_s=1e-3))])
def test_undeclared_random_stages_draw_nothing(effects):
    rng = np.random.default_rng(3)
    cam = EventCamera(10, 8, light=1.0, effects=effects, rng=rng)
    cam.capture(*_constant())
    assert rng.random() == np.random.default_rng(3).random()


def test_frozen_draws_happen_at_construction_only():
    rng = np.random.default_rng(3)
    cam = EventCamera(10, 8, light=1.0, effects=(effect("leak", rate_hz=1.0),), rng=rng)
    state = rng.bit_generator.state
    cam.capture(*_constant())
    assert rng.bit_generator.state == state


def test_stage_metadata_lists_declared_stages_with_params_and_time():
    frames, times = _constant()
    s = EventCamera(10, 8, light=0.5, effects=ALL, rng=np.random.default_rng(0)).capture(frames, times)
    names = [x["name"] for x in s.meta["stages"]]
    assert names == ["dvs_pixel", "threshold_mismatch", "bandwidth", "leak", "shot_noise", "refractory"]
    by_name = {x["name"]: x for x in s.meta["stages"]}
    assert by_name["bandwidth"]["params"] == {"cutoff_hz": 30.0}
    assert by_name["dvs_pixel"]["params"]["light"] == 0.5
    assert all(x["seconds"] >= 0 for x in s.meta["stages"])


# --------------------------------------------------------------------------- threshold mismatch
def test_threshold_mismatch_is_frozen_gaussian_with_floor():
    cam = EventCamera(200, 100, light=1.0, effects=(effect("threshold_mismatch", sigma=0.05),),
                      rng=np.random.default_rng(0))
    on, off = cam.theta_on, cam.theta_off
    assert abs(on.mean() - 0.2) < 0.002 and abs(on.std() - 0.05) < 0.002
    assert abs(off.mean() - 0.2) < 0.002 and not np.array_equal(on, off)
    wide = EventCamera(200, 100, light=1.0, effects=(effect("threshold_mismatch", sigma=0.3),),
                       rng=np.random.default_rng(0))
    assert wide.theta_on.min() == pytest.approx(0.01) and (wide.theta_on >= np.float32(0.01)).all()
    again = EventCamera(200, 100, light=1.0, effects=(effect("threshold_mismatch", sigma=0.05),),
                        rng=np.random.default_rng(0))
    np.testing.assert_array_equal(again.theta_on, on)


def test_mismatch_counts_follow_each_pixels_threshold():
    cam = EventCamera(30, 20, light=1.0, effects=(effect("threshold_mismatch", sigma=0.05),),
                      rng=np.random.default_rng(4))
    delta = 1.3
    frames = np.stack([np.full((20, 30), ln_radiance(4.0)), np.full((20, 30), ln_radiance(4.0 + delta))])
    s = cam.capture(frames, np.array([0.0, 1e-3]))
    counts = np.bincount(pixel_index(s), minlength=600)
    exact = delta / cam.theta_on.ravel().astype(np.float64)
    clear = np.abs(exact - np.round(exact)) > 1e-4
    np.testing.assert_array_equal(counts[clear], np.floor(exact[clear]))


# --------------------------------------------------------------------------- bandwidth
def test_bandwidth_follows_first_order_low_pass():
    """A step held for K samples: the filtered log reaches L1 + (L0 - L1)(1 - eps)^K."""
    cutoff, dt, k = 30.0, 1e-3, 12
    levels = np.array([4.0, 5.5])  # two pixels: darker and brighter final intensity
    radiance0 = np.array([ln_radiance(4.0), ln_radiance(4.0)])
    radiance1 = np.array([ln_radiance(levels[0] + 0.8), ln_radiance(levels[1] + 0.8)])
    frames = np.concatenate([radiance0[None], np.repeat(radiance1[None], k, axis=0)]).reshape(k + 1, 1, 2)
    cam = EventCamera(2, 1, light=1.0, threshold_on=0.05, threshold_off=0.05,
                      effects=(effect("bandwidth", cutoff_hz=cutoff),))
    s = cam.capture(frames, np.arange(k + 1) * dt)
    counts = np.bincount(s.x, minlength=2)
    for pix in range(2):
        l0, l1 = 4.0, levels[pix] + 0.8
        eps = min(1.0, (255 * float(radiance1[pix]) + 20) / 275 * dt * 2 * math.pi * cutoff)
        filtered = l1 + (l0 - l1) * (1 - eps) ** k
        expected = (filtered - l0) / 0.05
        assert abs(expected - round(expected)) > 0.05  # no float32 boundary case
        assert counts[pix] == math.floor(expected)
    unfiltered = EventCamera(2, 1, light=1.0, threshold_on=0.05, threshold_off=0.05).capture(frames, np.arange(k + 1) * dt)
    full = np.bincount(unfiltered.x, minlength=2)
    assert counts[0] / full[0] < counts[1] / full[1] < 1  # darker pixels are slower


# --------------------------------------------------------------------------- refractory
def _greedy_refractory(stream, period):
    pix = pixel_index(stream)
    keep = np.zeros(len(stream), bool)
    last = {}
    for i in np.lexsort((stream.t_s, pix)):
        if pix[i] not in last or stream.t_s[i] - last[pix[i]] >= period:
            keep[i] = True
            last[pix[i]] = stream.t_s[i]
    return keep


@pytest.mark.parametrize("period", [2e-5, 3e-4])  # shorter and longer than the sample interval
def test_refractory_only_thins_the_output(period):
    rng = np.random.default_rng(2)
    frames = (rng.random((30, 12, 16)) * 2).astype(np.float32)
    times = np.arange(30) * 1e-4
    base = (effect("threshold_mismatch", sigma=0.05), effect("leak", rate_hz=50.0),
            effect("shot_noise", rate_hz=2000.0))
    free = EventCamera(16, 12, light=1.0, effects=base, rng=np.random.default_rng(9)).capture(frames, times)
    held = EventCamera(16, 12, light=1.0, effects=base + (effect("refractory", period_s=period),),
                       rng=np.random.default_rng(9)).capture(frames, times)
    # no two events of a pixel closer than the period ...
    pix = pixel_index(held)
    order = np.lexsort((held.t_s, pix))
    same = np.diff(pix[order]) == 0
    assert (np.diff(held.t_s[order])[same] >= period).all()
    # ... and exactly the events a greedy filter keeps from the unfiltered stream
    keep = _greedy_refractory(free, period)
    assert 0 < len(held) < len(free)
    assert same_stream(held, EventStream(free.t_s[keep], free.x[keep], free.y[keep], free.p[keep], 16, 12))


# --------------------------------------------------------------------------- shot noise and leak
@pytest.mark.parametrize("radiance, mismatch", [(0.0, None), (0.04, 0.05), (1.0, None)])
def test_shot_noise_rate_matches_declared_rate(radiance, mismatch):
    rate_hz, width, height, duration = 40.0, 200, 100, 0.05
    effects = (effect("shot_noise", rate_hz=rate_hz),)
    if mismatch:
        effects = (effect("threshold_mismatch", sigma=mismatch),) + effects
    cam = EventCamera(width, height, light=1.0, effects=effects, rng=np.random.default_rng(5))
    times = np.linspace(0.0, duration, 11)
    s = cam.capture(np.full((11, height, width), radiance, np.float32), times)
    i01 = min(1.0, (255 * radiance + 20) / 275)
    factor = 1 - 0.75 * i01
    on = (rate_hz / 2) * factor * (0.2 / cam.theta_on.astype(np.float64)).sum() * duration
    off = (rate_hz / 2) * factor * (0.2 / cam.theta_off.astype(np.float64)).sum() * duration
    assert abs(np.count_nonzero(s.p > 0) - on) < 0.1 * on
    assert abs(np.count_nonzero(s.p < 0) - off) < 0.1 * off
    # continuous time: noise timestamps are not tied to the samples
    assert np.isin(s.t_s, times).mean() < 0.01


def test_shot_noise_unbiased_over_long_intervals():
    # one 0.2 s interval: a per-interval coin flip would give at most one event per pixel
    cam = EventCamera(50, 40, light=1.0, effects=(effect("shot_noise", rate_hz=100.0),),
                      rng=np.random.default_rng(1))
    s = cam.capture(np.zeros((2, 40, 50), np.float32), np.array([0.0, 0.2]))
    expected = 100.0 * (1 - 0.75 * 20 / 275) * 0.2 * 2000
    assert abs(len(s) - expected) < 0.1 * expected
    assert np.bincount(pixel_index(s)).max() > 1


def test_noise_event_resets_the_memorised_level(monkeypatch):
    """A noise event at fraction f_n: crossings after it are measured from the signal at f_n."""
    theta, start, delta = 0.1, 4.0, 0.55  # crossings at fractions k * theta / delta
    f_noise = 0.3

    def inject(pixels, rng, radiance, dt, scale8):
        return np.array([0]), np.array([f_noise]), np.array([False])

    monkeypatch.setattr(event_capture, "draw_shot_noise", inject)
    cam = EventCamera(1, 1, light=1.0, threshold_on=theta, threshold_off=theta,
                      effects=(effect("shot_noise", rate_hz=1.0),), rng=np.random.default_rng(0))
    frames = np.array([ln_radiance(start), ln_radiance(start + delta)]).reshape(2, 1, 1)
    s = cam.capture(frames, np.array([0.0, 1.0]))
    before = [k * theta / delta for k in (1,)]  # crossing at 0.1 / 0.55 = 0.18 < 0.3
    after = [f_noise + k * theta / delta for k in (1, 2, 3)]  # from the reset level at 0.3
    expected = sorted(before + [f_noise] + after)
    np.testing.assert_allclose(s.t_s, expected, atol=1e-6)
    np.testing.assert_array_equal(s.p, [1, -1, 1, 1, 1])


def reference_with_resets(logs, times, theta_on, theta_off, drift_per_s, noise):
    """One pixel in float64: crossings of the linear signal, resets at the given noise events.

    ``logs`` (K,) log intensity at the samples; ``drift_per_s`` the leak drift of the memorised
    level; ``noise`` a list of (fraction, ON) injected in every interval.
    """
    events = []
    mem = logs[0]
    for i in range(1, len(logs)):
        t_a, dt = times[i - 1], times[i] - times[i - 1]
        slope = logs[i] - logs[i - 1] + drift_per_s * dt  # of d = log - mem, per unit fraction
        d = logs[i - 1] - mem
        f = 0.0
        for f_stop, on in sorted(noise) + [(1.0, None)]:
            while slope != 0:
                target = theta_on if slope > 0 else -theta_off
                f_cross = f + (target - d) / slope
                if f_cross > f_stop:
                    break
                events.append((t_a + f_cross * dt, 1 if slope > 0 else -1))
                d, f = 0.0, f_cross
            d += slope * (f_stop - f)
            f = f_stop
            if on is not None:
                events.append((t_a + f * dt, 1 if on else -1))
                d = 0.0
        mem = logs[i] - d
    return events


@pytest.mark.parametrize("leak", [False, True])
def test_noise_resets_match_a_plain_reference(monkeypatch, leak):
    noise = [(0.7, True), (0.2, False), (0.45, True)]  # injected unsorted, three in one pixel
    order = [1, 0, 2]

    def inject(pixels, rng, radiance, dt, scale8):
        pix = np.array([2, 0, 2, 2, 3])
        frac = np.array([noise[order[0]][0], 0.5, noise[order[1]][0], noise[order[2]][0], 0.05])
        on = np.array([noise[order[0]][1], True, noise[order[1]][1], noise[order[2]][1], False])
        return pix, frac, on

    monkeypatch.setattr(event_capture, "draw_shot_noise", inject)
    effects = (effect("shot_noise", rate_hz=1.0),) + ((effect("leak", rate_hz=30.0),) if leak else ())
    cam = EventCamera(4, 1, light=1.0, threshold_on=0.1, threshold_off=0.15, effects=effects,
                      rng=np.random.default_rng(0))
    levels = np.array([[4.0, 4.03, 4.64, 3.9], [4.0, 4.5, 4.1, 4.2], [4.0, 4.05, 4.62, 4.0],
                       [5.0, 4.4, 4.45, 5.2]])  # (pixel, sample)
    frames = np.array([[ln_radiance(v) for v in row] for row in levels]).T.reshape(4, 1, 4)
    times = np.array([0.0, 0.01, 0.02, 0.05])
    got = cam.capture(frames, times)
    logs = np.log(255.0 * frames.reshape(4, 4).astype(np.float64))
    drift = (cam.pixels.leak_per_s.astype(np.float64) if leak else np.zeros(4))
    pixel_noise = {0: [(0.5, True)], 2: noise, 3: [(0.05, False)]}
    for pix in range(4):
        ref = reference_with_resets(logs[:, pix], times, 0.1, 0.15, drift[pix], pixel_noise.get(pix, []))
        mine = got.x == pix
        assert np.count_nonzero(mine) == len(ref)
        ref_t, ref_p = (np.array(c) for c in zip(*ref))
        np.testing.assert_allclose(got.t_s[mine], ref_t, rtol=0, atol=1e-6)  # float32 state
        np.testing.assert_array_equal(got.p[mine], ref_p)


def test_leak_gives_on_events_at_about_the_leak_rate():
    rate_hz, duration = 20.0, 1.0
    cam = EventCamera(50, 40, light=1.0, effects=(effect("leak", rate_hz=rate_hz),
                                                  effect("threshold_mismatch", sigma=0.03)),
                      rng=np.random.default_rng(8))
    times = np.linspace(0.0, duration, 101)
    s = cam.capture(np.full((101, 40, 50), 0.5, np.float32), times)
    assert (s.p == 1).all()
    rate = len(s) / (2000 * duration)
    # log-normal spread of 0.1 decade: mean rate is rate_hz * exp((0.1 ln 10)^2 / 2) = 1.027 rate_hz
    assert abs(rate - rate_hz) < 0.1 * rate_hz
    # each pixel fires every 1 / rate_pixel seconds (its frozen rate: drift / theta_on)
    rate_pixel = cam.pixels.leak_per_s.astype(np.float64) / cam.pixels.th_on
    counts = np.bincount(pixel_index(s), minlength=2000)
    assert np.abs(counts - np.floor(rate_pixel * duration)).max() <= 1
    assert 0.5 < np.log10(rate_pixel).std() / 0.1 * 2 < 2.5


# --------------------------------------------------------------------------- determinism
def _noisy_scene():
    rng = np.random.default_rng(11)
    frames = (rng.random((24, 10, 12)) * 1.5).astype(np.float32)
    return frames, np.arange(24) / 22_500.0


def test_same_seed_same_bytes_and_different_seeds_differ():
    frames, times = _noisy_scene()
    a = EventCamera(12, 10, light=1.0, effects=ALL, rng=np.random.default_rng(42)).capture(frames, times)
    b = EventCamera(12, 10, light=1.0, effects=ALL, rng=np.random.default_rng(42)).capture(frames, times)
    c = EventCamera(12, 10, light=1.0, effects=ALL, rng=np.random.default_rng(43)).capture(frames, times)
    assert a.t_s.tobytes() + a.x.tobytes() + a.y.tobytes() + a.p.tobytes() == \
        b.t_s.tobytes() + b.x.tobytes() + b.y.tobytes() + b.p.tobytes()
    assert not same_stream(a, c)


@pytest.mark.parametrize("effects", [(), ALL, ALL[:-1] + (effect("shot_noise", rate_hz=3000.0),)])
def test_chunked_capture_equals_one_capture(effects):
    frames, times = _noisy_scene()
    one = EventCamera(12, 10, light=1.0, effects=effects, rng=np.random.default_rng(5)).capture(frames, times)
    cam = EventCamera(12, 10, light=1.0, effects=effects, rng=np.random.default_rng(5))
    parts = [cam.capture(frames[a:b], times[a:b]) for a, b in ((0, 1), (1, 2), (2, 9), (9, 24))]
    assert same_stream(EventStream.concatenate(parts), one)


@pytest.mark.parametrize("effects", [(), ALL])
def test_worker_thread_gives_the_same_bytes(effects):
    frames, times = _noisy_scene()
    one = EventCamera(12, 10, light=1.0, effects=effects, rng=np.random.default_rng(5), threads=1)
    two = EventCamera(12, 10, light=1.0, effects=effects, rng=np.random.default_rng(5), threads=2)
    for a, b in ((0, 5), (5, 24)):
        assert same_stream(one.capture(frames[a:b], times[a:b]), two.capture(frames[a:b], times[a:b]))


def test_reset_starts_over():
    frames, times = _noisy_scene()
    cam = EventCamera(12, 10, light=1.0)
    first = cam.capture(frames, times)
    cam.reset()
    again = cam.capture(frames, times + 1.0)
    assert len(again) == len(first) and np.array_equal(again.x, first.x) and np.array_equal(again.p, first.p)
    np.testing.assert_allclose(again.t_s, first.t_s + 1.0, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("kwargs, match", [
    ({"effects": (effect("initial_charge"),)}, "spikes effect"),
    ({"effects": (effect("leak"), effect("leak"))}, "twice"),
    ({"effects": ("leak",)}, "Effect objects"),
    ({"effects": (effect("shot_noise"),), "rng": None}, "rng"),
    ({"light": 0.0}, "light"),
    ({"threshold_on": -0.1}, "threshold_on"),
])
def test_bad_configuration(kwargs, match):
    args = {"light": 1.0, "rng": np.random.default_rng(0)} | kwargs
    with pytest.raises(InputError, match=match):
        EventCamera(4, 3, **args)


def test_bad_capture_input_leaves_state_unchanged():
    cam = EventCamera(4, 3, light=1.0)
    good = np.full((2, 3, 4), 0.5, np.float32)
    cam.capture(good, np.array([0.0, 1e-3]))
    bad_cases = [
        (np.full((2, 4, 3), 0.5, np.float32), np.array([1.0, 2.0]), "H x W"),
        (np.full((3, 4), 0.5, np.float32), np.array([1.0, 2.0]), "shape"),
        (np.where(np.arange(12).reshape(1, 3, 4) == 5, np.nan, 0.5), np.array([1.0]), "finite"),
        (np.full((1, 3, 4), -0.5), np.array([1.0]), ">= 0"),
        (good, np.array([2.0, 2.0]), "increasing"),
        (good, np.array([1e-3, 2e-3]), "previous capture"),
        (good, np.array([1.0]), "matching"),
    ]
    for frames, times, match in bad_cases:
        with pytest.raises(InputError, match=match):
            cam.capture(frames, times)
    assert cam.last_time_s == 1e-3
    after = cam.capture(np.full((1, 3, 4), 0.5 * math.exp(0.3), np.float32), np.array([2e-3]))
    assert len(after) == 12


# --------------------------------------------------------------------------- explicit pixel state
from tests.neuspike.sensors.test_event_kernels import events_of, moving_scene  # noqa: E402


def test_a_capture_is_a_function_of_the_frozen_pixels_and_the_carried_state():
    """The camera's state is a value: handed to a second camera with the same frozen draws, the next
    capture gives the same events as the first camera's (every stage declared, both backends)."""
    from neuspike.conditions import EVENT_PRESETS

    effects = EVENT_PRESETS["noisy"] + (effect("refractory", period_s=1e-4),)
    frames, times = moving_scene(np.random.default_rng(4), k=12)
    for backend in ("numpy", "numba"):
        a = EventCamera(frames.shape[2], frames.shape[1], light=0.5, effects=effects,
                        rng=np.random.default_rng(9), backend=backend)
        b = EventCamera(frames.shape[2], frames.shape[1], light=0.5, effects=effects,
                        rng=np.random.default_rng(9), backend=backend)
        a.capture(frames[:6], times[:6])
        b.state = a.state.copy()
        b._rng = np.random.default_rng(1)  # the shot noise of the next capture, drawn alike
        a._rng = np.random.default_rng(1)
        first, second = a.capture(frames[6:], times[6:]), b.capture(frames[6:], times[6:])
        assert len(first) > 50 and events_of(first) == events_of(second)
        assert a.state.mem.tobytes() == b.state.mem.tobytes()


def test_a_rejected_capture_leaves_the_state_as_it_was():
    frames, times = moving_scene(np.random.default_rng(4), k=8)
    cam = EventCamera(frames.shape[2], frames.shape[1], light=0.5)
    cam.capture(frames[:4], times[:4])
    before = cam.state.copy()
    with pytest.raises(InputError, match="must follow"):
        cam.capture(frames[4:], times[:4])
    assert cam.state.t_last == before.t_last and cam.state.mem.tobytes() == before.mem.tobytes()


def test_the_refractory_stage_as_a_function_keeps_events_a_period_after_the_last():
    """Keys at fractions 0..3 of a 1 s interval (scale 1/4): pixel 0 last fired at t = -0.1 s, pixel 1
    at 0.4 s; with a period of 0.5 s pixel 0's event at 0.5 s stays, pixel 1's at 0.75 s is dropped."""
    pix_bits = 2
    keys = np.array([(2 << pix_bits) | (0 << 1) | 1, (3 << pix_bits) | (1 << 1) | 0], np.int64)
    last = np.array([-0.1, 0.4])
    kept, pix = event_capture.refractory_filter(keys, np.array([0, 1]), 0.0, 0.25, pix_bits, last, 0.5)
    assert kept.tolist() == [keys[0]] and pix.tolist() == [0]
    assert last.tolist() == [0.5, 0.4]  # the emitted event is the pixel's new last


def test_threshold_mismatch_is_floored_and_drawn_on_first():
    on, off = event_capture.threshold_mismatch(np.random.default_rng(0), 1000, 0.2, 0.3, 0.5)
    rng = np.random.default_rng(0)
    expect_on = np.maximum(rng.normal(0.2, 0.5, 1000), event_capture.THRESHOLD_FLOOR).astype(np.float32)
    assert np.array_equal(on, expect_on) and on.dtype == np.float32
    assert on.min() == pytest.approx(event_capture.THRESHOLD_FLOOR) and off.min() >= event_capture.THRESHOLD_FLOOR
