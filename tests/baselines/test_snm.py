"""The SNM-style baseline against closed forms, analytic scenes and the hard cases.

Spike planes come from a small integrate-and-fire helper defined here (reset by subtraction,
threshold 1, input ``L * radiance`` per plane), independent of the suite's simulator.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines import snm
from neuspike.methods.normalisation import GAIN, ROBUST, robust_scale
from neuspike.errors import InputError
from neuspike.sample import Sample
from neuspike.streams import SpikeStream

RATE_HZ = 20_000.0


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20200614)


def integrate_and_fire(radiance: np.ndarray, light: float, charge0: np.ndarray | None = None) -> np.ndarray:
    """Spike planes of ideal pixels: ``v += light * radiance[j]``; a spike and ``v -= 1`` at ``v >= 1``.

    ``radiance`` is (T, H, W); ``charge0`` the initial charge (H, W), 0 by default. Returns bool (T, H, W).
    """
    num_planes = radiance.shape[0]
    v = np.zeros(radiance.shape[1:]) if charge0 is None else charge0.astype(np.float64).copy()
    out = np.zeros(radiance.shape, dtype=bool)
    for j in range(num_planes):
        v += light * radiance[j]
        fired = v >= 1.0
        v[fired] -= 1.0
        out[j] = fired
    return out


def constant_scene(radiance: float, light: float, shape: tuple[int, int, int], rng) -> np.ndarray:
    """A constant scene with a random initial charge in [0, 1) per pixel (random firing phases)."""
    return integrate_and_fire(np.full(shape, radiance), light, rng.uniform(0.0, 1.0, shape[1:]))


def make_sample(planes: np.ndarray, gain: float | None, key_plane: int | None = None, **extra) -> Sample:
    num_planes, height, width = planes.shape
    key = num_planes // 2 if key_plane is None else key_plane
    return Sample(
        height=height,
        width=width,
        key_time_s=(key + 0.5) / RATE_HZ,
        window_start_s=0.0,
        window_end_s=num_planes / RATE_HZ,
        spikes=SpikeStream(planes, plane_rate_hz=RATE_HZ, gain=gain, dark_rate=0.0),
        **extra,
    )


def reconstruct(planes: np.ndarray, gain: float | None, **params) -> tuple[np.ndarray, str]:
    method = snm.SNM(**params)
    image = method.reconstruct(make_sample(planes, gain))
    return image, method.last_normalisation


def periodic(period: int, num_planes: int, phases: np.ndarray) -> np.ndarray:
    """Spikes at planes j with (j - phase) % period == 0, phase per pixel (H, W)."""
    j = np.arange(num_planes)[:, None, None]
    return (j - phases[None]) % period == 0


# --- calibration ------------------------------------------------------------------------------

@pytest.mark.parametrize("period", [1, 2, 3, 7, 50, 120])
def test_periodic_train_reads_out_its_rate_exactly(rng, period):
    phases = rng.integers(0, period, size=(6, 7))
    planes = periodic(period, 400, phases)
    rate = snm.snm_rate(planes, 200, plane_rate_hz=RATE_HZ)
    np.testing.assert_allclose(rate, 1.0 / period, rtol=2e-6)


@pytest.mark.parametrize("rate", [1.0, 0.4, 1 / 7, 0.013])
@pytest.mark.parametrize("tau_planes", [3.0, 40.0, 400.0])
def test_threshold_steady_state_is_the_fixed_point_of_its_recursion(rate, tau_planes):
    q = math.exp(-1.0 / tau_planes)
    excess, mass = 0.0, 0.0
    for _ in range(int(60 * tau_planes)):
        excess = q * excess + snm.THRESHOLD_STEP_MV * rate
        mass = q * mass + 1.0
    assert snm.threshold_steady_state_mv(rate, time_constant_planes=tau_planes) == pytest.approx(excess, rel=1e-12)
    assert snm.steady_state_mass(tau_planes) == pytest.approx(mass, rel=1e-12)
    steady = snm.threshold_steady_state_mv(rate, time_constant_planes=tau_planes)
    assert snm.rate_from_threshold(steady, snm.steady_state_mass(tau_planes)) == pytest.approx(rate, rel=1e-12)


@pytest.mark.parametrize("period", [2, 5, 9])
def test_converged_neuron_sits_at_the_analytic_steady_state(period):
    # A one-sided neuron (key plane = last plane, which holds a spike) after 25 time constants.
    tau_ms = 2.0
    tau_planes = tau_ms * RATE_HZ / 1000.0
    num_planes = period * int(25 * tau_planes / period + 1)
    planes = periodic(period, num_planes, np.full((3, 4), period - 1))
    state = snm.snm_state(planes, num_planes - 1, snm.SNMParams(threshold_time_constant_ms=tau_ms), plane_rate_hz=RATE_HZ)
    expected = snm.threshold_steady_state_mv(1.0 / period, time_constant_planes=tau_planes)
    np.testing.assert_allclose(state.threshold_excess_mv.numpy(), expected, rtol=1e-4)
    np.testing.assert_allclose(state.mass.numpy(), snm.steady_state_mass(tau_planes), rtol=1e-4)
    rate = snm.rate_from_threshold(state.threshold_excess_mv, snm.steady_state_mass(tau_planes))
    np.testing.assert_allclose(rate.numpy(), 1.0 / period, rtol=1e-4)


# Levels where the expected ISI is at most T / 4 planes (several complete ISIs in the window). The
# error of an interval read-out of a constant pixel is below rate / span (span: planes between the
# first and last spike, >= T / 2 here), i.e. below radiance / 128 <= 0.0071 in radiance.
LEVELS = [(light, rad) for light in (1 / 2, 1 / 8, 1 / 32) for rad in (0.1, 0.3, 0.5, 0.9, 1.0)
          if 1.0 / (light * rad) <= 64]


@pytest.mark.parametrize("light,radiance", LEVELS)
def test_constant_scene_gives_the_true_radiance(rng, light, radiance):
    planes = constant_scene(radiance, light, (256, 12, 16), rng)
    image, label = reconstruct(planes, gain=light)
    assert label == GAIN
    np.testing.assert_allclose(image, radiance, atol=0.0075)
    assert abs(float(image.mean()) - radiance) < 0.002


@pytest.mark.parametrize("isi_planes", [160, 200, 300, 600])
def test_dark_pixels_without_a_complete_isi_are_unbiased(rng, isi_planes):
    # ISI > T / 2: pixels fire once or twice (or never) in 256 planes depending on their phase. The
    # single-spike read-out T / (2 G^2) makes the mean over random phases 1 / ISI; its spread per
    # pixel is at most about 2 / ISI, so over 64 x 64 pixels the mean's standard error is < 3 %.
    planes = constant_scene(1.0 / isi_planes, 1.0, (256, 64, 64), rng)
    rate = snm.snm_rate(planes, 128, snm.SNMParams(coupling_length_px=0.0), plane_rate_hz=RATE_HZ)
    assert float(rate.mean()) * isi_planes == pytest.approx(1.0, abs=0.08)


def test_without_gain_the_robust_path_is_taken(rng):
    radiance = np.tile(np.linspace(0.2, 0.8, 16), (12, 1))
    planes = integrate_and_fire(np.broadcast_to(radiance, (256, 12, 16)), 0.5, rng.uniform(0, 1, (12, 16)))
    rate = snm.snm_rate(planes, 128, plane_rate_hz=RATE_HZ)
    image, label = reconstruct(planes, gain=None)
    assert label == ROBUST
    np.testing.assert_allclose(image, np.clip(rate / robust_scale(rate), 0, 1), rtol=1e-6)


def test_time_constants_are_in_milliseconds_of_sensor_time(rng):
    # The same planes at twice the plane rate with every time constant halved: identical planes.
    radiance = rng.uniform(0.1, 1.0, (256, 10, 12))
    planes = integrate_and_fire(radiance, 0.25, rng.uniform(0, 1, (10, 12)))
    a = snm.snm_rate(planes, 128, plane_rate_hz=20_000.0)
    b = snm.snm_rate(planes, 128, snm.SNMParams(threshold_time_constant_ms=10.0, stdp_time_constant_ms=5.0),
                     plane_rate_hz=40_000.0)
    np.testing.assert_array_equal(a, b)
    c = snm.snm_rate(planes, 128, plane_rate_hz=40_000.0)
    assert not np.array_equal(a, c)


# --- motion -----------------------------------------------------------------------------------

def moving_edge(velocity_px: float, light: float, rng, shape=(256, 8, 64)):
    """A bright (0.8) / dark (0.2) vertical step moving right; pixel values are area averages."""
    num_planes, height, width = shape
    key = num_planes // 2
    edge = 32.0 + velocity_px * (np.arange(num_planes) + 0.5 - key)
    bright = np.clip(edge[:, None] - np.arange(width)[None, :], 0.0, 1.0)
    radiance = np.broadcast_to((0.2 + 0.6 * bright)[:, None, :], shape)
    planes = integrate_and_fire(radiance, light, rng.uniform(0, 1, shape[1:]))
    return planes, radiance[key], edge[key]


def edge_width(image: np.ndarray) -> float:
    """Mean number of pixels per row between 10 % and 90 % of the 0.2 -> 0.8 step."""
    profile = (image - 0.2) / 0.6
    return float(np.mean(((profile > 0.1) & (profile < 0.9)).sum(axis=1)))


@pytest.mark.parametrize("velocity_px", [0.05, 0.125, 0.25])
def test_moving_edge_is_sharper_than_the_full_window_rate(rng, velocity_px):
    light = 0.25
    planes, truth, edge_at_key = moving_edge(velocity_px, light, rng)
    image, _ = reconstruct(planes, gain=light)
    full_window = planes.mean(axis=0) / light  # TFP over the whole window, computed here
    smear = velocity_px * planes.shape[0]
    assert edge_width(full_window) > 0.6 * smear  # the yardstick does smear
    assert edge_width(image) <= 3.0               # the synapses widen a step to two pixels, no more
    assert np.abs(image - truth).mean() < 0.25 * np.abs(full_window - truth).mean()
    # ... and the edge sits where it is at the key instant: 50 % crossing within a pixel of it.
    crossing = (image > 0.5).sum(axis=1)
    assert np.all(np.abs(crossing - edge_at_key) <= 1.0)


def test_a_step_in_time_is_forgotten(rng):
    # One pixel's input steps from 1/10 to 1/3 spikes per plane at plane 100; read at plane 200.
    radiance = np.full((256, 1, 1), 0.1)
    radiance[100:] = 1.0 / 3.0
    planes = integrate_and_fire(radiance, 1.0)
    rate = snm.snm_rate(planes, 200, plane_rate_hz=RATE_HZ)
    assert float(rate[0, 0]) == pytest.approx(1.0 / 3.0, rel=0.02)
    mixed = planes.sum() / planes.shape[0]
    assert abs(mixed - 1.0 / 3.0) > 0.05  # what ignoring the step would give


@settings(max_examples=40, deadline=None)
@given(
    rates=st.lists(st.floats(min_value=1 / 60, max_value=1.0), min_size=6, max_size=6),
    phases=st.lists(st.floats(min_value=0.0, max_value=0.999), min_size=6, max_size=6),
)
def test_static_pixels_are_never_excited(rates, phases):
    # Constant input fires at ISIs floor(1/r) and ceil(1/r): never a marked change.
    planes = integrate_and_fire(np.broadcast_to(np.array(rates)[None, None, :], (240, 1, 6)), 1.0,
                                np.array(phases)[None, :])
    state = snm.snm_state(planes, 120, plane_rate_hz=RATE_HZ)
    assert float(state.excited_planes.sum()) == 0.0


def test_a_moving_edge_excites_its_path(rng):
    planes, _, _ = moving_edge(0.125, 0.25, rng)
    state = snm.snm_state(planes, 128, plane_rate_hz=RATE_HZ)
    excited = state.excited_planes.numpy()
    assert excited[:, 20:44].min() > 0        # the edge sweeps columns 16..48
    assert excited[:, 52:].max() == 0         # far ahead of it nothing changes


@settings(max_examples=200, deadline=None)
@given(
    a=st.integers(min_value=1, max_value=400),
    b=st.integers(min_value=1, max_value=400),
    c=st.integers(min_value=1, max_value=400),
)
def test_step_instant_conserves_one_spike_of_charge(a, b, c):
    if not (a > b > c or a < b < c):
        return
    t_m = float(snm.step_instant(*(torch.tensor([float(v)], dtype=torch.float64) for v in (a, b, c))))
    assert 0.0 < t_m < b
    assert t_m / a + (b - t_m) / c == pytest.approx(1.0, rel=1e-12)


def test_step_instant_mask_leaves_zero_and_no_nan():
    a = torch.tensor([4.0, 3.0, 5.0])
    b = torch.tensor([3.0, 3.0, 4.0])
    c = torch.tensor([2.0, 3.0, 5.0])   # only the first triple is monotonic; the others have c == a
    mask = torch.tensor([1.0, 0.0, 0.0])
    t_m = snm.step_instant(a, b, c, mask=mask)
    assert t_m.tolist() == [2.0, 0.0, 0.0]


def test_isi_change_allows_one_plane_of_quantisation():
    u = torch.tensor([2.0, 1.0, 1.0, 10.0, 10.0, 8.0])
    v = torch.tensor([3.0, 2.0, 3.0, 13.0, 14.0, 8.0])
    # |u - v| - 1 > 0.25 min(u, v): 0>0.5, 0>0.25, 1>0.25, 2>2.5, 3>2.5, -1>2
    expected = [0.0, 0.0, 1.0, 0.0, 1.0, 0.0]
    assert snm.isi_changed(u, v, 0.25).tolist() == expected
    assert snm.isi_changed(v, u, 0.25).tolist() == expected


def test_coupling_weights_follow_the_distance_law():
    w = snm.coupling_weights(1.5)
    assert w.dtype == np.float32 and w.shape == (3, 3)
    assert w[1, 1] == 1.0
    np.testing.assert_allclose(w[[0, 1, 1, 2], [1, 0, 2, 1]], math.exp(-10 / 15), rtol=1e-6)
    np.testing.assert_allclose(w[[0, 0, 2, 2], [0, 2, 0, 2]], math.exp(-10 * math.sqrt(2) / 15), rtol=1e-6)
    only_centre = snm.coupling_weights(0.0)
    assert only_centre.sum() == 1.0 and only_centre[1, 1] == 1.0


# --- contract and hard cases ------------------------------------------------------------------

def check_image(image: np.ndarray, shape: tuple[int, int]) -> None:
    assert image.dtype == np.float32 and image.shape == shape
    assert np.isfinite(image).all() and image.min() >= 0.0 and image.max() <= 1.0


def run_strict(planes: np.ndarray, gain: float | None) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image, _ = reconstruct(planes, gain)
    check_image(image, planes.shape[1:])
    return image


@pytest.mark.parametrize("gain", [0.25, None])
def test_no_spikes_give_black(gain):
    image = run_strict(np.zeros((256, 9, 11), dtype=bool), gain)
    assert image.max() == 0.0


def test_a_spike_on_every_plane_gives_rate_one():
    image = run_strict(np.ones((256, 9, 11), dtype=bool), 1.0)
    np.testing.assert_array_equal(image, 1.0)


@pytest.mark.parametrize("gain", [1.0, None])
def test_a_single_plane_falls_back_to_its_count(rng, gain):
    planes = rng.random((1, 9, 11)) < 0.5
    image = run_strict(planes, gain)
    np.testing.assert_array_equal(image, planes[0].astype(np.float32))


def test_lowest_light_white_reads_one(rng):
    # L = 1/32: rate 1/32 at white.
    planes = constant_scene(1.0, 1 / 32, (256, 10, 10), rng)
    image = run_strict(planes, 1 / 32)
    np.testing.assert_allclose(image, 1.0, atol=0.01)


@pytest.mark.parametrize("gain", [0.3, None])
def test_noisy_spikes_stay_in_range(rng, gain):
    run_strict(rng.random((256, 20, 30)) < 0.3, gain)


@pytest.mark.parametrize("height,width", [(260, 346), (180, 240)])
def test_odd_sensor_sizes(rng, height, width):
    radiance = np.tile(np.linspace(0.05, 1.0, width), (height, 1))
    charge0 = rng.uniform(0, 1, (height, width))
    planes = integrate_and_fire(np.broadcast_to(radiance, (256, height, width)), 0.25, charge0)
    image = run_strict(planes, 0.25)
    # interior columns: a static ramp, well away from the darkest columns' sparse spikes
    np.testing.assert_allclose(image[:, width // 4 :], radiance[:, width // 4 :], atol=0.01)


def test_deterministic(rng):
    planes = rng.random((64, 15, 17)) < 0.2
    a, _ = reconstruct(planes, 0.2)
    b, _ = reconstruct(planes.copy(), 0.2)
    assert a.tobytes() == b.tobytes()


def test_the_callers_thread_count_is_restored(rng):
    planes = rng.random((16, 6, 7)) < 0.3
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        snm.snm_rate(planes, 8, plane_rate_hz=RATE_HZ)
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_ground_truth_is_never_read(rng):
    planes = constant_scene(0.5, 0.25, (64, 10, 12), rng)
    clean = snm.SNM().reconstruct(make_sample(planes, 0.25))
    poisoned = snm.SNM().reconstruct(make_sample(planes, 0.25, ground_truth=np.full((10, 12), np.nan, np.float32)))
    assert clean.tobytes() == poisoned.tobytes()


# --- interface --------------------------------------------------------------------------------

def test_registers_snm_with_spike_input():
    calls = []
    snm.register_methods(lambda name, factory, **kw: calls.append((name, factory, kw)))
    assert [c[0] for c in calls] == ["snm"]
    name, factory, kw = calls[0]
    method = factory(name=name, **kw["params"])
    assert method.name == "snm" and method.inputs == frozenset({"spikes"})
    assert method.params["threshold_time_constant_ms"] == snm.THRESHOLD_TIME_CONSTANT_MS


@pytest.mark.parametrize(
    "params",
    [
        {"threshold_time_constant_ms": 0.0},
        {"stdp_time_constant_ms": -1.0},
        {"coupling_length_px": math.nan},
        {"motion_threshold": -0.1},
        {"motion_memory_isi": 0.0},
        {"step_forgetting": math.inf},
        {"dynamic_refining": "yes"},
    ],
)
def test_bad_parameters_raise(params):
    with pytest.raises(InputError, match=next(iter(params))):
        snm.SNM(**params)
    with pytest.raises(InputError, match=next(iter(params))):
        snm.SNMParams(**params)


@pytest.mark.parametrize(
    "planes,key",
    [
        (np.zeros((4, 3, 3), dtype=np.uint8), 0),
        (np.zeros((3, 3), dtype=bool), 0),
        (np.zeros((4, 3, 3), dtype=bool), 4),
        (np.zeros((4, 3, 3), dtype=bool), 1.5),
    ],
)
def test_bad_planes_raise(planes, key):
    with pytest.raises(InputError):
        snm.snm_rate(planes, key, plane_rate_hz=RATE_HZ)


# --- the compiled kernel against the torch reference -----------------------------------------

def simulated_window(kind: str, light: float, seed: int) -> np.ndarray:
    """A 128-plane window of the suite's simulator (pan or still photograph, 40x24, random charge)."""
    from neuspike.conditions import Condition, effect
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.recording import SensorConfig
    from neuspike.simulation.window import simulate_window

    scene = make_scene(SceneSpec(kind=kind, image="camera", size=(40, 24), velocity_px_s=(6000.0, 1600.0)))
    cond = Condition(light=light, motion=32, effects=(effect("initial_charge"),))
    rec = simulate_window(scene, cond, rng=np.random.default_rng(seed), sensor=SensorConfig(planes=128),
                          modalities={"spikes"})
    return rec.spikes.planes


# Tolerance of the compiled kernel against the reference, stated once: the float32 arithmetic is
# the same, operation by operation, except the moving decay's exp (a float32 series instead of
# torch's exp, a few float32 roundings) and any fused multiply-add inside torch; over the
# windows this leaves relative differences of a few 1e-6 in the charge and mass.
STATE_RTOL = 2e-5
RATE_ATOL = 1e-6  # spikes per plane (rates are in [0, 1])


@pytest.mark.parametrize("kind", ["still", "pan"])
@pytest.mark.parametrize("light", [1 / 32, 1 / 4, 1 / 2])
def test_compiled_kernel_matches_the_torch_reference(kind, light):
    planes = simulated_window(kind, light, seed=3)
    key = planes.shape[0] // 2
    fast = snm.snm_state(planes, key, plane_rate_hz=RATE_HZ, backend="numba")
    ref = snm.snm_state(planes, key, plane_rate_hz=RATE_HZ, backend="torch")
    for field in ("count", "first_spike", "excited_planes"):  # integer-valued: exact
        np.testing.assert_array_equal(getattr(fast, field).numpy(), getattr(ref, field).numpy(), err_msg=field)
    for field in ("threshold_excess_mv", "mass"):
        np.testing.assert_allclose(getattr(fast, field).numpy(), getattr(ref, field).numpy(), rtol=STATE_RTOL,
                                   atol=1e-30, err_msg=field)
    assert ref.excited_planes.sum() > 0 or kind == "still"
    rate_fast = snm.snm_rate(planes, key, plane_rate_hz=RATE_HZ, backend="numba")
    rate_ref = snm.snm_rate(planes, key, plane_rate_hz=RATE_HZ, backend="torch")
    np.testing.assert_allclose(rate_fast, rate_ref, rtol=0, atol=RATE_ATOL)


@pytest.mark.parametrize("params", [
    {"dynamic_refining": False},
    {"step_forgetting": 0.0, "motion_threshold": 0.0},
    {"threshold_time_constant_ms": 2.0, "motion_memory_isi": 3.0},
])
def test_compiled_kernel_matches_with_other_parameters(params, rng):
    planes = rng.random((96, 9, 13)) < rng.uniform(0.02, 0.4, (9, 13))
    for key in (0, 47, 95):
        fast = snm.snm_rate(planes, key, snm.SNMParams(**params), plane_rate_hz=RATE_HZ, backend="numba")
        ref = snm.snm_rate(planes, key, snm.SNMParams(**params), plane_rate_hz=RATE_HZ, backend="torch")
        np.testing.assert_allclose(fast, ref, rtol=0, atol=RATE_ATOL)


def test_a_memory_beyond_the_compiled_range_takes_the_reference_path(rng):
    # motion_memory_isi 0.5: the moving decay's argument spans more than the compiled series covers
    planes = rng.random((64, 5, 6)) < 0.3
    fast = snm.snm_rate(planes, 31, snm.SNMParams(motion_memory_isi=0.5), plane_rate_hz=RATE_HZ, backend="numba")
    ref = snm.snm_rate(planes, 31, snm.SNMParams(motion_memory_isi=0.5), plane_rate_hz=RATE_HZ, backend="torch")
    np.testing.assert_array_equal(fast, ref)


def test_unknown_backend_raises(rng):
    with pytest.raises(InputError, match="backend"):
        snm.snm_rate(rng.random((8, 3, 3)) < 0.5, 4, plane_rate_hz=RATE_HZ, backend="cuda")
