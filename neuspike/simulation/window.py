"""One spike window of Algorithm 1 (NeuSpike-Net) and the matching events.

The motion scale S picks S scene instants spread over a scene-time span of ``S / upsampled_rate_hz``
seconds (the paper's upsampled frame rate, 22,500 frames/s), centred on the key instant; each
instant is held for ``planes // S`` planes. The event camera sees the same S frames (times L), each
placed at the sensor time of the centre of its hold interval, so both recordings share one sensor
clock and align plane for plane. The ground truth is the scene at the key instant (the window's
centre). With ``history_s`` the event camera first sees the scene before the window at the same
frame spacing (warm-up history for recurrent methods); the spike window is unchanged.
"""

from __future__ import annotations

import time
from typing import Any, Iterable

import numpy as np

from neuspike.conditions import EVENTS, SPIKES, Condition
from neuspike.errors import InputError
from neuspike.utils.rng import derive_rng
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulation.cameras import base_meta, make_cameras, tag_stages
from neuspike.simulation.recording import MODALITIES, Recording, SensorConfig, check_modalities


def window_times(condition: Condition, sensor: SensorConfig, history_s: float, events: bool,
                  center_s: float = 0.0) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Algorithm 1's instants: ``(hold, n_history_frames, scene_times, sensor_times)``.

    The S frames of the window (plus ``n_history_frames`` before it when ``events``), each held for
    ``hold`` planes; scene instants are ``1 / upsampled_rate_hz`` apart around ``center_s``, sensor
    instants the centres of the held frames, the window starting at sensor time 0.
    """
    if history_s < 0 or not np.isfinite(history_s):
        raise InputError(f"history_s must be >= 0, got {history_s!r}")
    s = condition.motion
    hold = sensor.planes // s
    frame_dt_sensor = hold / sensor.plane_rate_hz
    n_hist = int(np.ceil(history_s / frame_dt_sensor - 1e-9)) if events else 0
    k = np.arange(-n_hist, s, dtype=np.float64)
    frame_dt_scene = 1.0 / sensor.upsampled_rate_hz
    scene_times = center_s + (k - (s - 1) / 2.0) * frame_dt_scene
    sensor_times = (k + 0.5) * frame_dt_sensor
    return hold, n_hist, scene_times, sensor_times


def static_region(
    scene_spec: SceneSpec,
    condition: Condition,
    *,
    sensor: SensorConfig,
    modalities: Iterable[str] = MODALITIES,
    history_s: float = 0.0,
    min_fraction: float = 0.0,
    chunk: int = 64,
) -> np.ndarray:
    """Pixels whose radiance never changes while the cameras of :func:`simulate_window` look.

    The scene is rendered at exactly the instants the simulator renders for the same arguments (the
    window's S frames and, when events are simulated, their history) and a pixel is static when
    its value is the same at every instant. A still scene is static everywhere, a fan outside the
    blades' reach; a pan or zoom only where the photograph itself is uniform. Rendered ``chunk``
    frames at a time, so memory stays small on long histories. With ``min_fraction``, a region
    that cannot cover that fraction of the view (judged from the first and last instants alone) is
    returned empty without rendering the rest. A simulated recording carries the same mask
    (:meth:`~neuspike.simulation.recording.Recording.static_region`) without a second rendering.

    Returns
    -------
    numpy.ndarray
        bool (H, W).
    """
    mods = check_modalities(modalities)
    if sensor.planes % condition.motion:
        raise InputError(f"the spike window of {sensor.planes} planes is not a whole multiple of S = {condition.motion}")
    _, _, times, _ = window_times(condition, sensor, history_s, EVENTS in mods)
    scene = make_scene(scene_spec)
    ends = scene.render(times[[0, -1]])
    if np.mean(ends[0] == ends[1]) < min_fraction:
        return np.zeros(ends.shape[1:], dtype=bool)
    lo = hi = None
    for i in range(0, len(times), max(1, int(chunk))):
        frames = scene.render(times[i:i + chunk])
        f_lo, f_hi = frames.min(axis=0), frames.max(axis=0)
        lo = f_lo if lo is None else np.minimum(lo, f_lo)
        hi = f_hi if hi is None else np.maximum(hi, f_hi)
    return np.asarray(lo == hi)


def _unchanging(frames: np.ndarray) -> np.ndarray:
    """bool (H, W): the pixels equal in every frame of ``frames`` (T, H, W)."""
    return np.asarray(frames.min(axis=0) == frames.max(axis=0))


def simulate_window(
    scene: Any,
    condition: Condition,
    *,
    rng: np.random.Generator,
    sensor: SensorConfig = SensorConfig(),
    center_s: float = 0.0,
    modalities: Iterable[str] = MODALITIES,
    history_s: float = 0.0,
    seed: int | None = None,
) -> Recording:
    """Simulate one spike window (Algorithm 1) and the matching events.

    Parameters
    ----------
    scene : Scene
        Anything with ``width``, ``height``, ``render(times_s) -> float32 (T, H, W)`` and ``describe()``.
    condition : Condition
        Light L, motion S, noise level and extra effects.
    rng : numpy.random.Generator
        Source of every random draw (only declared effects draw).
    sensor : SensorConfig
    center_s : float
        Scene time of the key instant.
    modalities : iterable of {"spikes", "events"}
        What to simulate; the other modality is not simulated at all.
    history_s : float
        Sensor seconds of event history before the window (0 = none).
    seed : int or None
        Recorded in the metadata only.

    Returns
    -------
    Recording
        The spike window starts at sensor time 0; the key instant is its centre.
    """
    mods = check_modalities(modalities)
    s = condition.motion
    if sensor.planes % s:
        lo = (sensor.planes // s) * s
        raise InputError(
            f"the spike window of {sensor.planes} planes is not a whole multiple of the motion scale "
            f"S = {s} (Algorithm 1 holds each of the S frames for T // S planes); use T = {lo or s} or {lo + s}"
        )
    hold, n_hist, scene_times, sensor_times = window_times(condition, sensor, history_s, EVENTS in mods, center_s)
    frame_dt_sensor = hold / sensor.plane_rate_hz

    spike_cam, event_cam, effects = make_cameras(scene, condition, sensor, mods, rng)
    meta = base_meta(scene, condition, sensor, seed, effects, "window")
    meta.update({"planes": sensor.planes, "hold_planes": hold, "motion": s, "history_s": n_hist * frame_dt_sensor})

    t0 = time.perf_counter()
    frames = scene.render(scene_times)
    gt = scene.render(np.array([center_s]))[0]
    stages = [{"modality": "scene", "name": "render", "params": {"frames": int(len(scene_times)) + 1},
               "seconds": time.perf_counter() - t0}]

    # what each camera saw never changed there: the static region, kept with the recording
    window_static = _unchanging(frames[n_hist:])
    static_masks = {SPIKES: window_static} if spike_cam is not None else {}
    if event_cam is not None:
        static_masks[EVENTS] = _unchanging(frames) if n_hist else window_static

    spikes = events = None
    if spike_cam is not None:
        spikes = spike_cam.capture(np.ascontiguousarray(frames[n_hist:]), hold_planes=hold, start_s=0.0)
        stages += tag_stages(spikes.meta.get("stages", []), SPIKES)
        meta["spike_count"] = int(spikes.meta.get("spike_count", np.count_nonzero(spikes.planes)))
        meta["dark_rate"] = spike_cam.dark_rate  # 0.0 without a dark-current stage: known, not missing
    if event_cam is not None:
        events = event_cam.capture(frames, sensor_times)
        stages += tag_stages(events.meta.get("stages", []), EVENTS)
        meta["event_count"] = len(events)
        meta["event_count_window"] = int(len(events) - np.searchsorted(events.t_s, 0.0))
    meta["stages"] = stages
    meta["key_time_s"] = sensor.planes / (2.0 * sensor.plane_rate_hz)
    meta["start_s"] = 0.0
    return Recording(
        spikes=spikes, events=events, ground_truth=np.asarray(gt, dtype=np.float32),
        key_time_s=meta["key_time_s"], window_start_s=0.0,
        window_end_s=sensor.planes / sensor.plane_rate_hz, meta=meta, static_masks=static_masks,
    )


def sample_rng(seed: int, scene_spec: SceneSpec, condition: Condition) -> np.random.Generator:
    """The generator of every random draw of one simulated sample: derived from (seed, scene, condition)."""
    return derive_rng(seed, "cell", scene_spec.as_dict(), condition.as_dict())
