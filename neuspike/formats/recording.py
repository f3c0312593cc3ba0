"""Open a recording (files or a simulated folder) once: its metadata, and its data read by range.

:func:`open_recording` is the one opener of recordings: :func:`neuspike.formats.samples.stream_samples`
cuts samples from what it returns, and :func:`neuspike.formats.samples.load_sample` is one such cut. The
rules it applies, in order of precedence:

Sensor metadata
    A ``meta.json`` in the folder of the spike file (else of the event file) is a recording written
    by ``python -m neuspike.simulate``; its ``width``, ``height``, ``plane_rate_hz``, ``start_s``,
    ``gain``, ``threshold``, ``event_threshold`` and ``key_time_s`` are used (each checked: a plane
    rate must be a positive number, a size whole numbers >= 1). Explicit arguments override it where
    they are independent of the file (``gain``, ``plane_rate_hz``); a size given explicitly must
    agree with the one the file or ``meta.json`` states. Without ``meta.json``: the size comes from
    the ``.npz`` array or the event file; a bare ``.dat`` has no header and needs ``height`` and
    ``width``; the plane rate, start time and gain stored in an ``.npz`` are used; otherwise the
    plane rate is the Vidar's :data:`DEFAULT_PLANE_RATE_HZ`, the spike file starts at sensor time 0
    and the gain is unknown (``None``) unless given.

Key instant (:meth:`RecordingReader.key_instant`)
    ``plane=K`` (an index into the spike file; the instant is the centre of plane K) or ``at_s``
    (sensor time, in the event file's clock for events-only recordings). Default: the recording's
    ``key_time_s`` from ``meta.json``, else the middle plane of the spike file (plane ``T // 2``, at
    its centre), else the centre of the event recording (midway between its first and last event).

Events are read by range (:mod:`neuspike.formats.event_ranges`) with the checks of a whole read.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.utils.checks import check_int, check_nonnegative, check_positive, check_positive_int
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.streams import VIDAR_PLANE_RATE_HZ, EventStream, SpikeStream

__all__ = [
    "DEFAULT_PLANE_RATE_HZ", "DEFAULT_WINDOW_PLANES", "EVENT_HISTORY_S", "RecordingReader", "meta_float",
    "open_recording", "read_meta", "spike_file_extent", "window_bounds",
]

#: Spike planes per window when neither the caller nor a simulated recording says otherwise.
DEFAULT_WINDOW_PLANES = 256
#: Planes per second assumed for spike files that do not state it (the Vidar's).
DEFAULT_PLANE_RATE_HZ = VIDAR_PLANE_RATE_HZ
#: Seconds of event history before the window that a sample carries.
EVENT_HISTORY_S = 1.0
#: Suffixes of spike files.
SPIKE_SUFFIXES = (".dat", ".npz")
META_NAME = "meta.json"
#: Spike and event file names looked for in a simulated recording folder.
FOLDER_SPIKES = ("spikes.dat", "spikes.npz")
FOLDER_EVENTS = ("events.h5", "events.hdf5", "events.npz", "events.txt", "events.aedat4")


# --------------------------------------------------------------------------- metadata
def read_meta(folder: str | os.PathLike) -> dict[str, Any] | None:
    """The ``meta.json`` of a simulated recording folder, or ``None`` when there is none.

    Raises
    ------
    FormatError
        The file exists but is not a JSON object.
    """
    path = Path(folder) / META_NAME
    if not path.is_file():
        return None
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        raise FormatError(f"{path}: not a readable JSON file ({type(exc).__name__}: {exc})") from None
    if not isinstance(meta, dict):
        raise FormatError(f"{path}: expected a JSON object, got {type(meta).__name__}")
    return meta


def meta_float(meta: dict[str, Any] | None, key: str, *, positive: bool = False) -> float | None:
    """A finite number from ``meta.json`` (``None`` when absent; ``positive``: also > 0); anything
    else is a :class:`FormatError`."""
    if meta is None or meta.get(key) is None:
        return None
    value = meta[key]
    try:
        v = float(value) if not isinstance(value, (bool, str)) else math.nan
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v) or (positive and v <= 0):
        raise FormatError(f"meta.json: {key} must be a {'positive' if positive else 'finite'} number, got {value!r}")
    return v


def meta_int(meta: dict[str, Any], key: str) -> int:
    """A whole number >= 1 from ``meta.json``."""
    v = meta[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v) or v < 1:
        raise FormatError(f"meta.json: {key} must be a whole number >= 1, got {v!r}")
    return int(v)


def _resolve_size(height: int | None, width: int | None, meta: dict[str, Any] | None) -> tuple[int | None, int | None]:
    """The stated size: explicit arguments (both or neither), checked against meta.json's."""
    if (height is None) != (width is None):
        raise InputError("give both height and width, or neither")
    if height is not None:
        height = check_positive_int("height", height)
        width = check_positive_int("width", width)
    if meta is not None and meta.get("height") is not None and meta.get("width") is not None:
        mh, mw = meta_int(meta, "height"), meta_int(meta, "width")
        if height is not None and (height, width) != (mh, mw):
            raise InputError(f"size {width}x{height} given, but meta.json states {mw}x{mh}")
        return mh, mw
    return height, width


def window_bounds(key_plane: int, total_planes: int, window_planes: int) -> tuple[int, int]:
    """[start, stop) of a window of ``window_planes`` centred on ``key_plane`` inside the file
    (shifted, not shortened, at the file's ends; a file no longer than the window is used whole)."""
    if total_planes <= window_planes:
        return 0, total_planes
    start = key_plane - window_planes // 2
    start = min(max(start, 0), total_planes - window_planes)
    return start, start + window_planes


def _is_window_recording(meta: dict[str, Any] | None) -> bool:
    return (meta is not None and meta.get("mode", "window") == "window" and meta.get("planes") is not None
            and meta_int(meta, "planes") > 0)


def plane_of(time_s: float, start_s: float, rate_hz: float) -> int:
    """The plane (from ``start_s`` at ``rate_hz``) that holds the instant ``time_s``."""
    return int(math.floor((time_s - start_s) * rate_hz + 1e-9))


def spike_file_extent(
    path: Path, *, height: int | None, width: int | None, raw_width: int | None,
    rate_given: float | None, start_given: float | None,
) -> tuple[SpikeStream | None, int, float, float]:
    """A spike file's extent: ``(whole, planes, plane_rate_hz, start_s)``.

    A ``.dat`` has no header: its size must be given, its planes are counted from the file's length
    (``whole`` is ``None``: nothing is read). An ``.npz`` is read whole (``whole``); a size given
    must match it. ``rate_given`` / ``start_given`` override the file's (a ``.dat``: 20 kHz from 0 s).

    Raises
    ------
    InputError
        A ``.dat`` without its size, ``raw_width`` for an ``.npz``, a size that does not match.
    FormatError
        A file holding no planes.
    """
    if path.suffix.lower() == ".dat":
        if height is None:
            raise InputError(
                f"spike file {path}: a .dat file has no header; give its size (--height H --width W), "
                "e.g. --height 250 --width 400 for a Vidar"
            )
        from neuspike.formats.vidar_dat import count_planes

        whole = None
        total = int(count_planes(path, height=height, width=width, raw_width=raw_width))
        rate = rate_given if rate_given is not None else DEFAULT_PLANE_RATE_HZ
        start_s = start_given if start_given is not None else 0.0
    else:
        if raw_width is not None:
            raise InputError("raw_width applies to .dat files only")
        from neuspike.formats.spike_npz import read_spike_npz

        whole = read_spike_npz(path, plane_rate_hz=rate_given)
        rate = whole.plane_rate_hz
        start_s = start_given if start_given is not None else whole.start_s
        if height is not None and (whole.height, whole.width) != (height, width):
            raise InputError(
                f"spike file {path}: holds {whole.width}x{whole.height} planes, but the size given is {width}x{height}"
            )
        total = whole.num_planes
    if total < 1:
        raise FormatError(f"spike file {path}: holds no planes")
    return whole, total, rate, start_s


# --------------------------------------------------------------------------- the opened recording
@dataclass
class RecordingReader:
    """A recording opened once: its metadata, and its data read by range on demand.

    Attributes
    ----------
    height, width : int
        Sensor size (H, W).
    plane_rate_hz : float
        Spike planes per second (the Vidar's when the recording does not say).
    start_s : float
        Sensor time of the start of the spike file's plane 0.
    num_planes : int
        Planes in the spike file (0 without spikes).
    gain, gain_source : float or None, str
        Expected spikes per plane per unit radiance and where it came from (``"given"``,
        ``"meta.json"``, ``"file"`` or ``"unknown"``).
    threshold, event_threshold : float or None
        Spike threshold and nominal contrast threshold, when known.
    dark_rate : float or None
        The spike sensor's dark rate (spikes per plane in darkness, mean over pixels), when known
        (``meta.json``, else the ``.npz``).
    meta : dict or None
        The ``meta.json`` of a simulated recording folder.
    folder : Path
        The folder of the spike file (else of the event file).
    """

    height: int
    width: int
    plane_rate_hz: float
    start_s: float
    num_planes: int
    gain: float | None
    gain_source: str
    threshold: float | None
    event_threshold: float | None
    meta: dict[str, Any] | None
    folder: Path
    dark_rate: float | None = None
    spikes_path: Path | None = None
    events_path: Path | None = None
    raw_width: int | None = None
    _spike_npz: SpikeStream | None = field(default=None, repr=False)
    _events: Any = field(default=None, repr=False)

    @property
    def modalities(self) -> frozenset[str]:
        """The inputs present: a subset of {"spikes", "events"}."""
        return frozenset(n for n, p in (("spikes", self.spikes_path), ("events", self.events_path)) if p is not None)

    @property
    def event_count(self) -> int:
        return 0 if self._events is None else int(self._events.count)

    @property
    def key_time_s(self) -> float | None:
        """The instant ``meta.json`` names (the one its ground truth shows), or ``None``."""
        return meta_float(self.meta, "key_time_s")

    def event_span_s(self) -> tuple[float, float]:
        """First and last event times, seconds.

        Raises
        ------
        InputError
            The event file holds no events.
        FormatError
            The last event comes before the first (the timestamps are not sorted).
        """
        if self.event_count == 0:
            raise InputError(f"event file {self.events_path}: holds no events")
        first, last = self.event_time(0), self.event_time(self.event_count - 1)
        if last < first:
            raise FormatError(f"event file {self.events_path}: timestamps are not sorted (the first event is at "
                              f"{first!r} s, the last at {last!r} s)")
        return first, last

    def span_s(self) -> tuple[float, float]:
        """The recording's time span in sensor seconds: the spike file's, else first to last event."""
        if self.spikes_path is not None:
            return self.start_s, self.start_s + self.num_planes / self.plane_rate_hz
        return self.event_span_s()

    def default_window_planes(self) -> int:
        """The file's length for a simulated window recording, else :data:`DEFAULT_WINDOW_PLANES`."""
        if _is_window_recording(self.meta):
            return self.num_planes if self.spikes_path is not None else meta_int(self.meta, "planes")  # type: ignore[arg-type]
        return DEFAULT_WINDOW_PLANES

    def key_instant(self, *, plane: int | None = None, at_s: float | None = None) -> float:
        """The key instant of a single cut, by the precedence of the module docstring.

        Raises
        ------
        InputError
            Both ``plane`` and ``at_s``, a plane or time outside the recording, a plane index for an
            event recording without a spike clock, an empty event recording without ``at_s``.
        """
        if plane is not None and at_s is not None:
            raise InputError("give the key instant as a plane index or as a time, not both")
        if plane is not None:
            plane = check_int("plane", plane, minimum=0, what="a plane index")
        if at_s is not None:
            at_s = float(at_s)
            if not math.isfinite(at_s):
                raise InputError(f"at_s: expected a finite time in seconds, got {at_s!r}")
        start, rate, meta_key = self.start_s, self.plane_rate_hz, self.key_time_s
        if self.spikes_path is not None:
            total, end = self.num_planes, self.start_s + self.num_planes / rate
            if plane is not None:
                if plane >= total:
                    raise InputError(f"plane {plane} is outside the spike file's {total} planes (0..{total - 1})")
                return start + (plane + 0.5) / rate
            if at_s is not None:
                if not start <= at_s <= end:
                    raise InputError(f"time {at_s} s is outside the spike recording [{start}, {end}] s")
                return at_s
            if meta_key is not None and start <= meta_key <= end:
                return meta_key
            return start + (total // 2 + 0.5) / rate
        if plane is not None:
            if self.meta is None:
                raise InputError("a plane index needs a spike clock; for an event recording give the key instant "
                                 "with --at SECONDS (sensor time)")
            if _is_window_recording(self.meta) and plane >= meta_int(self.meta, "planes"):
                raise InputError(f"plane {plane} is outside the recording's {meta_int(self.meta, 'planes')} planes")
            return start + (plane + 0.5) / rate
        if at_s is not None:
            if self.meta is None and self.event_count:
                first, last = self.event_span_s()
                if not first <= at_s <= last:
                    raise InputError(f"time {at_s} s is outside the event recording [{first}, {last}] s")
            return at_s
        if meta_key is not None:
            return meta_key
        if self.event_count == 0:
            raise InputError("the event file holds no events; give the key instant with --at SECONDS")
        first, last = self.event_span_s()
        return 0.5 * (first + last)

    def read_planes(self, start: int, stop: int) -> np.ndarray:
        """Planes ``[start, stop)`` of the spike file, bool (stop - start, H, W)."""
        if self.spikes_path is None:
            raise InputError("the recording has no spikes")
        if not 0 <= start <= stop <= self.num_planes:
            raise InputError(f"plane range [{start}, {stop}) is outside the file's {self.num_planes} planes")
        if self._spike_npz is not None:
            return self._spike_npz.planes[start:stop]
        from neuspike.formats.vidar_dat import read_dat

        return read_dat(self.spikes_path, height=self.height, width=self.width, start=start, stop=stop,
                        raw_width=self.raw_width)

    def event_index(self, t_s: float) -> int:
        """Index of the first event at or after ``t_s``."""
        return self._events.index(t_s)

    def event_time(self, i: int) -> float:
        """Timestamp of event ``i``, seconds."""
        return self._events.time_of(i)

    def read_events(self, i0: int, i1: int) -> EventStream:
        """Events ``[i0, i1)`` of the event file."""
        if self._events is None:
            raise InputError("the recording has no events")
        return self._events.read(i0, i1)

    def close(self) -> None:
        if self._events is not None:
            self._events.close()

    def __enter__(self) -> "RecordingReader":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _folder_files(folder: Path) -> tuple[Path | None, Path | None]:
    meta = read_meta(folder) or {}
    files = meta.get("files") or {}
    spikes = events = None
    if isinstance(files, dict):
        if files.get("spikes"):
            spikes = folder / str(files["spikes"])
        if files.get("events"):
            events = folder / str(files["events"])
    spikes = spikes or next((folder / n for n in FOLDER_SPIKES if (folder / n).is_file()), None)
    events = events or next((folder / n for n in FOLDER_EVENTS if (folder / n).is_file()), None)
    if spikes is None and events is None:
        raise SourceError(f"{folder}: no spike file ({', '.join(FOLDER_SPIKES)}) or event file ({', '.join(FOLDER_EVENTS)})")
    return spikes, events


def _is_event_npz(path: Path) -> bool:
    """An ``.npz`` holding events (``t_s``, ``x``, ``y``, ``p``) rather than spike planes."""
    if path.suffix.lower() != ".npz":
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            return "t_s" in z.files and "planes" not in z.files and "spk" not in z.files
    except (OSError, ValueError):
        return False


def open_recording(
    path: str | os.PathLike | None = None,
    *,
    spikes: str | os.PathLike | None = None,
    events: str | os.PathLike | None = None,
    height: int | None = None,
    width: int | None = None,
    raw_width: int | None = None,
    plane_rate_hz: float | None = None,
    gain: float | None = None,
    dark_rate: float | None = None,
) -> RecordingReader:
    """Open a recording (metadata only; data is read later, by range), by the rules of the module docstring.

    Parameters
    ----------
    path : path or None
        A simulated recording folder (its ``meta.json`` names ``spikes.dat`` / ``events.h5``),
        or a single spike (``.dat``, ``.npz``) or event file.
    spikes, events : path or None
        The spike file and the event file, instead of (not with) ``path``.
    height, width : int or None
        Sensor size (H, W); required for a bare ``.dat``; must agree with the file's otherwise.
    raw_width : int or None
        Stored width of a ``.dat`` with extra columns (416-wide captures); the extra columns are dropped.
    plane_rate_hz : float or None
        Planes per second; overrides ``meta.json`` and the file; default :data:`DEFAULT_PLANE_RATE_HZ`.
    gain : float or None
        Expected spikes per plane per unit radiance; overrides the recording's.
    dark_rate : float or None
        The spike sensor's dark rate (spikes per plane in darkness, mean over pixels, from a capped
        calibration); overrides the recording's.

    Returns
    -------
    RecordingReader
        Use it as a context manager (HDF5 event files stay open while it is).

    Raises
    ------
    InputError, SourceError, FormatError
        Conflicting arguments, a missing or unreadable file, malformed metadata.
    """
    if path is not None:
        if spikes is not None or events is not None:
            raise InputError("give a recording path, or --spikes/--events, not both")
        p = Path(path)
        if p.is_dir():
            spikes, events = _folder_files(p)
        elif not p.exists():
            raise SourceError(f"recording {p}: no such file or folder")
        elif p.suffix.lower() in SPIKE_SUFFIXES and not _is_event_npz(p):
            spikes = p
        else:
            events = p
    if spikes is None and events is None:
        raise InputError("give a recording folder, a spike file, an event file or both")
    sp = Path(spikes) if spikes is not None else None
    ev = Path(events) if events is not None else None
    for kind, f in (("spike", sp), ("event", ev)):
        if f is not None and f.is_dir():
            raise SourceError(f"{kind} file {f}: is a folder, not a file (a simulated recording's folder is "
                              f"given as the recording itself, without --{kind}s)")
        if f is not None and not f.is_file():
            raise SourceError(f"{kind} file {f}: no such file")
    if sp is not None and sp.suffix.lower() not in SPIKE_SUFFIXES:
        raise InputError(f"spike file {sp}: expected one of {', '.join(SPIKE_SUFFIXES)}, got {sp.suffix or 'no suffix'!r}")
    if gain is not None:
        gain = check_positive("gain", gain)
        if sp is None:
            raise InputError("a gain applies to spike recordings; no spike file was given")
    if dark_rate is not None:
        dark_rate = check_nonnegative("dark_rate", dark_rate)
        if sp is None:
            raise InputError("a dark rate applies to spike recordings; no spike file was given")

    folder = (sp or ev).parent  # type: ignore[union-attr]
    meta = read_meta(folder)
    height, width = _resolve_size(height, width, meta)
    rate_given = (check_positive("plane_rate_hz", plane_rate_hz) if plane_rate_hz is not None
                  else meta_float(meta, "plane_rate_hz", positive=True))
    start_given = meta_float(meta, "start_s")
    rate = rate_given if rate_given is not None else DEFAULT_PLANE_RATE_HZ
    start_s = start_given if start_given is not None else 0.0
    num_planes = 0
    file_gain = file_threshold = file_dark = None
    npz = None
    if sp is not None:
        npz, num_planes, rate, start_s = spike_file_extent(sp, height=height, width=width, raw_width=raw_width,
                                                           rate_given=rate_given, start_given=start_given)
        if npz is not None:
            height, width = npz.height, npz.width
            file_gain, file_threshold, file_dark = npz.gain, npz.threshold, npz.dark_rate
    source = None
    if ev is not None:
        from neuspike.formats.event_ranges import open_event_source

        source = open_event_source(ev, width, height)
        if height is not None and (source.height, source.width) != (height, width):
            source.close()
            raise InputError(f"event file {ev}: sensor size {source.width}x{source.height} does not match {width}x{height}")
        height, width = source.height, source.width
    meta_gain = meta_float(meta, "gain")
    if sp is None:
        used_gain, gain_source = None, "unknown"
    elif gain is not None:
        used_gain, gain_source = gain, "given"
    elif meta_gain is not None:
        used_gain, gain_source = meta_gain, "meta.json"
    elif file_gain is not None:
        used_gain, gain_source = file_gain, "file"
    else:
        used_gain, gain_source = None, "unknown"
    threshold = meta_float(meta, "threshold")
    meta_dark = meta_float(meta, "dark_rate") if sp is not None else None
    if meta_dark is not None and meta_dark < 0:
        raise FormatError(f"meta.json: dark_rate must be a number >= 0, got {meta_dark!r}")
    if dark_rate is None:
        dark_rate = meta_dark if meta_dark is not None else file_dark
    return RecordingReader(
        height=int(height), width=int(width), plane_rate_hz=float(rate), start_s=float(start_s),  # type: ignore[arg-type]
        num_planes=num_planes, gain=used_gain, gain_source=gain_source,
        threshold=threshold if threshold is not None else file_threshold,
        event_threshold=meta_float(meta, "event_threshold"), meta=meta, folder=folder,
        dark_rate=dark_rate,
        spikes_path=sp, events_path=ev, raw_width=raw_width, _spike_npz=npz, _events=source,
    )
