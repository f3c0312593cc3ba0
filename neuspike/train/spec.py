"""The frozen training specification: one :class:`TrainSpec` with a data section, saved as JSON.

The data section says what a training item is:

* :class:`WindowData` (``kind = "windows"``): single simulated windows (spike planes, events and
  the ground truth at the key instant) for feed-forward networks (NeuSpike-Net);
* :class:`SequenceData` (``kind = "sequences"``): sequences of consecutive event windows of one
  moving scene, with their targets and exact flow, for recurrent networks (E2VID, FireNet).

Everything else (optimiser, schedule, validation and checkpoint cadence, device, precision,
starting weights) is shared. Spec files written by the earlier trainers (the flat single-window
spec and the sequence spec with ``lr_warmup_steps``) are refused by :func:`spec_from_dict`, naming
the commit that still reads them: they served only runs that left the tree. This module imports nothing heavy (the command's ``--help`` stays fast).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, ClassVar, Mapping, Sequence, Union

from neuspike.errors import InputError
from neuspike.train.mixture import SWEEP_GRID_NAMES, legacy_mixture, mixture_key, resolve_mixture
from neuspike.train.terms import DEFAULT_LOSSES, DEFAULT_SEQUENCE_LOSSES, legacy_losses, resolve_losses
from neuspike.utils.checks import check_int

__all__ = [
    "DATA_KINDS", "KIND_WEIGHTS", "KINDS", "LIGHTS", "MOTIONS", "NOISE_LEVELS", "SEQUENCE_KINDS", "SWEEP_POINTS",
    "SequenceData", "TrainSpec", "WindowData", "learning_rate", "load_spec", "spec_from_dict", "with_out_dir",
]

#: Scene kinds drawn for single windows and their probabilities (``dead_leaves`` is procedural).
KIND_WEIGHTS: dict[str, float] = {"pan": 0.3, "zoom": 0.12, "fan": 0.13, "still": 0.05, "dead_leaves": 0.4}
#: Scene kinds of sequence items by default, and every kind a sequence item can be drawn from.
KINDS = ("pan", "zoom", "fan")
SEQUENCE_KINDS = KINDS + ("dead_leaves", "broad_leaves")  # broad_leaves: dead leaves with wide uniform regions
#: Motion scales S and light scales L of sequence items.
MOTIONS = (16, 32, 64, 128, 256)
LIGHTS = (1 / 2, 1 / 4, 1 / 8, 1 / 16, 1 / 32)
#: The noise levels of :mod:`neuspike.conditions` (repeated here so that this module stays light;
#: a test checks they agree).
NOISE_LEVELS = ("none", "small", "medium", "high")
#: The full sweeps' 12 distinct points, (L, S, noise): the light sweep at S = 128, the motion sweep at
#: L = 1/4 (its S = 128 is the light sweep's L = 1/4), the noise test at L = 1/4, S = 128.
SWEEP_POINTS: tuple[tuple[float, int, str], ...] = (
    tuple((light, 128, "none") for light in sorted(LIGHTS))
    + tuple((1 / 4, m, "none") for m in MOTIONS if m != 128)
    + tuple((1 / 4, 128, n) for n in ("small", "medium", "high")))
#: The light x noise report's points (every light scale at every noise level, S = 128) joined to the sweeps'.
LIGHT_NOISE_POINTS: tuple[tuple[float, int, str], ...] = SWEEP_POINTS + tuple(
    (light, 128, n) for light in sorted(LIGHTS) if light != 1 / 4 for n in ("small", "medium", "high"))
#: Which points the ``sweep`` data term draws from (its ``grid``).
SWEEP_GRIDS: dict[str, tuple[tuple[float, int, str], ...]] = {"sweeps": SWEEP_POINTS, "light-noise": LIGHT_NOISE_POINTS}
assert tuple(SWEEP_GRIDS) == SWEEP_GRID_NAMES  # (the sweep data term checks a grid's name without this module)
#: Pan speed of the sweeps (px/s at the 400x250 sensor's scale).
SWEEP_SPEED_PX_S = 1000.0
_PHOTO_DEFAULT: tuple[str, ...] = ("astronaut", "brick", "cat", "cell", "coffee", "grass", "hubble_deep_field",
                                   "immunohistochemistry", "page", "rocket")


def _whole(name: str, value: Any, minimum: int) -> int:
    return check_int(name, value, minimum=minimum)


def _check_photos(photos: Any) -> tuple[str, ...]:
    from neuspike.scenes.photos import HELDOUT_PICTURES, TEST_PHOTOS, TRAIN_PHOTOS

    photos = tuple(photos)
    refused = [p for p in photos if p in TEST_PHOTOS or p in HELDOUT_PICTURES]
    if refused:
        raise InputError(f"photos: {refused} are test photographs or held-out pictures (evaluation only); "
                         f"training may use only {', '.join(TRAIN_PHOTOS)}")
    unknown = [p for p in photos if p not in TRAIN_PHOTOS]
    if unknown:
        raise InputError(f"photos: {unknown} are not training photographs ({', '.join(TRAIN_PHOTOS)})")
    if not photos:
        raise InputError("photos: at least one training photograph is needed")
    return photos


def _check_levels(levels: Any) -> tuple[str, ...]:
    levels = tuple(levels)
    bad = sorted(set(levels) - set(NOISE_LEVELS))
    if bad:
        raise InputError(f"noise_levels: unknown {bad}; choose from {', '.join(NOISE_LEVELS)}")
    if not levels:
        raise InputError("noise_levels: expected at least one level")
    return levels


#: Pan speeds of the single-window training data (px/s at a view 400 pixels wide).
DEFAULT_SPEED_RANGE = (100.0, 4000.0)


@dataclass(frozen=True)
class WindowData:
    """Single simulated windows (feed-forward networks), and how they are scored.

    Parameters
    ----------
    shard_dir : str
        Folder of the simulated windows (shared by runs with the same :meth:`key`). The photograph
        crops are named by path in the scene specs, so the bytes depend on this folder too.
    view : int
        Side of the simulated square views the crops come from.
    train_items, val_items : int
        Training windows simulated once and reused (with random crops, flips and quarter turns);
        validation windows (never augmented).
    light_range : (float, float)
        L drawn log-uniformly in this range.
    motions : tuple of int
        S drawn uniformly from these.
    speed_range : (float, float)
        Pan and dead-leaves speeds (px/s of scene time at a view 400 pixels wide, scaled with the
        view) drawn log-uniformly in this range, in a uniformly drawn direction. The sweeps pan at
        1000 px/s; at S = 256 a window spans about 11 ms of scene time. With ``scale_range`` the
        speeds are in px/s at the sensor's native scale instead, scaled by the view's scale.
    scale_range : (float, float) or None
        ``None`` (the default, the shards made before the field): a photograph's region is drawn at
        0.3-1.2 times the scale at which the photograph fills the 400x250 sensor (the sweeps' scale),
        and pans move at ``speed_range`` times view / 400, as if the whole sensor were shrunk to the
        view. Given: the region's scale r is drawn log-uniformly in this range (1 = the sweeps'
        scale, so a 128-pixel view of r = 1 is a 128-pixel crop of a sweep's frame) and every speed
        is multiplied by r, so a scene moves as many of its own pixels per window as in the sweeps.
        The default draw is at 0.6 of the sweeps' scale on average (geometric mean): per pixel, the
        training views carry about 1.7 times the sweeps' detail, and edge events stand out more
        against noise events.
    noise_levels, photos : tuple of str
        Noise levels drawn uniformly (repeat a level to draw it more often); training photographs
        (the test photographs are refused).
    workers : int
        Processes that simulate the shard (not part of the run's identity).
    losses : {term: weight or {parameter: value}}
        The loss: the registered terms it adds up (:mod:`neuspike.train.terms`: ``l1``, ``ssim``,
        ``offset``, ``support``, ``edge_ssim``, ``gate_target``, ``distill``, ``spike_floor``), each with
        its parameters; a bare number is the weight. Default: L1 + the SSIM loss (window 11). Kept in
        the registry's order with every parameter filled in; a term at weight 0 with its defaults is
        left out. The earlier fields (``ssim_weight``, ``offset_weight``, ``spike_floor_weight``, ...) are
        read into it (:func:`neuspike.train.terms.legacy_losses`).
    val_view : (int, int) or None
        Validation windows at this (width, height), e.g. (400, 250), the sweeps' frame, instead of the
        square ``view``: the training crops stay small, while the best step is chosen on whole frames,
        where the level of an image is set. ``None`` (the default): the square view.
    spike_only_fraction : float
        Fraction of steps (for a fusion network) run with the motion path silenced, which trains the
        spike-only variant inside the same weights.
    crop_trim : int
        Each step cuts 0 to ``crop_trim`` rows and, independently, 0 to ``crop_trim`` columns off the
        bottom and right of every crop of its batch (drawn from ``derive_rng(seed, "trim", step)``),
        so that the sides are not always multiples of 8 and the network pads its input as it does at
        inference (a 400x250 frame gains 6 zero rows; a network that pads inside and normalises its
        features over the padded map never saw that in training, and at high noise the band cost the
        fusion 2.3 dB at the sweeps' frame). 0 to 7; 0 (the default, earlier specs): square crops.
    train_parts : ``"all"`` or ``"motion"``
        ``"motion"`` (fusion networks, with ``init_from``): only the motion path learns (the motion
        encoder, the fusion modules, the motion gate, the event transformer); the texture path, the
        residual blocks, the decoders and the head are held as ``init_from`` gave them, so the spike-only
        variant the run exports is those weights bit for bit, and every step is a fusion step
        (``spike_only_fraction`` is not used). Default ``"all"``.
    mixture : {term: fraction or {parameter: value}}
        The data terms mixed into the draw (:mod:`neuspike.train.mixture`): ``sweep`` (a share of the
        cells at the sweeps' points, ``grid`` ``"sweeps"`` (the three sweeps' 12, :data:`SWEEP_POINTS`) or
        ``"light-noise"`` (with the light x noise report's, :data:`LIGHT_NOISE_POINTS`: 24), panning at the
        sweeps' 1000 px/s, with ``scenes`` the sweeps' own four scenes in shares ``scene_weights``) and
        ``broad`` (a share of the picture cells with a broad-leaves picture), ``smooth`` (a share of the
        photographs blurred outside a sharp ellipse) and ``fast_pans`` (a share of
        pans at multiples of the sweeps' speed at S = 256, the fast-motion reports'); a bare number is the
        fraction. Default: none (the base draw alone, as every spec before the terms). The earlier fields
        (``sweep_fraction``, ``sweep_grid``, ``sweep_scenes``, ``sweep_scene_weights``, ``broad_fraction``)
        are read into it (:func:`neuspike.train.mixture.legacy_mixture`), and the shard keys stay theirs.
    """

    kind: ClassVar[str] = "windows"

    shard_dir: str = "runs/shard"
    view: int = 128
    train_items: int = 4000
    val_items: int = 48
    light_range: tuple[float, float] = (1 / 40, 0.6)
    motions: tuple[int, ...] = MOTIONS
    speed_range: tuple[float, float] = DEFAULT_SPEED_RANGE
    noise_levels: tuple[str, ...] = NOISE_LEVELS
    photos: tuple[str, ...] = _PHOTO_DEFAULT
    workers: int = 2
    spike_only_fraction: float = 0.3
    val_view: tuple[int, int] | None = None
    scale_range: tuple[float, float] | None = None
    crop_trim: int = 0
    train_parts: str = "all"
    mixture: dict[str, Any] = field(default_factory=dict)
    losses: dict[str, Any] = field(default_factory=lambda: dict(DEFAULT_LOSSES))

    #: What ``train_parts`` may be.
    TRAIN_PARTS: ClassVar[tuple[str, ...]] = ("all", "motion")

    def __post_init__(self) -> None:
        put = object.__setattr__
        if self.train_parts not in self.TRAIN_PARTS:
            raise InputError(f"train_parts: expected one of {self.TRAIN_PARTS}, got {self.train_parts!r}")
        if isinstance(self.crop_trim, bool) or not isinstance(self.crop_trim, int) or not 0 <= self.crop_trim <= 7:
            raise InputError(f"crop_trim: expected a whole number of pixels 0..7, got {self.crop_trim!r}")
        for name in ("view", "train_items", "val_items", "workers"):
            _whole(name, getattr(self, name), 1)
        value = self.spike_only_fraction
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
            raise InputError(f"spike_only_fraction: expected a fraction in [0, 1], got {value!r}")
        put(self, "spike_only_fraction", float(value))
        put(self, "mixture", resolve_mixture(self.mixture, "windows"))
        put(self, "losses", resolve_losses(self.losses))
        if self.val_view is not None:
            try:
                vw, vh = (int(v) for v in self.val_view)
            except (TypeError, ValueError):
                raise InputError(f"val_view: expected (width, height), got {self.val_view!r}") from None
            if vw < 16 or vh < 16:
                raise InputError(f"val_view: expected at least 16x16 pixels, got {vw}x{vh}")
            put(self, "val_view", (vw, vh))
        lo, hi = (float(v) for v in self.light_range)
        if not 0 < lo <= hi:
            raise InputError(f"light_range: expected 0 < low <= high, got {self.light_range}")
        put(self, "light_range", (lo, hi))
        lo, hi = (float(v) for v in self.speed_range)
        if not 0 < lo <= hi:
            raise InputError(f"speed_range: expected 0 < low <= high px/s, got {self.speed_range}")
        put(self, "speed_range", (lo, hi))
        if self.scale_range is not None:
            try:
                lo, hi = (float(v) for v in self.scale_range)
            except (TypeError, ValueError):
                raise InputError(f"scale_range: expected (low, high), got {self.scale_range!r}") from None
            if not 0 < lo <= hi:
                raise InputError(f"scale_range: expected 0 < low <= high, got {self.scale_range}")
            put(self, "scale_range", (lo, hi))
        motions = tuple(int(m) for m in self.motions)
        if not motions or any(m < 1 for m in motions):
            raise InputError(f"motions: expected motion scales >= 1, got {self.motions}")
        put(self, "motions", motions)
        put(self, "noise_levels", _check_levels(self.noise_levels))
        put(self, "photos", _check_photos(self.photos))

    def key(self, seed: int) -> dict[str, Any]:
        """What the simulated windows depend on (a shard is reused only when this matches).

        (``train_items`` and ``val_items`` only say how many of the same deterministic cells exist.)
        """
        key = {"seed": seed, "view": self.view, "light_range": list(self.light_range),
               "motions": list(self.motions), "noise_levels": list(self.noise_levels), "photos": list(self.photos)}
        if self.speed_range != DEFAULT_SPEED_RANGE:  # shards made before the range was a field keep their key
            key["speed_range"] = list(self.speed_range)
        if self.val_view is not None:  # likewise
            key["val_view"] = list(self.val_view)
        if self.scale_range is not None:  # likewise
            key["scale_range"] = list(self.scale_range)
        key.update(mixture_key(self.mixture, "windows"))  # (the earlier fields' entries: the same keys)
        return key


@dataclass(frozen=True)
class SequenceData:
    """Sequences of event windows of one moving scene (recurrent networks), and how they are scored.

    ``size`` is the simulated item (width = height, pixels); ``windows`` the windows per item;
    ``events_per_pixel`` the fixed window count per pixel (the methods' 0.35); ``threshold_range``
    the event contrast thresholds (log units, drawn log-uniformly); ``displacement_px`` the scene
    displacement aimed at for the history (doubled until the windows fit, at most 4 times).
    ``kinds`` and ``noise_levels`` are drawn uniformly over the tuple, so a repeated entry is drawn
    more often.

    ``view`` (width, height) or None: the scene view the photograph is fitted to. With a view, each
    item is a ``size`` x ``size`` crop of it at a random position, so the photographs are seen at
    the scale of an evaluation at that view size (the sweeps' 400x250); without one the whole
    photograph is fitted to ``size`` x ``size``; dead-leaves items (procedural, no view to cut from)
    are drawn at ``size`` x ``size`` either way. ``view_fraction`` (with a view): share of the items
    cut from the view, the rest fitted whole (default 1: every item). ``hdr_fraction``: share of items whose photograph
    is mapped to radiance through a drawn dynamic range of 10 to 1,000; the rest are linear in luma.

    ``shard_root`` holds one folder per :meth:`key`; ``train_items`` / ``val_items`` are the items
    simulated, by ``workers`` processes (not part of the key or the run's identity: the items are the
    same whatever the count). Scoring: ``length`` consecutive windows per training sequence, the first
    ``warmup_windows`` of them only carry the state; the loss is the sum of the registered sequence terms
    ``losses`` names (:data:`neuspike.train.terms.SEQUENCE_TERMS`; default ``l1 * |o - y| + ssim * (1 - SSIM) +
    temporal * M * |o_k - warp(o_{k-1})|`` with the occlusion mask's ``occlusion_alpha`` 50; ``history``: the gap
    between the last image and the same image from a second pass over the last ``length - length // 2`` windows
    started from a zero state; ``empty``: the spatial spread of the image that one window without events gives
    from a zero state). The earlier fields ``l1``, ``ssim``, ``temporal``, ``occlusion_alpha``, ``history`` and
    ``empty`` are read into those terms. ``mixture``: the data terms (:mod:`neuspike.train.mixture`):
    ``partial_first``, a share of the training runs whose first window is cut short
    (:func:`neuspike.train.sequences.partial_window`; default none; the earlier field of that name is
    read into it).
    ``sensor``: how each sequence's event camera is drawn beyond its threshold, a key of
    :data:`neuspike.train.sequences.SENSOR_DRAWS` (``"nominal"``: the noise level's stages only, as
    every spec before the field; ``"randomised"``: per-pixel mismatch, refractory period, leak, shot
    noise and bandwidth drawn per sequence, as real DAVIS pixels differ; ``"mixed"``: each sequence
    one or the other, with probability 1/2).
    """

    kind: ClassVar[str] = "sequences"
    #: Fields that say what an item is (the shard key); the others say how many and how they are scored.
    KEY_FIELDS: ClassVar[tuple[str, ...]] = ("size", "windows", "events_per_pixel", "threshold_range", "noise_levels",
                                             "kinds", "photos", "displacement_px", "view", "hdr_fraction",
                                             "view_fraction", "sensor")

    size: int = 128
    windows: int = 8
    events_per_pixel: float = 0.35
    threshold_range: tuple[float, float] = (0.1, 0.4)
    noise_levels: tuple[str, ...] = NOISE_LEVELS
    kinds: tuple[str, ...] = KINDS
    photos: tuple[str, ...] = _PHOTO_DEFAULT
    displacement_px: float = 8.0
    view: tuple[int, int] | None = None
    hdr_fraction: float = 0.5
    view_fraction: float = 1.0
    shard_root: str = "runs/shards"
    train_items: int = 300
    val_items: int = 16
    workers: int = 1
    length: int = 8
    warmup_windows: int = 2
    mixture: dict[str, Any] = field(default_factory=dict)
    sensor: str = "nominal"
    losses: dict[str, Any] = field(default_factory=lambda: dict(DEFAULT_SEQUENCE_LOSSES))

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "photos", _check_photos(self.photos))
        put(self, "noise_levels", _check_levels(self.noise_levels))
        if self.sensor not in SENSOR_DRAW_NAMES:
            raise InputError(f"sensor: expected one of {', '.join(SENSOR_DRAW_NAMES)}, got {self.sensor!r}")
        kinds = tuple(self.kinds)
        if not kinds or not set(kinds) <= set(SEQUENCE_KINDS):
            raise InputError(f"kinds: expected a non-empty subset of {SEQUENCE_KINDS}, got {kinds}")
        put(self, "kinds", kinds)
        if self.size < 16 or self.windows < 2:
            raise InputError(f"size >= 16 and windows >= 2 expected, got {self.size}, {self.windows}")
        if self.view is not None:
            try:
                vw, vh = (int(v) for v in self.view)
            except (TypeError, ValueError):
                raise InputError(f"view: expected (width, height), got {self.view!r}") from None
            if vw < self.size or vh < self.size:
                raise InputError(f"view: {vw}x{vh} is smaller than the {self.size}x{self.size} items cut from it")
            put(self, "view", (vw, vh))
        if not 0.0 <= self.hdr_fraction <= 1.0:
            raise InputError(f"hdr_fraction: expected a share in [0, 1], got {self.hdr_fraction}")
        if not (isinstance(self.view_fraction, (int, float)) and 0.0 <= self.view_fraction <= 1.0):
            raise InputError(f"view_fraction: expected a share in [0, 1], got {self.view_fraction!r}")
        put(self, "view_fraction", float(self.view_fraction))
        if self.view is None and self.view_fraction != 1.0:
            raise InputError("view_fraction: a share of items cut from a view needs the view (e.g. 400x250)")
        lo, hi = (float(v) for v in self.threshold_range)
        if not 0 < lo <= hi:
            raise InputError(f"threshold_range: expected 0 < low <= high, got {self.threshold_range}")
        put(self, "threshold_range", (lo, hi))
        _whole("train_items", self.train_items, 1)
        _whole("val_items", self.val_items, 1)
        _whole("workers", self.workers, 1)
        if not 1 <= self.length <= self.windows:
            raise InputError(f"length: expected 1..{self.windows} windows, got {self.length}")
        if not 0 <= self.warmup_windows < self.length:
            raise InputError(f"warmup_windows: expected 0..{self.length - 1}, got {self.warmup_windows}")
        put(self, "losses", resolve_losses(self.losses, "sequences"))
        put(self, "mixture", resolve_mixture(self.mixture, "sequences"))
        if "history" in self.losses and self.length < 2:
            raise InputError("losses.history: the second pass needs sequences of at least 2 windows (length >= 2)")

    def key(self, seed: int | None = None) -> str:
        """The shard folder's name: a hash of what an item is (not of the counts or scoring).

        Item ``i`` is drawn from ``derive_rng(seed, ...)``, so the training seed is part of what an item is:
        a seed other than 0 enters the hash (seed 0 and ``None`` leave it out, so the shards every stage
        trained on keep their key). ``view``, ``hdr_fraction`` and ``view_fraction`` are left out at their
        defaults, so shards made before those fields existed keep their key (the default data:
        ``f40df6737f28``).
        """
        d = {k: v for k, v in asdict(self).items() if k in self.KEY_FIELDS}
        if seed:
            d["seed"] = int(seed)
        if d["view"] is None:
            del d["view"]
        if d["hdr_fraction"] == 0.5:
            del d["hdr_fraction"]
        if d["view_fraction"] == 1.0:
            del d["view_fraction"]
        if d["sensor"] == "nominal":  # likewise: every shard before the field keeps its key
            del d["sensor"]
        text = json.dumps(d, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:12]


#: The names of :data:`neuspike.train.sequences.SENSOR_DRAWS` (kept here so a spec validates without torch).
SENSOR_DRAW_NAMES = ("nominal", "randomised", "mixed")

DataSection = Union[WindowData, SequenceData]
DATA_KINDS: dict[str, type] = {"windows": WindowData, "sequences": SequenceData}


@dataclass(frozen=True)
class TrainSpec:
    """Everything a training run depends on (``spec.json`` beside the checkpoint).

    Parameters
    ----------
    method : str
        A registered learned method (:class:`~neuspike.methods.learned.LearnedMethod`).
    data : WindowData or SequenceData
        What is simulated and how it is scored.
    out_dir : str
        The run folder: spec.json, checkpoint.pt, train_log.csv, the best weights.
    seed : int
        Seeds the data (cells, order, crops) and the initial weights.
    steps, batch, crop : int
        Optimiser steps, items per step, side of the square training crops (pixels).
    optimizer : ``"adamw"`` or ``"adam"``
        With ``weight_decay`` (AdamW only).
    lr, lr_min, warmup : float, float or None, int
        The schedule (:func:`learning_rate`): linear warm-up over ``warmup`` steps to ``lr``, then a
        cosine down to ``lr_min`` at ``steps``, or constant when ``lr_min`` is None.
    val_every, checkpoint_every : int
        Steps between validations (a better score exports the weights) and between checkpoints.
    threads : int or None
        torch threads (None: as the process has them).
    device : str
        The torch device the module, the batches and the loss run on (``"cpu"``, ``"cuda"``,
        ``"cuda:1"``, ...; resolved by :func:`neuspike.methods.learned.resolve_device` when the
        trainer starts, so a device this machine lacks is refused before anything is simulated or
        written). The data and every random draw of data and order stay on the CPU: the same seed
        gives the same batches on any device. Spec files without the field mean ``"cpu"``. Not part
        of the run's identity: a run may resume on another device (its numbers then agree with a
        straight run to rounding, not bit for bit).
    precision : ``"auto"``, ``"float32"`` or ``"bfloat16"``
        Autocast precision; auto = bfloat16 where the device computes it natively and a timed training
        step is faster in it (:meth:`neuspike.train.loop.Trainer.choose_precision`), else float32.
    params : dict
        Overrides of the method's registered parameters.
    init_from : str or None
        Weights (a ``.safetensors`` of the full module) to start from instead of a fresh
        initialisation; a checkpoint in ``out_dir`` still wins. The file may lack parts that the
        module builds as the identity (``STARTS_AS_IDENTITY``, such as NeuSpike-Net's motion gate).
    new_parts_lr_scale : float
        With ``init_from``: the parts the file lacked learn at this multiple of the schedule's rate
        (1: like the rest). They start from nothing while the rest is already trained.
    part_lr_scales : dict
        ``{name prefix: multiple}``: the parameters whose names start with a prefix learn at that
        multiple of the schedule's rate (the first prefix that matches; parts the ``init_from`` file
        lacked keep ``new_parts_lr_scale``). A small part, such as NeuSpike-Net's motion gate, can so
        move as far as the rest in a short fine-tuning run; a multiple of 0 holds the part as
        ``init_from`` gave it (no gradient, no optimiser state). Every prefix must name a parameter that
        would learn. Default ``{}`` (earlier specs mean none).
    export : bool
        Also write the best weights into the package's ``neuspike/trained/``.
    export_dir : str or None
        Also write the best weights into this folder.
    Distillation is the ``distill`` loss term of a window spec's ``losses``
    (:mod:`neuspike.train.terms`: ``{"distill": {"weight": 1, "teacher": "neuspike/trained/neuspike-net.safetensors"}}``);
    the earlier top-level ``teacher`` and ``distill_weight`` are read into it.
    """

    method: str = "neuspike-net"
    data: DataSection = field(default_factory=WindowData)
    out_dir: str = "runs/neuspike-net"
    seed: int = 0
    steps: int = 9000
    batch: int = 8
    crop: int = 128
    optimizer: str = "adamw"
    lr: float = 5e-4
    lr_min: float | None = 1e-5
    warmup: int = 200
    weight_decay: float = 1e-4
    val_every: int = 250
    checkpoint_every: int = 100
    threads: int | None = 1
    device: str = "cpu"
    precision: str = "auto"
    params: dict[str, Any] = field(default_factory=dict)
    init_from: str | None = None
    new_parts_lr_scale: float = 1.0
    part_lr_scales: dict[str, float] = field(default_factory=dict)
    export: bool = False
    export_dir: str | None = None

    #: Fields that do not change what a run computes (the device only its rounding): a resumed run may change them.
    NOT_IDENTITY: ClassVar[tuple[str, ...]] = ("out_dir", "threads", "device", "export", "export_dir")

    def __post_init__(self) -> None:
        put = object.__setattr__
        if not isinstance(self.data, (WindowData, SequenceData)):
            raise InputError(f"data: expected WindowData or SequenceData, got {type(self.data).__name__}")
        _whole("seed", self.seed, 0)
        for name in ("steps", "batch", "crop", "val_every", "checkpoint_every"):
            _whole(name, getattr(self, name), 1)
        _whole("warmup", self.warmup, 0)
        if self.threads is not None:
            _whole("threads", self.threads, 1)
        if self.optimizer not in ("adamw", "adam"):
            raise InputError(f"optimizer: expected adamw or adam, got {self.optimizer!r}")
        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            raise InputError(f"lr: expected a positive number, got {self.lr!r}")
        if self.lr_min is not None and not 0 <= self.lr_min <= self.lr:
            raise InputError(f"lr_min: expected 0 <= lr_min <= lr ({self.lr}), got {self.lr_min}")
        if not isinstance(self.device, str) or not self.device.strip():
            raise InputError(f"device: expected a torch device name such as 'cpu' or 'cuda', got {self.device!r}")
        if self.precision not in ("auto", "float32", "bfloat16"):
            raise InputError(f"precision: expected auto, float32 or bfloat16, got {self.precision!r}")
        if not (isinstance(self.new_parts_lr_scale, (int, float)) and math.isfinite(self.new_parts_lr_scale)
                and self.new_parts_lr_scale > 0):
            raise InputError(f"new_parts_lr_scale: expected a positive number, got {self.new_parts_lr_scale!r}")
        if not isinstance(self.part_lr_scales, Mapping):
            raise InputError(f"part_lr_scales: expected {{name prefix: multiple}}, got {self.part_lr_scales!r}")
        for prefix, scale in self.part_lr_scales.items():
            if not isinstance(prefix, str) or not prefix:
                raise InputError(f"part_lr_scales: expected parameter name prefixes, got {prefix!r}")
            if isinstance(scale, bool) or not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale >= 0):
                raise InputError(f"part_lr_scales[{prefix!r}]: expected a number >= 0, got {scale!r}")
        put(self, "part_lr_scales", {k: float(v) for k, v in self.part_lr_scales.items()})
        if self.init_from is not None and not str(self.init_from).endswith(".safetensors"):
            raise InputError(f"init_from: expected a .safetensors file, got {self.init_from!r}")
        if isinstance(self.data, WindowData):
            if self.data.train_parts != "all" and self.init_from is None:
                raise InputError(f"train_parts {self.data.train_parts!r}: holds the other parts as init_from gives "
                                 "them; give init_from (trained weights), or train_parts 'all'")
            if self.crop > self.data.view:
                raise InputError(f"crop: {self.crop} is larger than the simulated view {self.data.view}")
            if self.crop % 8:
                raise InputError(f"crop: expected a multiple of 8, got {self.crop}")
        elif not 8 <= self.crop <= self.data.size:
            raise InputError(f"crop: expected 8..{self.data.size}, got {self.crop}")
        put(self, "params", dict(self.params))

    @property
    def kind(self) -> str:
        """``"windows"`` or ``"sequences"``."""
        return self.data.kind

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON data (tuples as lists); the data section carries its ``kind``."""
        out = json.loads(json.dumps(asdict(self)))
        out["data"] = {"kind": self.data.kind, **out["data"]}
        return out

    def identity(self) -> dict[str, Any]:
        """What a resumed run must share with the run folder's spec (:data:`NOT_IDENTITY` left out,
        and the data section's worker count and shard root, which change no byte)."""
        d = self.as_dict()
        for k in self.NOT_IDENTITY:
            d.pop(k)
        d["data"].pop("workers", None)
        d["data"].pop("shard_root", None)
        return d


def learning_rate(spec: TrainSpec, step: int) -> float:
    """The rate of step ``step`` (from 0): linear warm-up to ``spec.lr`` over ``max(1, spec.warmup)``
    steps, then constant (``lr_min`` None) or a cosine from ``lr`` down to ``lr_min`` at ``spec.steps``."""
    warm = max(1, spec.warmup)
    if step < warm:
        return spec.lr * (step + 1) / warm
    if spec.lr_min is None:
        return spec.lr
    frac = min(1.0, (step - warm) / max(1, spec.steps - warm))
    return spec.lr_min + 0.5 * (spec.lr - spec.lr_min) * (1.0 + math.cos(math.pi * frac))


# --- reading spec files ----------------------------------------------------------------------------

#: Where the readers of the earlier trainers' spec files and checkpoints remain (they served only runs that
#: left the tree: every shipped card's spec is in the current form).
EARLIER_TRAINERS_COMMIT = "61a150f8"


def _strict(cls: type, data: Mapping[str, Any], where: str) -> Any:
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"{where}: unknown spec keys {unknown}")
    return cls(**data)


def _data_section(d: Mapping[str, Any], where: str) -> DataSection:
    d = dict(d)
    kind = d.pop("kind", None)
    if kind not in DATA_KINDS:
        raise InputError(f"{where}: data.kind must be one of {sorted(DATA_KINDS)}, got {kind!r}")
    if d.get("view") is not None and kind == "sequences":
        d["view"] = tuple(d["view"])
    # the earlier loss fields become their registered terms
    d, d["losses"] = legacy_losses({k: v for k, v in d.items() if k != "losses"}, d.get("losses"), kind)
    # and the earlier data fields their data terms
    d, d["mixture"] = legacy_mixture({k: v for k, v in d.items() if k != "mixture"}, d.get("mixture"), kind)
    return _strict(DATA_KINDS[kind], d, f"{where} (data)")


def spec_from_dict(d: Mapping[str, Any], *, where: str = "spec", out_dir: str | None = None) -> TrainSpec:
    """A :class:`TrainSpec` from its JSON data: ``data`` a mapping with ``kind`` (what :meth:`TrainSpec.as_dict`
    writes, and every shipped card's spec). ``out_dir`` fills the run folder where the data does not name one.

    Raises
    ------
    InputError
        On unknown keys, and on a spec of the earlier single-window or sequence trainers (no ``data.kind``),
        which this trainer no longer reads: they ran at commit ``61a150f8`` and before.
    """
    d = dict(d)
    if not (isinstance(d.get("data"), Mapping) and "kind" in d["data"]):
        raise InputError(f"{where}: a spec of an earlier trainer (no data.kind), which this trainer no longer reads; "
                         f"run it at commit {EARLIER_TRAINERS_COMMIT} (or earlier), or write it in the current form "
                         "(python -m neuspike.train METHOD --help; a run folder's spec.json shows one)")
    teacher = {k: d.pop(k) for k in ("teacher", "distill_weight") if k in d}  # earlier: distillation at the top
    if any(v not in (None, 0, 0.0) for v in teacher.values()):
        if d["data"].get("kind") != "windows":
            raise InputError(f"{where}: teacher: distillation trains on single windows (neuspike-net); this spec's "
                             "data are sequences")
        d["data"] = {**d["data"], **teacher}
    d["data"] = _data_section(d["data"], where)
    if "out_dir" not in d and out_dir is not None:
        d["out_dir"] = out_dir
    return _strict(TrainSpec, d, where)


def load_spec(path: str | Path, *, out_dir: str | None = None) -> TrainSpec:
    """A spec from its JSON file (any of the forms :func:`spec_from_dict` reads; unknown keys are an error)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a readable spec file ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a JSON object")
    return spec_from_dict(data, where=str(path), out_dir=out_dir)


def apply_settings(spec: TrainSpec, settings: Sequence[str]) -> TrainSpec:
    """``spec`` with each ``KEY=VALUE`` of ``settings`` set (``--set``), checked as a spec file is.

    ``KEY`` is a field of the spec or, dotted, of one of its sections: ``lr=1e-4``,
    ``data.speed_range=[2000,24000]``, ``params.width=0.45``, ``data.noise_levels=["high"]``. ``VALUE`` is
    JSON, or else taken as text (``init_from=runs/a/neuspike-net.safetensors``). A key the spec does not
    have is refused by name, as in a spec file; the data section's ``kind`` cannot change.
    """
    d = spec.as_dict()
    for item in settings:
        key, sep, raw = str(item).partition("=")
        parts = key.strip().split(".")
        if not sep or not all(parts):
            raise InputError(f"--set: expected KEY=VALUE (e.g. lr=1e-4, data.speed_range=[2000,24000]), got {item!r}")
        try:
            value = json.loads(raw)
        except ValueError:
            value = raw
        node: Any = d
        for depth, part in enumerate(parts[:-1]):
            if part not in node and depth == 0 and part in ("params", "part_lr_scales"):
                node[part] = {}
            node = node.get(part) if isinstance(node, dict) else None
            if not isinstance(node, dict):
                sections = ", ".join(k for k, v in d.items() if isinstance(v, dict))
                raise InputError(f"--set {key}: {'.'.join(parts[:depth + 1])} is not a section of the spec "
                                 f"(its sections: {sections})")
        if node is d.get("data") and parts[-1] == "kind":
            raise InputError(f"--set {key}: the data kind follows from the method ({d['data']['kind']})")
        node[parts[-1]] = value
    return spec_from_dict(d, where="--set")


def with_out_dir(spec: TrainSpec, out_dir: str) -> TrainSpec:
    """``spec`` run in another folder."""
    return replace(spec, out_dir=str(out_dir))
