"""Metrics against closed forms and scikit-image's reference implementation."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from skimage import data
from skimage.metrics import structural_similarity

from neuspike import metrics
from neuspike.errors import InputError


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def photo() -> np.ndarray:
    """A real photograph in [0, 1], float64 (128, 128)."""
    img = data.camera().astype(np.float64) / 255.0
    return cv2.resize(img, (128, 128), interpolation=cv2.INTER_AREA)


# --- PSNR -----------------------------------------------------------------------------------

@pytest.mark.parametrize("delta", [0.01, 0.05, 0.2])
def test_psnr_of_constant_offset_is_closed_form(rng, delta):
    reference = rng.uniform(0.25, 0.75, size=(40, 50))
    image = reference + delta
    assert metrics.psnr(image, reference, data_range=1.0) == pytest.approx(-20 * math.log10(delta), abs=1e-9)


def test_psnr_scales_with_data_range(rng):
    reference = rng.uniform(0.5, 1.5, size=(20, 30))
    image = reference - 0.1
    assert metrics.psnr(image, reference, data_range=2.0) == pytest.approx(20 * math.log10(2.0 / 0.1), abs=1e-9)


def test_identical_images_give_infinite_psnr_and_unit_ssim(photo):
    assert metrics.psnr(photo, photo, data_range=1.0) == math.inf
    assert metrics.ssim(photo, photo, data_range=1.0) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("fn", [metrics.psnr, metrics.ssim, metrics.evaluate, metrics.psnr_affine, metrics.ssim_affine])
def test_data_range_is_required_and_keyword_only(photo, fn):
    with pytest.raises(TypeError):
        fn(photo, photo)
    with pytest.raises(TypeError):
        fn(photo, photo, 1.0)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, "one"])
def test_data_range_must_be_positive_and_finite(photo, bad):
    with pytest.raises(InputError):
        metrics.psnr(photo, photo, data_range=bad)


# --- SSIM -----------------------------------------------------------------------------------

def test_ssim_matches_skimage_with_evreal_settings(photo, rng):
    noisy = np.clip(photo + rng.normal(0.0, 0.05, photo.shape), 0.0, 1.0)
    expected = structural_similarity(
        noisy, photo, data_range=1.0, gaussian_weights=True, sigma=1.5, use_sample_covariance=False
    )
    assert metrics.ssim(noisy, photo, data_range=1.0) == pytest.approx(expected, abs=1e-12)
    # The pinned settings matter: scikit-image's defaults (7x7 uniform window) give another number.
    default = structural_similarity(noisy, photo, data_range=1.0)
    assert abs(default - expected) > 1e-3


def test_ssim_settings_are_pinned_and_described():
    s = metrics.SSIM_SETTINGS
    assert isinstance(s, dict)
    assert s["gaussian_weights"] is True and s["sigma"] == 1.5 and s["use_sample_covariance"] is False
    text = metrics.describe_metrics()
    for item in ("gaussian_weights=True", "sigma=1.5", "use_sample_covariance=False"):
        assert item in text


def test_ssim_rejects_images_smaller_than_the_window(rng):
    a = rng.uniform(size=(10, 40))
    with pytest.raises(InputError, match="11x11"):
        metrics.ssim(a, a, data_range=1.0)


# --- affine alignment -----------------------------------------------------------------------

@pytest.mark.parametrize("gain, offset", [(2.5, -0.3), (0.4, 0.1), (-0.8, 0.9)])
def test_affine_alignment_recovers_known_gain_and_offset(photo, gain, offset):
    # reference = gain * image + offset exactly; build image from the reference
    reference = photo * 0.6 + 0.2
    image = (reference - offset) / gain
    aligned, g, o = metrics.affine_align(image, reference)
    assert g == pytest.approx(gain, rel=1e-10)
    assert o == pytest.approx(offset, abs=1e-10)
    np.testing.assert_allclose(aligned, reference, atol=1e-10)


def test_affine_fit_satisfies_the_normal_equations(rng, photo):
    image = rng.uniform(size=photo.shape)
    aligned, g, o = metrics.affine_align(image, photo)
    residual = aligned - photo
    # least squares: the residual is orthogonal to both regressors (the image and the constant)
    assert abs(np.sum(residual)) < 1e-8 * residual.size
    assert abs(np.sum(residual * image)) < 1e-8 * residual.size


def test_affine_of_constant_image_is_the_reference_mean(photo):
    aligned, g, o = metrics.affine_align(np.full(photo.shape, 0.3), photo)
    assert g == 0.0 and o == pytest.approx(photo.mean())
    np.testing.assert_allclose(aligned, photo.mean())


def test_affine_alignment_clips_only_when_asked(photo):
    image = photo ** 3  # a nonlinear relation: the linear fit overshoots at the ends
    unclipped, _, _ = metrics.affine_align(image, photo)
    clipped, _, _ = metrics.affine_align(image, photo, data_range=1.0)
    assert unclipped.max() > 1.0 or unclipped.min() < 0.0
    assert clipped.min() >= 0.0 and clipped.max() <= 1.0
    np.testing.assert_array_equal(clipped, np.clip(unclipped, 0.0, 1.0))


def test_evaluate_reports_the_four_metrics_consistently(photo):
    image = 0.5 * photo + 0.1  # right structure, wrong scale
    scores = metrics.evaluate(image, photo, data_range=1.0)
    assert tuple(scores) == metrics.FULL_REFERENCE_METRICS
    assert scores["psnr"] == pytest.approx(metrics.psnr(image, photo, data_range=1.0))
    assert scores["ssim"] == pytest.approx(metrics.ssim(image, photo, data_range=1.0))
    assert scores["psnr_affine"] == pytest.approx(metrics.psnr_affine(image, photo, data_range=1.0))
    assert scores["ssim_affine"] == pytest.approx(metrics.ssim_affine(image, photo, data_range=1.0))
    # an exact affine relation is undone by the alignment
    assert scores["psnr_affine"] > 100.0 and scores["psnr"] < 20.0
    assert scores["ssim_affine"] == pytest.approx(1.0, abs=1e-9)


# --- input validation -----------------------------------------------------------------------

def test_inputs_are_validated(photo):
    with pytest.raises(InputError, match="same shape"):
        metrics.psnr(photo, photo[:-1], data_range=1.0)
    bad = photo.copy()
    bad[3, 4] = np.nan
    with pytest.raises(InputError, match="finite"):
        metrics.evaluate(bad, photo, data_range=1.0)
    with pytest.raises(InputError, match="2-D"):
        metrics.ssim(photo[None], photo[None], data_range=1.0)
    # the 6 dB trap's cousin: an 8-bit-scaled image scored with data_range 1
    with pytest.raises(InputError, match=r"\[0, data_range\]"):
        metrics.psnr(photo * 255.0, photo, data_range=1.0)
    with pytest.raises(InputError):
        metrics.no_reference(np.zeros((2, 5, 5)))


# --- no-reference measures ------------------------------------------------------------------

def test_noise_estimate_matches_pure_gaussian_noise(rng):
    sigma = 0.05
    noise = rng.normal(0.0, sigma, size=(256, 256))
    assert metrics.haar_noise_sigma(noise) == pytest.approx(sigma, rel=0.05)


def test_noise_estimate_is_zero_on_a_linear_ramp():
    yy, xx = np.mgrid[0:64, 0:80]
    ramp = 0.002 * xx + 0.003 * yy
    assert metrics.no_reference(ramp)["noise_sigma"] == pytest.approx(0.0, abs=1e-12)


def test_noise_estimate_grows_with_added_noise(photo, rng):
    sigmas = [0.0, 0.02, 0.05, 0.1]
    estimates = [metrics.no_reference(photo + rng.normal(0.0, s, photo.shape))["noise_sigma"] for s in sigmas]
    assert all(a < b for a, b in zip(estimates, estimates[1:]))
    assert estimates[-1] == pytest.approx(0.1, rel=0.15)


def test_sharpness_drops_with_blur(photo):
    values = [metrics.no_reference(photo)["laplacian_var"]]
    for ksize in (3, 7, 15):
        values.append(metrics.no_reference(cv2.GaussianBlur(photo, (ksize, ksize), 0))["laplacian_var"])
    assert all(a > b for a, b in zip(values, values[1:]))
    assert metrics.laplacian_variance(np.full((20, 20), 0.7)) == 0.0


def test_laplacian_variance_of_a_checkerboard_is_closed_form():
    # +-a checkerboard: the 3x3 Laplacian is -8 * value at every interior pixel, so var = 64 a^2
    a = 0.25
    board = a * np.where((np.add.outer(np.arange(16), np.arange(16)) % 2) == 0, 1.0, -1.0)
    assert metrics.laplacian_variance(board) == pytest.approx(64 * a * a, rel=1e-12)


# --- static texture --------------------------------------------------------------------------------

def test_static_texture_is_invariant_to_gain_and_offset(photo):
    static = np.ones_like(photo, dtype=bool)
    image = np.clip(0.2 + 0.5 * photo, 0, 1)
    assert metrics.static_texture(image, photo, static, data_range=1.0) == pytest.approx(1.0, abs=1e-9)


def test_static_texture_scores_a_flat_image_zero_and_falls_with_blur(photo, rng):
    static = np.ones_like(photo, dtype=bool)
    flat = np.full_like(photo, 0.5)
    assert metrics.static_texture(flat, photo, static, data_range=1.0) == 0.0
    blurred = [cv2.GaussianBlur(photo, (0, 0), s) for s in (1.0, 3.0, 8.0)]
    scores = [metrics.static_texture(b, photo, static, data_range=1.0) for b in blurred]
    assert scores[0] > scores[1] > scores[2]
    noise = rng.random(photo.shape).astype(np.float32)  # texture unrelated to the reference
    assert abs(metrics.static_texture(noise, photo, static, data_range=1.0)) < 0.1


def test_static_texture_looks_only_inside_the_trimmed_region(photo):
    """Texture outside the region (or within the trimmed margin of its edge) does not count."""
    h, w = photo.shape
    static = np.zeros((h, w), dtype=bool)
    static[:, : w // 2] = True
    image = photo.copy()
    cut = w // 2 - metrics.STATIC_ERODE_PX  # the measured pixels end here
    image[:, cut - 1:] = 0.5  # flat beyond: the 3x3 gradient at the last measured column reads col cut
    image[:, cut - 1] = photo[:, cut - 1]
    assert metrics.static_texture(image, photo, static, data_range=1.0) > 0.97
    image[:, : cut - 3] = 0.5
    assert metrics.static_texture(image, photo, static, data_range=1.0) < 0.5


def test_static_texture_needs_a_large_enough_region(photo):
    tiny = np.zeros_like(photo, dtype=bool)
    tiny[:10, :10] = True
    assert math.isnan(metrics.static_texture(photo, photo, tiny, data_range=1.0))
    with pytest.raises(InputError, match="static"):
        metrics.static_texture(photo, photo, tiny.astype(np.uint8), data_range=1.0)


# --- isolated outliers (specks) ---------------------------------------------------------------

def test_isolated_outliers_count_single_pixels_beyond_all_their_neighbours(photo):
    """A bright and a dark speck on a smooth ramp are two of the interior pixels; the same pixels
    pushed by less than the margin, or by the margin on a textured photograph's edges, are not."""
    ramp = np.tile(np.linspace(0.2, 0.8, 64), (48, 1))
    specked = ramp.copy()
    specked[10, 10] += 0.15
    specked[30, 40] -= 0.15
    interior = 46 * 62
    assert metrics.isolated_outliers(specked, ramp, data_range=1.0) == pytest.approx(2 / interior)
    faint = ramp.copy()
    faint[10, 10] += 0.05
    assert metrics.isolated_outliers(faint, ramp, data_range=1.0) == 0.0
    assert metrics.isolated_outliers(photo, photo, data_range=1.0) == 0.0  # the truth's own are not counted
    # a speck the truth has is not the image's fault
    assert metrics.isolated_outliers(specked, specked, data_range=1.0) == 0.0
    # data_range scales the margin
    assert metrics.isolated_outliers(255 * specked, 255 * ramp, data_range=255.0) == pytest.approx(2 / interior)


def test_isolated_outliers_tell_specks_from_noise_that_spreads(rng):
    """Noise of the same strength, once spread over 3x3 neighbourhoods (as SNM's synapses and most
    smoothing spread it), makes almost no pixel stand beyond all eight neighbours; white speckle
    at a tenth of a percent of the pixels is counted one for one."""
    flat = np.full((200, 200), 0.5)
    spread = np.clip(flat + cv2.GaussianBlur(rng.normal(0, 0.2, flat.shape), (0, 0), 1.0), 0, 1)
    assert metrics.isolated_outliers(spread, flat, data_range=1.0) < 1e-4
    specks = flat.copy()
    where = rng.choice(flat.size, 40, replace=False)
    specks.flat[where] = rng.choice([0.2, 0.8], 40)
    inner = np.zeros(flat.shape, bool)
    inner[1:-1, 1:-1] = True
    expected = np.count_nonzero(inner.flat[where]) / (198 * 198)
    assert metrics.isolated_outliers(specks, flat, data_range=1.0) == pytest.approx(expected, rel=0.05)


def test_isolated_outliers_refuse_bad_input():
    with pytest.raises(InputError, match="3x3"):
        metrics.isolated_outliers(np.zeros((2, 5)), np.zeros((2, 5)), data_range=1.0)
    with pytest.raises(InputError, match="data_range"):
        metrics.isolated_outliers(np.full((4, 4), 2.0), np.zeros((4, 4)), data_range=1.0)
