"""Turn recording files (real or simulated) into a :class:`~neuspike.sample.Sample`.

:func:`load_sample` reads a spike file (Vidar ``.dat`` or a ``.npz`` with a spike array), an event
file (anything :func:`neuspike.formats.events_io.read_events` reads: HDF5 in the common or the
PKU-Vidar-DVS layout, E2VID text, ``.npz``, AEDAT4) or both, picks the key instant and cuts the
window a method receives. The rules, in order of precedence:

Sensor metadata
    A ``meta.json`` in the folder of the spike file (else of the event file) is a recording written
    by ``python -m neuspike.simulate``; its ``width``, ``height``, ``plane_rate_hz``, ``start_s``,
    ``gain``, ``threshold``, ``event_threshold`` and ``key_time_s`` are used. Explicit arguments
    override it where they are independent of the file (``gain``, the key instant); a size given
    explicitly must agree with the one the file or ``meta.json`` states, otherwise an error is raised.
    Without ``meta.json``: the size comes from the ``.npz`` array or the event file; a bare ``.dat``
    has no header and needs ``height`` and ``width``; the plane rate, start time and gain stored in
    an ``.npz`` are used; otherwise the plane rate is the Vidar's :data:`DEFAULT_PLANE_RATE_HZ`, the
    spike file starts at sensor time 0 and the gain is unknown (``None``) unless given, and methods
    then apply their documented robust normalisation.

Key instant
    ``plane=K`` (an index into the spike file; the instant is the centre of plane K) or
    ``at_s`` (sensor time, in the event file's clock for events-only recordings). Default: the
    recording's ``key_time_s`` from ``meta.json``, else the middle plane of the spike file (plane
    ``T // 2``, at its centre), else the centre of the event recording (midway between its first and
    last event). A key instant chosen by plane is always a plane's centre, never a plane boundary,
    so that rounding cannot move it into the neighbouring plane.

Spike window
    ``window_planes`` planes centred on the key plane (planes ``K - N//2 .. K + N//2 - 1`` for even N),
    shifted, not shortened, to stay inside the file; a file no longer than the window is used whole.
    Only that range is read from a ``.dat``. Default N: the file's own length for a simulated window
    recording (``meta.json`` with ``mode`` ``"window"``), else :data:`DEFAULT_WINDOW_PLANES` (256,
    12.8 ms at 20 kHz, the length of the paper's spike windows).

Events
    With spikes, the window is the spike window's span; events-only, it lasts ``window_planes`` /
    plane rate (default :data:`DEFAULT_WINDOW_PLANES` planes at the plane rate, 12.8 ms at 20 kHz; a
    simulated window recording's own span) centred on the key instant. The sample carries the events
    with ``t < window_end`` and, as history for recurrent methods, those of the
    :data:`EVENT_HISTORY_S` (1 s) before the window start; earlier events are not loaded into the
    sample (the sample's ``meta`` records how many were left out).

Ground truth (for evaluation only)
    ``gt`` (a ``.png`` or ``.npy`` file) when given. Otherwise ``gt.npy`` (preferred: not quantised)
    or ``gt.png`` beside the recording, used only when the key instant lies in the same plane as the
    recording's ``key_time_s`` (the instant that ground truth shows); a note in ``meta["notes"]``
    says when it was left out. Values above 1 (HDR radiance) are clipped to [0, 1], as the harness
    does, and the number of clipped pixels is noted. 8-bit PNGs are divided by 255, 16-bit by 65535;
    a colour image is accepted only if its channels are equal.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.checks import check_positive, check_positive_int
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.sample import Sample
from neuspike.streams import VIDAR_PLANE_RATE_HZ, EventStream, SpikeStream

#: Spike planes per window when neither the caller nor a simulated recording says otherwise.
DEFAULT_WINDOW_PLANES = 256
#: Planes per second assumed for spike files that do not state it (the Vidar's).
DEFAULT_PLANE_RATE_HZ = VIDAR_PLANE_RATE_HZ
#: Seconds of event history before the window that a sample carries.
EVENT_HISTORY_S = 1.0
#: Suffixes of spike files :func:`load_sample` reads.
SPIKE_SUFFIXES = (".dat", ".npz")
META_NAME = "meta.json"
GT_NAMES = ("gt.npy", "gt.png")


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


def _check_file(kind: str, path: str | os.PathLike) -> Path:
    p = Path(path)
    if not p.is_file():
        raise SourceError(f"{kind} file {p}: no such file")
    return p


def meta_float(meta: dict[str, Any] | None, key: str) -> float | None:
    """A finite number from ``meta.json`` (``None`` when absent); anything else is a :class:`FormatError`."""
    if meta is None or meta.get(key) is None:
        return None
    try:
        v = float(meta[key])
    except (TypeError, ValueError):
        raise FormatError(f"meta.json: {key} must be a number, got {meta[key]!r}") from None
    if not math.isfinite(v):
        raise FormatError(f"meta.json: {key} must be finite, got {meta[key]!r}")
    return v


def _meta_int(meta: dict[str, Any], key: str) -> int:
    """A whole number >= 1 from ``meta.json``."""
    v = meta[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v) or v < 1:
        raise FormatError(f"meta.json: {key} must be a whole number >= 1, got {v!r}")
    return int(v)


def _resolve_size(
    height: int | None, width: int | None, meta: dict[str, Any] | None
) -> tuple[int | None, int | None]:
    """The stated size: explicit arguments (both or neither), checked against meta.json's."""
    if (height is None) != (width is None):
        raise InputError("give both height and width, or neither")
    if height is not None:
        height = check_positive_int("height", height)
        width = check_positive_int("width", width)
    if meta is not None and meta.get("height") is not None and meta.get("width") is not None:
        mh, mw = _meta_int(meta, "height"), _meta_int(meta, "width")
        if height is not None and (height, width) != (mh, mw):
            raise InputError(f"size {width}x{height} given, but meta.json states {mw}x{mh}")
        return mh, mw
    return height, width


def window_bounds(key_plane: int, total_planes: int, window_planes: int) -> tuple[int, int]:
    """[start, stop) of a window of ``window_planes`` centred on ``key_plane`` inside the file."""
    if total_planes <= window_planes:
        return 0, total_planes
    start = key_plane - window_planes // 2
    start = min(max(start, 0), total_planes - window_planes)
    return start, start + window_planes


def _is_window_recording(meta: dict[str, Any] | None) -> bool:
    return (meta is not None and meta.get("mode", "window") == "window" and meta.get("planes") is not None
            and _meta_int(meta, "planes") > 0)


def _plane_of(time_s: float, start_s: float, rate_hz: float) -> int:
    return int(math.floor((time_s - start_s) * rate_hz + 1e-9))


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
) -> Sample:
    """Load a recording into a :class:`Sample` (rules in the module docstring).

    Parameters
    ----------
    spikes : path or None
        Vidar ``.dat`` (needs ``height``/``width`` or a ``meta.json`` beside it) or ``.npz``.
    events : path or None
        An event file.
    height, width : int or None
        Sensor size (H, W); required for a bare ``.dat``; must agree with the file's otherwise.
    plane : int or None
        Key plane index into the spike file (the key instant is the plane's centre).
    at_s : float or None
        Key instant in sensor seconds. At most one of ``plane`` and ``at_s``.
    gain : float or None
        Expected spikes per plane per unit radiance; overrides the recording's (real data: unknown).
    window_planes : int or None
        Spike window length in planes (events-only: the window's duration in planes).
    gt : path or None
        Ground-truth image (``.png`` or ``.npy``); ``None`` looks beside the recording.
    raw_width : int or None
        Stored width of a ``.dat`` with extra columns (416-wide captures); the extra columns are dropped.
    plane_rate_hz : float or None
        Planes per second; overrides ``meta.json``; default :data:`DEFAULT_PLANE_RATE_HZ`.

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
    spike_path = _check_file("spike", spikes) if spikes is not None else None
    event_path = _check_file("event", events) if events is not None else None
    if spike_path is not None and spike_path.suffix.lower() not in SPIKE_SUFFIXES:
        raise InputError(
            f"spike file {spike_path}: expected one of {', '.join(SPIKE_SUFFIXES)}, got {spike_path.suffix or 'no suffix'!r}"
        )
    if plane is not None and (isinstance(plane, bool) or not isinstance(plane, (int, np.integer)) or plane < 0):
        raise InputError(f"plane: expected a plane index >= 0, got {plane!r}")
    if at_s is not None:
        at_s = float(at_s)
        if not math.isfinite(at_s):
            raise InputError(f"at_s: expected a finite time in seconds, got {at_s!r}")
    if gain is not None:
        gain = check_positive("gain", gain)
        if spike_path is None:
            raise InputError("a gain applies to spike recordings; no spike file was given")
    if window_planes is not None:
        window_planes = check_positive_int("window_planes", window_planes)

    home = (spike_path or event_path).parent  # type: ignore[union-attr]
    meta = read_meta(home)
    height, width = _resolve_size(height, width, meta)
    # stated by the caller or meta.json; else the spike file's own (an .npz may store it), else the Vidar's
    rate_given = check_positive("plane_rate_hz", plane_rate_hz) if plane_rate_hz is not None else (
        meta_float(meta, "plane_rate_hz")
    )
    rate = rate_given or DEFAULT_PLANE_RATE_HZ
    start_given = meta_float(meta, "start_s")
    file_start_s = start_given or 0.0
    meta_key_s = meta_float(meta, "key_time_s")
    notes: list[str] = []
    info: dict[str, Any] = {
        "spikes_path": str(spike_path) if spike_path else None,
        "events_path": str(event_path) if event_path else None,
        "meta_json": str(home / META_NAME) if meta is not None else None,
    }

    spike_stream: SpikeStream | None = None
    if spike_path is not None:
        spike_stream, key_time_s, rate, file_start_s = _load_spikes(
            spike_path, height=height, width=width, meta=meta, rate_given=rate_given, start_given=start_given,
            meta_key_s=meta_key_s, plane=plane, at_s=at_s, window_planes=window_planes,
            raw_width=raw_width, gain=gain, info=info,
        )
        height, width = spike_stream.height, spike_stream.width
        w_start_s, w_end_s = spike_stream.start_s, spike_stream.end_s

    event_stream: EventStream | None = None
    if event_path is not None:
        event_stream = _read_events(event_path, height=height, width=width)
        if height is None:
            height, width = event_stream.height, event_stream.width
        if spike_path is None:
            key_time_s, w_start_s, w_end_s = _events_only_window(
                event_stream, meta=meta, rate=rate, file_start_s=file_start_s, meta_key_s=meta_key_s,
                plane=plane, at_s=at_s, window_planes=window_planes,
            )
        n_before = int(np.searchsorted(event_stream.t_s, w_start_s - EVENT_HISTORY_S, side="left"))
        n_after = len(event_stream) - int(np.searchsorted(event_stream.t_s, w_end_s, side="left"))
        event_stream = event_stream.between(w_start_s - EVENT_HISTORY_S, w_end_s)
        info.update({
            "event_history_s": EVENT_HISTORY_S,
            "events_left_out_before": n_before,
            "events_left_out_after": n_after,
        })

    ground_truth = None
    gt_path: Path | None = Path(gt) if gt is not None else None
    if gt_path is None:
        beside = [home / n for n in GT_NAMES if (home / n).is_file()]
        if beside:
            if meta_key_s is not None and _plane_of(key_time_s, file_start_s, rate) == _plane_of(meta_key_s, file_start_s, rate):
                gt_path = beside[0]
            else:
                notes.append(
                    f"{beside[0].name} beside the recording shows the key time "
                    f"{'(unknown)' if meta_key_s is None else f'{meta_key_s:.6f} s'}, not {key_time_s:.6f} s: not used"
                )
    from neuspike.metrics import SSIM_WINDOW_SIDE

    if gt_path is not None and min(height, width) < SSIM_WINDOW_SIDE:  # type: ignore[type-var]
        # no SSIM exists below the pinned window: refuse a ground truth asked for, skip one found beside
        if gt is not None:
            raise InputError(
                f"ground truth {gt_path}: {width}x{height} is smaller than the {SSIM_WINDOW_SIDE}x{SSIM_WINDOW_SIDE} "
                f"SSIM window, so no method could be scored; leave out --gt for no-reference measures"
            )
        notes.append(f"{gt_path.name} beside the recording not used: {width}x{height} is smaller than the "
                     f"{SSIM_WINDOW_SIDE}x{SSIM_WINDOW_SIDE} SSIM window")
        gt_path = None
    if gt_path is not None:
        ground_truth, gt_notes = load_ground_truth(gt_path, height=height, width=width)  # type: ignore[arg-type]
        notes.extend(gt_notes)
    info["ground_truth_path"] = str(gt_path) if gt_path is not None else None
    info["plane_rate_hz"] = rate
    info["notes"] = notes

    event_threshold = meta_float(meta, "event_threshold")
    return Sample(
        height=int(height),  # type: ignore[arg-type]
        width=int(width),  # type: ignore[arg-type]
        key_time_s=float(key_time_s),
        window_start_s=float(w_start_s),
        window_end_s=float(w_end_s),
        spikes=spike_stream,
        events=event_stream,
        event_threshold=event_threshold,
        ground_truth=ground_truth,
        meta=info,
    )


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
        rate = rate_given or DEFAULT_PLANE_RATE_HZ
        start_s = start_given or 0.0
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


def _load_spikes(
    path: Path, *, height: int | None, width: int | None, meta: dict[str, Any] | None,
    rate_given: float | None, start_given: float | None, meta_key_s: float | None, plane: int | None,
    at_s: float | None, window_planes: int | None, raw_width: int | None, gain: float | None,
    info: dict[str, Any],
) -> tuple[SpikeStream, float, float, float]:
    """Read the spike window; return (stream, key_time_s, plane_rate_hz, file_start_s)."""
    whole, total, rate, file_start_s = spike_file_extent(path, height=height, width=width, raw_width=raw_width,
                                                         rate_given=rate_given, start_given=start_given)
    end_s = file_start_s + total / rate

    if plane is not None:
        if plane >= total:
            raise InputError(f"plane {plane} is outside the spike file's {total} planes (0..{total - 1})")
        key_plane, key_time_s = int(plane), file_start_s + (plane + 0.5) / rate
    elif at_s is not None:
        if not file_start_s <= at_s <= end_s:
            raise InputError(f"time {at_s} s is outside the spike recording [{file_start_s}, {end_s}] s")
        key_plane, key_time_s = min(_plane_of(at_s, file_start_s, rate), total - 1), at_s
    elif meta_key_s is not None and file_start_s <= meta_key_s <= end_s:
        key_plane, key_time_s = min(_plane_of(meta_key_s, file_start_s, rate), total - 1), meta_key_s
    else:
        key_plane = total // 2
        key_time_s = file_start_s + (key_plane + 0.5) / rate

    if window_planes is None:
        window_planes = total if _is_window_recording(meta) else DEFAULT_WINDOW_PLANES
    w0, w1 = window_bounds(key_plane, total, window_planes)
    if whole is None:
        from neuspike.formats.vidar_dat import read_dat

        planes = read_dat(path, height=height, width=width, start=w0, stop=w1, raw_width=raw_width)
        stream_meta: dict[str, Any] = {"source": str(path)}
        file_gain = None
        threshold = None
    else:
        planes = whole.planes[w0:w1]
        stream_meta = dict(whole.meta)
        file_gain = whole.gain
        threshold = whole.threshold

    meta_gain = meta_float(meta, "gain")
    if gain is not None:
        used_gain, gain_source = gain, "given"
    elif meta_gain is not None:
        used_gain, gain_source = meta_gain, "meta.json"
    elif file_gain is not None:
        used_gain, gain_source = file_gain, "file"
    else:
        used_gain, gain_source = None, "unknown"
    threshold = meta_float(meta, "threshold") if meta_float(meta, "threshold") is not None else threshold

    stream = SpikeStream(
        planes, plane_rate_hz=rate, start_s=file_start_s + w0 / rate, gain=used_gain,
        threshold=threshold, meta=stream_meta,
    )
    info.update({
        "file_planes": total,
        "window_planes_in_file": [w0, w1],
        "key_plane_in_file": key_plane,
        "gain": used_gain,
        "gain_source": gain_source,
    })
    return stream, key_time_s, rate, file_start_s


def _read_events(path: Path, *, height: int | None, width: int | None) -> EventStream:
    from neuspike.formats.events_io import read_events

    kwargs = {} if height is None else {"width": width, "height": height}
    stream = read_events(path, **kwargs)
    if height is not None and (stream.height, stream.width) != (height, width):
        raise InputError(
            f"event file {path}: sensor size {stream.width}x{stream.height} does not match {width}x{height}"
        )
    return stream


def _events_only_window(
    events: EventStream, *, meta: dict[str, Any] | None, rate: float, file_start_s: float,
    meta_key_s: float | None, plane: int | None, at_s: float | None, window_planes: int | None,
) -> tuple[float, float, float]:
    """(key_time_s, window_start_s, window_end_s) for a recording without spikes."""
    if window_planes is None:
        window_planes = int(meta["planes"]) if _is_window_recording(meta) else DEFAULT_WINDOW_PLANES  # type: ignore[index]
    duration_s = window_planes / rate
    have = len(events) > 0
    first, last = (float(events.t_s[0]), float(events.t_s[-1])) if have else (None, None)
    if plane is not None:
        if meta is None:
            raise InputError(
                "a plane index needs a spike clock; for an event recording give the key instant "
                "with --at SECONDS (sensor time)"
            )
        if _is_window_recording(meta) and plane >= int(meta["planes"]):  # type: ignore[index]
            raise InputError(f"plane {plane} is outside the recording's {int(meta['planes'])} planes")  # type: ignore[index]
        key_s = file_start_s + (plane + 0.5) / rate
    elif at_s is not None:
        if meta is None and have and not first <= at_s <= last:  # type: ignore[operator]
            raise InputError(f"time {at_s} s is outside the event recording [{first}, {last}] s")
        key_s = at_s
    elif meta_key_s is not None:
        key_s = meta_key_s
    elif have:
        key_s = 0.5 * (first + last)  # type: ignore[operator]
    else:
        raise InputError("the event file holds no events; give the key instant with --at SECONDS")
    return key_s, key_s - duration_s / 2.0, key_s + duration_s / 2.0


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
        )
    if sample.events is not None:
        n_win = len(sample.window_events())
        parts.append(f"{n_win} events in the window + {len(sample.events) - n_win} of history")
    return "; ".join(parts)
