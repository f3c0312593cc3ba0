"""The on-disk cache of simulated recordings (used by the sweeps and by training datasets).

A cell's recording is a deterministic function of the scene spec, the condition (with every
declared stage), the sensor configuration, the seed, the simulated modalities, the event history
and the simulator's version (:data:`neuspike.simulate.SIMULATOR_VERSION`). :func:`recording_key`
hashes exactly these, so a cached recording is reused whenever they match (for example when a
method is added to a sweep) and never when any of them changes.

File format (``<key>.npz``, written atomically: a temporary file in the same folder, then
``os.replace``; loaded with ``allow_pickle=False``)

``format``            the string :data:`CACHE_FORMAT` as uint8 bytes
``ground_truth``      float32 (H, W) radiance at the key instant
``times``             float64 [key_time_s, window_start_s, window_end_s]
``meta_json``         the recording's metadata as UTF-8 JSON (uint8)
``spike_bits``        ``np.packbits(planes, axis=-1, bitorder="little")``, uint8 (T, H, ceil(W / 8))
``spike_shape``       int64 [T, H, W]
``spike_json``        plane_rate_hz, start_s, gain, threshold and the stream's meta (JSON)
``event_t``, ``event_x``, ``event_y``, ``event_p``  the event arrays in the stream's dtypes
``event_json``        width, height and the stream's meta (JSON)

Metadata passes through JSON, so tuples come back as lists and NumPy scalars as Python numbers;
the arrays come back bit for bit.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from neuspike.atomic import write_with
from neuspike.conditions import Condition
from neuspike.errors import FormatError
from neuspike.jsonio import canonical_json, stable_hash
from neuspike.scenes import SceneSpec
from neuspike.simulate import SIMULATOR_VERSION, Recording, SensorConfig
from neuspike.streams import EventStream, SpikeStream

CACHE_FORMAT = "neuspike-recording-cache/1"


# ----------------------------------------------------------------------------------------------
# Keys
# ----------------------------------------------------------------------------------------------

def recording_key(
    *,
    scene_spec: SceneSpec,
    condition: Condition,
    sensor: SensorConfig,
    seed: int,
    modalities: Iterable[str],
    history_s: float,
) -> str:
    """The cache key of a simulated window: a hash of everything that determines its bytes.

    Parameters
    ----------
    scene_spec : SceneSpec
    condition : Condition
    sensor : SensorConfig
    seed : int
    modalities : iterable of {"spikes", "events"}
    history_s : float
        Seconds of event history before the window (0 when no recurrent method needs it).

    Returns
    -------
    str
        40 hex characters.
    """
    return stable_hash({
        "format": CACHE_FORMAT,
        "simulator_version": SIMULATOR_VERSION,
        "scene": scene_spec.as_dict(),
        "condition": condition.as_dict(),
        "stages_declared": [e.as_dict() for e in condition.all_effects()],
        "sensor": sensor.as_dict(),
        "seed": int(seed),
        "modalities": sorted(modalities),
        "history_s": float(history_s),
    }, length=40)


# ----------------------------------------------------------------------------------------------
# Saving and loading recordings
# ----------------------------------------------------------------------------------------------

def _json_bytes(obj: Any) -> np.ndarray:
    return np.frombuffer(canonical_json(obj).encode("utf-8"), dtype=np.uint8)


def _from_json_bytes(array: np.ndarray) -> Any:
    return json.loads(array.tobytes().decode("utf-8"))


def save_recording(path: str | os.PathLike, recording: Recording) -> Path:
    """Write a :class:`~neuspike.simulate.Recording` to ``path`` (npz, atomically)."""
    arrays: dict[str, np.ndarray] = {
        "format": np.frombuffer(CACHE_FORMAT.encode(), dtype=np.uint8),
        "ground_truth": np.asarray(recording.ground_truth, dtype=np.float32),
        "times": np.array([recording.key_time_s, recording.window_start_s, recording.window_end_s], np.float64),
        "meta_json": _json_bytes(recording.meta),
    }
    if recording.spikes is not None:
        s = recording.spikes
        arrays["spike_bits"] = np.packbits(s.planes, axis=-1, bitorder="little")
        arrays["spike_shape"] = np.array(s.planes.shape, dtype=np.int64)
        arrays["spike_json"] = _json_bytes({
            "plane_rate_hz": s.plane_rate_hz, "start_s": s.start_s, "gain": s.gain,
            "threshold": s.threshold, "meta": s.meta,
        })
    if recording.events is not None:
        e = recording.events
        arrays.update(event_t=e.t_s, event_x=e.x, event_y=e.y, event_p=e.p)
        arrays["event_json"] = _json_bytes({"width": e.width, "height": e.height, "meta": e.meta})
    return write_with(path, lambda f: np.savez(f, **arrays))


def load_recording(path: str | os.PathLike) -> Recording:
    """Read a recording written by :func:`save_recording`.

    Raises
    ------
    FormatError
        The file is not a valid recording cache file of this format.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as exc:  # OSError, ValueError, zipfile.BadZipFile, EOFError, ...
        raise FormatError(f"{path}: not a readable recording cache file ({type(exc).__name__}: {exc})") from exc
    fmt = data.get("format")
    if fmt is None or fmt.tobytes().decode("utf-8", "replace") != CACHE_FORMAT:
        raise FormatError(f"{path}: expected cache format {CACHE_FORMAT!r}")
    try:
        return _recording_from(data, path)
    except (KeyError, ValueError) as exc:  # includes InputError from the streams' validation
        if isinstance(exc, FormatError):
            raise
        raise FormatError(f"{path}: invalid recording cache file ({type(exc).__name__}: {exc})") from exc


def _recording_from(data: dict[str, np.ndarray], path: Path) -> Recording:
    spikes = events = None
    if "spike_bits" in data:
        t, h, w = (int(v) for v in data["spike_shape"])
        planes = np.unpackbits(data["spike_bits"], axis=-1, count=w, bitorder="little").astype(bool)
        if planes.shape != (t, h, w):
            raise FormatError(f"{path}: spike planes unpack to {planes.shape}, expected {(t, h, w)}")
        info = _from_json_bytes(data["spike_json"])
        spikes = SpikeStream(planes, plane_rate_hz=info["plane_rate_hz"], start_s=info["start_s"],
                             gain=info["gain"], threshold=info["threshold"], meta=info["meta"])
    if "event_t" in data:
        info = _from_json_bytes(data["event_json"])
        events = EventStream(data["event_t"], data["event_x"], data["event_y"], data["event_p"],
                             info["width"], info["height"], info["meta"])
    key_time_s, start_s, end_s = (float(v) for v in data["times"])
    return Recording(spikes=spikes, events=events, ground_truth=data["ground_truth"],
                     key_time_s=key_time_s, window_start_s=start_s, window_end_s=end_s,
                     meta=_from_json_bytes(data["meta_json"]))


class RecordingCache:
    """A folder of cached recordings, ``<folder>/<key>.npz``; ``folder=None`` disables caching.

    Several processes may share a folder: each file is written atomically, and two processes that
    simulate the same key write identical content.
    """

    def __init__(self, folder: str | os.PathLike | None) -> None:
        self.folder = Path(folder) if folder is not None else None

    def path(self, key: str) -> Path | None:
        return self.folder / f"{key}.npz" if self.folder is not None else None

    def get_or_simulate(self, key: str, simulate: Callable[[], Recording]) -> tuple[Recording, bool]:
        """The recording for ``key``: from the cache when present, else ``simulate()`` (then stored).

        Returns
        -------
        (Recording, bool)
            The recording and whether it came from the cache. An unreadable cache file is
            simulated again and overwritten.
        """
        path = self.path(key)
        if path is not None and path.exists():
            try:
                return load_recording(path), True
            except FormatError:
                pass  # replaced below
        recording = simulate()
        if path is not None:
            save_recording(path, recording)
        return recording, False
