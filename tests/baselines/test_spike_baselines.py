"""TFP, TFI and TFSTP against closed-form references.

The spike planes come from a small integrate-and-fire helper below (threshold 1, reset by
subtraction, charge ``L * radiance`` per plane), so the expected counts and intervals are known in
closed form: over ``n`` planes a pixel with constant rate ``a < 1`` fires ``floor(n a)`` or
``ceil(n a)`` times, and its intervals are ``floor(1 / a)`` or ``ceil(1 / a)`` planes.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import baselines.tfi as tfi_module
import baselines.tfp as tfp_module
import baselines.tfstp as tfstp_module
from baselines.tfi import TFI, planes_to_first_spike, tfi_isi_planes, tfi_rate
from baselines.tfp import TFP, tfp_rate, tfp_window
from baselines.tfstp import TFSTP, STPParams, stp_rates, stp_step, tfstp_rate, tfstp_state
from neuspike.errors import InputError
from neuspike.sample import Sample
from neuspike.streams import SpikeStream

PLANE_RATE_HZ = 20_000.0
METHODS = ("tfp", "tfp-w8", "tfp-w16", "tfp-w32", "tfp-w64", "tfi", "tfstp")


# --- helpers -------------------------------------------------------------------------------------


def integrate_and_fire(drive: np.ndarray, num_planes: int, charge: np.ndarray) -> np.ndarray:
    """Planes (T, H, W) of ideal pixels: charge += drive per plane; fire at >= 1 and subtract 1."""
    c = np.array(charge, dtype=np.float64)
    drive = np.broadcast_to(np.asarray(drive, dtype=np.float64), c.shape)
    planes = np.empty((num_planes,) + c.shape, dtype=bool)
    for j in range(num_planes):
        c += drive
        np.greater_equal(c, 1.0, out=planes[j])
        c -= planes[j]
    return planes


def make_sample(planes: np.ndarray, gain: float | None, ground_truth: np.ndarray | None = None) -> Sample:
    """A sample whose key instant is the window's centre, as for simulated data."""
    t, h, w = planes.shape
    return Sample(
        height=h,
        width=w,
        key_time_s=0.5 * t / PLANE_RATE_HZ,
        window_start_s=0.0,
        window_end_s=t / PLANE_RATE_HZ,
        spikes=SpikeStream(planes, plane_rate_hz=PLANE_RATE_HZ, gain=gain, dark_rate=0.0),
        ground_truth=ground_truth,
    )


def local_registry() -> dict:
    """Register this file's three modules into a plain dict (no global registry involved)."""
    entries: dict = {}

    def register(name, factory, *, params=None, inputs=None, description=""):
        assert name not in entries, f"duplicate {name}"
        entries[name] = (factory, dict(params or {}), description)

    for module in (tfp_module, tfi_module, tfstp_module):
        module.register_methods(register)
    return entries


REGISTRY = local_registry()


def create(name: str):
    factory, params, _ = REGISTRY[name]
    return factory(name=name, **params)


def level_image(levels, height: int = 8) -> np.ndarray:
    """A constant scene: one column per radiance level, ``height`` rows."""
    return np.repeat(np.asarray(levels, dtype=np.float64)[None, :], height, axis=0)


# --- registry ------------------------------------------------------------------------------------


def test_registry_entries_are_variants_of_one_implementation():
    assert set(REGISTRY) == set(METHODS)
    for name, planes in (("tfp", None), ("tfp-w8", 8), ("tfp-w16", 16), ("tfp-w32", 32), ("tfp-w64", 64)):
        factory, params, description = REGISTRY[name]
        assert factory is TFP and description
        method = create(name)
        assert method.params["window"] == planes and method.name == name
        assert method.inputs == frozenset({"spikes"})
    assert create("tfstp").params == {
        "u0": 0.15,
        "recovery_planes": 1.0,
        "facilitation_planes": 10.0,
        "facilitation": 0.15,
    }
    assert create("tfi").params == {}


def test_invalid_parameters_raise():
    for bad in (0, -3, 2.5, True, "8"):
        with pytest.raises(InputError):
            TFP(window=bad)
    bad_stp = ({"u0": 1.0}, {"u0": 0.0}, {"facilitation": 1.5}, {"recovery_planes": -1.0}, {"facilitation_planes": 1e9})
    for kwargs in bad_stp:
        with pytest.raises(InputError, match=next(iter(kwargs))):
            TFSTP(**kwargs)
        with pytest.raises(InputError, match=next(iter(kwargs))):
            STPParams(**kwargs)
    with pytest.raises(InputError, match="STPParams"):
        tfstp_rate(np.zeros((4, 3, 3), dtype=bool), 1, {"u0": 0.2})
    planes = np.zeros((4, 3, 3), dtype=bool)
    with pytest.raises(InputError):
        tfp_rate(planes.astype(np.uint8), 1, None)
    with pytest.raises(InputError):
        tfi_rate(planes, 4)
    with pytest.raises(InputError):
        tfstp_rate(planes[0], 0)
    with pytest.raises(InputError):
        stp_rates(np.array([1.0]), np.array([0.0]))


# --- TFP -----------------------------------------------------------------------------------------


def test_tfp_window_placement():
    # Odd windows are centred on the key plane, even ones on the key plane's start.
    assert tfp_window(41, 20, 41) == (0, 41)
    assert tfp_window(20, 10, 5) == (8, 13)
    assert tfp_window(20, 10, 8) == (6, 14)
    # Near an end the window shifts inward and keeps its planes; a short stream is used whole.
    assert tfp_window(20, 0, 8) == (0, 8)
    assert tfp_window(20, 19, 8) == (12, 20)
    assert tfp_window(5, 2, 8) == (0, 5)
    assert tfp_window(20, 3, None) == (0, 20)
    # The counted planes are exactly those: one spike per plane in its own pixel.
    planes = np.zeros((20, 1, 20), dtype=bool)
    planes[np.arange(20), 0, np.arange(20)] = True
    counted = tfp_rate(planes, 10, 8)[0] * 8
    np.testing.assert_array_equal(counted, (np.arange(20) >= 6) & (np.arange(20) < 14))


def test_tfp_records_the_effective_window():
    rng = np.random.default_rng(1)
    planes = rng.random((5, 4, 6)) < 0.5
    method = create("tfp-w64")
    image = method.reconstruct(make_sample(planes, gain=1.0))
    assert method.last_window == (0, 5)
    np.testing.assert_allclose(image, planes.mean(axis=0), atol=1e-7)


@pytest.mark.parametrize("light", [1 / 2, 1 / 8, 1 / 32])
def test_tfp_constant_scene_within_count_quantisation(light):
    # Over n planes the count is floor(n a) or ceil(n a), a = L r: the radiance error is < 1/(n L).
    rng = np.random.default_rng(2)
    radiance = level_image([0.0, 0.137, 0.31, 0.55, 0.83, 0.97])
    rate = light * radiance
    planes = integrate_and_fire(rate, 256, rng.random(radiance.shape))
    sample = make_sample(planes, gain=light)
    for name in METHODS[:5]:
        method = create(name)
        image = method.reconstruct(sample)
        start, stop = method.last_window
        n = stop - start
        assert n == (method.params["window"] or 256)
        lo = np.minimum(np.floor(n * rate) / (n * light), 1.0)
        hi = np.minimum(np.ceil(n * rate) / (n * light), 1.0)
        on_a_level = np.isclose(image, lo, atol=1e-6) | np.isclose(image, hi, atol=1e-6)
        assert on_a_level.all(), name
        assert (np.abs(image - np.minimum(radiance, 1.0)) <= 1.0 / (n * light) + 1e-6).all(), name
        assert method.last_normalisation == "gain"


def test_tfp_unknown_gain_uses_the_robust_path():
    rng = np.random.default_rng(3)
    radiance = level_image(np.linspace(0.05, 1.0, 50), height=4)
    planes = integrate_and_fire(0.25 * radiance, 256, rng.random(radiance.shape))
    method = create("tfp")
    image = method.reconstruct(make_sample(planes, gain=None))
    assert method.last_normalisation == "robust-p99"
    counts = planes.sum(axis=0) / 256.0
    np.testing.assert_allclose(image, np.clip(counts / np.percentile(counts, 99), 0, 1), atol=1e-6)


# --- TFI -----------------------------------------------------------------------------------------


def test_tfi_known_trains_and_the_edge_rule():
    t, key = 12, 5
    cases = {  # spike planes -> expected ISI
        (3, 10): 7,
        (5, 9): 4,  # a spike on the key plane counts as the previous one
        (1, 3, 4, 6, 11): 2,
        (2,): t - 2,  # no spike after: virtual spike at plane T
        (8,): 8 + 1,  # no spike before: virtual spike at plane -1
        (): t + 1,  # no spike: both virtual spikes
        tuple(range(t)): 1,
    }
    planes = np.zeros((t, 1, len(cases)), dtype=bool)
    for column, spikes in enumerate(cases):
        planes[list(spikes), 0, column] = True
    expected = np.array(list(cases.values()))
    np.testing.assert_array_equal(tfi_isi_planes(planes, key)[0], expected)
    gain = 0.3
    image = TFI().reconstruct(
        Sample(
            height=1,
            width=len(cases),
            key_time_s=(key + 0.5) / PLANE_RATE_HZ,
            window_start_s=0.0,
            window_end_s=t / PLANE_RATE_HZ,
            spikes=SpikeStream(planes, gain=gain, dark_rate=0.0),
        )
    )
    np.testing.assert_allclose(image[0], np.minimum(1.0 / (expected * gain), 1.0), rtol=1e-6)


@pytest.mark.parametrize("num_planes", [1, 7, 255, 256, 600])
def test_tfi_matches_a_per_pixel_search(num_planes):
    rng = np.random.default_rng(num_planes)
    planes = rng.random((num_planes, 5, 7)) < (0.004 if num_planes > 255 else 0.2)
    for key in sorted({0, num_planes // 2, num_planes - 1}):
        expected = np.empty((5, 7), dtype=np.int64)
        for y in range(5):
            for x in range(7):
                fired = np.flatnonzero(planes[:, y, x])
                before, after = fired[fired <= key], fired[fired > key]
                t_prev = before[-1] if before.size else -1
                t_next = after[0] if after.size else num_planes
                expected[y, x] = t_next - t_prev
        np.testing.assert_array_equal(tfi_isi_planes(planes, key), expected)
    assert planes_to_first_spike(planes[:0]).shape == (5, 7)


@pytest.mark.parametrize("light", [1 / 2, 1 / 8, 1 / 32])
def test_tfi_constant_scene_within_interval_quantisation(light):
    # Intervals are floor(1/a) or ceil(1/a) planes: the estimate lies in [1/ceil(1/a), 1/floor(1/a)] / L.
    # Levels keep ceil(1/a) <= 128, so both neighbours of the key plane (128 of 256) are seen.
    rng = np.random.default_rng(4)
    radiance = level_image([0.25, 0.31, 0.55, 0.83, 0.97])
    rate = light * radiance
    planes = integrate_and_fire(rate, 256, rng.random(radiance.shape))
    image = create("tfi").reconstruct(make_sample(planes, gain=light))
    lo = 1.0 / (np.ceil(1.0 / rate) * light)
    hi = np.minimum(1.0 / (np.floor(1.0 / rate) * light), 1.0)
    assert ((image >= lo - 1e-6) & (image <= hi + 1e-6)).all()


# --- TFSTP ---------------------------------------------------------------------------------------

STP_PARAMS = [
    {"u0": 0.15, "recovery_planes": 1.0, "facilitation_planes": 10.0, "facilitation": 0.15},
    {"u0": 0.3, "recovery_planes": 2.5, "facilitation_planes": 4.0, "facilitation": 0.4},
]


def closed_form_steady_state(isi, u0, recovery_planes, facilitation_planes, facilitation):
    """Fixed point of the STP updates under a periodic train, solved by hand: (1 - R*, u* - u0)."""
    e_r, e_u = math.exp(-isi / recovery_planes), math.exp(-isi / facilitation_planes)
    u_excess = facilitation * (1 - u0) * e_u / (1 - (1 - facilitation) * e_u)
    u = u0 + u_excess
    r_deficit = u * e_r / (1 - (1 - u) * e_r)
    return r_deficit, u_excess


@pytest.mark.parametrize("params", STP_PARAMS)
@pytest.mark.parametrize("isi", [1, 2, 3, 7, 20, 100, 300, 700])
def test_tfstp_readout_inverts_its_own_steady_state(isi, params):
    q, v = np.zeros(1), np.zeros(1)
    for _ in range(400):
        q, v = stp_step(q, v, float(isi), STPParams(**params))
    q_star, v_star = closed_form_steady_state(isi, **params)
    np.testing.assert_allclose([q[0], v[0]], [q_star, v_star], rtol=1e-12)
    rate_r, rate_u = stp_rates(q, v, STPParams(**params))
    np.testing.assert_allclose([rate_r[0], rate_u[0]], [1.0 / isi, 1.0 / isi], rtol=1e-11)
    if isi <= 7:  # R itself is representable: the textbook forms in R and u agree
        r, u = 1.0 - q_star, params["u0"] + v_star
        u0, d, big_f, f = (params[k] for k in ("u0", "recovery_planes", "facilitation_planes", "facilitation"))
        rho_r = -1.0 / (d * math.log((1 - r) / (1 - r * (1 - u))))
        rho_u = -1.0 / (big_f * math.log((u - u0) / (u * (1 - f) + f - u0)))
        np.testing.assert_allclose([rho_r, rho_u], [1.0 / isi, 1.0 / isi], rtol=1e-9)
        # ... and the variant with F in place of f is not the inverse.
        rho_wrong = -1.0 / (big_f * math.log((u - u0) / (u * (1 - f) + big_f - u0)))
        assert abs(rho_wrong * isi - 1.0) > 0.01


def test_tfstp_readout_limits():
    # At rest (fewer than two spikes) both read-outs are 0, the limit of an infinite interval; with
    # D = 1, 1 - R underflows to 0 after ~745 planes and its read-out takes that limit too.
    rate_r, rate_u = stp_rates(np.zeros(3), np.zeros(3))
    np.testing.assert_array_equal(rate_r, 0.0)
    np.testing.assert_array_equal(rate_u, 0.0)
    q, v = np.zeros(1), np.zeros(1)
    for _ in range(50):
        q, v = stp_step(q, v, 800.0)
    rate_r, rate_u = stp_rates(q, v)
    assert q[0] == 0.0 and rate_r[0] == 0.0
    np.testing.assert_allclose(rate_u, 1.0 / 800.0, rtol=1e-12)
    # The estimate is then the read-out that still measures, not half of it.
    planes = np.zeros((1700, 1, 2), dtype=bool)
    planes[[99, 899, 1699], 0, 0] = True
    planes[1699, 0, 1] = True
    np.testing.assert_allclose(tfstp_rate(planes, 1699), [[1.0 / 800.0, 0.0]], rtol=1e-12)


def test_tfstp_matches_a_per_pixel_reference():
    # Literal per-pixel updates of R and u (first spike only starts the clock), read out with the
    # textbook formulas; intervals are short, so R stays representable.
    rng = np.random.default_rng(5)
    planes = rng.random((60, 4, 5)) < 0.4
    planes[:, 0, 0] = False  # never fires
    planes[:, 0, 1] = False
    planes[30, 0, 1] = True  # fires once
    u0, d, big_f, f = 0.15, 1.0, 10.0, 0.15
    key = 45
    expected = np.zeros((4, 5))
    for y in range(4):
        for x in range(5):
            r, u, last = 1.0, u0, None
            for j in np.flatnonzero(planes[: key + 1, y, x]):
                if last is not None:
                    isi = j - last
                    r, u = (
                        1 - (1 - r * (1 - u)) * math.exp(-isi / d),
                        u0 + (u + f * (1 - u) - u0) * math.exp(-isi / big_f),
                    )
                last = j
            if last is not None and r < 1.0:
                rho_r = -1.0 / (d * math.log((1 - r) / (1 - r * (1 - u))))
                rho_u = -1.0 / (big_f * math.log((u - u0) / (u * (1 - f) + f - u0)))
                expected[y, x] = 0.5 * (rho_r + rho_u)
    np.testing.assert_allclose(tfstp_rate(planes, key), expected, rtol=1e-9, atol=0)
    assert expected[0, 0] == expected[0, 1] == 0.0


@pytest.mark.parametrize("isi", [1, 2, 3, 5, 8, 16])
def test_tfstp_periodic_train_gives_the_rate(isi):
    planes = np.zeros((256, 2, 3), dtype=bool)
    planes[isi - 1 :: isi] = True
    np.testing.assert_allclose(tfstp_rate(planes, 255), 1.0 / isi, rtol=1e-9)


@pytest.mark.parametrize("light", [1 / 2, 1 / 8, 1 / 32])
def test_tfstp_constant_scene(light):
    # Intervals are floor(1/a) or ceil(1/a): once the states have converged both read-outs lie
    # between the rates of those two intervals. The start-up transient shrinks by
    # (1 - f) exp(-Δ/F) per interval; with 1/a <= 32 there are >= 3 intervals before the key plane
    # (128), which leaves < 1e-3 of it. Where 1/a is a whole number the train is periodic and the
    # estimate is exact up to that transient.
    rng = np.random.default_rng(6)
    exact = {1 / 2: [1.0, 0.5], 1 / 8: [1.0, 0.5, 0.25], 1 / 32: [1.0]}[light]
    radiance = level_image(exact + [x for x in (0.137, 0.31, 0.55, 0.83, 0.97) if light * x >= 1 / 32])
    rate = light * radiance
    planes = integrate_and_fire(rate, 256, rng.random(radiance.shape))
    sample = make_sample(planes, gain=light)
    image = create("tfstp").reconstruct(sample)
    lo = 1.0 / (np.ceil(1.0 / rate) * light)
    hi = np.minimum(1.0 / (np.floor(1.0 / rate) * light), 1.0)
    assert ((image >= lo * (1 - 1e-3)) & (image <= hi * (1 + 1e-6))).all()
    np.testing.assert_allclose(image[:, : len(exact)], radiance[:, : len(exact)], rtol=1e-3)


def test_tfstp_state_is_causal():
    rng = np.random.default_rng(7)
    planes = rng.random((40, 3, 4)) < 0.3
    changed = planes.copy()
    changed[21:] = ~changed[21:]
    for a, b in zip(tfstp_state(planes, 20), tfstp_state(changed, 20)):
        np.testing.assert_array_equal(a, b)


def simulated_window(kind: str, light: float, seed: int) -> np.ndarray:
    """A 256-plane window of the suite's simulator (pan or still photograph, 64x40, random charge)."""
    from neuspike.conditions import Condition, effect
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.window import simulate_window

    scene = make_scene(SceneSpec(kind=kind, image="camera", size=(64, 40), velocity_px_s=(3000.0, 800.0)))
    cond = Condition(light=light, motion=64, effects=(effect("initial_charge"),))
    return simulate_window(scene, cond, rng=np.random.default_rng(seed), modalities={"spikes"}).spikes.planes


@pytest.mark.parametrize("kind", ["still", "pan"])
@pytest.mark.parametrize("light", [1 / 32, 1 / 4, 1 / 2])
def test_tfstp_compiled_pass_equals_the_numpy_reference(kind, light):
    # Same float64 operations in the same order: the states and the rate agree bit for bit.
    planes = simulated_window(kind, light, seed=4)
    for key in (0, 63, 128, 255):
        fast = tfstp_state(planes, key, backend="numba")
        ref = tfstp_state(planes, key, backend="numpy")
        for a, b in zip(fast, ref):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(tfstp_rate(planes, key, backend="numba"),
                                      tfstp_rate(planes, key, backend="numpy"))


def test_tfstp_compiled_pass_on_long_windows_and_edge_cases():
    # More than 64 planes per bit mask word, the hard cases' trains, and the saturation limit.
    rng = np.random.default_rng(10)
    planes = rng.random((300, 3, 17)) < rng.uniform(0.0, 1.0, (3, 17))
    planes[:, 0, 0] = True
    planes[:, 0, 1] = False
    for key in (62, 63, 64, 127, 128, 299):
        np.testing.assert_array_equal(tfstp_rate(planes, key, backend="numba"),
                                      tfstp_rate(planes, key, backend="numpy"))
    params = STPParams(u0=0.5, recovery_planes=3.0, facilitation_planes=40.0, facilitation=0.6)
    np.testing.assert_array_equal(tfstp_rate(planes, 200, params, backend="numba"),
                                  tfstp_rate(planes, 200, params, backend="numpy"))
    with pytest.raises(InputError, match="backend"):
        tfstp_rate(planes, 5, backend="torch")


# --- every method: hard cases, ground truth never read -------------------------------------------


def dark_current_isi(rng, shape, sigma):
    """Per-pixel dark intervals ~ Normal(180, sigma^2), redrawn below 1 plane."""
    isi = rng.normal(180.0, sigma, size=shape)
    while (bad := isi < 1).any():
        isi[bad] = rng.normal(180.0, sigma, size=int(bad.sum()))
    return isi


def hard_cases():
    rng = np.random.default_rng(8)
    texture = rng.random((250, 400))
    white = np.ones((250, 400))
    noisy_drive = texture / 2 + 1.0 / dark_current_isi(rng, texture.shape, 90.0)
    return {
        "no spikes": np.zeros((256, 250, 400), dtype=bool),
        "every plane": np.ones((256, 250, 400), dtype=bool),
        "single plane": rng.random((1, 250, 400)) < 0.3,
        "L=1/32": integrate_and_fire(white / 32, 256, rng.random(white.shape)),
        "256 planes": integrate_and_fire(texture / 4, 256, rng.random(texture.shape)),
        "sigma 90": integrate_and_fire(noisy_drive, 256, rng.normal(size=texture.shape)),
        "346x260": integrate_and_fire(rng.random((260, 346)) / 2, 64, rng.random((260, 346))),
        "240x180": integrate_and_fire(rng.random((180, 240)) / 2, 64, rng.random((180, 240))),
    }


HARD_CASES = hard_cases()


@pytest.mark.parametrize("case", list(HARD_CASES))
def test_hard_cases_give_valid_images_without_warnings(case):
    planes = HARD_CASES[case]
    for gain in (1 / 32, None):
        sample = make_sample(planes, gain=gain)
        for name in METHODS:
            method = create(name)
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                image = method.reconstruct(sample)
            assert image.dtype == np.float32 and image.shape == planes.shape[1:], (case, name)
            assert np.isfinite(image).all() and image.min() >= 0 and image.max() <= 1, (case, name)
            # (a one-plane window at gain 1/32 is below TFI's detection floor: its label adds that it counted)
            assert method.last_normalisation.split(";")[0] == ("gain" if gain else "robust-p99")


def test_hard_case_values():
    t = 256
    zeros, ones = make_sample(HARD_CASES["no spikes"], 0.5), make_sample(HARD_CASES["every plane"], 0.5)
    np.testing.assert_array_equal(create("tfp").reconstruct(zeros), 0.0)
    np.testing.assert_array_equal(create("tfstp").reconstruct(zeros), 0.0)
    np.testing.assert_allclose(create("tfi").reconstruct(zeros), 1.0 / ((t + 1) * 0.5), rtol=1e-6)
    for name in METHODS:  # rate 1 spike per plane = radiance 2 at gain 0.5: saturated
        np.testing.assert_array_equal(create(name).reconstruct(ones), 1.0)
    np.testing.assert_allclose(tfstp_rate(HARD_CASES["every plane"][:, :2, :2], 128), 1.0, rtol=1e-12)


def test_methods_never_read_the_ground_truth():
    rng = np.random.default_rng(9)
    truth = rng.random((30, 40)).astype(np.float32)
    planes = integrate_and_fire(truth / 4, 64, rng.random(truth.shape))
    for gain in (0.25, None):
        sane = make_sample(planes, gain=gain, ground_truth=truth)
        poisoned = make_sample(planes, gain=gain, ground_truth=np.full_like(truth, np.nan))
        for name in METHODS:
            np.testing.assert_array_equal(create(name).reconstruct(sane), create(name).reconstruct(poisoned))
