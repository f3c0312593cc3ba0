"""Turn a scene into spike and event recordings: the simulation pipeline and its command line.

Two modes:

*window* (Algorithm 1 of NeuSpike-Net)
    One spike window of ``planes`` planes (T = 256 by default). The motion scale S picks S scene
    instants spread over a scene-time span of ``S / upsampled_rate_hz`` seconds (the paper's
    upsampled frame rate, 22,500 frames/s), centred on the key instant; each instant is held for
    ``planes // S`` planes. The event camera sees the same S frames (times L), each placed at the
    sensor time of the centre of its hold interval, so both recordings share one sensor clock and
    align plane for plane. The ground truth is the scene at the key instant (the window's centre).
    With ``history_s`` the event camera first sees the scene before the window at the same frame
    spacing (warm-up history for recurrent methods); the spike window is unchanged.
*continuous*
    For videos and long sequences: every plane samples the scene at its own instant (the centre
    of the plane), processed in chunks so that any length fits in memory; the event camera samples
    the same instants. ``time_scale`` is the scene seconds per sensor second (below 1 is slow motion).

Only declared effect stages run, and a modality no consumer asks for is not simulated at all.
Every recording's metadata lists the stages that ran with their parameters and wall time.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

from neuspike.atomic import write_bytes, write_json, write_text
from neuspike.checks import check_positive, check_positive_int, parse_size
from neuspike.conditions import EVENTS, NOISE_LEVELS, SPIKES, Condition, Effect, merge_effects, parse_effects
from neuspike.errors import InputError, NeuSpikeError
from neuspike.formats.events_io import EventsH5Writer, write_events_h5
from neuspike.formats.vidar_dat import DatWriter, write_dat
from neuspike.images import write_png
from neuspike.rng import derive_rng
from neuspike.sample import Sample
from neuspike.scenes import SceneSpec, make_scene
from neuspike.sensors.event_camera import EventCamera
from neuspike.sensors.spike_camera import SpikeCamera
from neuspike.streams import VIDAR_PLANE_RATE_HZ, EventStream, SpikeStream

if TYPE_CHECKING:
    from neuspike.cache import RecordingCache

#: Bump when a change alters simulated bytes for the same inputs (part of every cache key).
SIMULATOR_VERSION = "1"
#: Event history simulated before a window for recurrent methods to warm up on, in window durations
#: (the default of the sweeps and the timing benchmark alike).
DEFAULT_HISTORY_WINDOWS = 5.0
MODALITIES = (SPIKES, EVENTS)


@dataclass(frozen=True)
class SensorConfig:
    """Sensor and timing parameters shared by both cameras.

    Parameters
    ----------
    planes : int
        Spike planes per window (T).
    plane_rate_hz : float
        Spike planes per second of sensor time (Vidar: 20,000).
    upsampled_rate_hz : float
        Scene frames per second of the upsampled source (the paper: 22,500).
    spike_threshold : float
        Integrate-and-fire threshold phi (radiance 1 at L = 1 adds 1 per plane).
    event_threshold : float
        Nominal DVS contrast threshold, ON and OFF, in log units.
    """

    planes: int = 256
    plane_rate_hz: float = VIDAR_PLANE_RATE_HZ
    upsampled_rate_hz: float = 22_500.0
    spike_threshold: float = 1.0
    event_threshold: float = 0.2

    def __post_init__(self) -> None:
        check_positive_int("planes", self.planes)
        for name in ("plane_rate_hz", "upsampled_rate_hz", "spike_threshold", "event_threshold"):
            check_positive(name, getattr(self, name))

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True, eq=False)
class Recording:
    """What one simulated window gives.

    ``ground_truth`` is the radiance at the key instant, float32 (H, W) (may exceed 1 in HDR
    scenes); ``key_time_s`` and the window are in sensor time. ``events`` includes the warm-up
    history (``t < window_start_s``) when one was simulated.
    """

    spikes: SpikeStream | None
    events: EventStream | None
    ground_truth: np.ndarray
    key_time_s: float
    window_start_s: float
    window_end_s: float
    meta: dict[str, Any] = field(default_factory=dict)

    def to_sample(self) -> Sample:
        """The recording as a method's :class:`~neuspike.sample.Sample` (ground truth clipped to [0, 1])."""
        h, w = self.ground_truth.shape
        return Sample(
            height=h,
            width=w,
            key_time_s=self.key_time_s,
            window_start_s=self.window_start_s,
            window_end_s=self.window_end_s,
            spikes=self.spikes,
            events=self.events,
            event_threshold=self.meta.get("event_threshold"),
            ground_truth=np.clip(self.ground_truth, 0.0, 1.0).astype(np.float32),
            meta=dict(self.meta),
        )


def _check_modalities(modalities: Iterable[str]) -> frozenset[str]:
    mods = frozenset(modalities)
    if not mods or not mods <= set(MODALITIES):
        raise InputError(f"modalities must be a non-empty subset of {MODALITIES}, got {sorted(mods)}")
    return mods


def scene_effects(scene: Any, condition: Condition) -> tuple[Effect, ...]:
    """The declared stages: the noise level's, then the scene's own, then the condition's extras."""
    spec_effects = tuple(getattr(getattr(scene, "spec", None), "effects", ()) or ())
    return merge_effects(NOISE_LEVELS[condition.noise], spec_effects, condition.effects)


def _cameras(scene: Any, condition: Condition, sensor: SensorConfig, modalities: frozenset[str],
             rng: np.random.Generator):

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


def _base_meta(scene: Any, condition: Condition, sensor: SensorConfig, seed: int | None,
               effects: tuple[Effect, ...], mode: str) -> dict[str, Any]:
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


def _merge_stages(*stage_lists: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
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


def _tag(stages: Iterable[dict[str, Any]], modality: str) -> list[dict[str, Any]]:
    return [{"modality": modality, **s} for s in stages]


def _window_times(condition: Condition, sensor: SensorConfig, history_s: float, events: bool,
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
    """Pixels whose radiance never changes while the cameras of :func:`simulate_recording` look.

    The scene is rendered at exactly the instants the simulator renders for the same arguments (the
    window's S frames and, when events are simulated, their history) and a pixel is static when
    its value is the same at every instant. A still scene is static everywhere, a fan outside the
    blades' reach; a pan or zoom only where the photograph itself is uniform. Rendered ``chunk``
    frames at a time, so memory stays small on long histories. With ``min_fraction``, a region
    that cannot cover that fraction of the view (judged from the first and last instants alone) is
    returned empty without rendering the rest.

    Returns
    -------
    numpy.ndarray
        bool (H, W).
    """
    mods = _check_modalities(modalities)
    if sensor.planes % condition.motion:
        raise InputError(f"the spike window of {sensor.planes} planes is not a whole multiple of S = {condition.motion}")
    _, _, times, _ = _window_times(condition, sensor, history_s, EVENTS in mods)
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
    mods = _check_modalities(modalities)
    s = condition.motion
    if sensor.planes % s:
        lo = (sensor.planes // s) * s
        raise InputError(
            f"the spike window of {sensor.planes} planes is not a whole multiple of the motion scale "
            f"S = {s} (Algorithm 1 holds each of the S frames for T // S planes); use T = {lo or s} or {lo + s}"
        )
    hold, n_hist, scene_times, sensor_times = _window_times(condition, sensor, history_s, EVENTS in mods, center_s)
    frame_dt_sensor = hold / sensor.plane_rate_hz

    spike_cam, event_cam, effects = _cameras(scene, condition, sensor, mods, rng)
    meta = _base_meta(scene, condition, sensor, seed, effects, "window")
    meta.update({"planes": sensor.planes, "hold_planes": hold, "motion": s, "history_s": n_hist * frame_dt_sensor})

    t0 = time.perf_counter()
    frames = scene.render(scene_times)
    gt = scene.render(np.array([center_s]))[0]
    stages = [{"modality": "scene", "name": "render", "params": {"frames": int(len(scene_times)) + 1},
               "seconds": time.perf_counter() - t0}]

    spikes = events = None
    if spike_cam is not None:
        spikes = spike_cam.capture(np.ascontiguousarray(frames[n_hist:]), hold_planes=hold, start_s=0.0)
        stages += _tag(spikes.meta.get("stages", []), SPIKES)
        meta["spike_count"] = int(spikes.meta.get("spike_count", np.count_nonzero(spikes.planes)))
    if event_cam is not None:
        events = event_cam.capture(frames, sensor_times)
        stages += _tag(events.meta.get("stages", []), EVENTS)
        meta["event_count"] = len(events)
        meta["event_count_window"] = int(len(events) - np.searchsorted(events.t_s, 0.0))
    meta["stages"] = stages
    meta["key_time_s"] = sensor.planes / (2.0 * sensor.plane_rate_hz)
    meta["start_s"] = 0.0
    return Recording(
        spikes=spikes, events=events, ground_truth=np.asarray(gt, dtype=np.float32),
        key_time_s=meta["key_time_s"], window_start_s=0.0,
        window_end_s=sensor.planes / sensor.plane_rate_hz, meta=meta,
    )


def sample_rng(seed: int, scene_spec: SceneSpec, condition: Condition) -> np.random.Generator:
    """The generator of every random draw of one simulated sample: derived from (seed, scene, condition)."""
    return derive_rng(seed, "cell", scene_spec.as_dict(), condition.as_dict())


def simulate_recording(
    scene_spec: SceneSpec,
    condition: Condition,
    *,
    sensor: SensorConfig,
    seed: int,
    modalities: Iterable[str] = MODALITIES,
    history_s: float = 0.0,
    cache: "RecordingCache | None" = None,
) -> tuple[Recording, bool]:
    """One window of ``scene_spec`` under ``condition``, simulated or taken from ``cache``.

    This is the one way from a (scene, condition, seed) cell to a recording: the sweeps, the timing
    benchmark, the tests and the training datasets all come through it, so the same arguments give
    the same bytes everywhere. Random draws come from :func:`sample_rng`.

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
    cache : neuspike.cache.RecordingCache or None
        Where recordings are kept between runs; ``None`` always simulates.

    Returns
    -------
    (Recording, bool)
        The recording and whether it came from the cache.
    """
    from neuspike.cache import RecordingCache, recording_key  # the cache stores Recordings: a cycle

    mods = _check_modalities(modalities)

    def simulate() -> Recording:
        return simulate_window(make_scene(scene_spec), condition, rng=sample_rng(seed, scene_spec, condition),
                               sensor=sensor, modalities=mods, history_s=history_s, seed=seed)

    if cache is None:
        return simulate(), False
    if not isinstance(cache, RecordingCache):
        raise InputError(f"cache: expected a RecordingCache or None, got {type(cache).__name__}")
    key = recording_key(scene_spec=scene_spec, condition=condition, sensor=sensor, seed=seed,
                        modalities=mods, history_s=history_s)
    return cache.get_or_simulate(key, simulate)


def simulate_sample(
    scene_spec: SceneSpec,
    condition: Condition,
    *,
    sensor: SensorConfig,
    seed: int,
    modalities: Iterable[str] = MODALITIES,
    history_s: float = 0.0,
    cache: "RecordingCache | None" = None,
) -> Sample:
    """The :class:`~neuspike.sample.Sample` of :func:`simulate_recording` (ground truth clipped to [0, 1])."""
    recording, _ = simulate_recording(scene_spec, condition, sensor=sensor, seed=seed, modalities=modalities,
                                      history_s=history_s, cache=cache)
    return recording.to_sample()


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
    mods = _check_modalities(modalities)
    check_positive("duration_s", duration_s)
    check_positive("time_scale", time_scale)
    chunk_planes = check_positive_int("chunk_planes", chunk_planes)
    total = int(np.floor(duration_s / time_scale * sensor.plane_rate_hz + 1e-9))
    if total < 1:
        raise InputError(f"duration {duration_s} s is shorter than one plane at {sensor.plane_rate_hz} planes/s")
    spike_cam, event_cam, effects = _cameras(scene, condition, sensor, mods, rng)
    meta = _base_meta(scene, condition, sensor, seed, effects, "continuous")
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
                stage_lists.append(_tag(spikes.meta.get("stages", []), SPIKES))
                n_spikes += int(spikes.meta.get("spike_count", np.count_nonzero(spikes.planes)))
            if event_cam is not None:
                events = event_cam.capture(frames, sensor_t)
                stage_lists.append(_tag(events.meta.get("stages", []), EVENTS))
                n_events += len(events)
            on_chunk(spikes, events)
            if bar is not None:
                bar.update(j1 - j0)
    finally:
        if bar is not None:
            bar.close()
    meta["stages"] = _merge_stages(
        [{"modality": "scene", "name": "render", "params": {"frames": total}, "seconds": render_s}], *stage_lists
    )
    if spike_cam is not None:
        meta["spike_count"] = n_spikes
    if event_cam is not None:
        meta["event_count"] = n_events
    return meta


# --------------------------------------------------------------------------------------------
# Writing recordings
# --------------------------------------------------------------------------------------------

def write_png_atomic(path: Path, image01: np.ndarray) -> None:
    """Write a radiance image as an 8-bit PNG, atomically (HDR values above 1 saturate, by choice)."""
    write_png(path, image01, clip=True)


def write_npy_atomic(path: Path, array: np.ndarray) -> None:
    """``np.save`` through a temporary file in the same folder."""
    buf = io.BytesIO()
    np.save(buf, array)
    write_bytes(path, buf.getvalue())


#: Entries a simulation writes into its folder; a new run replaces all of them.
RECORDING_ENTRIES = ("spikes.dat", "events.h5", "gt.png", "gt.npy", "meta.json", "frames")


def write_recording(recording: Recording, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write ``spikes.dat``, ``events.h5``, ``gt.png`` / ``gt.npy`` and ``meta.json`` into ``out_dir``.

    The files are written into a temporary folder beside ``out_dir`` that replaces it in one step
    when complete (:func:`neuspike.formats.staging.staged_folder`): a run killed at any point
    leaves ``out_dir`` entirely as it was. No file of an earlier recording
    (:data:`RECORDING_ENTRIES`) survives beside the new ones; other files in ``out_dir`` are kept.
    """
    from neuspike.formats.staging import staged_folder

    final = Path(out_dir)
    with staged_folder(final, ours=RECORDING_ENTRIES) as staging:
        written = _write_recording_files(recording, staging)
    return {k: final / v.name for k, v in written.items()}


def _write_recording_files(recording: Recording, out: Path) -> dict[str, Path]:
    written: dict[str, Path] = {}
    if recording.spikes is not None:
        write_dat(out / "spikes.dat", recording.spikes.planes)
        written["spikes"] = out / "spikes.dat"
    if recording.events is not None:
        write_events_h5(out / "events.h5", recording.events)
        written["events"] = out / "events.h5"
    write_png_atomic(out / "gt.png", recording.ground_truth)
    write_npy_atomic(out / "gt.npy", recording.ground_truth.astype(np.float32))
    written["gt"] = out / "gt.png"
    meta = dict(recording.meta)
    if recording.spikes is not None and recording.spikes.num_planes:
        # a pixel firing on every plane saturates: its radiance is only known to be >= threshold / L
        fired_always = recording.spikes.planes.all(axis=0)
        meta["saturated_pixels"] = int(np.count_nonzero(fired_always))
        meta["saturated_fraction"] = float(np.mean(fired_always))
    meta["files"] = {k: v.name for k, v in written.items()}
    meta["window_start_s"] = recording.window_start_s
    meta["window_end_s"] = recording.window_end_s
    write_json(out / "meta.json", meta)
    written["meta"] = out / "meta.json"
    return written


def write_sequence(
    scene: Any,
    condition: Condition,
    out_dir: str | os.PathLike,
    *,
    rng: np.random.Generator,
    start_s: float,
    duration_s: float,
    sensor: SensorConfig = SensorConfig(),
    time_scale: float = 1.0,
    modalities: Iterable[str] = MODALITIES,
    progress: bool = False,
    seed: int | None = None,
) -> dict[str, Any]:
    """Continuous simulation streamed to ``out_dir`` (``spikes.dat``, ``events.h5``, ``frames/``,
    ``frames/timestamps.txt``, ``meta.json``).

    Everything is written into a temporary folder beside ``out_dir`` that replaces it in one step
    when complete, as in :func:`write_recording`: a killed run leaves ``out_dir`` as it was.

    Ground-truth frames are the scene at its real frame instants inside the span (videos: the
    source frames; other scenes: every 256 planes), with their sensor and scene times.
    """
    from neuspike.formats.staging import staged_folder

    mods = _check_modalities(modalities)
    with staged_folder(Path(out_dir), ours=RECORDING_ENTRIES) as staging:
        return _write_sequence_files(scene, condition, staging, rng=rng, start_s=start_s, duration_s=duration_s,
                                     sensor=sensor, time_scale=time_scale, mods=mods, progress=progress, seed=seed)


def _write_sequence_files(
    scene: Any, condition: Condition, out: Path, *, rng: np.random.Generator, start_s: float, duration_s: float,
    sensor: SensorConfig, time_scale: float, mods: frozenset[str], progress: bool, seed: int | None,
) -> dict[str, Any]:
    dat = DatWriter(out / "spikes.dat") if SPIKES in mods else None
    h5 = EventsH5Writer(out / "events.h5", scene.width, scene.height) if EVENTS in mods else None

    def on_chunk(spikes: SpikeStream | None, events: EventStream | None) -> None:
        if dat is not None and spikes is not None:
            dat.write(spikes.planes)
        if h5 is not None and events is not None:
            h5.write(events)

    ok = False
    try:
        meta = simulate_sequence(
            scene, condition, rng=rng, start_s=start_s, duration_s=duration_s, on_chunk=on_chunk,
            sensor=sensor, time_scale=time_scale, modalities=mods, progress=progress, seed=seed,
        )
        ok = True
    finally:
        for writer in (dat, h5):
            if writer is None:
                continue
            if ok:
                writer.close()
            else:
                writer.abort()
    end_s = start_s + duration_s
    frame_times = np.asarray(getattr(scene, "frame_times_s", None) if getattr(scene, "frame_times_s", None) is not None
                             else start_s + time_scale * np.arange(0, meta["planes"], 256) / sensor.plane_rate_hz)
    frame_times = frame_times[(frame_times >= start_s) & (frame_times <= end_s)]
    frames_dir = out / "frames"
    frames_dir.mkdir(exist_ok=True)
    lines = ["# index sensor_time_s scene_time_s file"]
    for i, t in enumerate(frame_times):
        img = scene.render(np.array([t]))[0]
        name = f"frame_{i:06d}.png"
        write_png_atomic(frames_dir / name, img)
        lines.append(f"{i} {(t - start_s) / time_scale:.9f} {t:.9f} {name}")
    write_text(frames_dir / "timestamps.txt", "\n".join(lines) + "\n")
    meta["files"] = {**({"spikes": "spikes.dat"} if dat else {}), **({"events": "events.h5"} if h5 else {}),
                     "frames": "frames/timestamps.txt"}
    meta["ground_truth_frames"] = len(frame_times)
    write_json(out / "meta.json", meta)
    return meta


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------

def _parse_size(text: str) -> tuple[int, int]:
    try:
        return parse_size(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parse_fraction(text: str) -> float:
    try:
        if "/" in text:
            a, b = text.split("/")
            return float(a) / float(b)
        return float(text)
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"expected a number such as 0.25 or 1/4, got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m neuspike.simulate",
        description=(
            "Simulate a spike camera (Vidar, integrate-and-fire) and an event camera (DVS) looking at "
            "a scene or a video. Writes spikes.dat (Vidar format), events.h5 (events/xs, ys, ts, ps), "
            "the ground truth (gt.png and gt.npy for a window; frames/ with timestamps for a video) "
            "and meta.json (gain, threshold, plane rate, size, the stages that ran with their "
            "parameters and seconds, spike and event counts)."
        ),
        epilog=(
            "examples:\n"
            "  python -m neuspike.simulate --out out/pan\n"
            "  python -m neuspike.simulate --scene fan --rpm 2600 --light 1/8 --motion 256 --noise high --out out/fan\n"
            "  python -m neuspike.simulate --video ../shared/realdata/video/slider_depth --duration 0.2 --out out/slider\n"
            "  python -m neuspike.simulate --effects 'refractory:period_s=5e-4,leak:rate_hz=0.1' --out out/pan_fx"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--scene", choices=["pan", "zoom", "fan", "still"], default="pan",
                   help="analytic scene kind (default: pan); ignored with --video")
    p.add_argument("--image", default="camera",
                   help="photograph: a scikit-image bundled name (e.g. camera, astronaut) or an image file (default: camera)")
    p.add_argument("--video", help="a video file or a folder of images (optional images.txt with '<t> <file>' lines)")
    p.add_argument("--velocity", type=float, nargs=2, metavar=("VX", "VY"), help="pan velocity in px/s of scene time")
    p.add_argument("--rpm", type=float, help="fan speed in revolutions per minute")
    p.add_argument("--zoom-rate", type=float, help="zoom: the view scale grows as exp(rate * t), rate in 1/s")
    p.add_argument("--dynamic-range", type=float, help="HDR: map the photograph's luma to radiance spanning this ratio (e.g. 1000)")
    p.add_argument("--light", type=_parse_fraction, default=0.25, help="light scale L, e.g. 1/4 (default: 1/4)")
    p.add_argument("--motion", type=int, default=128, help="motion scale S in 16..256 (default: 128; window mode)")
    p.add_argument("--noise", choices=list(NOISE_LEVELS), default="none",
                   help="the paper's noise level (default: none = no noise stage runs)")
    p.add_argument("--effects", default="",
                   help="extra stages, e.g. 'threshold_mismatch:sigma=0.05,refractory:period_s=5e-4,shot_noise:rate_hz=5'")
    p.add_argument("--size", type=_parse_size, help="sensor size WxH (default: 400x250; a video's own size for --video)")
    p.add_argument("--planes", type=int, default=256, help="spike planes per window T (default: 256)")
    p.add_argument("--plane-rate", type=float, default=VIDAR_PLANE_RATE_HZ,
                   help=f"spike planes per second (default: {VIDAR_PLANE_RATE_HZ:g})")
    p.add_argument("--threshold", type=float, default=1.0, help="spike threshold phi (default: 1)")
    p.add_argument("--event-threshold", type=float, default=0.2, help="DVS contrast threshold (default: 0.2)")
    p.add_argument("--modalities", default="spikes,events", help="what to simulate (default: spikes,events)")
    p.add_argument("--mode", choices=["window", "continuous"],
                   help="window = Algorithm 1 (default for scenes); continuous = a sample per plane (default for --video)")
    p.add_argument("--at", type=float, default=0.0, help="scene time of the key instant / start, seconds (default: 0)")
    p.add_argument("--duration", type=float, help="continuous mode: scene seconds to simulate (default: the whole video, or 0.0128 s)")
    p.add_argument("--time-scale", type=float, default=1.0, help="continuous mode: scene seconds per sensor second (default: 1)")
    p.add_argument("--upsample", type=int, help="video: snap render instants to U x the video frame rate (default: continuous flow interpolation)")
    p.add_argument("--history", type=float, default=0.0, help="window mode: seconds of event history before the window (default: 0)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    from neuspike.formats.staging import check_writable_folder

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")
    check_writable_folder(out.parent, what="--out: the folder", create=False)  # before any work
    mode_wanted = args.mode or ("continuous" if args.video else "window")
    if mode_wanted == "window" and isinstance(args.motion, int) and args.motion >= 1 and isinstance(args.planes, int) \
            and args.planes >= 1 and args.planes % args.motion:
        s_, t_ = args.motion, args.planes
        plane_counts = sorted({n for n in ((t_ // s_) * s_, (t_ // s_ + 1) * s_) if n > 0})
        motions = [d for d in range(1, t_ + 1) if t_ % d == 0]
        near = sorted(motions, key=lambda d: (abs(d - s_), d))[:2]
        raise InputError(
            f"--planes {t_} is not a whole multiple of --motion {s_} (Algorithm 1 holds each of the S frames "
            f"for T // S planes): use {' or '.join(f'--planes {n}' for n in plane_counts)}, or "
            f"{' or '.join(f'--motion {d}' for d in sorted(near))}"
        )
    modalities = _check_modalities(m.strip() for m in args.modalities.split(",") if m.strip())
    sensor = SensorConfig(planes=args.planes, plane_rate_hz=args.plane_rate, spike_threshold=args.threshold,
                          event_threshold=args.event_threshold)
    condition = Condition(light=args.light, motion=args.motion, noise=args.noise, effects=parse_effects(args.effects))
    spec_kwargs: dict[str, Any] = {}
    if args.video:
        spec_kwargs.update(kind="video", video=args.video, size=args.size)
        if args.upsample is not None:
            spec_kwargs["upsample"] = args.upsample
    else:
        spec_kwargs.update(kind=args.scene, image=args.image, size=args.size or (400, 250))
        if args.velocity is not None:
            spec_kwargs["velocity_px_s"] = tuple(args.velocity)
        if args.rpm is not None:
            spec_kwargs["rpm"] = args.rpm
        if args.zoom_rate is not None:
            spec_kwargs["zoom_rate_hz"] = args.zoom_rate
    if args.dynamic_range is not None:
        spec_kwargs["dynamic_range"] = args.dynamic_range
    scene = make_scene(SceneSpec(**spec_kwargs))
    mode = args.mode or ("continuous" if args.video else "window")
    rng = derive_rng(args.seed, "simulate", scene.describe(), condition.as_dict(), mode)
    t0 = time.perf_counter()
    if mode == "window":
        rec = simulate_window(scene, condition, rng=rng, sensor=sensor, center_s=args.at, modalities=modalities,
                              history_s=args.history, seed=args.seed)
        write_recording(rec, out)
        meta = rec.meta
    else:
        start = args.at if not args.video or args.at else float(getattr(scene, "start_s", 0.0))
        if args.duration is not None:
            duration = args.duration
        elif args.video:
            duration = float(scene.end_s) - start
        else:
            duration = sensor.planes / sensor.plane_rate_hz * args.time_scale
        meta = write_sequence(scene, condition, out, rng=rng, start_s=start, duration_s=duration, sensor=sensor,
                              time_scale=args.time_scale, modalities=modalities,
                              progress=not args.no_progress, seed=args.seed)
    elapsed = time.perf_counter() - t0
    parts = [f"{meta['planes']} planes at {scene.width}x{scene.height}"]
    if "spike_count" in meta:
        parts.append(f"{meta['spike_count']:,} spikes")
    if "event_count" in meta:
        parts.append(f"{meta['event_count']:,} events")
    ran = ", ".join(f"{s['name']} {s['seconds'] * 1e3:.1f} ms" for s in meta["stages"])
    print(f"wrote {out}/: {'; '.join(parts)} in {elapsed:.2f} s")
    print(f"stages: {ran}")
    saturated = json.loads((out / "meta.json").read_text()).get("saturated_fraction")
    if saturated:
        print(f"warning: {saturated:.1%} of the pixels fired on every plane (saturated: the light scale "
              f"{condition.light:g} is too high for threshold {sensor.spike_threshold:g}; spike methods cannot "
              f"tell their radiance apart)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
