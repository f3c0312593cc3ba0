"""The on-disk cache of simulated windows (used by the sweeps and by training datasets).

A window is kept as one file per modality, so that what is cached serves any request for a subset
of it: a sweep that adds an event-only method after spike-and-event ones, or a spike-only method
after them, simulates nothing again.

Keys (:func:`part_key`)
    The spike part of a window is a deterministic function of the scene spec, the condition (with
    every declared stage), the sensor configuration, the seed and the simulator's version
    (:data:`~neuspike.simulation.recording.SIMULATOR_VERSION`); the event part also of the event
    history simulated before the window (``history_s``), which changes the event camera's state.
    Each camera draws from its own generator, so a part is the same whether or not the other
    modality was simulated with it. Which methods run never enters a key. A request for events with
    another history than the cached one is a miss for the event part only.

File format (``<key>.npz``, written atomically: a temporary file in the same folder, then
``os.replace``; loaded with ``allow_pickle=False``)

``format``            the string :data:`CACHE_FORMAT` as uint8 bytes
``ground_truth``      float32 (H, W) radiance at the key instant
``times``             float64 [key_time_s, window_start_s, window_end_s]
``meta_json``         the recording's metadata as UTF-8 JSON (uint8)
``spike_bits``        ``np.packbits(planes, axis=-1, bitorder="little")``, uint8 (T, H, ceil(W / 8))
``spike_shape``       int64 [T, H, W]
``spike_json``        plane_rate_hz, start_s, gain, threshold, dark_rate and the stream's meta (JSON)
``event_t``, ``event_x``, ``event_y``, ``event_p``  the event arrays in the stream's dtypes
``event_json``        width, height and the stream's meta (JSON)
``static_spikes``, ``static_events``  bool (H, W): the static region each camera saw (optional)

Metadata passes through JSON, so tuples come back as lists and NumPy scalars as Python numbers;
the arrays come back bit for bit.

Files of the earlier layout (one file per request, keyed by the modalities and the history, without
the static regions) are still read when a request matches one exactly and none of its parts is
cached; their recordings carry no static region (:meth:`Recording.static_region` is None), which
the caller computes by rendering (:func:`neuspike.simulation.window.static_region`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from neuspike.utils.atomic import write_with
from neuspike.conditions import EVENTS, SPIKES, Condition
from neuspike.errors import FormatError
from neuspike.utils.jsonio import canonical_json, stable_hash
from neuspike.scenes import SceneSpec
from neuspike.simulation.recording import MODALITIES, SIMULATOR_VERSION, Recording, SensorConfig, check_modalities
from neuspike.streams import EventStream, SpikeStream

CACHE_FORMAT = "neuspike-recording-cache/2"  # 2: the spike stream's dark rate is stored; files of 1 are simulated again
#: Metadata of one modality only: kept from that modality's part when parts are joined.
_MODALITY_META = {SPIKES: ("spike_count", "dark_rate"), EVENTS: ("event_count", "event_count_window", "history_s")}


# ----------------------------------------------------------------------------------------------
# Keys
# ----------------------------------------------------------------------------------------------

def _cell_identity(scene_spec: SceneSpec, condition: Condition, sensor: SensorConfig, seed: int) -> dict[str, Any]:
    return {
        "format": CACHE_FORMAT,
        "simulator_version": SIMULATOR_VERSION,
        "scene": scene_spec.as_dict(),
        "condition": condition.as_dict(),
        "stages_declared": [e.as_dict() for e in condition.all_effects()],
        "sensor": sensor.as_dict(),
        "seed": int(seed),
    }


def part_key(
    *,
    scene_spec: SceneSpec,
    condition: Condition,
    sensor: SensorConfig,
    seed: int,
    modality: str,
    history_s: float,
) -> str:
    """The cache key of one modality of a simulated window: a hash of everything that determines its bytes.

    Parameters
    ----------
    scene_spec : SceneSpec
    condition : Condition
    sensor : SensorConfig
    seed : int
    modality : {"spikes", "events"}
    history_s : float
        Seconds of event history before the window; part of the key of the events only.

    Returns
    -------
    str
        40 hex characters.
    """
    check_modalities([modality])
    identity = {**_cell_identity(scene_spec, condition, sensor, seed), "layout": "part", "modality": modality}
    if modality == EVENTS:
        identity["history_s"] = float(history_s)
    return stable_hash(identity, length=40)


def _request_key(*, scene_spec: SceneSpec, condition: Condition, sensor: SensorConfig, seed: int,
                 modalities: Iterable[str], history_s: float) -> str:
    """The key of the earlier layout: one file per (modalities, history) request."""
    return stable_hash({**_cell_identity(scene_spec, condition, sensor, seed),
                        "modalities": sorted(modalities), "history_s": float(history_s)}, length=40)


# ----------------------------------------------------------------------------------------------
# Saving and loading recordings
# ----------------------------------------------------------------------------------------------

def _json_bytes(obj: Any) -> np.ndarray:
    return np.frombuffer(canonical_json(obj).encode("utf-8"), dtype=np.uint8)


def _from_json_bytes(array: np.ndarray) -> Any:
    return json.loads(array.tobytes().decode("utf-8"))


def save_recording(path: str | os.PathLike, recording: Recording) -> Path:
    """Write a :class:`~neuspike.simulation.recording.Recording` to ``path`` (npz, atomically)."""
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
            "threshold": s.threshold, "dark_rate": s.dark_rate, "meta": s.meta,
        })
    if recording.events is not None:
        e = recording.events
        arrays.update(event_t=e.t_s, event_x=e.x, event_y=e.y, event_p=e.p)
        arrays["event_json"] = _json_bytes({"width": e.width, "height": e.height, "meta": e.meta})
    for modality, mask in recording.static_masks.items():
        arrays[f"static_{modality}"] = np.asarray(mask, dtype=bool)
    return write_with(path, lambda f: np.savez(f, **arrays))


def load_recording(path: str | os.PathLike) -> Recording:
    """Read a recording written by :func:`save_recording`.

    Raises
    ------
    FormatError
        The file is not a valid recording cache file of this format.
    """
    path = Path(path)
    if path.exists() and not path.is_file():  # a FIFO would block the read forever, a folder cannot be one
        raise FormatError(f"{path}: not a regular file, so not a recording cache file")
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
    except (KeyError, ValueError, TypeError, AttributeError, IndexError) as exc:  # InputError from the streams'
        # validation, and metadata of the wrong shape (a list where an object belongs)
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
                             gain=info["gain"], threshold=info["threshold"], dark_rate=info.get("dark_rate"),
                             meta=info["meta"])
    if "event_t" in data:
        info = _from_json_bytes(data["event_json"])
        events = EventStream(data["event_t"], data["event_x"], data["event_y"], data["event_p"],
                             info["width"], info["height"], info["meta"])
    ground_truth = data["ground_truth"]
    static_masks = {}
    for modality in MODALITIES:
        mask = data.get(f"static_{modality}")
        if mask is not None:
            if mask.dtype != np.bool_ or mask.shape != ground_truth.shape:
                raise FormatError(f"{path}: static_{modality} is {mask.dtype} {mask.shape}, "
                                  f"expected bool {ground_truth.shape}")
            static_masks[modality] = mask
    key_time_s, start_s, end_s = (float(v) for v in data["times"])
    return Recording(spikes=spikes, events=events, ground_truth=ground_truth,
                     key_time_s=key_time_s, window_start_s=start_s, window_end_s=end_s,
                     meta=_from_json_bytes(data["meta_json"]), static_masks=static_masks)


# ----------------------------------------------------------------------------------------------
# Parts: one modality of a window
# ----------------------------------------------------------------------------------------------

def _stages_of(meta: Mapping[str, Any], modalities: Iterable[str]) -> list[dict[str, Any]]:
    return [s for s in meta.get("stages", []) if s.get("modality") in set(modalities)]


def _part(recording: Recording, modality: str) -> Recording:
    """The ``modality`` part of ``recording``: its stream, static region, stages and counts alone."""
    other = EVENTS if modality == SPIKES else SPIKES
    meta = {k: v for k, v in recording.meta.items() if k not in _MODALITY_META[other]}
    meta["stages"] = _stages_of(recording.meta, ("scene", modality))
    if modality == SPIKES:
        meta["history_s"] = 0.0  # the spike window has no history
    return Recording(
        spikes=recording.spikes if modality == SPIKES else None,
        events=recording.events if modality == EVENTS else None,
        ground_truth=recording.ground_truth, key_time_s=recording.key_time_s,
        window_start_s=recording.window_start_s, window_end_s=recording.window_end_s, meta=meta,
        static_masks={m: v for m, v in recording.static_masks.items() if m == modality},
    )


def _join(parts: Mapping[str, Recording]) -> Recording:
    """One recording from the parts of one window (``{modality: part}``), as one simulation gives it."""
    if len(parts) == 1:
        return next(iter(parts.values()))
    spikes, events = parts[SPIKES], parts[EVENTS]
    meta = dict(events.meta)  # the event part's render covers the history too
    meta.update({k: spikes.meta[k] for k in _MODALITY_META[SPIKES] if k in spikes.meta})
    meta["stages"] = (_stages_of(events.meta, ("scene",)) + _stages_of(spikes.meta, (SPIKES,))
                      + _stages_of(events.meta, (EVENTS,)))
    return Recording(
        spikes=spikes.spikes, events=events.events, ground_truth=events.ground_truth,
        key_time_s=events.key_time_s, window_start_s=events.window_start_s, window_end_s=events.window_end_s,
        meta=meta, static_masks={**spikes.static_masks, **events.static_masks},
    )


class RecordingCache:
    """A folder of cached windows, ``<folder>/<key>.npz``, one file per modality; ``folder=None`` disables caching.

    Several processes may share a folder: each file is written atomically, and two processes that
    simulate the same key write identical content.
    """

    def __init__(self, folder: str | os.PathLike | None) -> None:
        self.folder = Path(folder) if folder is not None else None

    def path(self, key: str) -> Path | None:
        return self.folder / f"{key}.npz" if self.folder is not None else None

    def _load(self, key: str, modality: str | None = None) -> Recording | None:
        """The recording stored under ``key`` (holding ``modality`` when given), or None."""
        path = self.path(key)
        if path is None or not path.exists():
            return None
        if not path.is_file():  # a FIFO or a folder where a cache file belongs: simulated again, replaced
            if path.is_dir():
                raise FormatError(f"{path}: a folder where a recording cache file belongs; remove it")
            return None
        try:
            recording = load_recording(path)
        except FormatError:
            return None  # simulated again and replaced
        return None if modality is not None and getattr(recording, modality) is None else recording

    def get_or_simulate(
        self,
        *,
        scene_spec: SceneSpec,
        condition: Condition,
        sensor: SensorConfig,
        seed: int,
        modalities: Iterable[str],
        history_s: float,
        simulate: Callable[[frozenset[str]], Recording],
    ) -> tuple[Recording, frozenset[str]]:
        """The window for these arguments: its cached parts, and ``simulate(missing)`` for the others.

        ``simulate(modalities)`` must return the window of those modalities with ``history_s`` of
        event history (the parts it gives are stored). An unreadable cache file is simulated again
        and overwritten.

        Returns
        -------
        (Recording, frozenset of str)
            The recording of ``modalities`` and the modalities simulated now (empty: all from the cache).
        """
        mods = check_modalities(modalities)
        ident = dict(scene_spec=scene_spec, condition=condition, sensor=sensor, seed=seed)
        keys = {m: part_key(**ident, modality=m, history_s=history_s) for m in MODALITIES if m in mods}
        parts = {m: self._load(k, m) for m, k in keys.items()}
        missing = frozenset(m for m, part in parts.items() if part is None)
        if missing == mods:
            earlier = self._load(_request_key(**ident, modalities=mods, history_s=history_s))
            if earlier is not None:
                return earlier, frozenset()
        if missing:
            fresh = simulate(missing)
            for m in missing:
                parts[m] = _part(fresh, m)
                if self.folder is not None:
                    save_recording(self.path(keys[m]), parts[m])
            if missing == mods:
                return fresh, missing
        return _join(parts), missing
