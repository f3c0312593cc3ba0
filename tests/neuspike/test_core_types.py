"""Core types: effect declarations, conditions, streams, the method registry and the recording cache key."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from neuspike import methods as registry
from neuspike.simulation.cache import part_key
from neuspike.conditions import EFFECT_DEFAULTS, NOISE_LEVELS, Condition, effect, parse_effects
from neuspike.errors import InputError
from neuspike.methods import Method
from neuspike.scenes import SceneSpec
from neuspike.simulation.recording import SensorConfig
from neuspike.streams import EventStream, SpikeStream

# --- parse_effects ------------------------------------------------------------------------------


def test_parse_effects_reads_names_parameters_and_both_separators():
    got = parse_effects("refractory:period_s=1e-3,shot_noise:rate_hz=5;leak")
    assert [e.name for e in got] == ["refractory", "shot_noise", "leak"]
    assert got[0].param("period_s") == 1e-3 and got[1].param("rate_hz") == 5.0
    assert got[2] == effect("leak")  # defaults filled in
    assert parse_effects("  ") == ()


@given(st.lists(st.sampled_from(sorted(EFFECT_DEFAULTS)), min_size=1, max_size=4, unique=True),
       st.data())
def test_parse_effects_round_trips_every_declaration(names, data):
    declared = []
    for name in names:
        params = {k: data.draw(st.floats(0, 1e3, allow_nan=False)) for k in EFFECT_DEFAULTS[name][1]}
        declared.append(effect(name, **params))
    text = ";".join(e.name + (":" + ",".join(f"{k}={v!r}" for k, v in e.params) if e.params else "")
                    for e in declared)
    assert parse_effects(text) == tuple(declared)


@pytest.mark.parametrize("text", ["nonsense", "leak:rate_hz", "shot_noise:rate_hz=abc", "leak:bogus=1",
                                  "shot_noise:rate_hz=-1", "=3", "shot_noise:rate_hz=inf"])
def test_parse_effects_refuses_bad_declarations_with_a_typed_error(text):
    with pytest.raises(InputError):
        parse_effects(text)


# --- Condition ----------------------------------------------------------------------------------


def test_condition_validates_and_normalises():
    c = Condition(light=np.float32(0.25), motion=np.int64(64))
    assert type(c.light) is float and type(c.motion) is int
    for bad in ({"light": 0}, {"light": float("nan")}, {"motion": 0}, {"motion": True}, {"motion": 2.5},
                {"noise": "loud"}):
        with pytest.raises(InputError):
            Condition(**bad)


def test_condition_effects_merge_later_declarations_over_the_noise_level():
    c = Condition(noise="high", effects=(effect("shot_noise", rate_hz=7.0),))
    shot = [e for e in c.all_effects() if e.name == "shot_noise"]
    assert shot == [effect("shot_noise", rate_hz=7.0)]
    names = {e.name for e in NOISE_LEVELS["high"]}
    assert {e.name for e in c.all_effects()} == names
    assert all(e.modality == "events" for e in c.effects_for("events"))
    assert all(e.modality == "spikes" for e in c.effects_for("spikes"))
    with pytest.raises(InputError):
        c.effects_for("light")


# --- streams ------------------------------------------------------------------------------------


def test_spike_stream_validates_and_cuts_windows():
    planes = np.zeros((10, 3, 4), bool)
    planes[4, 1, 2] = True
    s = SpikeStream(planes, plane_rate_hz=1000.0, start_s=0.5, gain=0.25, dark_rate=0.005)
    w = s.window(3, 6)
    assert w.num_planes == 3 and w.start_s == pytest.approx(0.503) and w.planes[1, 1, 2]
    assert (w.gain, w.dark_rate) == (0.25, 0.005)  # sensor fields travel with a window
    for bad in (np.full((2, 3, 4), 2, np.uint8), np.zeros((3, 4), bool)):
        with pytest.raises(InputError):
            SpikeStream(bad)
    for dark in (-0.001, float("nan")):
        with pytest.raises(InputError, match="dark_rate"):
            SpikeStream(planes, dark_rate=dark)


def test_event_stream_validates_order_bounds_and_polarity():
    t = np.array([0.1, 0.2, 0.3])
    x = np.array([0, 1, 2])
    y = np.array([0, 0, 1])
    p = np.array([1, -1, 1])
    e = EventStream(t, x, y, p, 3, 2)
    assert len(e) == 3 and len(e.between(0.15, 0.3)) == 1  # half-open [t0, t1)
    for bad in (dict(t=t[::-1]), dict(x=np.array([0, 1, 3])), dict(p=np.array([1, 0, 1])),
                dict(t=np.array([0.1, np.nan, 0.3]))):
        args = {"t": t, "x": x, "y": y, "p": p, **bad}
        with pytest.raises(InputError):
            EventStream(args["t"], args["x"], args["y"], args["p"], 3, 2)


# --- registry -----------------------------------------------------------------------------------


class Zero(Method):
    inputs = frozenset({"spikes"})

    def _reconstruct(self, sample):
        return np.zeros((sample.height, sample.width), np.float32), "none"


def test_registry_entries_variants_and_errors():
    registry.available()
    registry.register("zz-zero", Zero, params={"k": 1}, description="test")
    try:
        assert "zz-zero" in registry.available()
        m = registry.create("zz-zero", k=2)
        assert isinstance(m, Zero) and m.params == {"k": 2} and m.name == "zz-zero"
        assert "device" not in m.params  # classical methods get no learned-method arguments
        with pytest.raises(InputError, match="already registered"):
            registry.register("zz-zero", Zero)
        with pytest.raises(InputError):
            registry.register("zz-events", Zero, inputs={"light"})
        with pytest.raises(InputError, match="unknown method"):
            registry.create("zz-missing")
    finally:
        registry.unregister("zz-zero")
    assert "zz-zero" not in registry.available()


# --- recording cache key -------------------------------------------------------------------------

SPEC = SceneSpec(kind="pan", image="camera", size=(32, 24))
BASE = dict(scene_spec=SPEC, condition=Condition(), sensor=SensorConfig(), seed=0, modality="events", history_s=0.0)


@pytest.mark.parametrize("change", [
    dict(scene_spec=dataclasses.replace(SPEC, image="coins")),
    dict(scene_spec=dataclasses.replace(SPEC, size=(32, 25))),
    dict(condition=Condition(light=0.5)),
    dict(condition=Condition(motion=64)),
    dict(condition=Condition(noise="small")),
    dict(condition=Condition(effects=(effect("leak"),))),
    dict(condition=Condition(effects=(effect("leak", rate_hz=0.2),))),
    dict(sensor=SensorConfig(planes=128)),
    dict(sensor=SensorConfig(event_threshold=0.3)),
    dict(sensor=SensorConfig(spike_threshold=2.0)),
    dict(seed=1),
    dict(modality="spikes"),
    dict(history_s=0.01),
])
def test_the_cache_key_changes_whenever_a_recording_would(change):
    assert part_key(**{**BASE, **change}) != part_key(**BASE)


def test_the_cache_key_ignores_what_does_not_change_a_recording():
    assert part_key(**BASE) == part_key(**{**BASE, "condition": Condition(light=np.float64(0.25))})
    # the spike window has no history: its part serves a request with any
    spikes = {**BASE, "modality": "spikes"}
    assert part_key(**spikes) == part_key(**{**spikes, "history_s": 0.01})
