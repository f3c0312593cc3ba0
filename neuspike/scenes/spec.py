"""The scene specification: plain, validated, hashable data.

A :class:`SceneSpec` says everything a scene is made of; :func:`neuspike.scenes.make_scene` turns
it into a renderable :class:`neuspike.scenes.Scene`. Two equal specs give scenes that render the
same bytes.

Coordinates
-----------
Pixel ``(row i, column j)`` of a view has its centre at ``x = j``, ``y = i`` (pixels; ``y`` points
down). The view centre is ``((W - 1) / 2, (H - 1) / 2)``.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from typing import Any

from neuspike.conditions import Effect
from neuspike.errors import InputError
from neuspike.utils.checks import check_finite, check_int

#: Every scene kind.
KINDS: tuple[str, ...] = ("pan", "zoom", "fan", "still", "video", "dead_leaves")

#: The kinds that render a ``crop`` of their view natively (only the crop's pixels are computed).
CROP_KINDS: tuple[str, ...] = ("pan", "zoom", "fan", "still")

#: The view size of the photograph kinds when ``size`` is not given: the Vidar sensor.
DEFAULT_SIZE: tuple[int, int] = (400, 250)

#: The frame rate assumed for a folder of images without a timestamps file.
DEFAULT_FOLDER_FPS: float = 25.0

#: The largest ``|zoom_rate_hz * t|`` a zoom scene renders (view scale within exp(+-30)).
MAX_ZOOM_EXPONENT: float = 30.0


_number = check_finite


def _pair(name: str, value: Any) -> tuple[float, float]:
    try:
        items = tuple(value)
    except TypeError:
        raise InputError(f"{name}: expected a pair of numbers, got {value!r}") from None
    if len(items) != 2:
        raise InputError(f"{name}: expected a pair of numbers, got {len(items)} items: {value!r}")
    return _number(f"{name}[0]", items[0]), _number(f"{name}[1]", items[1])


def _whole(name: str, value: Any, minimum: int) -> int:
    return check_int(name, value, minimum=minimum)


def _size(value: Any) -> tuple[int, int]:
    try:
        items = tuple(value)
    except TypeError:
        raise InputError(f"size: expected (width, height), got {value!r}") from None
    if len(items) != 2:
        raise InputError(f"size: expected (width, height), got {len(items)} items: {value!r}")
    return _whole("size width", items[0], 1), _whole("size height", items[1], 1)


def _crop(value: Any, kind: str, size: tuple[int, int] | None) -> tuple[int, int, int, int]:
    if kind not in CROP_KINDS:
        raise InputError(f"crop: only kinds {', '.join(CROP_KINDS)} render a crop, got kind {kind!r}")
    try:
        items = tuple(value)
    except TypeError:
        raise InputError(f"crop: expected (x, y, width, height), got {value!r}") from None
    if len(items) != 4:
        raise InputError(f"crop: expected (x, y, width, height), got {len(items)} items: {value!r}")
    x, y = _whole("crop x", items[0], 0), _whole("crop y", items[1], 0)
    w, h = _whole("crop width", items[2], 1), _whole("crop height", items[3], 1)
    if size is not None and (x + w > size[0] or y + h > size[1]):
        raise InputError(f"crop: ({x}, {y}, {w}, {h}) does not lie inside the {size[0]}x{size[1]} view")
    return x, y, w, h


def _path(name: str, value: Any) -> str:
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    if not isinstance(value, str) or not value:
        raise InputError(f"{name}: expected a non-empty path or name, got {value!r}")
    return value


@dataclass(frozen=True)
class SceneSpec:
    """What a scene is made of (plain data; validated on construction).

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`: ``"pan"``, ``"zoom"``, ``"fan"``, ``"still"``, ``"video"``.
    image : str
        The photograph of the photograph kinds: a name in
        :data:`neuspike.scenes.BUNDLED_PHOTOS` (these names win over a file of the same name) or
        a path to an image file (anything OpenCV decodes, or a ``.npy`` array). Ignored by
        ``"video"``.
    video : str or None
        ``"video"`` only (required there): a video file (decoded with OpenCV), a folder of images,
        or a timestamps file. A folder holding ``images.txt`` uses it as its timestamps file;
        otherwise its image files are taken in name order, ``1 / fps`` apart.
    timestamps : str or None
        ``"video"`` only: a timestamps file, lines ``<t seconds> <relative/path.png>`` (paths
        relative to the file's folder; blank lines and ``#`` comments skipped). Overrides a
        folder's ``images.txt``.
    fps : float or None
        ``"video"`` only: frames per second when no timestamps file is used. ``None`` means the
        video file's own rate, or :data:`DEFAULT_FOLDER_FPS` (25) for a folder.
    size : (int, int) or None
        ``(width, height)`` of the view in pixels. ``None`` means :data:`DEFAULT_SIZE` (400x250)
        for the photograph kinds (stored resolved) and the source's own size for ``"video"``.
    velocity_px_s : (float, float)
        ``"pan"``: the photograph's velocity ``(vx, vy)`` in view pixels per second of scene time.
    zoom_rate_hz : float
        ``"zoom"``: the view scale grows as ``exp(zoom_rate_hz * t)`` (negative = moving back).
    focus : (float, float) or None
        ``"zoom"``: the fixed point of the expansion; ``"fan"``: the hub. Pixels, ``(x, y)``;
        ``None`` = the view centre.
    rpm : float
        ``"fan"``: revolutions per minute; positive turns clockwise on screen (``y`` down).
    blades : int
        ``"fan"``: number of blades, evenly spaced.
    blade_width_deg : float
        ``"fan"``: angular width of one blade, ``0 < blade_width_deg * blades < 360``.
    blade_contrast : float
        ``"fan"``: radiance ratio blade / background at the same pixel, >= 0 (below 1 darker,
        above 1 brighter). The blades modulate the background multiplicatively.
    dynamic_range : float or None
        ``None``: radiance = ``peak * v`` for luma ``v`` in [0, 1]. A number ``D >= 1``: radiance
        = ``peak * D ** (v - 1)``, so white maps to ``peak``, black to ``peak / D`` (max/min = D).
    peak : float
        Radiance of luma 1 (1.0 = reference white; may exceed 1 for HDR scenes), > 0.
    upsample : int or None
        ``"video"`` only: with a factor ``U`` the time fraction between two real frames snaps to
        the nearest multiple of ``1 / U`` (the grid of ``U`` times the frame rate, anchored on
        every real frame); ``None`` = continuous interpolation.
    crop : (int, int, int, int) or None
        ``(x, y, width, height)``: render only this window of the view (pixels, inside ``size``),
        e.g. a 128x128 training crop of a 400x250 scene; its pixels equal those of the full view
        exactly, and only they are computed. ``None`` renders the whole view. Kinds
        :data:`CROP_KINDS` only.
    leaf_min_radius : float or None
        ``"dead_leaves"`` only: the smallest background leaf's radius as a fraction of the view's
        shorter side, in (0, 0.3). ``None`` (the default) paints the classic scale-invariant picture
        (radii from 1.5 px, hundreds of leaves); a value paints tens of leaves from that radius up, so
        the picture has wide uniform regions (the texture and the shading stay).
    effects : tuple of Effect
        Sensor effects this scene calls for (the simulators run them); no effect on rendering.
    seed : int
        Seed for random textures, >= 0. No current kind draws random numbers; it is recorded.

    Raises
    ------
    InputError
        For any field outside its documented domain, or a video-only field on another kind.
    """

    kind: str
    image: str = "camera"
    video: str | None = None
    timestamps: str | None = None
    fps: float | None = None
    size: tuple[int, int] | None = None
    velocity_px_s: tuple[float, float] = (1000.0, 0.0)
    zoom_rate_hz: float = 5.0
    focus: tuple[float, float] | None = None
    rpm: float = 1500.0
    blades: int = 3
    blade_width_deg: float = 30.0
    blade_contrast: float = 0.25
    dynamic_range: float | None = None
    peak: float = 1.0
    upsample: int | None = None
    crop: tuple[int, int, int, int] | None = None
    leaf_min_radius: float | None = None
    effects: tuple[Effect, ...] = field(default=())
    seed: int = 0

    def __post_init__(self) -> None:
        put = object.__setattr__
        if not isinstance(self.kind, str) or self.kind not in KINDS:
            raise InputError(f"kind: expected one of {', '.join(KINDS)}, got {self.kind!r}")
        put(self, "image", _path("image", self.image))
        video_only = {"video": self.video, "timestamps": self.timestamps, "fps": self.fps,
                      "upsample": self.upsample}
        if self.kind == "video":
            if self.video is None:
                raise InputError("video: a 'video' scene needs a video file or folder, got None")
            put(self, "video", _path("video", self.video))
            if self.timestamps is not None:
                put(self, "timestamps", _path("timestamps", self.timestamps))
            if self.fps is not None:
                fps = _number("fps", self.fps)
                if fps <= 0:
                    raise InputError(f"fps: expected a positive number, got {self.fps!r}")
                put(self, "fps", fps)
            if self.upsample is not None:
                put(self, "upsample", _whole("upsample", self.upsample, 1))
        else:
            given = [k for k, v in video_only.items() if v is not None]
            if given:
                raise InputError(
                    f"{', '.join(given)}: only a 'video' scene takes these, got kind {self.kind!r}"
                )
        if self.size is None:
            if self.kind != "video":
                put(self, "size", DEFAULT_SIZE)
        else:
            put(self, "size", _size(self.size))
        put(self, "velocity_px_s", _pair("velocity_px_s", self.velocity_px_s))
        put(self, "zoom_rate_hz", _number("zoom_rate_hz", self.zoom_rate_hz))
        if self.focus is not None:
            put(self, "focus", _pair("focus", self.focus))
        put(self, "rpm", _number("rpm", self.rpm))
        blades = _whole("blades", self.blades, 1)
        put(self, "blades", blades)
        width = _number("blade_width_deg", self.blade_width_deg)
        if not 0 < width * blades < 360:
            raise InputError(
                f"blade_width_deg: expected 0 < blade_width_deg * blades < 360, got {width!r} * {blades}"
            )
        put(self, "blade_width_deg", width)
        contrast = _number("blade_contrast", self.blade_contrast)
        if contrast < 0:
            raise InputError(f"blade_contrast: expected a radiance ratio >= 0, got {self.blade_contrast!r}")
        put(self, "blade_contrast", contrast)
        if self.dynamic_range is not None:
            d = _number("dynamic_range", self.dynamic_range)
            if d < 1:
                raise InputError(f"dynamic_range: expected a ratio >= 1 or None, got {self.dynamic_range!r}")
            put(self, "dynamic_range", d)
        peak = _number("peak", self.peak)
        if peak <= 0:
            raise InputError(f"peak: expected a positive radiance, got {self.peak!r}")
        put(self, "peak", peak)
        if self.crop is not None:
            put(self, "crop", _crop(self.crop, self.kind, self.size))
        if self.leaf_min_radius is not None:
            if self.kind != "dead_leaves":
                raise InputError(f"leaf_min_radius: only a 'dead_leaves' scene takes it, got kind {self.kind!r}")
            r = _number("leaf_min_radius", self.leaf_min_radius)
            if not 0 < r < 0.3:
                raise InputError(f"leaf_min_radius: expected a fraction of the shorter side in (0, 0.3), got {r!r}")
            put(self, "leaf_min_radius", r)
        try:
            effects = tuple(self.effects)
        except TypeError:
            raise InputError(f"effects: expected a tuple of Effect, got {self.effects!r}") from None
        names: list[str] = []
        for e in effects:
            if not isinstance(e, Effect):
                raise InputError(f"effects: expected Effect objects (neuspike.conditions.effect), got {e!r}")
            if e.name in names:
                raise InputError(f"effects: {e.name!r} is declared twice")
            names.append(e.name)
        put(self, "effects", effects)
        put(self, "seed", _whole("seed", self.seed, 0))

    def as_dict(self) -> dict[str, Any]:
        """The fields as JSON-serialisable data (effects as dicts, pairs as lists)."""
        out = asdict(self)
        out["effects"] = [e.as_dict() for e in self.effects]
        for key in ("crop", "leaf_min_radius"):
            if out[key] is None:  # absent rather than null: the dict (and what is derived from it,
                del out[key]      # cell seeds, cache keys) stays that of a spec without the field
        for key in ("size", "velocity_px_s", "focus", "crop"):
            if out.get(key) is not None:
                out[key] = list(out[key])
        return out
