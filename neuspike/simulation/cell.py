"""The one way from a (scene, condition, seed) cell to a recording, simulated or taken from the cache.

The sweeps, the timing benchmark, the tests and the training datasets all come through
:func:`simulate_recording`, so the same arguments give the same bytes everywhere.
"""

from __future__ import annotations

from typing import Iterable

from neuspike.utils.checks import check_nonnegative
from neuspike.conditions import Condition
from neuspike.errors import InputError
from neuspike.sample import Sample
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulation.cache import RecordingCache
from neuspike.simulation.recording import MODALITIES, Recording, SensorConfig, check_modalities
from neuspike.simulation.window import sample_rng, simulate_window


def simulate_recording(
    scene_spec: SceneSpec,
    condition: Condition,
    *,
    sensor: SensorConfig,
    seed: int,
    modalities: Iterable[str] = MODALITIES,
    history_s: float = 0.0,
    cache: RecordingCache | None = None,
) -> tuple[Recording, frozenset[str]]:
    """One window of ``scene_spec`` under ``condition``, simulated or taken from ``cache``.

    Random draws come from :func:`~neuspike.simulation.window.sample_rng`. With a cache, each
    modality is looked up on its own (:mod:`neuspike.simulation.cache`): only the modalities not
    cached are simulated, and the result is the same bytes as one simulation of all of them.

    Parameters
    ----------
    scene_spec : SceneSpec
        What to render (built with :func:`neuspike.scenes.make_scene`).
    condition : Condition
        Light, motion, noise and declared effects.
    sensor : SensorConfig
        Window length, plane rate, thresholds.
    seed : int
        The cell's seed.
    modalities : iterable of {"spikes", "events"}
        What to simulate; a modality nobody consumes is not simulated.
    history_s : float
        Seconds of event history before the window (warm-up of recurrent methods).
    cache : RecordingCache or None
        Where recordings are kept between runs; ``None`` always simulates.

    Returns
    -------
    (Recording, frozenset of str)
        The recording and the modalities simulated now: empty when all of it came from the cache.
    """
    mods = check_modalities(modalities)
    history_s = check_nonnegative("history_s", history_s)

    def simulate(which: frozenset[str] = mods) -> Recording:
        return simulate_window(make_scene(scene_spec), condition, rng=sample_rng(seed, scene_spec, condition),
                               sensor=sensor, modalities=which, history_s=history_s, seed=seed)

    if cache is None:
        return simulate(), mods
    if not isinstance(cache, RecordingCache):
        raise InputError(f"cache: expected a RecordingCache or None, got {type(cache).__name__}")
    return cache.get_or_simulate(scene_spec=scene_spec, condition=condition, sensor=sensor, seed=seed,
                                 modalities=mods, history_s=history_s, simulate=simulate)


def simulate_sample(
    scene_spec: SceneSpec,
    condition: Condition,
    *,
    sensor: SensorConfig,
    seed: int,
    modalities: Iterable[str] = MODALITIES,
    history_s: float = 0.0,
    cache: RecordingCache | None = None,
) -> Sample:
    """The :class:`~neuspike.sample.Sample` of :func:`simulate_recording` (ground truth clipped to [0, 1])."""
    recording, _ = simulate_recording(scene_spec, condition, sensor=sensor, seed=seed, modalities=modalities,
                                      history_s=history_s, cache=cache)
    return recording.to_sample()
