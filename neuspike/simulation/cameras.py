"""The cameras a condition calls for and the metadata every recording carries.

Only declared effect stages run, and a modality no consumer asks for gets no camera at all. Both
cameras draw from their own generator, spawned from the one given, so a modality's bytes do not
depend on whether the other one is simulated.
"""

from __future__ import annotations

import json
from typing import Any, Iterable

import numpy as np

from neuspike.conditions import EVENTS, NOISE_LEVELS, SPIKES, Condition, Effect, merge_effects
from neuspike.sensors.event_camera import EventCamera
from neuspike.sensors.spike_camera import SpikeCamera
from neuspike.simulation.recording import SIMULATOR_VERSION, SensorConfig


def scene_effects(scene: Any, condition: Condition) -> tuple[Effect, ...]:
    """The declared stages: the noise level's, then the scene's own, then the condition's extras."""
    spec_effects = tuple(getattr(getattr(scene, "spec", None), "effects", ()) or ())
    return merge_effects(NOISE_LEVELS[condition.noise], spec_effects, condition.effects)


def make_cameras(scene: Any, condition: Condition, sensor: SensorConfig, modalities: frozenset[str],
                 rng: np.random.Generator) -> tuple[SpikeCamera | None, EventCamera | None, tuple[Effect, ...]]:
    """``(spike camera or None, event camera or None, declared effects)`` for ``modalities``."""
    effects = scene_effects(scene, condition)
    spike_rng, event_rng = rng.spawn(2)
    spike_cam = event_cam = None
    if SPIKES in modalities:
        spike_cam = SpikeCamera(
            scene.width, scene.height, light=condition.light, threshold=sensor.spike_threshold,
            plane_rate_hz=sensor.plane_rate_hz,
            effects=tuple(e for e in effects if e.modality == SPIKES), rng=spike_rng,
        )
    if EVENTS in modalities:
        event_cam = EventCamera(
            scene.width, scene.height, light=condition.light, threshold_on=sensor.event_threshold,
            threshold_off=sensor.event_threshold,
            effects=tuple(e for e in effects if e.modality == EVENTS), rng=event_rng,
        )
    return spike_cam, event_cam, effects


def base_meta(scene: Any, condition: Condition, sensor: SensorConfig, seed: int | None,
              effects: tuple[Effect, ...], mode: str) -> dict[str, Any]:
    """The metadata of every recording: scene, condition, declared effects, sensor, seed, size, gain."""
    return {
        "simulator_version": SIMULATOR_VERSION,
        "mode": mode,
        "scene": scene.describe(),
        "condition": condition.as_dict(),
        "effects_declared": [e.as_dict() for e in effects],
        "sensor": sensor.as_dict(),
        "seed": seed,
        "width": scene.width,
        "height": scene.height,
        "plane_rate_hz": sensor.plane_rate_hz,
        "threshold": sensor.spike_threshold,
        "gain": condition.light / sensor.spike_threshold,
        "event_threshold": sensor.event_threshold,
        "light": condition.light,
    }


def merge_stages(*stage_lists: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Sum the wall time of stages with the same name and parameters, keeping first-seen order."""
    merged: dict[str, dict[str, Any]] = {}
    for stages in stage_lists:
        for s in stages:
            key = json.dumps([s.get("modality"), s["name"], s.get("params", {})], sort_keys=True, default=str)
            if key in merged:
                merged[key]["seconds"] += float(s.get("seconds", 0.0))
            else:
                merged[key] = {**s, "seconds": float(s.get("seconds", 0.0))}
    return list(merged.values())


def tag_stages(stages: Iterable[dict[str, Any]], modality: str) -> list[dict[str, Any]]:
    """``stages`` with their ``modality`` added (first key)."""
    return [{"modality": modality, **s} for s in stages]
