"""Continuous simulation, for videos and long sequences.

Every plane samples the scene at its own instant (the centre of the plane), processed in chunks so
that any length fits in memory; the event camera samples the same instants. ``time_scale`` is the
scene seconds per sensor second (below 1 is slow motion).
"""

from __future__ import annotations

import sys
import time
from typing import Any, Callable, Iterable

import numpy as np

from neuspike.utils.checks import check_positive, check_positive_int
from neuspike.conditions import EVENTS, SPIKES, Condition
from neuspike.errors import InputError
from neuspike.simulation.cameras import base_meta, make_cameras, merge_stages, tag_stages
from neuspike.simulation.recording import MODALITIES, SensorConfig, check_modalities
from neuspike.streams import EventStream, SpikeStream


def simulate_sequence(
    scene: Any,
    condition: Condition,
    *,
    rng: np.random.Generator,
    start_s: float,
    duration_s: float,
    on_chunk: Callable[[SpikeStream | None, EventStream | None], None],
    sensor: SensorConfig = SensorConfig(),
    time_scale: float = 1.0,
    modalities: Iterable[str] = MODALITIES,
    chunk_planes: int = 256,
    progress: bool = False,
    seed: int | None = None,
) -> dict[str, Any]:
    """Continuous mode: every plane samples the scene at its own instant; chunked.

    Plane ``j`` covers sensor time ``[j / rate, (j + 1) / rate)`` and sees the scene at scene time
    ``start_s + time_scale * (j + 0.5) / rate``. The event camera samples the same instants.
    ``on_chunk(spikes, events)`` receives each chunk (streams may be ``None`` for a modality not
    simulated) and typically writes it to disk. Returns the metadata (counts, stages, timing).
    """
    mods = check_modalities(modalities)
    check_positive("duration_s", duration_s)
    check_positive("time_scale", time_scale)
    chunk_planes = check_positive_int("chunk_planes", chunk_planes)
    total = int(np.floor(duration_s / time_scale * sensor.plane_rate_hz + 1e-9))
    if total < 1:
        raise InputError(f"duration {duration_s} s is shorter than one plane at {sensor.plane_rate_hz} planes/s")
    spike_cam, event_cam, effects = make_cameras(scene, condition, sensor, mods, rng)
    meta = base_meta(scene, condition, sensor, seed, effects, "continuous")
    meta.update({"planes": total, "time_scale": time_scale, "scene_start_s": start_s, "start_s": 0.0})
    render_s = 0.0
    stage_lists: list[list[dict[str, Any]]] = []
    n_spikes = n_events = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="plane", desc="simulating", file=sys.stderr)
    try:
        for j0 in range(0, total, chunk_planes):
            j1 = min(total, j0 + chunk_planes)
            idx = np.arange(j0, j1, dtype=np.float64)
            sensor_t = (idx + 0.5) / sensor.plane_rate_hz
            t0 = time.perf_counter()
            frames = scene.render(start_s + time_scale * sensor_t)
            render_s += time.perf_counter() - t0
            spikes = events = None
            if spike_cam is not None:
                spikes = spike_cam.capture(frames, hold_planes=1, start_s=j0 / sensor.plane_rate_hz)
                stage_lists.append(tag_stages(spikes.meta.get("stages", []), SPIKES))
                n_spikes += int(spikes.meta.get("spike_count", np.count_nonzero(spikes.planes)))
            if event_cam is not None:
                events = event_cam.capture(frames, sensor_t)
                stage_lists.append(tag_stages(events.meta.get("stages", []), EVENTS))
                n_events += len(events)
            on_chunk(spikes, events)
            if bar is not None:
                bar.update(j1 - j0)
    finally:
        if bar is not None:
            bar.close()
    meta["stages"] = merge_stages(
        [{"modality": "scene", "name": "render", "params": {"frames": total}, "seconds": render_s}], *stage_lists
    )
    if spike_cam is not None:
        meta["spike_count"] = n_spikes
        meta["dark_rate"] = spike_cam.dark_rate
    if event_cam is not None:
        meta["event_count"] = n_events
    return meta
