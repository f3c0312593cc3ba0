"""Spike camera: closed-form rates, charge conservation, dark-current statistics, determinism."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from neuspike.conditions import effect
from neuspike.errors import InputError
from neuspike.sensors.spike_camera import (
    SpikeCamera,
    draw_dark_charge,
    draw_initial_charge,
    integrate_and_fire,
)

BOTH = (effect("initial_charge"), effect("dark_current", isi_mean_planes=180.0, isi_std_planes=50.0))


def reference_loop(frames, hold, light, threshold, initial=None, dark=None):
    """Algorithm 1 written plainly (fancy-indexed reset), float32 in the documented order."""
    frames = np.asarray(frames, np.float32)
    k, h, w = frames.shape
    charge = np.zeros((h, w), np.float32) if initial is None else np.array(initial, np.float32)
    light, phi = np.float32(light), np.float32(threshold)
    out = []
    for f in frames:
        drive = f * light
        if dark is not None:
            drive = drive + np.asarray(dark, np.float32)
        for _ in range(hold):
            charge = charge + drive
            fired = charge >= phi
            charge[fired] = charge[fired] - phi
            out.append(fired)
    return np.array(out, dtype=bool).reshape(k * hold, h, w), charge


def f32(x: float) -> Fraction:
    return Fraction(float(np.float32(x)))


# ---------------------------------------------------------------------------------------------
# constant scenes: closed-form counts
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("light, radiance, threshold", [
    (0.25, 0.375, 1.0), (0.5, 0.8125, 0.5), (1 / 32, 0.75, 0.25), (0.125, 1.0, 1.0), (0.5, 0.0, 1.0),
])
@pytest.mark.parametrize("hold", [1, 16, 256])
def test_constant_scene_count_is_exact_for_dyadic_values(light, radiance, threshold, hold):
    t = 256
    frames = np.full((t // hold, 2, 3), radiance, np.float32)
    planes, charge = integrate_and_fire(frames, hold_planes=hold, light=light, threshold=threshold)
    # dyadic values: every float32 operation is exact, so the closed form holds to the spike
    expected = math.floor(Fraction(t) * f32(light) * f32(radiance) / f32(threshold))
    assert planes.shape == (t, 2, 3)
    assert (planes.sum(axis=0) == expected).all()
    remainder = Fraction(t) * f32(light) * f32(radiance) - expected * f32(threshold)
    np.testing.assert_array_equal(charge, np.float32(remainder))


@pytest.mark.parametrize("light, radiance, threshold", [(0.3, 0.7, 1.0), (0.2, 0.33, 0.9), (0.07, 0.9, 0.3)])
def test_constant_scene_rate_and_regular_intervals(light, radiance, threshold):
    t = 2000
    frames = np.full((1, 3, 4), radiance, np.float32)
    planes, _ = integrate_and_fire(frames, hold_planes=t, light=light, threshold=threshold)
    drive = f32(radiance) * f32(light)  # float32 product, exact value up to one rounding
    expected = Fraction(t) * drive / f32(threshold)
    counts = planes.sum(axis=0)
    assert (np.abs(counts - float(expected)) <= 1).all()
    # in a constant scene the intervals take only the two integers around threshold / drive
    times = np.flatnonzero(planes[:, 0, 0])
    isi = np.diff(times)
    ideal = float(f32(threshold) / drive)
    assert set(isi.tolist()) <= {math.floor(ideal), math.ceil(ideal)}


def test_rate_with_initial_charge_matches_gain_statistically():
    h, w, t = 100, 100, 256
    light, radiance, threshold = 0.25, 0.375, 1.0  # drive 3/32 per plane: 24 spikes in 256 planes
    cam = SpikeCamera(w, h, light=light, threshold=threshold, effects=(effect("initial_charge"),),
                      rng=np.random.default_rng(7))
    start = cam.charge.astype(np.float64)
    stream = cam.capture(np.full((t, h, w), radiance, np.float32), hold_planes=1)
    counts = stream.planes.sum(axis=0)
    # per pixel: floor((I0 + T * L * r) / phi), up to float rounding at the floor's edge
    per_pixel = np.maximum(0, np.floor((start + t * light * radiance) / threshold))
    assert (np.abs(counts - per_pixel) <= 1).all()
    assert np.mean(counts == per_pixel) > 0.999
    # over pixels: E[floor(N + x)] = x - 1/2 for N standard normal (x = 24 >> 1)
    mean_rate = counts.mean() / t
    tolerance = 5 * counts.std() / math.sqrt(counts.size) / t
    assert abs(mean_rate - (stream.gain * radiance - 0.5 / t)) < tolerance
    assert stream.gain == pytest.approx(light / threshold)


def test_saturation_fires_every_plane_and_keeps_the_surplus():
    frames = np.full((1, 1, 2), 10.0, np.float32)  # drive 2.5 per plane, threshold 1
    planes, charge = integrate_and_fire(frames, hold_planes=8, light=0.25, threshold=1.0)
    assert planes.all()
    np.testing.assert_array_equal(charge, np.float32(8 * 1.5))


# ---------------------------------------------------------------------------------------------
# conservation and the reference loop, for any scene
# ---------------------------------------------------------------------------------------------

@st.composite
def scenes(draw):
    k = draw(st.integers(1, 4))
    hold = draw(st.integers(1, 5))
    h = draw(st.integers(1, 4))
    w = draw(st.integers(1, 4))
    finite = dict(allow_nan=False, allow_infinity=False, allow_subnormal=False, width=32)
    frames = draw(arrays(np.float32, (k, h, w), elements=st.floats(0, 4, **finite)))
    light = draw(st.floats(0.01, 2.0))
    threshold = draw(st.floats(0.1, 4.0))
    initial = draw(st.none() | arrays(np.float32, (h, w), elements=st.floats(-4, 4, **finite)))
    dark = draw(st.none() | arrays(np.float32, (h, w), elements=st.floats(0, 1, **finite)))
    return frames, hold, light, threshold, initial, dark


@settings(max_examples=80, deadline=None)
@given(scenes())
def test_charge_is_conserved_for_any_scene(scene):
    frames, hold, light, threshold, initial, dark = scene
    planes, final = integrate_and_fire(frames, hold_planes=hold, light=light, threshold=threshold,
                                       initial_charge=initial, dark_charge=dark)
    n = planes.shape[0]
    start = np.zeros(frames.shape[1:]) if initial is None else initial.astype(np.float64)
    per_plane_dark = 0.0 if dark is None else dark.astype(np.float64)
    inflow = light * hold * frames.astype(np.float64).sum(axis=0) + per_plane_dark * n
    outflow = threshold * planes.sum(axis=0) + final.astype(np.float64)
    scale = np.abs(start) + inflow + threshold
    np.testing.assert_allclose(start + inflow, outflow, rtol=0, atol=float(1e-5 * scale.max() * (n + 1)))
    assert planes.dtype == np.bool_ and planes.flags.c_contiguous and final.dtype == np.float32


@settings(max_examples=60, deadline=None)
@given(scenes())
def test_matches_the_plain_reference_loop_bit_for_bit(scene):
    frames, hold, light, threshold, initial, dark = scene
    ref_planes, ref_final = reference_loop(frames, hold, light, threshold, initial, dark)
    for backend in ("numpy", "auto"):  # the plain loop, and the compiled kernel where numba imports
        planes, final = integrate_and_fire(frames, hold_planes=hold, light=light, threshold=threshold,
                                           initial_charge=initial, dark_charge=dark, backend=backend)
        np.testing.assert_array_equal(planes, ref_planes)
        np.testing.assert_array_equal(final, ref_final)


@pytest.mark.parametrize("light, threshold", [(1.0, 1.0), (1.0, 0.7), (0.3, 1.0), (0.25, 0.5)])
@pytest.mark.parametrize("with_dark", [False, True])
def test_unit_light_and_threshold_shortcuts_match_the_reference_loop(light, threshold, with_dark):
    rng = np.random.default_rng(12)
    frames = rng.random((6, 5, 8), dtype=np.float32) * 1.5
    initial = rng.normal(size=(5, 8)).astype(np.float32)
    dark = rng.random((5, 8), dtype=np.float32) * 0.1 if with_dark else None
    for hold in (1, 3):
        got = integrate_and_fire(frames, hold_planes=hold, light=light, threshold=threshold,
                                 initial_charge=initial, dark_charge=dark, backend="numpy")
        ref = reference_loop(frames, hold, light, threshold, initial, dark)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])


@pytest.mark.parametrize("budget", [1, 3 * 4 * 8 * 4, 1 << 30])  # bands of 1 row, 3 rows, whole sensor
def test_band_size_never_changes_the_result(budget, monkeypatch):
    from neuspike.sensors import spike_camera

    monkeypatch.setattr(spike_camera, "_CACHE_BUDGET_BYTES", budget)
    rng = np.random.default_rng(21)
    frames = rng.random((5, 7, 8), dtype=np.float32)
    initial = rng.normal(size=(7, 8)).astype(np.float32)
    dark = rng.random((7, 8), dtype=np.float32) * 0.2
    for hold in (1, 2):
        got = integrate_and_fire(frames, hold_planes=hold, light=0.6, threshold=0.7,
                                 initial_charge=initial, dark_charge=dark, backend="numpy")
        ref = reference_loop(frames, hold, 0.6, 0.7, initial, dark)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])


def test_camera_conserves_charge_across_captures():
    rng = np.random.default_rng(3)
    h, w = 20, 30
    cam = SpikeCamera(w, h, light=0.5, threshold=0.8, effects=BOTH, rng=np.random.default_rng(11))
    dark = cam.dark_charge.astype(np.float64)
    start = cam.charge.astype(np.float64)
    spikes = np.zeros((h, w))
    inflow = np.zeros((h, w))
    for hold in (1, 3, 2):
        frames = rng.random((7, h, w), dtype=np.float32) * 2
        s = cam.capture(frames, hold_planes=hold)
        spikes += s.planes.sum(axis=0)
        inflow += 0.5 * hold * frames.astype(np.float64).sum(axis=0) + dark * s.num_planes
    np.testing.assert_allclose(start + inflow, 0.8 * spikes + cam.charge, atol=1e-3)


def test_float64_frames_equal_their_float32_conversion():
    rng = np.random.default_rng(0)
    frames = rng.random((5, 6, 7))
    a = integrate_and_fire(frames, hold_planes=2, light=0.3, threshold=0.7)
    b = integrate_and_fire(frames.astype(np.float32), hold_planes=2, light=0.3, threshold=0.7)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


# ---------------------------------------------------------------------------------------------
# effects: dark current and initial charge
# ---------------------------------------------------------------------------------------------

def test_dark_current_isis_match_the_declared_pattern_and_distribution():
    h, w, t = 40, 50, 3000
    threshold = 0.5
    cam = SpikeCamera(w, h, light=0.25, threshold=threshold,
                      effects=(effect("dark_current", isi_mean_planes=180.0, isi_std_planes=50.0),),
                      rng=np.random.default_rng(5))
    declared = threshold / cam.dark_charge.astype(np.float64)  # each pixel's isi, in planes
    planes = cam.capture(np.zeros((1, h, w), np.float32), hold_planes=t).planes
    counts = planes.sum(axis=0)
    assert counts.min() >= 2
    measured = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            times = np.flatnonzero(planes[:, y, x])
            measured[y, x] = (times[-1] - times[0]) / (len(times) - 1)
    # per pixel: spikes at the planes where floor(j / isi) steps, so the mean interval is the isi
    assert (np.abs(measured - declared) <= 1.0 / (counts - 1) + 1e-3).all()
    # over pixels: the declared Normal(180, 50^2), within 5 standard errors
    n = measured.size
    assert abs(measured.mean() - 180.0) < 5 * 50.0 / math.sqrt(n)
    assert abs(measured.std() - 50.0) < 5 * 50.0 / math.sqrt(2 * n)


def test_dark_rate_is_the_rate_fired_in_darkness_and_zero_without_dark_current():
    h, w, t = 30, 40, 6000
    cam = SpikeCamera(w, h, light=0.25, threshold=0.5, effects=BOTH, rng=np.random.default_rng(3))
    stream = cam.capture(np.zeros((1, h, w), np.float32), hold_planes=t)
    assert stream.dark_rate == cam.dark_rate
    # conservation of charge in darkness: each pixel fires t * dark / threshold spikes, give or take
    # the one its starting charge (in [-3, 3] thresholds for all but a few pixels) adds or removes
    fired = stream.planes.sum(dtype=np.int64) / (t * h * w)
    assert abs(fired - cam.dark_rate) < 3.5 / t
    assert 1 / 230 < cam.dark_rate < 1 / 140  # the declared Normal(180, 50^2) isi, with its spread
    clean = SpikeCamera(w, h, light=0.25, threshold=0.5, rng=None)
    assert clean.dark_rate == 0.0 and clean.capture(np.zeros((1, h, w), np.float32), hold_planes=4).dark_rate == 0.0


def test_dark_charge_redraws_only_isis_below_one_plane():
    shape, mean, std = (200, 200), 2.0, 5.0
    dark = draw_dark_charge(shape, threshold=1.0, isi_mean_planes=mean, isi_std_planes=std,
                            rng=np.random.default_rng(9))
    isi = 1.0 / dark.astype(np.float64)
    assert isi.min() >= 1.0 - 1e-6
    first = np.random.default_rng(9).normal(mean, std, shape)  # the same first draw, independently
    kept = first >= 1
    np.testing.assert_allclose(isi[kept], first[kept], rtol=1e-6)
    # the result follows the normal truncated at 1: mean = mu + sigma * pdf(a) / (1 - cdf(a))
    a = (1 - mean) / std
    pdf = math.exp(-a * a / 2) / math.sqrt(2 * math.pi)
    tail = 0.5 * math.erfc(a / math.sqrt(2))
    truncated_mean = mean + std * pdf / tail
    assert abs(isi.mean() - truncated_mean) < 5 * std / math.sqrt(isi.size)


def test_dark_charge_rejects_isis_that_cannot_reach_one_plane():
    with pytest.raises(InputError, match="at least about 1 plane"):
        draw_dark_charge((4, 4), threshold=1.0, isi_mean_planes=0.5, isi_std_planes=0.0,
                         rng=np.random.default_rng(0))


def test_initial_charge_is_normal_times_threshold():
    c = draw_initial_charge((300, 300), threshold=2.0, rng=np.random.default_rng(1))
    assert c.dtype == np.float32 and c.shape == (300, 300)
    n = c.size
    assert abs(c.mean()) < 5 * 2.0 / math.sqrt(n)
    assert abs(c.std() - 2.0) < 5 * 2.0 / math.sqrt(2 * n)


# ---------------------------------------------------------------------------------------------
# determinism, chunking, metadata
# ---------------------------------------------------------------------------------------------

def _scene(k=12, h=9, w=10, seed=0):
    return np.random.default_rng(seed).random((k, h, w), dtype=np.float32)


def test_without_effects_output_depends_on_the_scene_only():
    frames = _scene()
    rng_a, rng_b = np.random.default_rng(1), np.random.default_rng(2)
    state = rng_a.bit_generator.state
    a = SpikeCamera(10, 9, light=0.5, rng=rng_a).capture(frames, hold_planes=2)
    b = SpikeCamera(10, 9, light=0.5, rng=rng_b).capture(frames, hold_planes=2)
    c = SpikeCamera(10, 9, light=0.5, rng=None).capture(frames, hold_planes=2)
    assert a.planes.tobytes() == b.planes.tobytes() == c.planes.tobytes()
    assert rng_a.bit_generator.state == state  # an undeclared stage draws nothing
    assert [s["name"] for s in a.meta["stages"]] == ["integrate_and_fire"]


def test_with_effects_same_seed_same_bytes_and_different_seeds_differ():
    frames = _scene()

    def run(seed):
        cam = SpikeCamera(10, 9, light=0.5, effects=BOTH, rng=np.random.default_rng(seed))
        return cam.capture(frames, hold_planes=2).planes.tobytes()

    assert run(4) == run(4)
    assert run(4) != run(5)


def test_chunked_capture_equals_one_capture():
    frames = _scene(k=20)

    def camera():
        return SpikeCamera(10, 9, light=0.7, threshold=0.9, effects=BOTH, rng=np.random.default_rng(8))

    whole_cam = camera()
    whole = whole_cam.capture(frames, hold_planes=3)
    cam = camera()
    parts = [cam.capture(frames[a:b], hold_planes=3, start_s=a * 3 / 20_000) for a, b in ((0, 5), (5, 6), (6, 20))]
    joined = np.concatenate([p.planes for p in parts])
    assert joined.tobytes() == whole.planes.tobytes()
    np.testing.assert_array_equal(cam.charge, whole_cam.charge)
    assert parts[1].start_s == pytest.approx(15 / 20_000)


def test_stream_metadata_lists_the_stages_that_ran():
    cam = SpikeCamera(10, 9, light=0.25, threshold=0.5, plane_rate_hz=10_000, effects=BOTH[::-1],
                      rng=np.random.default_rng(0))
    s = cam.capture(_scene(), hold_planes=4, start_s=1.5)
    names = [stage["name"] for stage in s.meta["stages"]]
    assert names == ["initial_charge", "dark_current", "integrate_and_fire"]
    assert s.meta["stages"][1]["params"] == {"isi_mean_planes": 180.0, "isi_std_planes": 50.0}
    assert all(stage["seconds"] >= 0 for stage in s.meta["stages"])
    assert s.meta["spike_count"] == int(s.planes.sum())
    assert (s.gain, s.threshold, s.plane_rate_hz, s.start_s) == (0.5, 0.5, 10_000, 1.5)
    assert s.num_planes == 48
    again = cam.capture(_scene(), hold_planes=1)
    assert [st_["seconds"] for st_ in again.meta["stages"][:2]] == [0.0, 0.0]  # draws happen once


def test_charge_is_a_read_only_copy():
    cam = SpikeCamera(4, 3, light=1.0, rng=None)
    c = cam.charge
    with pytest.raises(ValueError):
        c[0, 0] = 1.0
    assert cam.dark_charge is None


# ---------------------------------------------------------------------------------------------
# invalid input
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad, match", [(np.nan, "minimum of nan"), (-0.1, "minimum of -0.1"),
                                        (-np.inf, "minimum of -inf"), (np.inf, "overflowed")])
def test_invalid_radiance_raises_and_leaves_the_camera_unchanged(bad, match):
    cam = SpikeCamera(3, 2, light=0.5, effects=(effect("initial_charge"),), rng=np.random.default_rng(0))
    before = cam.charge
    frames = np.full((3, 2, 3), 0.5, np.float32)
    frames[1, 1, 2] = bad
    with pytest.raises(InputError, match=match):
        cam.capture(frames, hold_planes=2)
    np.testing.assert_array_equal(cam.charge, before)


def test_negative_radiance_that_underflows_with_the_light_scale_is_still_refused():
    frames = np.zeros((2, 1, 3), np.float32)
    frames[1, 0, 1] = -np.float32(1e-45)  # times 1/4 rounds to -0.0
    with pytest.raises(InputError, match=r"frames\[1\]: .* minimum of -1.4"):
        integrate_and_fire(frames, hold_planes=1, light=0.25, threshold=1.0)


def test_shape_and_parameter_errors():
    frames = np.zeros((2, 3, 4), np.float32)
    with pytest.raises(InputError, match=r"expected shape \(K, 3, 5\)"):
        SpikeCamera(5, 3, light=1.0, rng=None).capture(frames, hold_planes=1)
    with pytest.raises(InputError, match="initial_charge"):
        integrate_and_fire(frames, hold_planes=1, light=1, threshold=1, initial_charge=np.zeros((4, 3)))
    with pytest.raises(InputError, match="dark_charge"):
        integrate_and_fire(frames, hold_planes=1, light=1, threshold=1, dark_charge=-np.ones((3, 4)))
    with pytest.raises(InputError, match="hold_planes"):
        integrate_and_fire(frames, hold_planes=0, light=1, threshold=1)
    with pytest.raises(InputError, match="light"):
        integrate_and_fire(frames, hold_planes=1, light=0, threshold=1)
    with pytest.raises(InputError, match="floating-point"):
        integrate_and_fire(frames.astype(np.uint8), hold_planes=1, light=1, threshold=1)
    with pytest.raises(InputError, match="3-D"):
        integrate_and_fire(frames[0], hold_planes=1, light=1, threshold=1)


def test_effect_declarations_are_checked():
    with pytest.raises(InputError, match="not a spike-camera effect"):
        SpikeCamera(4, 3, light=1.0, effects=(effect("shot_noise"),), rng=np.random.default_rng(0))
    with pytest.raises(InputError, match="declared twice"):
        SpikeCamera(4, 3, light=1.0, effects=(effect("initial_charge"),) * 2, rng=np.random.default_rng(0))
    with pytest.raises(InputError, match="Generator"):
        SpikeCamera(4, 3, light=1.0, effects=(effect("initial_charge"),), rng=None)
    with pytest.raises(InputError, match="Effect objects"):
        SpikeCamera(4, 3, light=1.0, effects=("initial_charge",), rng=np.random.default_rng(0))
