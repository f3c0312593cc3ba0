"""The recording cache: one file per modality, so that cached windows serve any subset, and the static region kept with them."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

import neuspike.simulation.cell as cell_module
from bench.harness import grid as grids
from neuspike.methods.plugins import forget_plugin, load_plugins
from bench.harness.results import read_csv
from bench.harness.runner import Execution, SweepSpec, run_sweep
from neuspike import methods as registry
from neuspike.conditions import Condition
from neuspike.scenes import SceneSpec
from neuspike.simulation.cache import RecordingCache, _request_key, save_recording
from neuspike.simulation.cell import simulate_recording
from neuspike.simulation.recording import SensorConfig
from neuspike.scenes import make_scene
from neuspike.simulation.window import sample_rng, simulate_window, static_region

SENSOR = SensorConfig(planes=32)
HISTORY_S = 3 * 32 / 20_000
FAN = SceneSpec(kind="fan", image="coins", size=(40, 32))
NOISY = Condition(light=0.25, motion=8, noise="high")
BOTH = ("events", "spikes")


@pytest.fixture
def simulations(monkeypatch):
    """The modalities of every window simulated (not taken from the cache), in call order."""
    calls: list[tuple[str, ...]] = []
    real = cell_module.simulate_window

    def counting(*args, modalities, **kw):
        calls.append(tuple(sorted(modalities)))
        return real(*args, modalities=modalities, **kw)

    monkeypatch.setattr(cell_module, "simulate_window", counting)
    return calls


def _get(cache, modalities, history_s=HISTORY_S, spec=FAN, condition=NOISY):
    return simulate_recording(spec, condition, sensor=SENSOR, seed=4, modalities=modalities, history_s=history_s,
                              cache=cache)


def _fresh(modalities, history_s=HISTORY_S, spec=FAN, condition=NOISY):
    """The window simulated directly, without the cache (and without counting)."""
    return simulate_window(make_scene(spec), condition, rng=sample_rng(4, spec, condition), sensor=SENSOR,
                           modalities=modalities, history_s=history_s, seed=4)


def _assert_same_streams(a, b):
    assert (a.spikes is None) == (b.spikes is None) and (a.events is None) == (b.events is None)
    if a.spikes is not None:
        np.testing.assert_array_equal(a.spikes.planes, b.spikes.planes)
        assert a.spikes.gain == b.spikes.gain and a.spikes.dark_rate == b.spikes.dark_rate
    if a.events is not None:
        for name in ("t_s", "x", "y", "p"):
            np.testing.assert_array_equal(getattr(a.events, name), getattr(b.events, name))
        assert len(a.events) > 0
    np.testing.assert_array_equal(a.ground_truth, b.ground_truth)
    assert (a.key_time_s, a.window_start_s, a.window_end_s) == (b.key_time_s, b.window_start_s, b.window_end_s)


def _without_seconds(meta):
    return {**meta, "stages": [{k: v for k, v in s.items() if k != "seconds"} for s in meta["stages"]]}


def test_a_cached_window_serves_every_subset_of_its_modalities_without_simulating(tmp_path, simulations):
    cache = RecordingCache(tmp_path)
    both, simulated = _get(cache, BOTH)
    assert simulated == set(BOTH) and simulations == [BOTH]
    assert len(list(tmp_path.glob("*.npz"))) == 2  # one file per modality
    for mods in (("events",), ("spikes",), BOTH):
        served, simulated = _get(cache, mods)
        assert not simulated and simulations == [BOTH], mods
        _assert_same_streams(served, _fresh(mods))  # the bytes of a simulation of the subset alone
    again, _ = _get(cache, BOTH)
    assert _without_seconds(again.meta) == _without_seconds(both.meta)
    # the spike window has no history: a request without one is served from the same file
    assert not _get(cache, ("spikes",), history_s=0.0)[1] and simulations == [BOTH]


def test_only_what_is_not_cached_is_simulated(tmp_path, simulations):
    cache = RecordingCache(tmp_path)
    _get(cache, ("spikes",))
    joined, simulated = _get(cache, BOTH)
    assert simulated == {"events"} and simulations == [("spikes",), ("events",)]  # the spikes were not simulated again
    _assert_same_streams(joined, _fresh(BOTH))
    assert [s["modality"] for s in joined.meta["stages"]][0] == "scene"
    assert {"spike_count", "event_count", "event_count_window"} <= set(joined.meta)
    # events with another history are another recording; the spikes still come from the cache
    _get(cache, BOTH, history_s=2 * HISTORY_S)
    assert simulations[2:] == [("events",)]
    assert not _get(cache, BOTH, history_s=2 * HISTORY_S)[1] and not _get(cache, BOTH)[1] and len(simulations) == 3


@pytest.mark.parametrize("spec", [FAN, SceneSpec(kind="still", image="camera", size=(40, 32)),
                                  SceneSpec(kind="pan", image="camera", size=(40, 32))])
def test_the_static_region_comes_with_the_recording_and_its_cached_parts(tmp_path, spec):
    cache = RecordingCache(tmp_path)
    for mods, history_s in ((BOTH, HISTORY_S), (("spikes",), 0.0), (("events",), HISTORY_S), (BOTH, 0.0)):
        expected = static_region(spec, NOISY, sensor=SENSOR, modalities=mods, history_s=history_s)
        fresh = _fresh(mods, history_s, spec=spec)
        cached, _ = _get(cache, mods, history_s, spec=spec)
        np.testing.assert_array_equal(fresh.static_region(), expected)
        np.testing.assert_array_equal(cached.static_region(), expected)
    if spec.kind == "fan":  # the history sees more of the blades' sweep: a smaller static region
        window = static_region(spec, NOISY, sensor=SENSOR, modalities=("spikes",))
        longer = static_region(spec, NOISY, sensor=SENSOR, modalities=BOTH, history_s=HISTORY_S)
        assert longer.sum() < window.sum() and not (longer & ~window).any()


def test_an_entry_of_the_earlier_layout_is_still_read(tmp_path, simulations):
    rec = _fresh(BOTH)
    old = type(rec)(spikes=rec.spikes, events=rec.events, ground_truth=rec.ground_truth, key_time_s=rec.key_time_s,
                    window_start_s=rec.window_start_s, window_end_s=rec.window_end_s, meta=rec.meta)
    key = _request_key(scene_spec=FAN, condition=NOISY, sensor=SENSOR, seed=4, modalities=BOTH, history_s=HISTORY_S)
    save_recording(tmp_path / f"{key}.npz", old)
    simulations.clear()
    served, simulated = _get(RecordingCache(tmp_path), BOTH)
    assert not simulated and simulations == []
    _assert_same_streams(served, rec)
    assert served.static_region() is None  # not kept then: the sweep renders it (bench.harness.cells)


def test_a_file_of_the_first_format_without_the_dark_rate_is_simulated_again(tmp_path, simulations):
    cache = RecordingCache(tmp_path)
    rec, _ = _get(cache, BOTH)
    assert rec.spikes.dark_rate > 0  # the high noise level declares a dark current
    for path in tmp_path.glob("*.npz"):  # rewrite every part as format 1 wrote it
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["format"] = np.frombuffer(b"neuspike-recording-cache/1", dtype=np.uint8)
        np.savez(path, **arrays)
    simulations.clear()
    again, simulated = _get(RecordingCache(tmp_path), BOTH)
    assert simulated == set(BOTH) and simulations == [BOTH]
    _assert_same_streams(again, rec)


# ----------------------------------------------------------------------------------------------
# A method added to a finished sweep simulates nothing
# ----------------------------------------------------------------------------------------------

PLUGIN = textwrap.dedent('''
    import numpy as np

    from neuspike.methods import Method, register


    class SpikeRate(Method):
        inputs = frozenset({"spikes"})

        def _reconstruct(self, sample):
            s = sample.spikes
            return np.clip(s.planes.mean(axis=0) / s.gain, 0, 1).astype(np.float32), "gain"


    class EventCount(Method):
        """Events per pixel over everything given (the history too, when there is one)."""

        inputs = frozenset({"events"})

        def _reconstruct(self, sample):
            e = sample.events
            counts = np.zeros((sample.height, sample.width), np.float64)
            np.add.at(counts, (e.y, e.x), 1.0)
            return (counts / max(1.0, counts.max())).astype(np.float32), "max"


    class RecurrentEventCount(EventCount):
        recurrent = True


    class Fused(Method):
        inputs = frozenset({"spikes", "events"})

        def _reconstruct(self, sample):
            rate = sample.spikes.planes.mean(axis=0) / sample.spikes.gain
            return np.clip(0.5 * rate + 0.01 * len(sample.events) / rate.size, 0, 1).astype(np.float32), "none"


    register("sc-spikes", SpikeRate)
    register("sc-events", EventCount)
    register("sc-recurrent", RecurrentEventCount)
    register("sc-fused", Fused)
''')
NAMES = ("sc-spikes", "sc-events", "sc-recurrent", "sc-fused")


@pytest.fixture
def plugin(tmp_path):
    path = tmp_path / "sc_plugin.py"
    path.write_text(PLUGIN)
    load_plugins((str(path),))
    yield str(path)
    for name in NAMES:
        registry.unregister(name)
    forget_plugin(str(path))


def _sweep(plugin, methods, out, cache):
    grid = grids.Grid(scenes=(grids.scene_entry("fan:coins", (40, 32)),), lights=(0.25, 0.5), motions=(8,),
                      noises=("high",), seeds=(0,), effects=grids.DEFAULT_EFFECTS)
    spec = SweepSpec(name="sc", grid=grid, methods=tuple(methods), sensor=SENSOR, history_windows=2.0)
    return run_sweep(spec, out, Execution(plugins=(plugin,), progress=False, report=False, cache_dir=cache,
                                          use_cache=cache is not None))


@pytest.mark.parametrize("first, added", [
    (("sc-spikes", "sc-recurrent"), "sc-fused"),    # both modalities cached: any method after them
    (("sc-fused", "sc-spikes"), "sc-events"),       # an event-only method after the others
    (("sc-fused", "sc-recurrent"), "sc-spikes"),    # a spike-only method after the others
    (("sc-recurrent", "sc-fused"), "sc-events"),    # a method that needs no history, after one that did
])
def test_a_method_added_to_a_finished_sweep_simulates_nothing(plugin, tmp_path, simulations, first, added):
    cache = tmp_path / "cache"
    before = _sweep(plugin, first, tmp_path / "a", cache)
    assert before.exit_code == 0 and before.n_cache_hits == 0 and len(simulations) == 2
    after = _sweep(plugin, (*first, added), tmp_path / "b", cache)
    assert after.exit_code == 0 and len(simulations) == 2, simulations[2:]
    assert after.n_cache_hits == after.n_computed == 2 and after.simulated == {}
    assert "2 computed now, 2 from the recording cache" in after.summary()
    assert "simulated now" not in after.summary()
    # the same numbers as a sweep without the cache
    fresh = _sweep(plugin, (*first, added), tmp_path / "c", None)
    cols = ["light", "method", "metric", "value", "status"]
    assert read_csv(after.results_path)[cols].equals(read_csv(fresh.results_path)[cols])
    assert (read_csv(fresh.results_path)["status"] == "ok").all()


def test_what_the_cache_cannot_serve_is_only_what_was_never_simulated(plugin, tmp_path, simulations):
    cache = tmp_path / "cache"
    _sweep(plugin, ("sc-spikes",), tmp_path / "a", cache)
    assert simulations == [("spikes",)] * 2
    # events were never simulated: they are now, the spikes are not again
    events = _sweep(plugin, ("sc-spikes", "sc-events"), tmp_path / "b", cache)
    assert simulations[2:] == [("events",)] * 2 and events.n_cache_hits == 0 and events.simulated == {"events": 2}
    assert "simulated now: events for 2 of 2 recordings" in events.summary()
    # the first recurrent event method changes the event history, so the events are simulated again
    recurrent = _sweep(plugin, ("sc-spikes", "sc-events", "sc-recurrent"), tmp_path / "c", cache)
    assert simulations[4:] == [("events",)] * 2 and recurrent.simulated == {"events": 2}
    assert "cached events only one with the same event history: 0.0032 s here" in recurrent.summary()
    # every one of them again, in any order and subset (the recurrent event method alone: the
    # FireNet-only sweep over a full sweep's cache): nothing
    for i, methods in enumerate((("sc-recurrent",), ("sc-events",), ("sc-recurrent", "sc-spikes"),
                                 ("sc-fused", "sc-events"))):
        outcome = _sweep(plugin, methods, tmp_path / f"d{i}", cache)
        assert outcome.n_cache_hits == 2 and len(simulations) == 6, methods
        assert "simulated now" not in outcome.summary()


def test_a_fifo_or_a_damaged_entry_in_the_cache_is_simulated_again_not_waited_on(tmp_path):
    """A FIFO where a cache file belongs would block a read forever; a cache file whose metadata is a
    list failed every rerun. Both are treated as absent (simulated again and replaced)."""
    import os
    import threading

    from neuspike.errors import FormatError
    from neuspike.simulation.cache import RecordingCache, load_recording

    cache = RecordingCache(tmp_path)
    fifo = cache.path("fifo")
    os.mkfifo(fifo)
    got: list = []
    reader = threading.Thread(target=lambda: got.append(cache._load("fifo")), daemon=True)
    reader.start()
    reader.join(timeout=10)
    assert not reader.is_alive() and got == [None]
    with pytest.raises(FormatError, match="not a regular file"):
        load_recording(fifo)
    listed = cache.path("listed")
    np.savez(listed, format=np.frombuffer(b"neuspike-recording-cache/2", np.uint8),
             ground_truth=np.zeros((4, 4), np.float32), spike_bits=np.zeros((1, 4, 1), np.uint8),
             spike_shape=np.array([1, 4, 4]), spike_json=np.frombuffer(b"[1, 2]", np.uint8))
    with pytest.raises(FormatError, match="invalid recording cache file"):
        load_recording(listed)
    assert cache._load("listed") is None
