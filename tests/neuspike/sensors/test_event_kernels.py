"""The compiled event-camera backend against the NumPy path: the same events, byte for byte."""

from __future__ import annotations

import numpy as np
import pytest

from neuspike.conditions import EVENT_PRESETS, effect
from neuspike.utils.parallel import NUMBA_AVAILABLE
from neuspike.sensors.event_camera import EventCamera

pytestmark = pytest.mark.skipif(not NUMBA_AVAILABLE, reason="numba is not importable")

EVERY_EFFECT = (
    effect("threshold_mismatch", sigma=0.05), effect("bandwidth", cutoff_hz=30.0),
    effect("refractory", period_s=5e-4), effect("leak", rate_hz=0.1), effect("shot_noise", rate_hz=5.0),
)
CONFIGS = {
    "none": (),
    "clean": EVENT_PRESETS["clean"],
    "noisy": EVENT_PRESETS["noisy"],
    "mismatch": (effect("threshold_mismatch", sigma=0.08),),
    "bandwidth": (effect("bandwidth", cutoff_hz=40.0),),
    "bandwidth clipped": (effect("bandwidth", cutoff_hz=5000.0),),  # eps reaches 1 on bright pixels
    "leak": (effect("leak", rate_hz=200.0),),
    "shot noise": (effect("shot_noise", rate_hz=300.0),),
    "refractory": (effect("refractory", period_s=2e-4),),
    "every effect": EVERY_EFFECT,
}


def moving_scene(rng, k=24, h=12, w=20, rate_hz=5000.0):
    """A textured pattern sliding and brightening, with dark (lin-log) and HDR (> 1) pixels."""
    texture = rng.random((h, 3 * w)) ** 3 * 2.5
    frames = np.stack([np.roll(texture, 2 * i, axis=1)[:, :w] * (0.5 + 0.05 * i) for i in range(k)])
    frames[:, 0, :3] = 0.0
    return frames.astype(np.float32), np.arange(k) / rate_hz


def events_of(stream):
    return stream.t_s.tobytes(), stream.x.tobytes(), stream.y.tobytes(), stream.p.tobytes()


def captures(backend, effects, frames, times, *, light=1.0, threshold_on=0.2, threshold_off=0.2, threads=1):
    cam = EventCamera(frames.shape[2], frames.shape[1], light=light, threshold_on=threshold_on,
                      threshold_off=threshold_off, effects=effects, rng=np.random.default_rng(3),
                      backend=backend, threads=threads)
    half = frames.shape[0] // 2
    first = cam.capture(frames[:half], times[:half])
    second = cam.capture(frames[half:], times[half:])  # carried pixel state
    return cam, first, second


@pytest.mark.parametrize("name", list(CONFIGS))
def test_same_events_on_both_backends_for_every_effect(name):
    frames, times = moving_scene(np.random.default_rng(11))
    ref_cam, *ref = captures("numpy", CONFIGS[name], frames, times)
    cam, *got = captures("numba", CONFIGS[name], frames, times)
    assert sum(len(s) for s in ref) > 100  # the scene makes events
    for a, b in zip(got, ref):
        assert events_of(a) == events_of(b)
    assert cam.state.mem.tobytes() == ref_cam.state.mem.tobytes() and cam.state.sig.tobytes() == ref_cam.state.sig.tobytes()
    assert cam.backend == "numba" and ref_cam.backend == "numpy"
    assert got[0].meta["stages"][0]["params"]["backend"] == "numba"


@pytest.mark.parametrize("light, on, off", [(0.3, 0.15, 0.25), (2.0, 0.05, 0.05), (1.0, 0.4, 0.1)])
def test_same_events_with_asymmetric_thresholds_light_and_many_crossings(light, on, off):
    frames, times = moving_scene(np.random.default_rng(5), k=16)
    frames[5] *= 40.0  # a flash: dozens of crossings per pixel in one interval
    frames[9] *= 0.01
    for effects in [(), (effect("leak", rate_hz=50.0), effect("bandwidth", cutoff_hz=2000.0))]:
        _, *ref = captures("numpy", effects, frames, times, light=light, threshold_on=on, threshold_off=off)
        _, *got = captures("numba", effects, frames, times, light=light, threshold_on=on, threshold_off=off)
        for a, b in zip(got, ref):
            assert events_of(a) == events_of(b)
    counts = np.bincount(got[0].y.astype(np.int64) * frames.shape[2] + got[0].x)
    assert counts.max() > 48  # the NumPy path's cumulative expansion of many levels was exercised


@pytest.mark.parametrize("name", ["none", "noisy", "every effect"])
def test_a_worker_thread_changes_nothing(name):
    frames, times = moving_scene(np.random.default_rng(13), k=30)
    _, *ref = captures("numpy", CONFIGS[name], frames, times)
    _, *got = captures("numba", CONFIGS[name], frames, times, threads=2)
    for a, b in zip(got, ref):
        assert events_of(a) == events_of(b)


def test_stage_metadata_marks_stages_fused_into_the_compiled_pixel():
    frames, times = moving_scene(np.random.default_rng(2), k=6)
    effects = (effect("bandwidth", cutoff_hz=30.0), effect("leak", rate_hz=1.0))
    _, s, _ = captures("numba", effects, frames, times)
    by_name = {x["name"]: x for x in s.meta["stages"]}
    assert list(by_name) == ["dvs_pixel", "bandwidth", "leak"]
    assert by_name["bandwidth"]["fused_into"] == "dvs_pixel" and by_name["leak"]["fused_into"] == "dvs_pixel"
    _, s, _ = captures("numpy", effects, frames, times)
    assert all("fused_into" not in x for x in s.meta["stages"])


def test_a_pixel_whose_log_intensity_does_not_change_across_a_crossing_gives_numpy_semantics():
    """Regression: on a fan scene a pixel's change equals its distance to the memorised level, so the
    crossing fraction divides by zero; the compiled pass follows NumPy (inf, then the same clamps)
    instead of raising ZeroDivisionError, and the events equal the NumPy path's."""
    import neuspike.sensors.event_camera as ec
    from neuspike.conditions import Condition
    from neuspike.scenes import SceneSpec
    from neuspike.simulation.cell import simulate_sample
    from neuspike.simulation.recording import SensorConfig

    original = ec.EventCamera.__init__
    streams = {}
    for backend in ("numba", "numpy"):
        def init(self, *args, _backend=backend, **kwargs):
            kwargs["backend"] = _backend
            original(self, *args, **kwargs)

        ec.EventCamera.__init__ = init
        try:
            streams[backend] = simulate_sample(SceneSpec(kind="fan", image="coins", size=(160, 100)),
                                               Condition(light=0.25, motion=16), sensor=SensorConfig(), seed=0,
                                               modalities=("events",), history_s=0.064).events
        finally:
            ec.EventCamera.__init__ = original
    a, b = streams["numba"], streams["numpy"]
    assert len(a) > 0
    for field in ("t_s", "x", "y", "p"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field


@pytest.mark.parametrize("period_s", [5e-5, 2e-4, 1e-3])  # longer than, equal to and shorter than... the interval
@pytest.mark.parametrize("seed", [0, 1])
def test_same_events_with_dense_shot_noise_refractory_and_many_crossings(period_s, seed):
    """The compiled shot-noise and refractory stages against the NumPy path where they work hardest:
    several noise events per pixel and interval, flashes of many crossings, asymmetric thresholds, a
    refractory period shorter than, equal to and longer than the sample interval (2e-4 s)."""
    frames, times = moving_scene(np.random.default_rng(20 + seed), k=20)
    frames[6] *= 30.0
    frames[12] *= 0.02
    effects = (effect("threshold_mismatch", sigma=0.1), effect("leak", rate_hz=20.0),
               effect("shot_noise", rate_hz=4000.0), effect("refractory", period_s=period_s))
    ref_cam, *ref = captures("numpy", effects, frames, times, threshold_on=0.12, threshold_off=0.3)
    cam, *got = captures("numba", effects, frames, times, threshold_on=0.12, threshold_off=0.3)
    for a, b in zip(got, ref):
        assert events_of(a) == events_of(b)
    assert cam.state.mem.tobytes() == ref_cam.state.mem.tobytes()
    assert cam.state.last_emit_s.tobytes() == ref_cam.state.last_emit_s.tobytes()
    _, *unfiltered = captures("numpy", effects[:3], frames, times, threshold_on=0.12, threshold_off=0.3)
    assert sum(map(len, ref)) < sum(map(len, unfiltered))  # the period did drop events


def test_shot_noise_stage_keeps_its_own_time_and_refractory_is_fused():
    frames, times = moving_scene(np.random.default_rng(2), k=6)
    _, s, _ = captures("numba", CONFIGS["every effect"], frames, times)
    by_name = {x["name"]: x for x in s.meta["stages"]}
    assert by_name["refractory"]["fused_into"] == "dvs_pixel"
    assert "fused_into" not in by_name["shot_noise"] and by_name["shot_noise"]["seconds"] > 0


def test_an_interval_ending_crossing_never_lands_after_the_next_intervals_events():
    """Sensor instants -0.0003 and -0.0001 (history frames): ``t_a + (t_b - t_a)`` rounds one ulp above
    ``t_b``, so a crossing at the interval's very end used to be written after the next interval's
    first events (an unsorted stream, refused downstream). The compiled writer clamps it to ``t_b``."""
    from neuspike.sensors import event_kernels

    t_a, t_b = -0.00030000000000000003, -0.0001
    assert t_a + (t_b - t_a) > t_b  # the rounding this guards against
    pix_bits, width, q_one = 8, 4, 2 ** 44
    scale = (t_b - t_a) / q_one
    pixel_pol = np.array([2 * 3 + 1, 2 * 1 + 0], np.int64)  # pixel 3 ON, pixel 1 OFF
    fractions = np.array([q_one - 2 ** 20, q_one], np.int64)  # well inside, and at the very end
    keys = (fractions << pix_bits) | pixel_pol
    out = [np.empty(2), np.empty(2, np.uint16), np.empty(2, np.uint16), np.empty(2, np.int8)]
    event_kernels.write_events(keys, pix_bits, width, t_a, scale, t_b, *out)
    assert out[0][1] == t_b and t_a < out[0][0] < t_b
    assert out[1].tolist() == [3, 1] and out[3].tolist() == [1, -1]


def test_a_history_boundary_crossing_gives_a_sorted_stream_on_both_backends():
    """The training cell that met the rounding above (a fan at S = 64 with event history and medium
    noise): every event is in time order, and both backends agree byte for byte."""
    from unittest import mock

    import neuspike.sensors.event_camera as event_camera
    from neuspike.conditions import Condition
    from neuspike.scenes import SceneSpec
    from neuspike.simulation.cell import simulate_sample
    from neuspike.simulation.recording import SensorConfig

    scene = SceneSpec("fan", image="coffee", size=(128, 128), rpm=-1617.7994873558214, blades=5,
                      blade_width_deg=15.206296815359472, blade_contrast=0.30109810296906725)
    condition = Condition(light=0.0625, motion=64, noise="medium")
    sensor = SensorConfig(event_threshold=0.11255869399151351)
    streams = {}
    for backend in ("numba", "numpy"):
        with mock.patch.object(event_camera, "resolve_backend", lambda requested, b=backend: b):
            sample = simulate_sample(scene, condition, sensor=sensor, seed=384770998, modalities={"events"},
                                     history_s=0.011)
        streams[backend] = sample.events
        assert len(sample.events) > 10_000 and (np.diff(sample.events.t_s) >= 0).all()
    assert events_of(streams["numba"]) == events_of(streams["numpy"])
