"""Stream a recording through a method: one image per output instant, memory bounded by the window.

:func:`open_recording` opens a spike file (Vidar ``.dat``, ``.npz``), an event file (every format
:func:`neuspike.formats.events_io.read_events` reads) or both, or a simulated recording folder, and
reads its metadata only. :func:`stream_samples` then cuts, for each output instant, the same
:class:`~neuspike.sample.Sample` that :func:`neuspike.recordings.load_sample` would cut for that
instant (``at_s=t``: the same spike window, shifted at the file's ends, the same event window and
event history, gain, threshold and plane rate), reading as it goes:

* spike planes by plane range (a ``.dat`` is never read whole; an ``.npz`` is compressed and is
  read once, whole);
* events by time range (HDF5 files, in the common and the PKU-Vidar-DVS layouts, are searched by
  bisection and sliced; text, ``.npz`` and AEDAT4 files have no index and are read once, whole).

Neighbouring windows share their data: planes and events already in memory are kept while they
are still inside the window (or the event history) and only the new ones are read, so each plane
of a ``.dat`` is read and unpacked once however high the frame rate. What stays in memory is the
spike window (``window_planes`` planes) and the events of the window plus ``event_history_s``.

:func:`reconstruct_video` yields ``(time_s, image)`` for one method. Stateless methods give exactly
the images of single-frame reconstructions at the same instants (the samples are equal). Recurrent
methods are reset once, at the first frame (which warms up on the history as a single-frame call
does); later frames go through :meth:`~neuspike.methods.Method.reconstruct_next` where a method
offers it, which continues the recurrent state with only the input after the previous frame.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from neuspike.checks import check_nonnegative, check_positive, check_positive_int
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.recordings import (
    DEFAULT_PLANE_RATE_HZ,
    DEFAULT_WINDOW_PLANES,
    EVENT_HISTORY_S,
    SPIKE_SUFFIXES,
    meta_float,
    read_meta,
    spike_file_extent,
    window_bounds,
)
from neuspike.sample import Sample
from neuspike.streams import P_DTYPE, T_DTYPE, XY_DTYPE, EventStream, SpikeStream

__all__ = [
    "VideoRecording",
    "open_recording",
    "frame_times",
    "check_fps",
    "stream_samples",
    "stream_methods",
    "reconstruct_video",
]

#: Spike and event file names looked for in a simulated recording folder.
FOLDER_SPIKES = ("spikes.dat", "spikes.npz")
#: Events read from the file at a time (about 0.4 MB).
EVENT_BLOCK = 1 << 15
FOLDER_EVENTS = ("events.h5", "events.hdf5", "events.npz", "events.txt", "events.aedat4")


# --------------------------------------------------------------------------- event sources
class _WholeEvents:
    """An event file without an index: read once, sliced in memory."""

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        from neuspike.formats.events_io import read_events

        kwargs = {} if width is None else {"width": width, "height": height}
        self.stream = read_events(path, **kwargs)
        self.width, self.height = self.stream.width, self.stream.height
        self.count = len(self.stream)

    def time_of(self, i: int) -> float:
        return float(self.stream.t_s[i])

    def index(self, t_s: float) -> int:
        return int(np.searchsorted(self.stream.t_s, t_s, side="left"))

    def read(self, i0: int, i1: int) -> EventStream:
        s = self.stream
        return EventStream.trusted(s.t_s[i0:i1], s.x[i0:i1], s.y[i0:i1], s.p[i0:i1], s.width, s.height)

    def close(self) -> None:
        pass


class _H5Events:
    """An HDF5 event file (common or PKU-Vidar-DVS layout) read by index range.

    The first index at or after a time is found by bisection over the timestamp dataset (a few
    dozen element reads); a range is read with one slice per dataset and validated as the whole
    file would be (sorted, inside the sensor, known polarity values).
    """

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        import h5py

        from neuspike.formats.events_io import DAVIS346_SIZE

        self.path = path
        try:
            self.file = h5py.File(path, "r")
        except OSError as exc:
            raise FormatError(f"{path}: not a readable HDF5 file ({exc})") from None
        node = self.file.get("events")
        if isinstance(node, h5py.Group) and all(isinstance(node.get(k), h5py.Dataset) for k in ("xs", "ys", "ts", "ps")):
            self.layout = "common"
            self.ts, self.xs, self.ys, self.ps = node["ts"], node["xs"], node["ys"], node["ps"]
            declared = None
            if "sensor_resolution" in self.file.attrs:
                res = np.asarray(self.file.attrs["sensor_resolution"]).ravel()
                if res.size >= 2 and (res[:2] > 0).all():
                    declared = (int(res[1]), int(res[0]))
            self.divisor = 1.0
        elif isinstance(node, h5py.Dataset) and node.dtype.names is not None and "timestamp" in node.dtype.names:
            self.layout = "pku"
            self.node = node
            self.ts = node.fields("timestamp")
            declared = DAVIS346_SIZE
            self.divisor = 1e6  # microseconds, divided as the whole-file reader divides
        else:
            self.file.close()
            raise FormatError(f"{path}: neither the common HDF5 event layout nor the PKU-Vidar-DVS one")
        if width is not None:
            self.width, self.height = int(width), int(height)
        elif declared is not None:
            self.width, self.height = declared
        else:
            self.file.close()
            raise FormatError(f"{path}: no sensor_resolution attribute (height, width) in the file; give the size")
        self.count = int(self.file["events"]["ts"].shape[0]) if self.layout == "common" else int(node.shape[0])

    def time_of(self, i: int) -> float:
        if self.layout == "common":
            return float(self.ts[i])
        return float(self.node[i]["timestamp"]) / self.divisor

    def index(self, t_s: float) -> int:
        """The first event index with ``t >= t_s`` (``count`` when none)."""
        lo, hi = 0, self.count
        while lo < hi:
            mid = (lo + hi) // 2
            if self.time_of(mid) < t_s:
                lo = mid + 1
            else:
                hi = mid
        return lo

    def read(self, i0: int, i1: int) -> EventStream:
        if self.layout == "common":
            t = np.asarray(self.ts[i0:i1], dtype=T_DTYPE)
            x, y, p = self.xs[i0:i1], self.ys[i0:i1], np.asarray(self.ps[i0:i1])
            if p.size and (p == 0).any():
                p = p.astype(np.int8) * 2 - 1
        else:
            rec = self.node[i0:i1]
            t = rec["timestamp"].astype(np.float64) / self.divisor
            x, y = rec["x"], rec["y"]
            p = rec["polarity"].astype(np.int8) * 2 - 1
        try:
            return EventStream(t, np.asarray(x).astype(XY_DTYPE), np.asarray(y).astype(XY_DTYPE),
                               np.asarray(p, dtype=P_DTYPE), self.width, self.height)
        except InputError as exc:
            raise FormatError(f"{self.path}: events {i0}..{i1 - 1}: {exc}") from None

    def close(self) -> None:
        self.file.close()


# --------------------------------------------------------------------------- the recording
@dataclass
class VideoRecording:
    """A recording opened for streaming: its metadata, and its data read by range on demand.

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

    def span_s(self) -> tuple[float, float]:
        """The recording's time span in sensor seconds: the spike file's, else first to last event."""
        if self.spikes_path is not None:
            return self.start_s, self.start_s + self.num_planes / self.plane_rate_hz
        if self.event_count == 0:
            raise InputError(f"event file {self.events_path}: holds no events")
        return self.event_time(0), self.event_time(self.event_count - 1)

    def default_window_planes(self) -> int:
        """The file's length for a simulated window recording, else :data:`DEFAULT_WINDOW_PLANES`."""
        m = self.meta
        if m is not None and m.get("mode", "window") == "window" and m.get("planes") is not None:
            return self.num_planes if self.spikes_path is not None else int(m["planes"])
        return DEFAULT_WINDOW_PLANES

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

    def __enter__(self) -> "VideoRecording":
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
) -> VideoRecording:
    """Open a recording for streaming (metadata only; data is read later, by range).

    Parameters
    ----------
    path : path or None
        A simulated recording folder (its ``meta.json`` names ``spikes.dat`` / ``events.h5``),
        or a single spike (``.dat``, ``.npz``) or event file.
    spikes, events : path or None
        The spike file and the event file, instead of (not with) ``path``.
    height, width, raw_width, plane_rate_hz, gain
        As for :func:`neuspike.recordings.load_sample` (a bare ``.dat`` needs the size).

    Returns
    -------
    VideoRecording
        Use it as a context manager (HDF5 event files stay open while streaming).

    Raises
    ------
    InputError, SourceError, FormatError
        Conflicting arguments, a missing or unreadable file, a malformed metadata file.
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
        raise InputError("open_recording: give a recording folder, a spike file, an event file or both")
    sp = Path(spikes) if spikes is not None else None
    ev = Path(events) if events is not None else None
    for kind, f in (("spike", sp), ("event", ev)):
        if f is not None and not f.is_file():
            raise SourceError(f"{kind} file {f}: no such file")
    if sp is not None and sp.suffix.lower() not in SPIKE_SUFFIXES:
        raise InputError(f"spike file {sp}: expected one of {', '.join(SPIKE_SUFFIXES)}, got {sp.suffix or 'no suffix'!r}")
    if gain is not None:
        gain = check_positive("gain", gain)
        if sp is None:
            raise InputError("a gain applies to spike recordings; no spike file was given")
    if (height is None) != (width is None):
        raise InputError("give both height and width, or neither")
    if height is not None:
        height, width = check_positive_int("height", height), check_positive_int("width", width)

    folder = (sp or ev).parent  # type: ignore[union-attr]
    meta = read_meta(folder)
    if meta is not None and meta.get("height") is not None and meta.get("width") is not None:
        mh, mw = int(meta["height"]), int(meta["width"])
        if height is not None and (height, width) != (mh, mw):
            raise InputError(f"size {width}x{height} given, but meta.json states {mw}x{mh}")
        height, width = mh, mw
    rate_given = check_positive("plane_rate_hz", plane_rate_hz) if plane_rate_hz is not None else meta_float(meta, "plane_rate_hz")
    start_given = meta_float(meta, "start_s")
    rate = rate_given or DEFAULT_PLANE_RATE_HZ
    start_s = start_given or 0.0
    num_planes = 0
    file_gain = file_threshold = None
    npz = None
    if sp is not None:
        npz, num_planes, rate, start_s = spike_file_extent(sp, height=height, width=width, raw_width=raw_width,
                                                           rate_given=rate_given, start_given=start_given)
        if npz is not None:
            height, width = npz.height, npz.width
            file_gain, file_threshold = npz.gain, npz.threshold
    source = None
    if ev is not None:
        is_h5 = ev.suffix.lower() in (".h5", ".hdf5")
        if not is_h5:
            with open(ev, "rb") as fh:
                is_h5 = fh.read(8) == b"\x89HDF\r\n\x1a\n"
        source = (_H5Events if is_h5 else _WholeEvents)(ev, width, height)
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
    return VideoRecording(
        height=int(height), width=int(width), plane_rate_hz=float(rate), start_s=float(start_s),  # type: ignore[arg-type]
        num_planes=num_planes, gain=used_gain, gain_source=gain_source,
        threshold=threshold if threshold is not None else file_threshold,
        event_threshold=meta_float(meta, "event_threshold"), meta=meta, folder=folder,
        spikes_path=sp, events_path=ev, raw_width=raw_width, _spike_npz=npz, _events=source,
    )


def _is_event_npz(path: Path) -> bool:
    """An ``.npz`` holding events (``t_s``, ``x``, ``y``, ``p``) rather than spike planes."""
    if path.suffix.lower() != ".npz":
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            return "t_s" in z.files and "planes" not in z.files and "spk" not in z.files
    except (OSError, ValueError):
        return False


# --------------------------------------------------------------------------- instants
def frame_times(start_s: float, end_s: float, fps: float) -> np.ndarray:
    """Output instants: the centres of the ``1 / fps`` intervals that tile ``[start_s, end_s)``.

    Returns
    -------
    ndarray float64 (n,), ``start_s + (k + 0.5) / fps`` for ``k = 0 .. n - 1`` with
    ``n = floor((end_s - start_s) * fps)``. At ``fps`` equal to the plane rate, starting on a plane
    boundary, these are the plane centres: one frame per plane.

    Raises
    ------
    InputError
        ``end_s <= start_s``, a non-positive rate, or a range shorter than one frame.
    """
    fps = check_positive("fps", fps)
    start_s, end_s = float(start_s), float(end_s)
    if not (math.isfinite(start_s) and math.isfinite(end_s)):
        raise InputError(f"start and end must be finite, got {start_s!r}, {end_s!r}")
    if end_s <= start_s:
        raise InputError(f"the start {start_s:.6f} s is not before the end {end_s:.6f} s")
    n = int(math.floor((end_s - start_s) * fps + 1e-9))
    if n < 1:
        raise InputError(
            f"the range [{start_s:.6f}, {end_s:.6f}) s is shorter than one frame at {fps:g} frames/s "
            f"({1.0 / fps:.6f} s): no frame to write"
        )
    return start_s + (np.arange(n, dtype=np.float64) + 0.5) / fps


def check_fps(fps: float, recording: VideoRecording, inputs: Iterable[str]) -> float:
    """Refuse an output rate above the plane rate when a spike method is asked for.

    Spike methods cannot make more distinct frames than the sensor made planes (neighbouring frames
    inside one plane would repeat it); event-only methods may go higher (events are continuous).
    """
    fps = check_positive("fps", fps)
    if "spikes" in set(inputs) and fps > recording.plane_rate_hz * (1 + 1e-9):
        raise InputError(
            f"--fps {fps:g} is above the spike plane rate {recording.plane_rate_hz:g} planes/s: a spike "
            "method cannot make more frames than the sensor made planes (event-only methods can)"
        )
    return fps


# --------------------------------------------------------------------------- rolling buffers
class _PlaneBuffer:
    """Spike planes kept in memory, each read once while windows advance.

    Planes ``[b0, b1)`` live at the start of a buffer that holds ``2 * window_planes`` planes (or
    the window, if longer); a later window reads only its new planes, into the unused tail. When a
    window no longer fits, a new buffer is started with the planes still needed (one window's
    copy per window's worth of progress). A window handed out is a read-only view of planes that
    are never written again, so the samples already yielded stay valid.
    """

    def __init__(self, recording: VideoRecording, window_planes: int) -> None:
        self.rec = recording
        self.capacity = 2 * window_planes
        self.buf: np.ndarray | None = None
        self.b0 = self.b1 = 0

    def get(self, w0: int, w1: int) -> np.ndarray:
        buf = self.buf
        if buf is not None and self.b0 <= w0 <= self.b1 and w1 <= self.b0 + buf.shape[0]:
            if w1 > self.b1:
                buf[self.b1 - self.b0:w1 - self.b0] = self.rec.read_planes(self.b1, w1)
                self.b1 = w1
        else:
            new = np.empty((max(self.capacity, w1 - w0), self.rec.height, self.rec.width), dtype=np.bool_)
            filled = w0
            if buf is not None and self.b0 <= w0 < self.b1:
                filled = min(self.b1, w0 + new.shape[0])
                new[:filled - w0] = buf[w0 - self.b0:filled - self.b0]
            if w1 > filled:
                new[filled - w0:w1 - w0] = self.rec.read_planes(filled, w1)
                filled = w1
            self.buf, self.b0, self.b1 = new, w0, filled
        view = self.buf[w0 - self.b0:w1 - self.b0]
        view.flags.writeable = False
        return view


class _EventBuffer:
    """The events of the current window and history, read ahead in blocks of the file.

    Events are read in file order, :data:`EVENT_BLOCK` at a time, and appended to the unused tail of
    the arrays; a window is the slice ``t0 <= t < t1`` of what was read (found by bisection in
    memory). When an append does not fit, new arrays of twice the needed length are started with
    the events still needed. Streams handed out are views of events that are never written again,
    so the samples already yielded stay valid. A window that starts before the previous one, or
    after everything read, starts afresh by bisection in the file.
    """

    _FIELDS = (("t_s", T_DTYPE), ("x", XY_DTYPE), ("y", XY_DTYPE), ("p", P_DTYPE))

    def __init__(self, recording: VideoRecording) -> None:
        self.rec = recording
        self.t0 = math.inf
        self._restart(0)

    def _restart(self, file_index: int) -> None:
        self.arrays = {name: np.empty(0, dtype) for name, dtype in self._FIELDS}
        self.e0 = self.ea = 0  # events read and kept: arrays[e0:ea]
        self.ia = file_index  # file index of the first event not read

    def _append(self, new: EventStream) -> None:
        t = self.arrays["t_s"]
        if self.ea > self.e0 and len(new) and new.t_s[0] < t[self.ea - 1]:
            raise FormatError(f"{self.rec.events_path}: timestamps decrease at event {self.ia}")
        n, kept = len(new), self.ea - self.e0
        if self.ea + n > t.shape[0]:
            fresh = {name: np.empty(2 * (kept + n), dtype) for name, dtype in self._FIELDS}
            for name in fresh:
                fresh[name][:kept] = self.arrays[name][self.e0:self.ea]
            self.arrays, self.e0, self.ea = fresh, 0, kept
        for name, _ in self._FIELDS:
            self.arrays[name][self.ea:self.ea + n] = getattr(new, name)
        self.ea += n
        self.ia += n

    def get(self, t0: float, t1: float) -> EventStream:
        count = self.rec.event_count
        if t0 < self.t0:
            self._restart(self.rec.event_index(t0))
        self.e0 += int(np.searchsorted(self.arrays["t_s"][self.e0:self.ea], t0, side="left"))
        if self.e0 == self.ea and self.ia < count and self.rec.event_time(self.ia) < t0:
            self._restart(self.rec.event_index(t0))  # a jump forward: skip the events in between
        while self.ia < count and (self.ea == self.e0 or self.arrays["t_s"][self.ea - 1] < t1):
            self._append(self.rec.read_events(self.ia, min(count, self.ia + EVENT_BLOCK)))
        e1 = self.e0 + int(np.searchsorted(self.arrays["t_s"][self.e0:self.ea], t1, side="left"))
        self.t0 = t0
        v = self.arrays
        return EventStream.trusted(v["t_s"][self.e0:e1], v["x"][self.e0:e1], v["y"][self.e0:e1], v["p"][self.e0:e1],
                                   self.rec.width, self.rec.height)


# --------------------------------------------------------------------------- streaming
def _check_times(times_s: Sequence[float] | np.ndarray, recording: VideoRecording) -> np.ndarray:
    times = np.asarray(times_s, dtype=np.float64).reshape(-1)
    if times.size and not np.isfinite(times).all():
        raise InputError("times_s: expected finite times in seconds")
    if recording.spikes_path is not None and times.size:
        lo, hi = recording.span_s()
        bad = (times < lo) | (times > hi)
        if bad.any():
            t = float(times[np.argmax(bad)])
            raise InputError(f"time {t} s is outside the spike recording [{lo}, {hi}] s")
    return times


def stream_samples(
    recording: VideoRecording,
    times_s: Sequence[float] | np.ndarray,
    *,
    inputs: Iterable[str] | None = None,
    window_planes: int | None = None,
    event_history_s: float = EVENT_HISTORY_S,
) -> Iterator[Sample]:
    """The :class:`Sample` of each instant, cut as :func:`~neuspike.recordings.load_sample` cuts it.

    Parameters
    ----------
    recording : VideoRecording
    times_s : sequence of float
        Output instants in sensor seconds; inside the spike file's span when there are spikes.
        Increasing instants share data between neighbouring windows; any order is correct.
    inputs : iterable of {"spikes", "events"} or None
        The modalities to read (default: all the recording has). A modality left out is not read;
        the windows are cut the same way either way (by the spike window when there are spikes).
    window_planes : int or None
        Spike window length in planes (events-only: the window's duration in planes);
        default :meth:`VideoRecording.default_window_planes`.
    event_history_s : float
        Seconds of events before the window carried as history (default
        :data:`~neuspike.recordings.EVENT_HISTORY_S`, as a single-frame sample).

    Yields
    ------
    Sample
        Without ground truth. Its arrays are fresh or read-only views that later samples do not
        modify. ``meta`` names the plane range and the frame index.
    """
    want = recording.modalities if inputs is None else frozenset(inputs) & recording.modalities
    if inputs is not None and frozenset(inputs) - recording.modalities:
        raise InputError(f"the recording has {sorted(recording.modalities)}, not {sorted(frozenset(inputs) - recording.modalities)}")
    window_planes = recording.default_window_planes() if window_planes is None else check_positive_int("window_planes", window_planes)
    history = check_nonnegative("event_history_s", event_history_s)
    times = _check_times(times_s, recording)
    rate, total = recording.plane_rate_hz, recording.num_planes
    planes = _PlaneBuffer(recording, window_planes) if "spikes" in want else None
    events = _EventBuffer(recording) if "events" in want else None
    for k, t in enumerate(times):
        t = float(t)
        spikes = None
        info: dict[str, Any] = {"frame": k}
        if recording.spikes_path is not None:
            key_plane = min(int(math.floor((t - recording.start_s) * rate + 1e-9)), total - 1)
            w0, w1 = window_bounds(key_plane, total, window_planes)
            w_start, w_end = recording.start_s + w0 / rate, recording.start_s + w1 / rate
            info.update(window_planes_in_file=[w0, w1], key_plane_in_file=key_plane, file_planes=total)
            if planes is not None:
                block = planes.get(w0, w1)
                spikes = SpikeStream(block, plane_rate_hz=rate, start_s=w_start, gain=recording.gain,
                                     threshold=recording.threshold, meta={"source": str(recording.spikes_path)})
        else:
            half = window_planes / rate / 2.0
            w_start, w_end = t - half, t + half
        ev = events.get(w_start - history, w_end) if events is not None else None
        yield Sample(
            height=recording.height, width=recording.width, key_time_s=t, window_start_s=w_start,
            window_end_s=w_end, spikes=spikes, events=ev, event_threshold=recording.event_threshold,
            meta=info,
        )


def _next_image(method: Any, sample: Sample, previous_s: float | None) -> np.ndarray:
    hook = getattr(method, "reconstruct_next", None)
    if previous_s is None or hook is None:
        return method.reconstruct(sample)
    return hook(sample, previous_s=previous_s)


def stream_methods(
    methods: Sequence[Any],
    recording: VideoRecording,
    times_s: Sequence[float] | np.ndarray,
    *,
    window_planes: int | None = None,
    event_history_s: float = EVENT_HISTORY_S,
) -> Iterator[tuple[Sample, dict[str, np.ndarray], dict[str, float]]]:
    """Run several methods over one pass of the recording.

    Yields
    ------
    (sample, images, seconds)
        The instant's sample, each method's image by name, and each method's wall time for it
        (seconds, the method call only: reading and cutting the sample are shared and not counted).
    """
    import time

    names = [m.name for m in methods]
    if len(set(names)) != len(names):
        raise InputError(f"methods must have distinct names, got {names}")
    inputs: set[str] = set()
    for m in methods:
        inputs |= set(m.inputs)
    missing = inputs - recording.modalities
    if missing:
        who = [m.name for m in methods if set(m.inputs) & missing]
        raise InputError(f"method(s) {', '.join(who)} need {sorted(missing)}, which the recording lacks")
    for m in methods:
        m.reset()
    previous: float | None = None
    for sample in stream_samples(recording, times_s, inputs=inputs, window_planes=window_planes,
                                 event_history_s=event_history_s):
        images, seconds = {}, {}
        for m in methods:
            t0 = time.perf_counter()
            images[m.name] = _next_image(m, sample, previous)
            seconds[m.name] = time.perf_counter() - t0
        previous = sample.key_time_s
        yield sample, images, seconds


def reconstruct_video(
    method: Any,
    recording: VideoRecording,
    times_s: Sequence[float] | np.ndarray,
    *,
    window_planes: int | None = None,
    event_history_s: float = EVENT_HISTORY_S,
) -> Iterator[tuple[float, np.ndarray]]:
    """Yield ``(time_s, image)`` for each output instant, reading the recording as it goes.

    Parameters
    ----------
    method : neuspike.methods.Method
        Any registered method; it is reset before the first frame.
    recording : VideoRecording
        From :func:`open_recording`.
    times_s : sequence of float
        Output instants, sensor seconds (e.g. :func:`frame_times`).
    window_planes, event_history_s
        As for :func:`stream_samples`.

    Yields
    ------
    (float, ndarray float32 (H, W) in [0, 1])
        For stateless methods each image equals ``method.reconstruct(load_sample(..., at_s=t))``.
    """
    for sample, images, _ in stream_methods([method], recording, times_s, window_planes=window_planes,
                                            event_history_s=event_history_s):
        yield sample.key_time_s, images[method.name]
