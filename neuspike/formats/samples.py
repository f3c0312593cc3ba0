"""Turn recording files (real or simulated) into :class:`~neuspike.sample.Sample` s.

A recording is opened once by :func:`neuspike.formats.recording.open_recording` (whose docstring
gives the rules for its metadata and the default key instant). :func:`stream_samples` cuts the sample
of each requested instant from it, reading as it goes; :func:`load_sample` is one such cut, at the
key instant, plus the ground truth. The cut:

Spike window
    ``window_planes`` planes centred on the key plane (planes ``K - N//2 .. K + N//2 - 1`` for even N),
    shifted, not shortened, to stay inside the file; a file no longer than the window is used whole.
    Only that range is read from a ``.dat``. Default N: the file's own length for a simulated window
    recording (``meta.json`` with ``mode`` ``"window"``), else :data:`DEFAULT_WINDOW_PLANES` (256,
    12.8 ms at 20 kHz, the length of the paper's spike windows). A key instant chosen by plane is
    always a plane's centre, never a plane boundary, so that rounding cannot move it into the
    neighbouring plane.

Events
    With spikes, the window is the spike window's span; events-only, it lasts ``window_planes`` /
    plane rate (default :data:`DEFAULT_WINDOW_PLANES` planes at the plane rate, 12.8 ms at 20 kHz; a
    simulated window recording's own span) centred on the key instant. The sample carries the events
    with ``t < window_end`` and, as history for recurrent methods, those of the
    :data:`EVENT_HISTORY_S` (1 s) before the window start; earlier events are not loaded into the
    sample (:func:`load_sample`'s ``meta`` records how many were left out). HDF5 event files are read
    by range, other formats whole; either way with the checks of
    :func:`neuspike.formats.event_readers.read_events`.

Ground truth (for evaluation only; :func:`load_sample`)
    ``gt`` (a ``.png`` or ``.npy`` file) when given. Otherwise ``gt.npy`` (preferred: not quantised)
    or ``gt.png`` beside the recording, used only when the key instant lies in the same plane as the
    recording's ``key_time_s`` (the instant that ground truth shows); a note in ``meta["notes"]``
    says when it was left out. Values above 1 (HDR radiance) are clipped to [0, 1], as the harness
    does, and the number of clipped pixels is noted. 8-bit PNGs are divided by 255, 16-bit by 65535;
    a colour image is accepted only if its channels are equal.

Streaming shares data between neighbouring windows: planes and events already in memory are kept
while they are still inside the window (or the event history) and only the new ones are read, so
each plane of a ``.dat`` is read and unpacked once however high the frame rate. What stays in memory
is the spike window (``window_planes`` planes) and the events of the window plus the history.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from neuspike.utils.checks import check_nonnegative, check_positive_int
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.formats.recording import (
    DEFAULT_PLANE_RATE_HZ,
    DEFAULT_WINDOW_PLANES,
    EVENT_HISTORY_S,
    META_NAME,
    SPIKE_SUFFIXES,
    RecordingReader,
    meta_float,
    open_recording,
    plane_of,
    read_meta,
    spike_file_extent,
    window_bounds,
)
from neuspike.sample import Sample
from neuspike.streams import P_DTYPE, T_DTYPE, XY_DTYPE, EventStream, SpikeStream

__all__ = [
    "DEFAULT_PLANE_RATE_HZ", "DEFAULT_WINDOW_PLANES", "EVENT_HISTORY_S", "GT_NAMES", "SPIKE_SUFFIXES",
    "RecordingReader", "describe_sample", "load_ground_truth", "load_sample", "meta_float", "open_recording",
    "read_meta", "spike_file_extent", "stream_samples", "window_bounds",
]

GT_NAMES = ("gt.npy", "gt.png")
#: Events read from the file at a time (about 0.4 MB).
EVENT_BLOCK = 1 << 15


def load_ground_truth(path: str | os.PathLike, *, height: int, width: int) -> tuple[np.ndarray, list[str]]:
    """Read a ground-truth image as float32 (H, W) in [0, 1].

    Parameters
    ----------
    path : path of a ``.npy`` (float radiance, 1.0 = reference white) or an image file (8- or 16-bit)
    height, width : int
        The expected size.

    Returns
    -------
    image : ndarray float32 (H, W), values in [0, 1]
    notes : list of str
        What was done to the values (e.g. HDR values clipped).
    """
    p = Path(path)
    if not p.is_file():
        raise SourceError(f"ground truth {p}: no such file")
    notes: list[str] = []
    if p.suffix.lower() == ".npy":
        try:
            img = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise FormatError(f"ground truth {p}: not a readable .npy file ({exc})") from None
        if not (np.issubdtype(img.dtype, np.floating) or np.issubdtype(img.dtype, np.integer)):
            raise FormatError(f"ground truth {p}: expected a real-valued array, got dtype {img.dtype}")
        img = img.astype(np.float64)
    else:
        import cv2

        raw = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise SourceError(f"ground truth {p}: not a readable image")
        if raw.ndim == 3:
            if not all(np.array_equal(raw[..., 0], raw[..., c]) for c in range(1, min(raw.shape[2], 3))):
                raise InputError(f"ground truth {p}: expected a greyscale image, got {raw.shape[2]} differing channels")
            raw = raw[..., 0]
        if raw.dtype == np.uint8:
            img = raw.astype(np.float64) / 255.0
        elif raw.dtype == np.uint16:
            img = raw.astype(np.float64) / 65535.0
        else:
            raise FormatError(f"ground truth {p}: expected an 8- or 16-bit image, got dtype {raw.dtype}")
    if img.shape != (height, width):
        raise InputError(f"ground truth {p}: expected shape (H, W) = {(height, width)}, got {img.shape}")
    if not np.isfinite(img).all():
        raise FormatError(f"ground truth {p}: holds NaN or infinite values")
    if img.min() < 0:
        raise FormatError(f"ground truth {p}: holds negative values (minimum {float(img.min())})")
    above = int(np.count_nonzero(img > 1.0))
    if above:
        notes.append(f"ground truth: {above} pixels above 1 (HDR) clipped to 1")
        img = np.minimum(img, 1.0)
    return img.astype(np.float32), notes


# --------------------------------------------------------------------------- rolling buffers
class _PlaneBuffer:
    """Spike planes kept in memory, each read once while windows advance.

    Planes ``[b0, b1)`` live at the start of a buffer that holds ``2 * window_planes`` planes (or
    the window, if longer); a later window reads only its new planes, into the unused tail. When a
    window no longer fits, a new buffer is started with the planes still needed (one window's
    copy per window's worth of progress). A window handed out is a read-only view of planes that
    are never written again, so the samples already yielded stay valid.
    """

    def __init__(self, recording: RecordingReader, window_planes: int) -> None:
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

    def __init__(self, recording: RecordingReader) -> None:
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
def _check_times(times_s: Sequence[float] | np.ndarray, recording: RecordingReader) -> np.ndarray:
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
    recording: RecordingReader,
    times_s: Sequence[float] | np.ndarray,
    *,
    inputs: Iterable[str] | None = None,
    window_planes: int | None = None,
    event_history_s: float = EVENT_HISTORY_S,
) -> Iterator[Sample]:
    """The :class:`Sample` of each instant (the cut of the module docstring).

    Parameters
    ----------
    recording : RecordingReader
        From :func:`open_recording`.
    times_s : sequence of float
        Output instants in sensor seconds; inside the spike file's span when there are spikes.
        Increasing instants share data between neighbouring windows; any order is correct.
    inputs : iterable of {"spikes", "events"} or None
        The modalities to read (default: all the recording has). A modality left out is not read;
        the windows are cut the same way either way (by the spike window when there are spikes).
    window_planes : int or None
        Spike window length in planes (events-only: the window's duration in planes);
        default :meth:`~neuspike.formats.recording.RecordingReader.default_window_planes`.
    event_history_s : float
        Seconds of events before the window carried as history (default
        :data:`EVENT_HISTORY_S`, as :func:`load_sample`).

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
    # a window longer than the file is the whole file (window_bounds): the buffer never needs more
    planes = _PlaneBuffer(recording, min(window_planes, max(total, 1))) if "spikes" in want else None
    events = _EventBuffer(recording) if "events" in want else None
    for k, t in enumerate(times):
        t = float(t)
        spikes = None
        info: dict[str, Any] = {"frame": k}
        if recording.spikes_path is not None:
            key_plane = min(plane_of(t, recording.start_s, rate), total - 1)
            w0, w1 = window_bounds(key_plane, total, window_planes)
            w_start, w_end = recording.start_s + w0 / rate, recording.start_s + w1 / rate
            info.update(window_planes_in_file=[w0, w1], key_plane_in_file=key_plane, file_planes=total)
            if planes is not None:
                block = planes.get(w0, w1)
                meta: dict[str, Any] = {"source": str(recording.spikes_path)}
                if w0 == 0 and isinstance((recording.meta or {}).get("stages"), list):
                    # a simulation's first planes: how its sensor started is part of what it counts
                    meta["stages"] = [st for st in recording.meta["stages"]
                                      if isinstance(st, dict) and st.get("modality", "spikes") == "spikes"]
                spikes = SpikeStream(block, plane_rate_hz=rate, start_s=w_start, gain=recording.gain,
                                     threshold=recording.threshold, dark_rate=recording.dark_rate, meta=meta)
        else:
            half = window_planes / rate / 2.0
            w_start, w_end = t - half, t + half
        ev = events.get(w_start - history, w_end) if events is not None else None
        yield Sample(
            height=recording.height, width=recording.width, key_time_s=t, window_start_s=w_start,
            window_end_s=w_end, spikes=spikes, events=ev, event_threshold=recording.event_threshold,
            meta=info,
        )


def load_sample(
    *,
    spikes: str | os.PathLike | None = None,
    events: str | os.PathLike | None = None,
    height: int | None = None,
    width: int | None = None,
    plane: int | None = None,
    at_s: float | None = None,
    gain: float | None = None,
    window_planes: int | None = None,
    gt: str | os.PathLike | None = None,
    raw_width: int | None = None,
    plane_rate_hz: float | None = None,
    dark_rate: float | None = None,
) -> Sample:
    """Load one sample of a recording: the cut of :func:`stream_samples` at the key instant.

    Parameters
    ----------
    spikes : path or None
        Vidar ``.dat`` (needs ``height``/``width`` or a ``meta.json`` beside it) or ``.npz``.
    events : path or None
        An event file.
    height, width, raw_width, plane_rate_hz, gain, dark_rate
        As for :func:`~neuspike.formats.recording.open_recording`.
    plane : int or None
        Key plane index into the spike file (the key instant is the plane's centre).
    at_s : float or None
        Key instant in sensor seconds. At most one of ``plane`` and ``at_s``.
    window_planes : int or None
        Spike window length in planes (events-only: the window's duration in planes).
    gt : path or None
        Ground-truth image (``.png`` or ``.npy``); ``None`` looks beside the recording.

    Returns
    -------
    Sample
        ``meta`` holds the source paths, the plane range read, where the gain came from, the
        events left out and ``notes`` (list of str) worth printing.

    Raises
    ------
    InputError
        Missing or conflicting arguments, a key instant outside the recording.
    SourceError, FormatError
        A file that does not exist or cannot be read.
    """
    if spikes is None and events is None:
        raise InputError("load_sample: give a spike file, an event file or both")
    if plane is not None and at_s is not None:
        raise InputError("give the key instant as a plane index or as a time, not both")
    if window_planes is not None:
        window_planes = check_positive_int("window_planes", window_planes)
    with open_recording(spikes=spikes, events=events, height=height, width=width, raw_width=raw_width,
                        plane_rate_hz=plane_rate_hz, gain=gain, dark_rate=dark_rate) as rec:
        key_time_s = rec.key_instant(plane=plane, at_s=at_s)
        sample = next(stream_samples(rec, [key_time_s], window_planes=window_planes))
        info: dict[str, Any] = {
            "spikes_path": str(rec.spikes_path) if rec.spikes_path else None,
            "events_path": str(rec.events_path) if rec.events_path else None,
            "meta_json": str(rec.folder / META_NAME) if rec.meta is not None else None,
        }
        if rec.spikes_path is not None:
            info.update({k: sample.meta[k] for k in ("file_planes", "window_planes_in_file", "key_plane_in_file")})
            info.update(gain=rec.gain, gain_source=rec.gain_source, dark_rate=rec.dark_rate)
        if rec.events_path is not None:
            info.update({
                "event_history_s": EVENT_HISTORY_S,
                "events_left_out_before": rec.event_index(sample.window_start_s - EVENT_HISTORY_S),
                "events_left_out_after": rec.event_count - rec.event_index(sample.window_end_s),
            })
    notes: list[str] = []
    ground_truth, gt_path = _ground_truth(rec, key_time_s, gt, notes)
    info["ground_truth_path"] = str(gt_path) if gt_path is not None else None
    info["plane_rate_hz"] = rec.plane_rate_hz
    info["notes"] = notes
    return dataclasses.replace(sample, ground_truth=ground_truth, meta=info)


def _ground_truth(rec: RecordingReader, key_time_s: float, gt: str | os.PathLike | None,
                  notes: list[str]) -> tuple[np.ndarray | None, Path | None]:
    """The ground truth of a single cut and its path (rules in the module docstring); notes appended."""
    from neuspike.metrics import SSIM_WINDOW_SIDE

    height, width, meta_key_s = rec.height, rec.width, rec.key_time_s
    gt_path: Path | None = Path(gt) if gt is not None else None
    if gt_path is None:
        beside = [rec.folder / n for n in GT_NAMES if (rec.folder / n).is_file()]
        if beside:
            same = meta_key_s is not None and (plane_of(key_time_s, rec.start_s, rec.plane_rate_hz)
                                               == plane_of(meta_key_s, rec.start_s, rec.plane_rate_hz))
            if same:
                gt_path = beside[0]
            else:
                notes.append(
                    f"{beside[0].name} beside the recording shows the key time "
                    f"{'(unknown)' if meta_key_s is None else f'{meta_key_s:.6f} s'}, not {key_time_s:.6f} s: not used"
                )
    if gt_path is not None and min(height, width) < SSIM_WINDOW_SIDE:
        # no SSIM exists below the pinned window: refuse a ground truth asked for, skip one found beside
        if gt is not None:
            raise InputError(
                f"ground truth {gt_path}: {width}x{height} is smaller than the {SSIM_WINDOW_SIDE}x{SSIM_WINDOW_SIDE} "
                f"SSIM window, so no method could be scored; leave out --gt for no-reference measures"
            )
        notes.append(f"{gt_path.name} beside the recording not used: {width}x{height} is smaller than the "
                     f"{SSIM_WINDOW_SIDE}x{SSIM_WINDOW_SIDE} SSIM window")
        gt_path = None
    if gt_path is None:
        return None, None
    image, gt_notes = load_ground_truth(gt_path, height=height, width=width)
    notes.extend(gt_notes)
    return image, gt_path


def describe_sample(sample: Sample) -> str:
    """A one-line summary of a loaded sample (size, instant, window, inputs, gain)."""
    parts = [f"{sample.width}x{sample.height}", f"key {sample.key_time_s:.6f} s",
             f"window [{sample.window_start_s:.6f}, {sample.window_end_s:.6f}) s"]
    if sample.spikes is not None:
        w0, w1 = sample.meta.get("window_planes_in_file", (0, sample.spikes.num_planes))
        gain = sample.spikes.gain
        parts.append(
            f"{sample.spikes.num_planes} spike planes ({w0}..{w1 - 1} of {sample.meta.get('file_planes', '?')}), "
            f"key plane {sample.meta.get('key_plane_in_file', sample.key_plane)}, "
            + ("gain unknown" if gain is None else f"gain {gain:g} ({sample.meta.get('gain_source', '?')})")
            + ("" if sample.spikes.dark_rate is None else f", dark rate {sample.spikes.dark_rate:.4g}")
        )
    if sample.events is not None:
        n_win = len(sample.window_events())
        parts.append(f"{n_win} events in the window + {len(sample.events) - n_win} of history")
    return "; ".join(parts)
