"""The manifest of a dataset: which recordings, which instants, which ground truth, by which convention.

A dataset is a folder of recordings; its manifest is a JSON file (paths inside it are relative to
the dataset folder, so a dataset and its manifest move together). :func:`read_manifest` parses one,
:func:`infer_manifest` writes one for a folder in a layout it knows, and :func:`resolve` checks a
manifest against the files and turns it into the instants to reconstruct, before any work: every
problem it finds is one :class:`~neuspike.errors.InputError` line that names the recording.

Format (``"manifest": 1``)
--------------------------
::

    {
      "manifest": 1,
      "layout": "spike-gt",                  # how it was made: spike-gt, events-frames, files or manual
      "recordings": [
        {
          "name": "car",                     # unique; letters, digits, '.', '_', '-'
          "spikes": "spike/car.dat",         # a spike file (.dat or .npz), an event file, or both
          "events": null,
          "height": 250, "width": 400,       # needed for a .dat; checked against the files otherwise
          "raw_width": null,                 # stored width of a .dat with extra columns (416)
          "plane_rate_hz": 20000,            # spike planes per second (null: the file's, else 20 kHz)
          "gain": 0.6,                       # the rate convention: expected spikes per plane at
                                             # intensity 1 (null: unknown, each method normalises robustly)
          "window_planes": 256,              # the spike window (null: 256, a simulated window's own length)
          "instants": {"plane": 128},        # or {"centre": true}, {"planes": [..]}, {"times_s": [..]},
                                             # {"every_planes": N, "first_plane": K}
          "ground_truth": "gt/car.png"       # one path (one instant), a list aligned with the
                                             # instants (null where none), or null
        }
      ]
    }

Instants
    ``centre``: the middle plane of the spike file (plane ``T // 2``), else the middle of the event
    recording (the default of :meth:`~neuspike.formats.recording.RecordingReader.key_instant`).
    ``plane`` / ``planes``: key planes of the spike file (the instant is the plane's centre).
    ``times_s``: sensor times in seconds. ``every_planes``: key planes ``first_plane``,
    ``first_plane + N``, ... (default ``first_plane``: half the window, the centre of the first
    whole window) up to the last whose window fits in the file; for an events-only recording the
    same instants counted from its first event at the plane rate. A long recording thus gives one
    row per instant.

Layouts read without a manifest (:func:`infer_manifest`)
    ``spike-gt``: ``spike/NAME.dat`` (or ``.npz``) with ``gt/NAME.png`` (or ``.npy``), the key
    instant at the centre plane, the gain given on the command line (or the ``.npz``'s, else
    unknown); a ``.dat``'s size is the ground truth's. ``events-frames``: one event file, an
    ``images/`` folder and a list ``images.txt`` of ``<t seconds> images/<file>`` lines (the
    Event-Camera Dataset's; where several files could hold events, the one called ``events.*``), an
    instant at each frame's time inside the event recording, that frame as its ground truth. ``files``: spike files in ``spike/`` and event files in ``events/``
    (or at the top of the folder), each a recording of its own at its centre, without ground truth.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from neuspike.errors import InputError, NeuSpikeError, SourceError, one_line
from neuspike.utils.checks import check_int, check_positive, check_positive_int

__all__ = [
    "EVENT_SUFFIXES", "LAYOUTS", "MANIFEST_NAME", "MANIFEST_VERSION", "Instant", "Recording", "infer_manifest",
    "read_manifest", "resolve", "write_manifest",
]

MANIFEST_VERSION = 1
#: Where the command writes the manifest it used (inferred or given) in its output folder.
MANIFEST_NAME = "manifest.json"
#: Layouts :func:`infer_manifest` reads; ``manual`` marks a manifest written by hand.
LAYOUTS = ("spike-gt", "events-frames", "files")
KNOWN_LAYOUTS = (*LAYOUTS, "manual")
SPIKE_SUFFIXES = (".dat", ".npz")
EVENT_SUFFIXES = (".h5", ".hdf5", ".hdf", ".txt", ".npz", ".aedat4")
GT_SUFFIXES = (".png", ".npy")
FRAME_LISTS = ("images.txt", "timestamps.txt")
RECORDING_KEYS = ("name", "spikes", "events", "height", "width", "raw_width", "plane_rate_hz", "gain",
                  "window_planes", "instants", "ground_truth")
INSTANT_KINDS = ("centre", "plane", "planes", "times_s", "every_planes")
_NAME = re.compile(r"^[A-Za-z0-9._-]+$")
#: The longest recording name: names become file names (with a suffix), which most file systems cap at 255 bytes.
MAX_NAME_CHARS = 120


# --------------------------------------------------------------------------- the parsed manifest
@dataclass(frozen=True)
class Recording:
    """One recording of a manifest, checked for form (not yet against its files)."""

    name: str
    spikes: str | None = None
    events: str | None = None
    height: int | None = None
    width: int | None = None
    raw_width: int | None = None
    plane_rate_hz: float | None = None
    gain: float | None = None
    window_planes: int | None = None
    instants: dict[str, Any] = field(default_factory=lambda: {"centre": True})
    ground_truth: Any = None

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in RECORDING_KEYS}

    @property
    def inputs(self) -> frozenset[str]:
        return frozenset(m for m, p in (("spikes", self.spikes), ("events", self.events)) if p is not None)


@dataclass(frozen=True)
class Instant:
    """One reconstruction instant of a recording: how it was named (``plane`` or ``at_s``, what
    :func:`neuspike.formats.samples.load_sample` takes), its sensor time and its ground truth."""

    index: int
    time_s: float
    plane: int | None
    at_s: float | None
    ground_truth: str | None


@dataclass(frozen=True)
class Resolved:
    """A recording checked against its files: its instants, sensor size, rate and gain.

    ``damaged`` holds the one-line reason when the files exist but cannot be read: its instants
    then become failed rows (one per instant given, or one when they depend on the file).
    """

    recording: Recording
    root: str
    height: int | None
    width: int | None
    plane_rate_hz: float | None
    gain: float | None
    gain_source: str
    window_planes: int | None
    instants: tuple[Instant, ...]
    num_planes: int = 0
    span_s: tuple[float, float] | None = None
    damaged: str | None = None
    file_bytes: dict[str, int] = field(default_factory=dict)
    file_sha256: dict[str, str] = field(default_factory=dict)

    def path(self, rel: str | None) -> Path | None:
        return None if rel is None else Path(self.root) / rel

    def identity(self) -> dict[str, Any]:
        """What determines this recording's rows: paths relative to the dataset, and the content of
        every file it reads (sizes and sha256), so a file replaced by another of the same size, or a
        changed ground-truth image, is scored again on a resume."""
        return {"recording": self.recording.as_dict(), "height": self.height, "width": self.width,
                "plane_rate_hz": self.plane_rate_hz, "gain": self.gain, "window_planes": self.window_planes,
                "damaged": self.damaged, "file_bytes": self.file_bytes, "file_sha256": self.file_sha256}


def _fail(name: str, message: str) -> InputError:
    return InputError(f"recording {name}: {message}")


def _opt(name: str, entry: dict[str, Any], key: str, check) -> Any:
    value = entry.get(key)
    if value is None:
        return None
    try:
        return check(key, value)
    except InputError as exc:
        raise _fail(name, str(exc)) from None


def _rate(key: str, value: Any) -> float:
    """A rate or gain: a positive finite number (zero is refused by name)."""
    if not isinstance(value, bool) and isinstance(value, (int, float)) and value == 0:
        raise InputError(f"{key} is 0; it must be a positive number"
                         + (" (expected spikes per plane at intensity 1)" if key == "gain" else " (planes per second)"))
    return check_positive(key, value)


def _path(name: str, entry: dict[str, Any], key: str) -> str | None:
    value = entry.get(key)
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise _fail(name, f"{key}: expected a path relative to the dataset folder, got {value!r}")
    return value


def _instants(name: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {"centre": True}
    if not isinstance(value, dict) or len(set(value) & set(INSTANT_KINDS)) != 1:
        raise _fail(name, f"instants: expected an object with one of {', '.join(INSTANT_KINDS)}, got {value!r}")
    kind = next(k for k in INSTANT_KINDS if k in value)
    allowed = {kind, "first_plane"} if kind == "every_planes" else {kind}
    if set(value) - allowed:
        raise _fail(name, f"instants: unknown keys {sorted(set(value) - allowed)} beside {kind!r}")
    try:
        if kind == "centre":
            if value[kind] is not True:
                raise InputError(f"centre: expected true, got {value[kind]!r}")
        elif kind == "plane":
            check_int("instants.plane", value[kind], minimum=0, what="a plane index")
        elif kind == "planes":
            if not isinstance(value[kind], list) or not value[kind]:
                raise InputError(f"instants.planes: expected a non-empty list of plane indices, got {value[kind]!r}")
            for k in value[kind]:
                check_int("instants.planes", k, minimum=0, what="a plane index")
        elif kind == "times_s":
            times = value[kind]
            if not isinstance(times, list) or not times:
                raise InputError(f"instants.times_s: expected a non-empty list of times in seconds, got {times!r}")
            for t in times:
                if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
                    raise InputError(f"instants.times_s: expected finite times in seconds, got {t!r}")
        else:
            check_positive_int("instants.every_planes", value[kind])
            if value.get("first_plane") is not None:
                check_int("instants.first_plane", value["first_plane"], minimum=0, what="a plane index")
    except InputError as exc:
        raise _fail(name, str(exc)) from None
    return dict(value)


def parse_recording(entry: Any, index: int) -> Recording:
    """One entry of ``recordings``, checked for form."""
    if not isinstance(entry, dict):
        raise InputError(f"recordings[{index}]: expected an object, got {type(entry).__name__}")
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.match(name) or name in (".", "..") or len(name) > MAX_NAME_CHARS:
        shown = name if not isinstance(name, str) or len(name) <= 60 else f"{name[:40]}... ({len(name)} characters)"
        raise InputError(f"recordings[{index}]: name: expected 1 to {MAX_NAME_CHARS} letters, digits, '.', '_' or "
                         f"'-' (not '.' or '..': a name becomes a file name), got {shown!r}")
    unknown = sorted(set(entry) - set(RECORDING_KEYS))
    if unknown:
        raise _fail(name, f"unknown keys {unknown} (known: {', '.join(RECORDING_KEYS)})")
    spikes, events = _path(name, entry, "spikes"), _path(name, entry, "events")
    if spikes is None and events is None:
        raise _fail(name, "names neither a spike file nor an event file")
    if spikes is not None and Path(spikes).suffix.lower() not in SPIKE_SUFFIXES:
        raise _fail(name, f"spikes: expected a {' or '.join(SPIKE_SUFFIXES)} file, got {spikes!r}")
    height = _opt(name, entry, "height", check_positive_int)
    width = _opt(name, entry, "width", check_positive_int)
    if (height is None) != (width is None):
        raise _fail(name, "give both height and width, or neither")
    instants = _instants(name, entry.get("instants"))
    gt = entry.get("ground_truth")
    if gt is not None:
        many = isinstance(gt, list)
        for g in (gt if many else [gt]):
            if g is not None and (not isinstance(g, str) or not g.strip()):
                raise _fail(name, f"ground_truth: expected paths relative to the dataset folder, got {g!r}")
        if many and not any(k in instants for k in ("planes", "times_s")):
            raise _fail(name, "ground_truth: a list needs a list of instants (planes or times_s) to align with")
        count = len(instants.get("planes", instants.get("times_s", [])))
        if many and len(gt) != count:
            raise _fail(name, f"ground_truth: {len(gt)} entries for {count} instants")
        if not many and any(k in instants for k in ("planes", "times_s", "every_planes")) and \
                len(instants.get("planes", instants.get("times_s", [0, 0]))) != 1:
            raise _fail(name, "ground_truth: one image for several instants; give a list aligned with them")
    return Recording(
        name=name, spikes=spikes, events=events, height=height, width=width,
        raw_width=_opt(name, entry, "raw_width", check_positive_int),
        plane_rate_hz=_opt(name, entry, "plane_rate_hz", _rate), gain=_opt(name, entry, "gain", _rate),
        window_planes=_opt(name, entry, "window_planes", check_positive_int), instants=instants, ground_truth=gt,
    )


@dataclass(frozen=True)
class Manifest:
    layout: str
    recordings: tuple[Recording, ...]
    notes: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {"manifest": MANIFEST_VERSION, "layout": self.layout,
                "recordings": [r.as_dict() for r in self.recordings]}


def parse_manifest(data: Any, *, source: str = "manifest") -> Manifest:
    """A manifest from its JSON data (checked for form).

    Raises
    ------
    InputError
        A wrong version, an unknown layout, no recordings, repeated names, a malformed entry.
    """
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a JSON object, got {type(data).__name__}")
    if data.get("manifest") != MANIFEST_VERSION:
        raise InputError(f"{source}: expected \"manifest\": {MANIFEST_VERSION}, got {data.get('manifest')!r}")
    layout = data.get("layout", "manual")
    if layout not in KNOWN_LAYOUTS:
        raise InputError(f"{source}: unknown layout {layout!r}; known: {', '.join(KNOWN_LAYOUTS)}")
    unknown = sorted(set(data) - {"manifest", "layout", "recordings", "notes"})
    if unknown:
        raise InputError(f"{source}: unknown keys {unknown}")
    entries = data.get("recordings")
    if not isinstance(entries, list) or not entries:
        raise InputError(f"{source}: expected a non-empty list \"recordings\"")
    recordings = tuple(parse_recording(e, i) for i, e in enumerate(entries))
    names = [r.name for r in recordings]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise InputError(f"{source}: recording names repeat: {', '.join(repeated)}")
    return Manifest(layout=layout, recordings=recordings)


def read_manifest(path: str | os.PathLike) -> Manifest:
    """Read and check (for form) a manifest file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"manifest {p}: no such file")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        raise InputError(f"manifest {p}: not readable JSON ({one_line(exc)})") from None
    return parse_manifest(data, source=f"manifest {p}")


def write_manifest(path: str | os.PathLike, manifest: Manifest) -> Path:
    """Write ``manifest`` as indented JSON, atomically."""
    from neuspike.utils.atomic import write_text

    return write_text(Path(path), json.dumps(manifest.as_dict(), indent=2) + "\n")


# --------------------------------------------------------------------------- inference
def _files(folder: Path, suffixes: Sequence[str]) -> list[Path]:
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes
                  and not p.name.startswith("."))


def _is_event_file(path: Path) -> bool:
    if path.suffix.lower() not in EVENT_SUFFIXES or path.name in FRAME_LISTS:
        return False
    if path.suffix.lower() == ".npz":
        from neuspike.formats.recording import _is_event_npz

        return _is_event_npz(path)
    return path.suffix.lower() != ".txt" or path.name not in ("calib.txt",)


#: The subfolders each layout reads.
_LAYOUT_FOLDERS = {"spike-gt": ("spike", "gt"), "events-frames": ("images",), "files": ("spike", "events")}


def detect_layout(folder: Path) -> str:
    """The layout of ``folder`` (one of :data:`LAYOUTS`).

    Raises
    ------
    InputError
        A folder in none of them (the message says what each needs).
    """
    if (folder / "spike").is_dir() and (folder / "gt").is_dir():
        return "spike-gt"
    if any((folder / n).is_file() for n in FRAME_LISTS) and (folder / "images").is_dir():
        return "events-frames"
    if _files(folder / "spike", SPIKE_SUFFIXES) or [p for p in _files(folder / "events", EVENT_SUFFIXES)
                                                   if _is_event_file(p)] \
            or [p for p in _files(folder, (*SPIKE_SUFFIXES, *EVENT_SUFFIXES)) if p.suffix.lower() != ".txt"]:
        return "files"
    raise InputError(
        f"dataset {folder}: unknown layout; expected spike/ with gt/ (spike-gt), an event file with images/ and "
        f"images.txt (events-frames), or spike files in spike/ and event files in events/ (files); or give --manifest"
    )


def infer_manifest(folder: str | os.PathLike, *, layout: str = "auto", gain: float | None = None,
                   plane_rate_hz: float | None = None, window_planes: int | None = None,
                   height: int | None = None, width: int | None = None) -> Manifest:
    """The manifest of a folder in one of :data:`LAYOUTS` (module docstring).

    Parameters
    ----------
    folder : path
    layout : ``"auto"`` or one of :data:`LAYOUTS`
    gain, plane_rate_hz, window_planes, height, width
        Written into every spike recording's entry (``None``: the files' own, or unknown).

    Raises
    ------
    InputError
        An unknown layout, a folder that is not in the layout, no recording found.
    """
    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"dataset {root}: not a folder")
    if layout == "auto":
        layout = detect_layout(root)
    elif layout not in LAYOUTS:
        raise InputError(f"unknown layout {layout!r}; known: auto, {', '.join(LAYOUTS)}")
    if gain is not None:
        gain = _rate("gain", gain)
    if plane_rate_hz is not None:
        plane_rate_hz = _rate("plane_rate_hz", plane_rate_hz)
    common = {"plane_rate_hz": plane_rate_hz, "window_planes": window_planes}
    notes: list[str] = []
    if layout == "spike-gt":
        recordings = _infer_spike_gt(root, gain, common, height, width, notes)
    elif layout == "events-frames":
        recordings = [_infer_events_frames(root, common, notes)]
    else:
        recordings = _infer_files(root, gain, common, height, width)
    if not recordings:
        raise InputError(f"dataset {root}: no recording found for the {layout} layout")
    used = _LAYOUT_FOLDERS[layout]
    for sub in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        if sub.name not in used:  # said, not skipped silently
            hint = (" (a video is a scene for the simulator: python -m neuspike.simulate --video FOLDER)"
                    if sub.name in ("video", "videos") else "")
            notes.append(f"{sub.name}/ is not read by the {layout} layout{hint}")
    return Manifest(layout=layout, recordings=tuple(parse_recording(r, i) for i, r in enumerate(recordings)),
                    notes=tuple(notes))


def _centre_plane(path: Path, height: int | None, width: int | None) -> dict[str, Any]:
    """``{"plane": T // 2}`` when the file's length can be read, else ``{"centre": True}`` (the same rule)."""
    try:
        from neuspike.formats.recording import spike_file_extent

        _, total, _, _ = spike_file_extent(path, height=height, width=width, raw_width=None, rate_given=None,
                                           start_given=None)
        return {"plane": total // 2}
    except (NeuSpikeError, OSError, ValueError):
        return {"centre": True}  # a damaged file: its rows say why


def _gt_size(path: Path) -> tuple[int, int] | None:
    try:
        if path.suffix.lower() == ".npy":
            import numpy as np

            a = np.load(path, mmap_mode="r", allow_pickle=False)
            return (int(a.shape[0]), int(a.shape[1])) if a.ndim == 2 else None
        import cv2

        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        return None if img is None else (int(img.shape[0]), int(img.shape[1]))
    except (OSError, ValueError):
        return None


def _infer_spike_gt(root: Path, gain: float | None, common: dict[str, Any], height: int | None, width: int | None,
                    notes: list[str]) -> list[dict[str, Any]]:
    out = []
    for sp in _files(root / "spike", SPIKE_SUFFIXES):
        gt = next((root / "gt" / f"{sp.stem}{s}" for s in GT_SUFFIXES if (root / "gt" / f"{sp.stem}{s}").is_file()), None)
        h, w = height, width
        if gt is None:
            notes.append(f"spike/{sp.name} has no gt/{sp.stem}.png: no-reference measures only")
        elif h is None and sp.suffix.lower() == ".dat":
            size = _gt_size(gt)
            if size is None:  # the .dat has no header: its size was to come from this image
                raise InputError(f"dataset {root}: gt/{gt.name} is not a readable image, and spike/{sp.name} (a .dat "
                                 f"without a header) takes its size from it: repair or remove the image, or give "
                                 f"--height and --width")
            h, w = size
            notes.append(_dat_size_note(sp, gt, h, w))
        out.append({"name": sp.stem, "spikes": f"spike/{sp.name}", "height": h, "width": w, "gain": gain, **common,
                    "instants": _centre_plane(sp, h, w),
                    "ground_truth": f"gt/{gt.name}" if gt is not None else None})
    return out


def _dat_size_note(dat: Path, gt: Path, height: int, width: int) -> str:
    """What the manifest says where a headerless ``.dat`` takes its size from its ground truth: the size, and
    when the file is also a whole number of the Vidar's 400x250 planes and the image is another size, that
    the size is ambiguous (a downsized ground truth would read the recording as noise)."""
    from neuspike.streams import VIDAR_SIZE

    note = f"spike/{dat.name}: a .dat has no header; read at {width}x{height}, the size of gt/{gt.name}"
    vidar_w, vidar_h = VIDAR_SIZE
    plane_bytes = vidar_w * vidar_h // 8
    if (width, height) != (vidar_w, vidar_h) and dat.stat().st_size % plane_bytes == 0:
        note += (f" (the file is also a whole number of the Vidar's {vidar_w}x{vidar_h} planes: if that is its "
                 f"sensor, give --height {vidar_h} --width {vidar_w} and a ground truth of that size)")
    return note


def _infer_events_frames(root: Path, common: dict[str, Any], notes: list[str]) -> dict[str, Any]:
    events = [p for p in sorted(root.iterdir()) if p.is_file() and _is_event_file(p)]
    named = [p for p in events if p.stem == "events"]  # events.txt beside imu.txt, groundtruth.txt, ...
    events = named or events
    if len(events) != 1:
        found = ", ".join(p.name for p in events) or "none"
        raise InputError(f"dataset {root}: the events-frames layout needs exactly one event file beside images/, "
                         f"found {found}")
    listing = next(root / n for n in FRAME_LISTS if (root / n).is_file())
    times, frames = [], []
    for number, line in enumerate(listing.read_text(encoding="utf-8").splitlines(), 1):
        parts = line.split()
        if not parts or line.lstrip().startswith("#"):
            continue
        try:
            t = float(parts[0])
        except ValueError:
            raise InputError(f"dataset {root}: {listing.name} line {number}: expected '<t seconds> images/<file>', "
                             f"got {line!r}") from None
        if len(parts) < 2 or not math.isfinite(t):
            raise InputError(f"dataset {root}: {listing.name} line {number}: expected '<t seconds> images/<file>', "
                             f"got {line!r}")
        rel = parts[-1] if "/" in parts[-1] else f"images/{parts[-1]}"
        times.append(t)
        frames.append(rel)
    if not times:
        raise InputError(f"dataset {root}: {listing.name} lists no frames")
    span = _event_span(events[0])
    if span is not None:
        keep = [i for i, t in enumerate(times) if span[0] <= t <= span[1]]
        if len(keep) < len(times):
            notes.append(f"{len(times) - len(keep)} of {len(times)} frames lie outside the events "
                         f"[{span[0]:.6f}, {span[1]:.6f}] s and were left out")
        if not keep:
            raise InputError(f"dataset {root}: no frame of {listing.name} lies inside the event recording "
                             f"[{span[0]}, {span[1]}] s")
        times, frames = [times[i] for i in keep], [frames[i] for i in keep]
    window = common.get("window_planes")
    return {"name": events[0].stem, "events": events[0].name, **common, "window_planes": window,
            "instants": {"times_s": times}, "ground_truth": frames}


def _event_span(path: Path) -> tuple[float, float] | None:
    try:
        from neuspike.formats.recording import open_recording

        with open_recording(events=path) as rec:
            return rec.event_span_s()
    except (NeuSpikeError, OSError, ValueError):
        return None  # a damaged file: its rows say why


def _infer_files(root: Path, gain: float | None, common: dict[str, Any], height: int | None,
                 width: int | None) -> list[dict[str, Any]]:
    out = []
    spikes = _files(root / "spike", SPIKE_SUFFIXES) + [p for p in _files(root, SPIKE_SUFFIXES)
                                                       if not _is_event_file(p)]
    for sp in spikes:
        out.append({"name": sp.stem, "spikes": sp.relative_to(root).as_posix(), "height": height, "width": width,
                    "gain": gain, **common, "instants": _centre_plane(sp, height, width)})
    for ev in [p for p in _files(root / "events", EVENT_SUFFIXES) + _files(root, EVENT_SUFFIXES) if _is_event_file(p)]:
        out.append({"name": ev.stem, "events": ev.relative_to(root).as_posix(), **common,
                    "instants": {"centre": True}})
    return out


# --------------------------------------------------------------------------- resolution
def resolve(manifest: Manifest, root: str | os.PathLike, *, allow_outside: bool = False) -> list[Resolved]:
    """Check every recording of ``manifest`` against the files under ``root`` and list its instants.

    Missing files, a size that disagrees with the files, a ground truth of another size, an instant
    outside the recording: each raises :class:`InputError` naming the recording, before any work.
    A file that exists but cannot be read is not refused here: the recording is marked ``damaged``
    and its rows fail with the reason, while the others run.

    Every file a recording names must lie inside ``root`` once links are followed (no absolute path,
    no ``..`` out of it, no link that leads out of it) unless ``allow_outside``: a manifest cannot
    make the run read, and quote into its outputs, a file the user did not put in the dataset.
    """
    base = Path(root)
    if not base.is_dir():
        raise InputError(f"dataset {base}: not a folder")
    if not allow_outside:
        for rec in manifest.recordings:
            _check_inside(rec, base)
    return [_resolve_one(r, base) for r in manifest.recordings]


def _check_inside(rec: Recording, base: Path) -> None:
    """Refuse a recording whose files lead out of the dataset folder (:func:`resolve`)."""
    inside = base.resolve()
    gts = rec.ground_truth if isinstance(rec.ground_truth, list) else [rec.ground_truth]
    for key, rel in (("spikes", rec.spikes), ("events", rec.events), *(("ground_truth", g) for g in gts)):
        if rel is None:
            continue
        target = (base / rel).resolve()
        if Path(rel).is_absolute() or not target.is_relative_to(inside):
            raise _fail(rec.name, f"{key}: {rel} leads out of the dataset folder {base}; recordings are read "
                                  f"from inside it (--allow-outside reads them anyway)")


def _sha256(path: Path) -> str:
    """The sha256 of a file's bytes (read in blocks: a recording may be large)."""
    import hashlib

    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def _resolve_one(rec: Recording, base: Path) -> Resolved:
    from neuspike.errors import FormatError
    from neuspike.formats.recording import open_recording

    files = {}
    for kind, rel in (("spike", rec.spikes), ("event", rec.events)):
        if rel is not None:
            p = base / rel
            if not p.is_file():
                raise _fail(rec.name, f"{kind} file {rel} does not exist (in {base})")
            files[rel] = p.stat().st_size
    gts = rec.ground_truth if isinstance(rec.ground_truth, list) else [rec.ground_truth]
    for g in gts:
        if g is not None and not (base / g).is_file():
            raise _fail(rec.name, f"ground truth {g} does not exist (in {base})")
    digests = {rel: _sha256(base / rel) for rel in [*files, *(g for g in gts if g is not None)]}
    try:
        reader = open_recording(spikes=base / rec.spikes if rec.spikes else None,
                                events=base / rec.events if rec.events else None, height=rec.height,
                                width=rec.width, raw_width=rec.raw_width, plane_rate_hz=rec.plane_rate_hz,
                                gain=rec.gain)
    except InputError as exc:  # a size or option that disagrees with the files
        raise _fail(rec.name, str(exc)) from None
    except (FormatError, SourceError, OSError, ValueError, KeyError) as exc:
        return _damaged(rec, base, files, one_line(exc), digests=digests)
    with reader:
        try:
            span = reader.span_s()
        except (FormatError, InputError, OSError, ValueError) as exc:
            return _damaged(rec, base, files, one_line(exc), reader, digests=digests)
        window = rec.window_planes if rec.window_planes is not None else reader.default_window_planes()
        instants = _instants_of(rec, reader, span, window)
        h, w = reader.height, reader.width
        resolved = Resolved(recording=rec, root=str(base), height=h, width=w, plane_rate_hz=reader.plane_rate_hz,
                            gain=reader.gain, gain_source=reader.gain_source, window_planes=window,
                            instants=instants, num_planes=reader.num_planes, span_s=span, file_bytes=files,
                            file_sha256=digests)
    _check_ground_truth(rec, base, instants, h, w)
    return resolved


def _damaged(rec: Recording, base: Path, files: dict[str, int], reason: str, reader: Any = None, *,
             digests: dict[str, str]) -> Resolved:
    """A recording whose files cannot be read: the instants the manifest names (one when they depend on the file)."""
    inst = rec.instants
    gts = rec.ground_truth if isinstance(rec.ground_truth, list) else [rec.ground_truth]
    if "planes" in inst or "plane" in inst:
        planes = inst.get("planes", [inst.get("plane")])
        instants = tuple(Instant(i, math.nan, k, None, gts[i] if i < len(gts) else None) for i, k in enumerate(planes))
    elif "times_s" in inst:
        instants = tuple(Instant(i, float(t), None, float(t), gts[i] if i < len(gts) else None)
                         for i, t in enumerate(inst["times_s"]))
    else:
        instants = (Instant(0, math.nan, None, None, gts[0]),)
    return Resolved(recording=rec, root=str(base), height=rec.height, width=rec.width,
                    plane_rate_hz=rec.plane_rate_hz, gain=rec.gain, gain_source="given" if rec.gain else "unknown",
                    window_planes=rec.window_planes, instants=instants, damaged=reason, file_bytes=files,
                    file_sha256=digests)


#: The most instants one recording may ask for (each is a reconstruction by every method): beyond it the
#: manifest is refused before any work, with the count and a step that fits.
MAX_INSTANTS = 20_000


def _check_instant_count(name: str, count: int, step: int) -> None:
    if count > MAX_INSTANTS:
        fits = math.ceil(step * count / MAX_INSTANTS)
        raise _fail(name, f"instants.every_planes {step} asks for {count:,} instants (each reconstructed by every "
                          f"method); at most {MAX_INSTANTS:,} are run: take every_planes >= {fits:,}")


def _instants_of(rec: Recording, reader: Any, span: tuple[float, float], window: int) -> tuple[Instant, ...]:
    inst = rec.instants
    gts = rec.ground_truth if isinstance(rec.ground_truth, list) else None
    one_gt = rec.ground_truth if not isinstance(rec.ground_truth, list) else None
    rate = reader.plane_rate_hz
    spikes = reader.spikes_path is not None

    def at_plane(i: int, k: int, gt: str | None) -> Instant:
        try:
            t = reader.key_instant(plane=k)
        except InputError as exc:
            raise _fail(rec.name, f"key instant: {exc}") from None
        return Instant(i, t, k, None, gt)

    def at_time(i: int, t: float, gt: str | None) -> Instant:
        try:
            t = reader.key_instant(at_s=float(t))
        except InputError as exc:
            raise _fail(rec.name, f"key instant: {exc}") from None
        return Instant(i, t, None, float(t), gt)

    if "centre" in inst:
        if spikes:
            return (at_plane(0, reader.num_planes // 2, one_gt),)
        try:
            return (Instant(0, reader.key_instant(), None, None, one_gt),)
        except InputError as exc:
            raise _fail(rec.name, f"key instant: {exc}") from None
    if "plane" in inst:
        if not spikes:
            raise _fail(rec.name, "instants.plane needs a spike file; give times_s for an event recording")
        return (at_plane(0, int(inst["plane"]), one_gt),)
    if "planes" in inst:
        if not spikes:
            raise _fail(rec.name, "instants.planes needs a spike file; give times_s for an event recording")
        return tuple(at_plane(i, int(k), gts[i] if gts else one_gt) for i, k in enumerate(inst["planes"]))
    if "times_s" in inst:
        return tuple(at_time(i, t, gts[i] if gts else one_gt) for i, t in enumerate(inst["times_s"]))
    step = int(inst["every_planes"])
    first = inst.get("first_plane")
    first = window // 2 if first is None else int(first)
    if spikes:
        total = reader.num_planes
        last = max(total - (window - window // 2), min(first, total - 1))
        if first >= total:
            raise _fail(rec.name, f"key instant: instants.first_plane {first} is outside the spike file's {total} planes")
        _check_instant_count(rec.name, len(range(first, last + 1, step)), step)
        return tuple(at_plane(i, k, None) for i, k in enumerate(range(first, last + 1, step)))
    t0, t1 = span
    count = math.floor(((t1 - t0) * rate - 0.5 - first) / step + 1e-9) + 1
    _check_instant_count(rec.name, count, step)
    times = [t0 + (first + i * step + 0.5) / rate for i in range(max(0, count))]
    if not times:
        raise _fail(rec.name, f"key instant: the first instant (plane {first} at {rate:g} planes/s after the first "
                              f"event) lies after the last event")
    return tuple(Instant(i, t, None, t, None) for i, t in enumerate(times))


def _check_ground_truth(rec: Recording, base: Path, instants: Sequence[Instant], height: int, width: int) -> None:
    """Every ground truth has the sensor's size (read once per file)."""
    seen: set[str] = set()
    for inst in instants:
        g = inst.ground_truth
        if g is None or g in seen:
            continue
        seen.add(g)
        size = _gt_size(base / g)
        if size is None:
            continue  # unreadable: the row fails with the reader's message
        if size != (height, width):
            raise _fail(rec.name, f"ground truth {g} is {size[1]}x{size[0]}, the sensor {width}x{height}")
