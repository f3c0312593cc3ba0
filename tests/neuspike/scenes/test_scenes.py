"""Scenes: analytic checks of pan, zoom, fan, still and video rendering, and input validation."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from neuspike.conditions import effect
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.scenes import (
    BUNDLED_PHOTOS,
    TEST_PHOTOS,
    TRAIN_PHOTOS,
    SceneSpec,
    load_photo,
    make_scene,
    mirror_index,
)
from tests.shared_data import SHARED

SLIDER = SHARED / "realdata" / "video" / "slider_depth"
needs_slider = pytest.mark.skipif(not (SLIDER / "images.txt").is_file(), reason="shared slider_depth absent")


def write_png16(path: Path, values: np.ndarray) -> Path:
    """Write integer values (0..65535) as a 16-bit grey PNG."""
    assert cv2.imwrite(str(path), values.astype(np.uint16))
    return path


def ramp_values(width: int, height: int) -> np.ndarray:
    y, x = np.mgrid[0:height, 0:width]
    return 1000 + 500 * x + 300 * y


def smooth_texture(width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    """A smooth random texture in [0.1, 0.9] (blurred noise)."""
    noise = rng.random((height, width)).astype(np.float32)
    blurred = cv2.GaussianBlur(noise, (0, 0), 3.0, borderType=cv2.BORDER_REFLECT_101)
    blurred -= blurred.min()
    return 0.1 + 0.8 * blurred / blurred.max()


# ---------------------------------------------------------------------------------------------
# spec validation


@pytest.mark.parametrize(
    "kwargs",
    [
        {"kind": "spin"},
        {"kind": "pan", "size": (-400, 250)},
        {"kind": "pan", "size": (400, 0)},
        {"kind": "pan", "size": (400.5, 250)},
        {"kind": "pan", "size": (400, 250, 3)},
        {"kind": "pan", "velocity_px_s": (float("nan"), 0.0)},
        {"kind": "zoom", "zoom_rate_hz": float("inf")},
        {"kind": "zoom", "focus": (1.0,)},
        {"kind": "fan", "blades": 0},
        {"kind": "fan", "blades": True},
        {"kind": "fan", "blades": 4, "blade_width_deg": 90.0},
        {"kind": "fan", "blade_width_deg": 0.0},
        {"kind": "fan", "blade_contrast": -0.5},
        {"kind": "still", "dynamic_range": 0.5},
        {"kind": "still", "peak": 0.0},
        {"kind": "still", "seed": -1},
        {"kind": "still", "image": ""},
        {"kind": "still", "effects": ("initial_charge",)},
        {"kind": "still", "effects": (effect("leak"), effect("leak"))},
        {"kind": "pan", "upsample": 4},
        {"kind": "pan", "fps": 30.0},
        {"kind": "video"},
        {"kind": "video", "video": "x", "fps": -1.0},
        {"kind": "video", "video": "x", "upsample": 0},
    ],
)
def test_bad_spec_raises_input_error(kwargs):
    with pytest.raises(InputError):
        SceneSpec(**kwargs)


def test_spec_defaults_and_normalisation():
    spec = SceneSpec(kind="pan")
    assert spec.size == (400, 250)
    assert spec.velocity_px_s == (1000.0, 0.0)
    assert SceneSpec(kind="video", video="somewhere").size is None
    spec = SceneSpec(kind="fan", size=[346, 260], effects=[effect("leak")], blades=np.int64(5))
    assert spec.size == (346, 260) and isinstance(spec.effects, tuple) and spec.blades == 5
    assert hash(spec) == hash(SceneSpec(kind="fan", size=(346, 260), effects=(effect("leak"),), blades=5))
    json.dumps(spec.as_dict())


def test_make_scene_rejects_non_spec():
    with pytest.raises(InputError):
        make_scene({"kind": "pan"})


# ---------------------------------------------------------------------------------------------
# photographs


def test_split_is_fixed_disjoint_and_complete():
    assert set(TRAIN_PHOTOS).isdisjoint(TEST_PHOTOS)
    assert set(TRAIN_PHOTOS) | set(TEST_PHOTOS) == set(BUNDLED_PHOTOS)
    assert "camera" in TEST_PHOTOS
    assert len(TRAIN_PHOTOS) >= len(BUNDLED_PHOTOS) // 2


def test_held_out_pictures_are_a_third_set_that_loads_the_same_on_every_call():
    from neuspike.scenes import HELDOUT_PICTURES
    from neuspike.scenes.photos import read_photo

    assert set(HELDOUT_PICTURES).isdisjoint(set(BUNDLED_PHOTOS))
    assert set(HELDOUT_PICTURES) == {"portrait", "terrain", "typeset", "night", "foliage"}
    for name in HELDOUT_PICTURES:
        image = read_photo(name)
        assert image.shape[0] >= 400 and image.shape[1] >= 512, name  # the 400x250 view is never enlarged
        np.testing.assert_array_equal(image, read_photo(name))
    night = read_photo("night")
    assert np.mean(night < 0.1) > 0.8 and night.max() == 1.0  # dark, with lamps at white


def test_training_refuses_the_held_out_pictures():
    from neuspike.train.spec import _check_photos

    with pytest.raises(InputError, match="held-out"):
        _check_photos(["astronaut", "portrait"])


def test_every_bundled_photo_loads_as_luma():
    from neuspike.scenes import HELDOUT_PICTURES

    for name in BUNDLED_PHOTOS + HELDOUT_PICTURES:
        image = load_photo(name, (64, 40))
        assert image.shape == (40, 64) and image.dtype == np.float32, name
        assert 0.0 <= image.min() and image.max() <= 1.0, name
        assert image.std() > 0.01, name  # a picture, not a flat field


def test_colour_luma_uses_rec601_weights(tmp_path):
    bgr = np.zeros((10, 12, 3), np.uint8)
    bgr[:, :4, 2] = 255  # red
    bgr[:, 4:8, 1] = 255  # green
    bgr[:, 8:, 0] = 255  # blue
    cv2.imwrite(str(tmp_path / "rgb.png"), bgr)
    image = load_photo(tmp_path / "rgb.png", (12, 10))
    np.testing.assert_allclose(image[0, [0, 5, 10]], [0.299, 0.587, 0.114], atol=1e-6)


def test_cover_resize_and_centre_crop(tmp_path):
    # 100 x 50 column ramp onto a 40 x 40 view: scaled to 80 x 40, columns 20..59 kept
    values = np.tile(np.arange(100) * 600, (50, 1))
    image = load_photo(write_png16(tmp_path / "cols.png", values), (40, 40))
    scaled = cv2.resize((values / 65535.0).astype(np.float32), (80, 40), interpolation=cv2.INTER_AREA)
    expected = scaled[:, 20:60]
    np.testing.assert_allclose(image, expected, atol=1e-6)


def test_unreadable_image_raises_source_error_naming_path(tmp_path):
    missing = tmp_path / "missing.png"
    with pytest.raises(SourceError, match="missing.png"):
        load_photo(missing, (40, 30))
    garbage = tmp_path / "garbage.png"
    garbage.write_bytes(b"not an image at all")
    with pytest.raises(SourceError, match="garbage.png"):
        make_scene(SceneSpec(kind="still", image=str(garbage)))


def test_image_with_nan_or_out_of_range_raises_input_error(tmp_path):
    bad = np.full((30, 40), 0.5, np.float32)
    bad[3, 4] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(InputError):
        make_scene(SceneSpec(kind="pan", image=str(tmp_path / "nan.npy"), size=(40, 30)))
    np.save(tmp_path / "big.npy", np.full((30, 40), 1.5, np.float32))
    with pytest.raises(InputError):
        load_photo(tmp_path / "big.npy", (40, 30))


# ---------------------------------------------------------------------------------------------
# pan


def test_pan_of_ramp_is_exact_at_subpixel_offsets(tmp_path):
    width, height = 64, 40
    path = write_png16(tmp_path / "ramp.png", ramp_values(width, height))
    vx, vy = 37.3, -11.7
    scene = make_scene(SceneSpec(kind="pan", image=str(path), size=(width, height), velocity_px_s=(vx, vy)))
    times = np.array([0.0, 0.013, 0.1, -0.07, 0.25])
    frames = scene.render(times)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    for frame, t in zip(frames, times):
        sx, sy = x - vx * t, y - vy * t  # the plane point each pixel shows
        inside = (sx >= 0) & (sx <= width - 1) & (sy >= 0) & (sy <= height - 1)
        assert inside.sum() > 300
        expected = (1000 + 500 * sx + 300 * sy) / 65535.0
        np.testing.assert_allclose(frame[inside], expected[inside], rtol=0, atol=2e-6)


def test_pan_at_integer_displacement_is_a_plain_shift():
    scene = make_scene(SceneSpec(kind="pan", velocity_px_s=(1000.0, -500.0)))
    still, moved = scene.render([0.0, 0.004])  # shifted by (+4, -2) pixels
    np.testing.assert_array_equal(moved[:-2, 4:], still[2:, :-4])


def test_pan_has_no_seam_over_long_times(tmp_path):
    width, height = 90, 60
    texture = smooth_texture(width, height, np.random.default_rng(3))
    np.save(tmp_path / "smooth.npy", texture)
    scene = make_scene(SceneSpec(kind="pan", image=str(tmp_path / "smooth.npy"), size=(width, height),
                                 velocity_px_s=(1234.5, 321.7)))
    bound = max(np.abs(np.diff(texture, axis=0)).max(), np.abs(np.diff(texture, axis=1)).max())
    frames = scene.render(np.linspace(-10.0, 10.0, 97))  # tens of photo widths either way
    steps = max(np.abs(np.diff(frames, axis=1)).max(), np.abs(np.diff(frames, axis=2)).max())
    assert steps <= bound * (1 + 1e-4) + 1e-6
    # the same image tiled without mirroring would jump at the seam
    assert np.abs(texture[:, 0] - texture[:, -1]).max() > 2 * bound


def test_mirror_index_is_reflect_101():
    np.testing.assert_array_equal(mirror_index(np.arange(-4, 9), 4), [2, 3, 2, 1, 0, 1, 2, 3, 2, 1, 0, 1, 2])
    np.testing.assert_array_equal(mirror_index(np.array([-3, 0, 5]), 1), [0, 0, 0])


# ---------------------------------------------------------------------------------------------
# zoom


def test_zoom_at_zero_is_the_still_and_the_focus_stays_fixed():
    focus = (100.0, 60.0)
    still = make_scene(SceneSpec(kind="still")).render([0.0])[0]
    zoom = make_scene(SceneSpec(kind="zoom", focus=focus, zoom_rate_hz=5.0))
    frames = zoom.render([0.0, 0.05, 0.3, -0.2])
    np.testing.assert_array_equal(frames[0], still)
    np.testing.assert_array_equal(frames[:, 60, 100], np.full(4, still[60, 100]))
    assert np.abs(frames[2] - still).mean() > 0.02  # it does move


def test_zoom_scale_doubles_after_ln2_over_rate():
    rate = 4.0
    still = make_scene(SceneSpec(kind="still")).render([0.0])[0]
    zoom = make_scene(SceneSpec(kind="zoom", focus=(200.0, 120.0), zoom_rate_hz=rate))
    frame = zoom.render([math.log(2.0) / rate])[0]
    # view pixel focus + 2 d shows what the still shows at focus + d
    d = np.arange(-50, 50)
    np.testing.assert_allclose(frame[120 + 2 * d[30:70], 200], still[120 + d[30:70], 200], atol=1e-5)
    np.testing.assert_allclose(frame[120, 200 + 2 * d], still[120, 200 + d], atol=1e-5)


def test_zoom_beyond_scale_limit_raises():
    scene = make_scene(SceneSpec(kind="zoom", zoom_rate_hz=5.0, size=(40, 30)))
    with pytest.raises(InputError):
        scene.render([10.0])


# ---------------------------------------------------------------------------------------------
# fan


def test_fan_is_periodic_with_blade_period():
    rpm, blades = 1800.0, 3
    scene = make_scene(SceneSpec(kind="fan", rpm=rpm, blades=blades))
    period = 60.0 / (rpm * blades)
    assert scene.period_s == pytest.approx(period)
    t = np.array([0.0013, 0.0013 + period, 0.0013 + 7 * period, 0.0013 + period / 2])
    frames = scene.render(t)
    np.testing.assert_allclose(frames[1], frames[0], atol=1e-5)
    np.testing.assert_allclose(frames[2], frames[0], atol=1e-5)
    assert np.abs(frames[3] - frames[0]).max() > 0.1  # half a period later the blades moved


@pytest.mark.parametrize("contrast", [0.25, 3.0])
def test_fan_blade_pixel_has_declared_contrast_and_turns_clockwise(contrast):
    rpm = 600.0
    spec = SceneSpec(kind="fan", rpm=rpm, blades=3, blade_width_deg=30.0, blade_contrast=contrast,
                     focus=(200.0, 125.0))
    background = make_scene(SceneSpec(kind="still")).render([0.0])[0]
    scene = make_scene(spec)
    turn_s = 60.0 / rpm
    frames = scene.render([0.0, turn_s / 6, turn_s / 4])
    right, down = (125, 270), (195, 200)  # 70 px from the hub along +x and +y (screen down)
    # t = 0: blade 0 points along +x; +y (90 deg) lies 15 deg outside the blade at 120 deg
    assert frames[0][right] == pytest.approx(contrast * background[right], rel=1e-5)
    assert frames[0][down] == background[down]
    # half a blade spacing later nothing covers +x; a quarter turn later blade 0 covers +y
    assert frames[1][right] == background[right]
    assert frames[2][down] == pytest.approx(contrast * background[down], rel=1e-5)


def test_fan_coverage_is_antialiased_and_matches_blade_area():
    spec = SceneSpec(kind="fan", blades=4, blade_width_deg=40.0, blade_contrast=0.0, focus=(200.0, 125.0))
    scene = make_scene(spec)
    cover = scene.coverage(np.array([0.0, 0.00123]))
    assert ((cover > 0.05) & (cover < 0.95)).sum() > 200  # soft edges exist
    r_tip, r_hub = scene.tip_radius_px, scene.hub_radius_px
    width = math.radians(40.0)
    area = 4 * width / 2 * (r_tip**2 - r_hub**2) + math.pi * r_hub**2
    np.testing.assert_allclose(cover.sum(axis=(1, 2)), area, rtol=2e-3)
    # contrast 0: radiance = background * (1 - coverage)
    background = make_scene(SceneSpec(kind="still")).render([0.0])[0]
    np.testing.assert_allclose(scene.render([0.00123])[0], background * (1 - cover[1]), atol=1e-6)


# ---------------------------------------------------------------------------------------------
# dynamic range, invariants, determinism


def test_dynamic_range_maps_black_and_white_as_declared(tmp_path):
    values = np.zeros((30, 40))
    values[:, 20:] = 65535
    values[:, 10:20] = 32768
    path = str(write_png16(tmp_path / "bw.png", values))
    hdr = make_scene(SceneSpec(kind="still", image=path, size=(40, 30), dynamic_range=1000.0, peak=2.0))
    frame = hdr.render([0.0])[0]
    assert frame.max() == pytest.approx(2.0, rel=1e-6)
    assert frame.min() == pytest.approx(2.0 / 1000.0, rel=1e-5)
    assert frame[0, 15] == pytest.approx(2.0 * 1000.0 ** (32768 / 65535 - 1), rel=1e-5)
    linear = make_scene(SceneSpec(kind="still", image=path, size=(40, 30), peak=3.0)).render([0.0])[0]
    assert linear.min() == 0.0 and linear.max() == pytest.approx(3.0)


KIND_SPECS = [
    SceneSpec(kind="pan", size=(96, 64), velocity_px_s=(-700.0, 250.0), image="coins"),
    SceneSpec(kind="zoom", size=(96, 64), zoom_rate_hz=-3.0, dynamic_range=1000.0),
    SceneSpec(kind="fan", size=(96, 64), rpm=2600.0, image="gravel", peak=4.0),
    SceneSpec(kind="still", size=(96, 64), image="moon"),
]


@pytest.mark.parametrize("spec", KIND_SPECS, ids=lambda s: s.kind)
def test_render_contract_and_determinism(spec):
    times = np.linspace(-0.3, 0.4, 9)
    a = make_scene(spec).render(times)
    b = make_scene(spec).render(times)
    assert a.dtype == np.float32 and a.shape == (9, 64, 96)
    assert np.isfinite(a).all() and a.min() >= 0
    assert a.tobytes() == b.tobytes()
    scene = make_scene(spec)
    assert (scene.width, scene.height) == (96, 64) and scene.spec == spec
    assert scene.render(np.array([], np.float64)).shape == (0, 64, 96)
    description = json.loads(json.dumps(scene.describe()))
    assert description["kind"] == spec.kind and description["width"] == 96


@pytest.mark.parametrize("times", [np.zeros((2, 3)), np.array([0.0, np.nan]), np.array(["a"]), 0.5])
def test_bad_times_raise_input_error(times):
    with pytest.raises(InputError):
        make_scene(SceneSpec(kind="still", size=(8, 6))).render(times)


# ---------------------------------------------------------------------------------------------
# video


def make_sliding_folder(folder: Path, shift_px: int, frames: int = 4) -> np.ndarray:
    """Frames of a smooth texture translating right by ``shift_px`` per frame; returns the wide texture."""
    folder.mkdir()
    texture = smooth_texture(200, 72, np.random.default_rng(11))
    for k in range(frames):
        crop = texture[:, 40 - k * shift_px:40 - k * shift_px + 96]
        cv2.imwrite(str(folder / f"frame_{k:03d}.png"), np.round(crop * 255).astype(np.uint8))
    return texture


def test_video_folder_interpolates_motion_with_flow(tmp_path):
    texture = make_sliding_folder(tmp_path / "seq", shift_px=4)
    scene = make_scene(SceneSpec(kind="video", video=str(tmp_path / "seq")))
    assert (scene.width, scene.height) == (96, 72)
    np.testing.assert_allclose(scene.frame_times_s, np.arange(4) / 25.0)
    assert (scene.start_s, scene.end_s) == (0.0, 3 / 25.0)
    real = scene.render(scene.frame_times_s)
    for k in range(4):
        stored = cv2.imread(str(tmp_path / "seq" / f"frame_{k:03d}.png"), cv2.IMREAD_GRAYSCALE) / 255.0
        np.testing.assert_allclose(real[k], stored, atol=1e-6)
    middle = scene.render([1.5 / 25.0])[0]  # halfway between frames 1 and 2: shifted by 6 px
    truth = np.round(texture[:, 34:34 + 96] * 255) / 255.0
    inner = (slice(8, -8), slice(12, -12))
    flow_error = np.abs(middle - truth)[inner].mean()
    blend_error = np.abs(0.5 * (real[1] + real[2]) - truth)[inner].mean()
    assert flow_error < 0.5 * blend_error


def test_video_upsample_snaps_to_grid(tmp_path):
    make_sliding_folder(tmp_path / "seq", shift_px=2, frames=2)
    fine = make_scene(SceneSpec(kind="video", video=str(tmp_path / "seq"), fps=10.0))
    snapped = make_scene(SceneSpec(kind="video", video=str(tmp_path / "seq"), fps=10.0, upsample=4))
    a, b = snapped.render([0.031, 0.025])  # fraction 0.31 snaps to 0.25
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a, fine.render([0.025])[0], atol=1e-6)
    assert np.abs(fine.render([0.031])[0] - a).max() > 0


def test_video_file_round_trip(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (64, 48), isColor=False)
    if not writer.isOpened():
        pytest.skip("no MJPG writer in this OpenCV build")
    texture = smooth_texture(100, 48, np.random.default_rng(5))
    for k in range(5):
        writer.write(np.round(texture[:, 2 * k:2 * k + 64] * 255).astype(np.uint8))
    writer.release()
    scene = make_scene(SceneSpec(kind="video", video=str(path), size=(32, 24)))
    assert (scene.width, scene.height) == (32, 24)
    np.testing.assert_allclose(scene.frame_times_s, np.arange(5) / 30.0)
    frames = scene.render(np.linspace(scene.start_s, scene.end_s, 9))
    assert frames.shape == (9, 24, 32) and np.isfinite(frames).all() and frames.min() >= 0


def test_video_bad_inputs(tmp_path):
    make_sliding_folder(tmp_path / "seq", shift_px=2, frames=3)
    scene = make_scene(SceneSpec(kind="video", video=str(tmp_path / "seq")))
    with pytest.raises(InputError):
        scene.render([scene.end_s + 1e-3])
    with pytest.raises(InputError):
        scene.render([-1e-3])
    with pytest.raises(SourceError, match="nowhere"):
        make_scene(SceneSpec(kind="video", video=str(tmp_path / "nowhere")))
    (tmp_path / "broken.mp4").write_bytes(b"\x00" * 64)
    with pytest.raises(SourceError, match="broken.mp4"):
        make_scene(SceneSpec(kind="video", video=str(tmp_path / "broken.mp4")))
    (tmp_path / "single").mkdir()
    cv2.imwrite(str(tmp_path / "single" / "a.png"), np.zeros((8, 8), np.uint8))
    with pytest.raises(SourceError, match="single"):
        make_scene(SceneSpec(kind="video", video=str(tmp_path / "single")))
    stamps = tmp_path / "seq" / "times.txt"
    stamps.write_text("0.0 frame_000.png\n0.1 frame_001.png\n0.05 frame_002.png\n")
    with pytest.raises(FormatError):
        make_scene(SceneSpec(kind="video", video=str(tmp_path / "seq"), timestamps=str(stamps)))
    stamps.write_text("0.0 frame_000.png\nzero frame_001.png\n")
    with pytest.raises(FormatError):
        make_scene(SceneSpec(kind="video", video=str(stamps)))
    stamps.write_text("0.0 frame_000.png\n0.1 frame_009.png\n")
    with pytest.raises(SourceError, match="frame_009"):
        make_scene(SceneSpec(kind="video", video=str(stamps)))
    stamps.write_text("0.0 frame_000.png\n0.1 frame_001.png\n")
    with pytest.raises(InputError):
        make_scene(SceneSpec(kind="video", video=str(stamps), fps=10.0))


@needs_slider
def test_slider_depth_real_frames_and_in_between():
    scene = make_scene(SceneSpec(kind="video", video=str(SLIDER), size=(120, 90)))
    lines = (SLIDER / "images.txt").read_text().split("\n")
    times = np.array([float(line.split()[0]) for line in lines if line.strip()])
    np.testing.assert_array_equal(scene.frame_times_s, times)
    k = 40
    first = cv2.imread(str(SLIDER / "images" / f"frame_{k:08d}.png"), cv2.IMREAD_GRAYSCALE) / 255.0
    second = cv2.imread(str(SLIDER / "images" / f"frame_{k + 1:08d}.png"), cv2.IMREAD_GRAYSCALE) / 255.0
    first = cv2.resize(first.astype(np.float32), (120, 90), interpolation=cv2.INTER_AREA)
    second = cv2.resize(second.astype(np.float32), (120, 90), interpolation=cv2.INTER_AREA)
    at_k, middle, at_k1 = scene.render([times[k], 0.5 * (times[k] + times[k + 1]), times[k + 1]])
    np.testing.assert_allclose(at_k, first, atol=1e-5)
    np.testing.assert_allclose(at_k1, second, atol=1e-5)
    apart = np.mean((first - second) ** 2)
    assert apart > 1e-5
    assert np.mean((middle - first) ** 2) < apart and np.mean((middle - second) ** 2) < apart
    again = make_scene(SceneSpec(kind="video", video=str(SLIDER), size=(120, 90)))
    assert again.render([0.5 * (times[k] + times[k + 1])]).tobytes() == middle.tobytes()
    json.dumps(scene.describe())


# --- crops and the compiled samplers -----------------------------------------------------------

@pytest.mark.parametrize("kind", ["pan", "zoom", "fan", "still"])
def test_a_crop_renders_exactly_its_window_of_the_view(kind):
    from neuspike.scenes import SceneSpec, make_scene

    common = dict(kind=kind, image="camera", size=(90, 60), velocity_px_s=(1234.5, -321.0), zoom_rate_hz=7.0,
                  rpm=2000.0)
    times = np.array([-0.0031, 0.0, 0.00047, 0.0123])
    full = make_scene(SceneSpec(**common)).render(times)
    for crop in [(0, 0, 90, 60), (17, 5, 32, 32), (89, 59, 1, 1), (3, 0, 80, 60)]:
        scene = make_scene(SceneSpec(**common, crop=crop))
        x, y, w, h = crop
        assert (scene.width, scene.height, scene.view_width, scene.view_height) == (w, h, 90, 60)
        np.testing.assert_array_equal(scene.render(times), full[:, y:y + h, x:x + w])


def test_crop_is_validated_and_leaves_uncropped_specs_unchanged():
    from neuspike.errors import InputError
    from neuspike.scenes import SceneSpec

    assert "crop" not in SceneSpec(kind="pan").as_dict()  # cell seeds and cache keys derive from it
    assert SceneSpec(kind="pan", size=(40, 30), crop=[1, 2, 3, 4]).as_dict()["crop"] == [1, 2, 3, 4]
    for bad in [(0, 0, 41, 30), (38, 0, 3, 1), (0, 0, 0, 5), (-1, 0, 2, 2), (0, 0, 2), "no", (0.5, 0, 2, 2)]:
        with pytest.raises(InputError, match="crop"):
            SceneSpec(kind="pan", size=(40, 30), crop=bad)
    with pytest.raises(InputError, match="crop"):
        SceneSpec(kind="video", video="x.mp4", crop=(0, 0, 4, 4))


@pytest.mark.parametrize("kind", ["pan", "zoom"])
def test_compiled_samplers_equal_the_numpy_reference(kind, monkeypatch):
    # Same float32 operations in the same order: the frames agree bit for bit.
    from neuspike.scenes import SceneSpec, make_scene, sampling

    scene = make_scene(SceneSpec(kind=kind, image="coins", size=(71, 43), velocity_px_s=(-2e4, 7e3)))
    times = np.linspace(-0.004, 0.004, 9)
    fast = scene.render(times)
    for name in ("sample_translated", "sample_separable"):
        original = getattr(sampling, name)
        module = __import__(f"neuspike.scenes.{kind}", fromlist=["x"])
        if hasattr(module, name):
            monkeypatch.setattr(module, name, lambda *a, _f=original, **k: _f(*a, **{**k, "backend": "numpy"}))
    np.testing.assert_array_equal(scene.render(times), fast)
    with pytest.raises(Exception, match="backend"):
        sampling.sample_separable(np.zeros((3, 3), np.float32), np.zeros((1, 2)), np.zeros((1, 2)), backend="gpu")
