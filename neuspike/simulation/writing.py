"""Recording folders: ``spikes.dat``, ``events.h5``, the ground truth and ``meta.json``, in one step.

A folder is written under a temporary name beside the target and swapped in when complete
(:func:`neuspike.formats.staging.staged_folder`): a run killed at any point leaves it entirely as it
was.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from neuspike.utils.atomic import write_bytes, write_json, write_text
from neuspike.conditions import EVENTS, SPIKES, Condition
from neuspike.formats.event_writers import EventsH5Writer, write_events_h5
from neuspike.formats.staging import staged_folder
from neuspike.formats.vidar_dat import DatWriter, write_dat
from neuspike.formats.images import write_png
from neuspike.utils.resources import check_file_size_limit
from neuspike.simulation.budget import EVENTS_H5_CHUNK, Budget, check_budget, events_h5_bytes
from neuspike.simulation.recording import MODALITIES, Recording, SensorConfig, check_modalities
from neuspike.simulation.sequence import simulate_sequence
from neuspike.streams import EventStream, SpikeStream


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
    final = Path(out_dir)
    _check_room(recording, final)
    with staged_folder(final, ours=RECORDING_ENTRIES) as staging:
        written = _write_recording_files(recording, staging)
    return {k: final / v.name for k, v in written.items()}


def _check_room(recording: Recording, folder: Path) -> None:
    """Refuse, before writing, files that the free disk or the file size limit cannot take (naming the size)."""
    h, w = recording.ground_truth.shape
    files = {"gt.npy": 4.0 * h * w + 128, "gt.png": float(h * w)}
    if recording.spikes is not None:
        files["spikes.dat"] = recording.spikes.planes.size / 8
    if recording.events is not None:
        files["events.h5"] = events_h5_bytes(len(recording.events))
    check_budget(Budget(files=files), what="the recording", folder=folder)


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
    mods = check_modalities(modalities)
    with staged_folder(Path(out_dir), ours=RECORDING_ENTRIES) as staging:
        return _write_sequence_files(scene, condition, staging, rng=rng, start_s=start_s, duration_s=duration_s,
                                     sensor=sensor, time_scale=time_scale, mods=mods, progress=progress, seed=seed)


def _write_sequence_files(
    scene: Any, condition: Condition, out: Path, *, rng: np.random.Generator, start_s: float, duration_s: float,
    sensor: SensorConfig, time_scale: float, mods: frozenset[str], progress: bool, seed: int | None,
) -> dict[str, Any]:
    dat = DatWriter(out / "spikes.dat") if SPIKES in mods else None
    h5 = EventsH5Writer(out / "events.h5", scene.width, scene.height, chunk_events=EVENTS_H5_CHUNK) \
        if EVENTS in mods else None
    written = {"spikes.dat": 0.0, "events.h5": 0}

    def on_chunk(spikes: SpikeStream | None, events: EventStream | None) -> None:
        # a file about to outgrow the file size limit stops the run here, in one line (the system's
        # own refusal comes partway through a write, which HDF5 does not survive)
        if dat is not None and spikes is not None:
            written["spikes.dat"] += spikes.planes.size / 8
            check_file_size_limit(written["spikes.dat"], "spikes.dat")
            dat.write(spikes.planes)
        if h5 is not None and events is not None:
            written["events.h5"] += len(events)
            check_file_size_limit(events_h5_bytes(written["events.h5"], chunk_events=EVENTS_H5_CHUNK), "events.h5")
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
