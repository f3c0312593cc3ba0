"""The simulation pipeline: Algorithm-1 windows, continuous sequences, opt-in stages, files, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from neuspike.conditions import Condition, effect
from neuspike.errors import InputError
from neuspike.utils.rng import derive_rng
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulate import main
from neuspike.simulation.recording import SensorConfig
from neuspike.simulation.window import simulate_window
from neuspike.simulation.writing import write_sequence

SMALL = (48, 32)


def _pan(**kw):
    return make_scene(SceneSpec(kind="pan", image="camera", size=SMALL, **kw))


def _names(meta, modality):
    return [s["name"] for s in meta["stages"] if s["modality"] == modality]


def test_window_follows_algorithm_1_and_shares_the_clock():
    scene = _pan()
    cond = Condition(light=0.5, motion=16)
    rec = simulate_window(scene, cond, rng=np.random.default_rng(0), center_s=0.001)
    assert rec.spikes.planes.shape == (256, 32, 48)
    assert rec.spikes.gain == pytest.approx(0.5)
    assert rec.meta["hold_planes"] == 16
    # each of the S frames is held for T // S planes: without effects the input is constant per
    # hold, so the spike count over one hold equals the integrate-and-fire count of that frame
    times = 0.001 + (np.arange(16) - 7.5) / 22_500.0
    frames = scene.render(times)
    np.testing.assert_array_equal(rec.ground_truth, scene.render(np.array([0.001]))[0])
    charge = np.zeros(frames.shape[1:], np.float64)
    expected = []
    for f in frames:
        for _ in range(16):
            charge += 0.5 * f.astype(np.float64)
            fire = charge >= 1.0
            charge[fire] -= 1.0
            expected.append(fire)
    np.testing.assert_array_equal(rec.spikes.planes, np.array(expected))
    # both sensors on one clock: the window is [0, T / rate), the key instant its centre
    assert rec.window_end_s == pytest.approx(256 / 20_000)
    assert rec.key_time_s == pytest.approx(128 / 20_000)
    assert len(rec.events) > 0
    assert rec.events.t_s.min() >= 0.0 and rec.events.t_s.max() < rec.window_end_s


def test_window_must_be_a_multiple_of_the_motion_scale():
    with pytest.raises(InputError, match="multiple"):
        simulate_window(_pan(), Condition(motion=48), rng=np.random.default_rng(0))


def test_only_declared_stages_run_and_are_recorded():
    scene = _pan()
    rec = simulate_window(scene, Condition(noise="none", motion=32), rng=np.random.default_rng(0))
    assert _names(rec.meta, "spikes") == ["integrate_and_fire"]
    assert _names(rec.meta, "events") == ["dvs_pixel"]
    cond = Condition(noise="medium", motion=32, effects=(effect("refractory", period_s=1e-3),))
    rec = simulate_window(scene, cond, rng=np.random.default_rng(0))
    assert set(_names(rec.meta, "spikes")) == {"integrate_and_fire", "initial_charge", "dark_current"}
    assert set(_names(rec.meta, "events")) == {"dvs_pixel", "shot_noise", "refractory"}
    for s in rec.meta["stages"]:
        assert s["seconds"] >= 0.0


def test_unrequested_modality_is_not_simulated(monkeypatch):
    import neuspike.sensors.event_camera as ec

    def forbidden(*a, **k):
        raise AssertionError("the event camera must not be built when no consumer asks for events")

    monkeypatch.setattr(ec, "EventCamera", forbidden)
    rec = simulate_window(_pan(), Condition(motion=32), rng=np.random.default_rng(0), modalities={"spikes"})
    assert rec.events is None and rec.spikes is not None
    assert "events" not in {s["modality"] for s in rec.meta["stages"]}


def test_event_history_precedes_the_window():
    rec = simulate_window(_pan(velocity_px_s=(4000.0, 0.0)), Condition(motion=64), rng=np.random.default_rng(0),
                          history_s=0.005)
    assert rec.events.t_s.min() < 0.0
    assert rec.meta["event_count_window"] < rec.meta["event_count"]
    assert rec.spikes.num_planes == 256


def test_same_seed_same_bytes_and_cells_are_independent():
    scene = _pan()
    cond = Condition(noise="high", motion=32)
    a = simulate_window(scene, cond, rng=derive_rng(3, "cell", 1))
    b = simulate_window(scene, cond, rng=derive_rng(3, "cell", 1))
    c = simulate_window(scene, cond, rng=derive_rng(3, "cell", 2))
    np.testing.assert_array_equal(a.spikes.planes, b.spikes.planes)
    np.testing.assert_array_equal(a.events.t_s, b.events.t_s)
    assert not np.array_equal(a.spikes.planes, c.spikes.planes)
    # independent streams: the draws of two cells are uncorrelated
    x = derive_rng(3, "cell", 1).standard_normal(20_000)
    y = derive_rng(3, "cell", 2).standard_normal(20_000)
    assert abs(np.corrcoef(x, y)[0, 1]) < 0.05


def test_no_effects_is_deterministic_from_the_scene():
    scene = _pan()
    a = simulate_window(scene, Condition(motion=32), rng=np.random.default_rng(1))
    b = simulate_window(scene, Condition(motion=32), rng=np.random.default_rng(2))
    np.testing.assert_array_equal(a.spikes.planes, b.spikes.planes)
    np.testing.assert_array_equal(a.events.t_s, b.events.t_s)


def test_cli_writes_a_complete_recording(tmp_path, capsys):
    from neuspike.formats.event_readers import read_events
    from neuspike.formats.vidar_dat import read_dat

    out = tmp_path / "rec"
    rc = main(["--size", "48x32", "--motion", "64", "--noise", "small", "--out", str(out), "--seed", "4"])
    assert rc == 0
    meta = json.loads((out / "meta.json").read_text())
    for key in ("gain", "threshold", "plane_rate_hz", "width", "height", "stages", "spike_count", "event_count"):
        assert key in meta
    planes = read_dat(out / "spikes.dat", height=32, width=48)
    assert planes.shape == (256, 32, 48) and int(planes.sum()) == meta["spike_count"]
    assert len(read_events(out / "events.h5")) == meta["event_count"]
    assert (out / "gt.png").exists() and (out / "gt.npy").exists()
    assert "wrote" in capsys.readouterr().out


def test_cli_rejects_bad_input_without_writing(tmp_path, capsys):
    out = tmp_path / "bad"
    assert main(["--video", str(tmp_path / "missing.mp4"), "--out", str(out)]) == 2
    assert "error" in capsys.readouterr().err
    assert not (out / "meta.json").exists()
    assert main(["--size", "48x32", "--motion", "48", "--out", str(out)]) == 2


def test_sequence_is_streamed_in_chunks_and_nothing_is_half_written(tmp_path, monkeypatch):
    from neuspike.formats.vidar_dat import read_dat

    scene = make_scene(SceneSpec(kind="still", image="camera", size=SMALL))
    out = tmp_path / "seq"
    meta = write_sequence(scene, Condition(light=0.5), out, rng=np.random.default_rng(0), start_s=0.0,
                          duration_s=700 / 20_000)
    planes = read_dat(out / "spikes.dat", height=32, width=48)
    assert planes.shape[0] == meta["planes"] == 700
    # continuous mode with a still scene and no effects: counts follow the closed form
    radiance = scene.render(np.array([0.0]))[0].astype(np.float64)
    diff = planes.sum(axis=0) - np.floor(700 * 0.5 * radiance)
    assert np.abs(diff).max() <= 1  # float32 charge may land either side of an exact boundary
    assert np.mean(diff == 0) > 0.99
    assert (out / "frames" / "timestamps.txt").exists()

    import neuspike.sensors.event_camera as ec

    calls = {"n": 0}
    real = ec.EventCamera.capture

    def failing(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("disk on fire")
        return real(self, *a, **k)

    monkeypatch.setattr(ec.EventCamera, "capture", failing)
    out2 = tmp_path / "seq2"
    with pytest.raises(RuntimeError):
        write_sequence(scene, Condition(), out2, rng=np.random.default_rng(0), start_s=0.0, duration_s=700 / 20_000)
    assert not (out2 / "spikes.dat").exists() and not (out2 / "events.h5").exists()
    assert not (out2 / "meta.json").exists()


@pytest.mark.parametrize("motion, planes, advice", [
    (3, 256, "use --planes 255 or --planes 258, or --motion 2 or --motion 4"),
    (512, 256, "use --planes 512, or --motion 128 or --motion 256"),
])
def test_a_motion_scale_that_does_not_fit_the_window_names_both_options(tmp_path, capsys, motion, planes, advice):
    out = tmp_path / "m"
    assert main(["--size", "48x32", "--motion", str(motion), "--planes", str(planes), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--planes {planes} is not a whole multiple of --motion {motion}" in err[0]
    assert advice in err[0] and not out.exists()


# --- static region ---------------------------------------------------------------------------------

def test_static_region_of_each_kind():
    from neuspike.simulation.window import static_region

    sensor, cond = SensorConfig(planes=64), Condition(noise="none", motion=32)
    still = static_region(SceneSpec(kind="still", image="camera", size=SMALL), cond, sensor=sensor)
    assert still.all()
    pan = static_region(SceneSpec(kind="pan", image="camera", size=SMALL, velocity_px_s=(400.0, 0.0)), cond,
                        sensor=sensor)
    assert pan.mean() < 0.05
    assert not static_region(SceneSpec(kind="pan", image="camera", size=SMALL, velocity_px_s=(400.0, 0.0)), cond,
                             sensor=sensor, min_fraction=0.5).any()
    fan = static_region(SceneSpec(kind="fan", image="coins", size=SMALL), cond, sensor=sensor, history_s=0.01)
    assert 0.2 < fan.mean() < 0.95  # the background outside the blades' reach


def test_static_region_is_where_no_event_fires():
    """Independent check: with no noise, the pixels it calls static see no event, history included."""
    from neuspike.simulation.window import static_region

    spec = SceneSpec(kind="fan", image="coins", size=SMALL)
    sensor, cond = SensorConfig(planes=64), Condition(noise="none", motion=32)
    static = static_region(spec, cond, sensor=sensor, history_s=0.01)
    rec = simulate_window(make_scene(spec), cond, rng=np.random.default_rng(0), sensor=sensor, history_s=0.01)
    ev = rec.events
    fired = np.zeros(static.shape, dtype=bool)
    fired[ev.y, ev.x] = True
    assert fired.any() and not (fired & static).any()
    assert fired[~static].mean() > 0.5  # and most moving pixels do fire
