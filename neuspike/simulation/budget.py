"""What a simulation will need, estimated before it starts: peak memory and the files it writes.

The estimates count what is known in advance: the rendered frames, the spike planes, the Vidar
file (exactly), and the events of the declared noise stages (``shot_noise`` and ``leak`` fire at
their rates whatever the scene shows). Events caused by the scene's own changes are not known
before simulating and are left out, so the estimates are lower bounds: work refused by them
certainly cannot fit. :func:`check_budget` compares them with the memory available, the free disk
and the file size limit.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from neuspike.conditions import EVENTS, NOISE_LEVELS, SPIKES, Condition, Effect, merge_effects
from neuspike.utils.resources import check_disk, check_file_size_limit, check_memory, format_bytes
from neuspike.simulation.recording import SensorConfig, check_modalities

#: Bytes of one event held in memory: t (float64), x, y (uint16), p (int8), and one copy when joined.
EVENT_BYTES_HELD = 2 * (8 + 2 + 2 + 1)
#: Bytes of one event on disk (``events.h5``: the same four arrays, uncompressed).
EVENT_BYTES_STORED = 8 + 2 + 2 + 1
#: Bytes per noise draw of one sample interval while it is thinned (three uniforms, pixel index, rates).
NOISE_DRAW_BYTES = 80
#: Events per HDF5 chunk of a streamed ``events.h5`` (its datasets grow a chunk at a time).
EVENTS_H5_CHUNK = 1 << 16
#: HDF5's own structures in ``events.h5`` (groups, dataset headers, attributes), bounded from above.
EVENTS_H5_OVERHEAD = 16 * 1024


def events_h5_bytes(n_events: float, *, chunk_events: int | None = None) -> float:
    """Size of an ``events.h5`` of ``n_events`` events (upper bound), its datasets grown in ``chunk_events``."""
    n = float(n_events)
    if chunk_events:
        n = np.ceil(n / chunk_events) * chunk_events
    return EVENT_BYTES_STORED * n + EVENTS_H5_OVERHEAD


@dataclass(frozen=True)
class Budget:
    """Peak memory by part, the size of each file written and how many of it, in bytes (lower bounds)."""

    memory: dict[str, float] = field(default_factory=dict)
    files: dict[str, float] = field(default_factory=dict)
    counts: dict[str, float] = field(default_factory=dict)

    @property
    def memory_bytes(self) -> float:
        return float(sum(self.memory.values()))

    @property
    def disk_bytes(self) -> float:
        return float(sum(size * self.counts.get(name, 1) for name, size in self.files.items()))

    def describe_memory(self) -> str:
        """``"noise events 30 PiB, frames 49 MiB"``: the parts, largest first."""
        return _describe(self.memory)

    def describe_files(self) -> str:
        """``"spikes.dat 229 PiB, frames/*.png 3 x 97.7 KiB"``: the files, largest first."""
        totals = {name: size * self.counts.get(name, 1) for name, size in self.files.items()}
        return ", ".join(f"{name} {format_bytes(size)}" if self.counts.get(name, 1) == 1
                         else f"{name} {self.counts[name]:,.0f} x {format_bytes(size)}"
                         for name, size in sorted(self.files.items(), key=lambda kv: -totals[kv[0]]) if size)


def _describe(parts: dict[str, float]) -> str:
    return ", ".join(f"{k} {format_bytes(v)}" for k, v in sorted(parts.items(), key=lambda kv: -kv[1]) if v)


def noise_rate_hz(condition: Condition, scene_effects: Iterable[Effect] = ()) -> float:
    """Events per second per pixel of the declared noise stages (``shot_noise`` and ``leak``), nominal."""
    effects = merge_effects(NOISE_LEVELS[condition.noise], tuple(scene_effects), condition.effects)
    return float(sum(e.param("rate_hz") for e in effects if e.modality == EVENTS and e.name in ("shot_noise", "leak")))


def _events(width: int, height: int, *, condition: Condition, scene_effects: Iterable[Effect],
            duration_s: float, interval_s: float) -> tuple[float, float]:
    """(events over ``duration_s``, noise draws in one sample interval of ``interval_s``)."""
    rate = noise_rate_hz(condition, scene_effects) * width * height
    return rate * duration_s, rate * interval_s


def window_budget(width: int, height: int, *, sensor: SensorConfig, condition: Condition,
                  modalities: Iterable[str], history_s: float, scene_effects: Iterable[Effect] = ()) -> Budget:
    """What :func:`~neuspike.simulation.window.simulate_window` and a recording folder of it need."""
    mods = check_modalities(modalities)
    px = float(width) * float(height)
    hold = sensor.planes // condition.motion
    frame_dt = hold / sensor.plane_rate_hz
    n_hist = int(np.ceil(history_s / frame_dt - 1e-9)) if EVENTS in mods else 0
    n_frames = n_hist + condition.motion
    memory = {"frames": 4.0 * px * (n_frames + 1)}
    files = {"gt.npy": 4.0 * px, "gt.png": px}
    if SPIKES in mods:
        memory["spike planes"] = px * sensor.planes
        files["spikes.dat"] = px * sensor.planes / 8
    if EVENTS in mods:
        events, draws = _events(width, height, condition=condition, scene_effects=scene_effects,
                                duration_s=n_frames * frame_dt, interval_s=frame_dt)
        memory["noise events"] = EVENT_BYTES_HELD * events + NOISE_DRAW_BYTES * draws
        files["events.h5"] = events_h5_bytes(events)
    return Budget(memory, files)


def sequence_budget(width: int, height: int, *, sensor: SensorConfig, condition: Condition,
                    modalities: Iterable[str], planes: float, ground_truth_frames: float,
                    scene_effects: Iterable[Effect] = (), chunk_planes: int = 256) -> Budget:
    """What :func:`~neuspike.simulation.writing.write_sequence` needs for ``planes`` planes (chunked)."""
    mods = check_modalities(modalities)
    px = float(width) * float(height)
    chunk = min(float(planes), float(chunk_planes))
    memory = {"frames": 4.0 * px * chunk}
    files = {"frames/*.png": px}
    if SPIKES in mods:
        memory["spike planes"] = px * chunk
        files["spikes.dat"] = px * float(planes) / 8
    if EVENTS in mods:
        chunk_events, draws = _events(width, height, condition=condition, scene_effects=scene_effects,
                                      duration_s=chunk / sensor.plane_rate_hz, interval_s=1 / sensor.plane_rate_hz)
        events = chunk_events * float(planes) / chunk
        memory["noise events"] = EVENT_BYTES_HELD * chunk_events + NOISE_DRAW_BYTES * draws
        files["events.h5"] = events_h5_bytes(events, chunk_events=EVENTS_H5_CHUNK)
    return Budget(memory, files, {"frames/*.png": float(ground_truth_frames)})


def check_budget(budget: Budget, *, what: str, folder: str | os.PathLike | None = None, processes: int = 1) -> None:
    """Refuse (:class:`~neuspike.errors.InputError`, one line naming the sizes) what cannot fit.

    Memory for ``processes`` such jobs side by side; with ``folder``, the free disk there and the
    file size limit for each file.
    """
    detail = budget.describe_memory() + (f", times {processes} processes" if processes > 1 else "")
    check_memory(budget.memory_bytes * processes, what, detail)
    if folder is not None:
        check_disk(folder, budget.disk_bytes, what, budget.describe_files())
        for name, size in sorted(budget.files.items(), key=lambda kv: -kv[1]):
            check_file_size_limit(size, f"{name} of {what}")
