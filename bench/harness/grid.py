"""Sweep grids: the presets of a benchmark and the cells they span (the axes: :mod:`bench.harness.axes`).

A grid has five axes: scene, light scale L, motion scale S, noise level and seed. A *cell* is one
point of it, (scene, condition, seed): one simulated recording that every method of the sweep
reconstructs. Cells are enumerated in a fixed order (scene, noise, light, motion, seed), so the same
grid always gives the same list.

Presets (the paper's figures and tables)
----------------------------------------
``light``  (Figure 3)  S = 128, L in {1/32, 1/16, 1/8, 1/4, 1/2}, noise ``none``.
``motion`` (Figure 4)  L = 1/4, S in {16, 32, 64, 128, 256}, noise ``none``.
``noise``  (Table 3)   L = 1/4, S = 128, noise in {small, medium, high} (the paper's levels:
                       spike fixed-pattern sigma 10 / 50 / 90 planes with a random initial charge,
                       event shot noise 0.001 / 10 / 100 Hz; see :mod:`neuspike.conditions`).
``light-noise``        S = 128, Figure 3's five light scales at each noise level (none, small,
                       medium, high): light and noise together, a grid of two swept axes.

Every condition of a preset also declares :data:`DEFAULT_EFFECTS`: the random initial charge of
Algorithm 1 (the paper's simulator always draws it) and the event camera's ``clean`` preset from
v2e (a frozen per-pixel threshold mismatch of sigma 0.02). Without them a spike window in weak light
starts with every pixel at zero charge and fires in lock-step, which no real sensor does. Pass
``effects=()`` for the ideal sensors.

Sizes and scenes
----------------
The quick default (:data:`QUICK_SCENES` at :data:`QUICK_SIZE`, one seed) finishes in minutes on a
2-core laptop; ``full=True`` is the paper's sensor size 400x250 over every scene kind (pan, zoom,
fan, still) and :data:`FULL_PHOTOS` (two test photographs: 8 scenes), with :data:`FULL_SEEDS` (two):
80 cells for a light or motion sweep, 48 for the noise test. At 400x250 the cost of a cell is
dominated by the heavier methods (recurrent networks warming up on the event history, SNM), a few
seconds each, so this size is what fits in about half an hour on a 2-core machine; ``--scenes``
and ``--seeds`` widen it.
A scene is named ``KIND:IMAGE`` (e.g. ``pan:camera``); IMAGE is one of scikit-image's bundled
photographs or a path to an image file. Pan velocities scale with the view width (1000 px/s at 400
pixels wide, diagonal), so a smaller view sees the same relative motion.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, Iterable, Sequence

from neuspike.utils import checks
from neuspike.conditions import EVENT_PRESETS, NOISE_LEVELS, Condition, Effect, effect, merge_effects
from neuspike.errors import InputError
from neuspike.scenes import SceneSpec


#: Scene kinds a grid may use (``video`` needs a file and is not part of the presets).
SCENE_KINDS = ("pan", "zoom", "fan", "still")
#: The light scales of Figure 3, and the fixed light of Figure 4 and Table 3.
PAPER_LIGHTS = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2)
PAPER_FIXED_LIGHT = 1 / 4
#: The motion scales of Figure 4, and the fixed motion of Figure 3 and Table 3.
PAPER_MOTIONS = (16, 32, 64, 128, 256)
PAPER_FIXED_MOTION = 128
#: The noise levels of Table 3.
PAPER_NOISE_LEVELS = ("small", "medium", "high")
#: The presets (:func:`preset`): one per swept axis, and light and noise swept together.
PRESETS = ("light", "motion", "noise", "light-noise")
#: The axis along which a preset's reconstructions are kept for the figure grid (its swept axis; the
#: light x noise grid keeps them across the noise levels at its first, darkest, light scale).
IMAGE_AXIS = {"light": "light", "motion": "motion", "noise": "noise", "light-noise": "noise"}
#: The noise levels of the light x noise grid.
LIGHT_NOISE_LEVELS = ("none",) + PAPER_NOISE_LEVELS

#: Extra stages declared in every preset condition (see the module docstring).
DEFAULT_EFFECTS: tuple[Effect, ...] = (effect("initial_charge"),) + tuple(EVENT_PRESETS["clean"])

#: The quick default: two test photographs, one panning, one behind a rotating fan.
QUICK_SCENES = ("pan:camera", "fan:coins")
QUICK_SIZE = (160, 100)
QUICK_SEEDS = (0,)
#: The full run: every scene kind over these test photographs, at the Vidar sensor size.
FULL_PHOTOS = ("camera", "clock")
FULL_SIZE = (400, 250)
FULL_SEEDS = (0, 1)

#: Pan speed (px/s of scene time) at a view 400 pixels wide; scaled with the width.
PAN_SPEED_PX_S_AT_400 = 1000.0


#: The paper's Table 2 resolutions (width, height).
TABLE2_RESOLUTIONS: tuple[tuple[int, int], ...] = ((240, 180), (346, 260), (400, 250), (640, 480))


@dataclass(frozen=True)
class SceneEntry:
    """A named scene of a grid: ``name`` (``KIND:IMAGE``) and its :class:`~neuspike.scenes.SceneSpec`."""

    name: str
    spec: SceneSpec

    @property
    def kind(self) -> str:
        return self.spec.kind

    @property
    def image(self) -> str:
        return self.spec.image


def scene_entry(name: str, size: tuple[int, int]) -> SceneEntry:
    """Build the scene called ``KIND:IMAGE`` at ``size`` = (W, H).

    Parameters
    ----------
    name : str
        ``"pan:camera"``, ``"zoom:clock"``, ``"fan:coins"``, ``"still:moon"``, or ``KIND:PATH``. A pan
        may carry a speed factor: ``"pan@8x:camera"`` pans 8 times the default speed
        (:data:`PAN_SPEED_PX_S_AT_400`, scaled with the view width).
    size : (int, int)
        View width and height in pixels.

    Raises
    ------
    InputError
        Unknown kind, missing image, or a size that is not two whole numbers >= 1.
    """

    if not isinstance(name, str) or ":" not in name:
        raise InputError(f"scene: expected KIND:IMAGE with KIND in {', '.join(SCENE_KINDS)}, got {name!r}")
    kind, _, image = name.partition(":")
    kind, image = kind.strip(), image.strip()
    kind, factor = _speed_factor(name, kind)
    if kind not in SCENE_KINDS:
        raise InputError(f"scene {name!r}: kind must be one of {', '.join(SCENE_KINDS)}, got {kind!r}")
    if not image:
        raise InputError(f"scene {name!r}: no image after the colon")
    width, height = _check_size(size)
    params: dict[str, Any] = {}
    if kind == "pan":
        speed = PAN_SPEED_PX_S_AT_400 * width / 400.0 * factor
        params["velocity_px_s"] = (0.8 * speed, 0.6 * speed)  # |v| = speed, diagonal
    elif factor != 1.0:
        raise InputError(f"scene {name!r}: a speed factor (@Fx) applies to pans only")
    spec = SceneSpec(kind=kind, image=image, size=(width, height), **params)
    label = kind if factor == 1.0 else f"{kind}@{factor:g}x"
    return SceneEntry(f"{label}:{image}", spec)


def _speed_factor(name: str, kind: str) -> tuple[str, float]:
    """``"pan@8x"`` -> ("pan", 8.0); a kind without ``@`` -> (kind, 1.0)."""
    if "@" not in kind:
        return kind, 1.0
    base, _, text = kind.partition("@")
    try:
        factor = float(text.strip().removesuffix("x"))
    except ValueError:
        factor = float("nan")
    if not (factor > 0 and factor != float("inf")):
        raise InputError(f"scene {name!r}: expected a speed factor such as pan@8x:IMAGE, got {text!r}")
    return base.strip(), factor


def _check_size(size: Any) -> tuple[int, int]:
    try:
        w, h = size
    except (TypeError, ValueError):
        raise InputError(f"size: expected (width, height), got {size!r}") from None
    return checks.check_size("size", w, h)


@dataclass(frozen=True)
class Cell:
    """One point of a grid: a scene seen under a condition, with a seed for every random draw."""

    scene: SceneEntry
    condition: Condition
    seed: int

    def identity(self) -> dict[str, Any]:
        """Plain data that determines the cell (scene spec, condition with every stage, seed)."""
        return {
            "scene": self.scene.name,
            "scene_spec": self.scene.spec.as_dict(),
            "condition": self.condition.as_dict(),
            "stages_declared": [e.as_dict() for e in self.condition.all_effects()],
            "seed": self.seed,
        }


@dataclass(frozen=True)
class Grid:
    """The axes of a sweep; :meth:`cells` spans them.

    Parameters
    ----------
    scenes : tuple of SceneEntry
    lights : tuple of float
        Light scales L (> 0).
    motions : tuple of int
        Motion scales S (>= 1); each must divide the window's plane count (checked by
        :meth:`check_planes`).
    noises : tuple of str
        Keys of :data:`neuspike.conditions.NOISE_LEVELS`.
    seeds : tuple of int
        Seeds (>= 0).
    effects : tuple of Effect
        Stages declared in every condition on top of the noise level's.
    """

    scenes: tuple[SceneEntry, ...]
    lights: tuple[float, ...]
    motions: tuple[int, ...]
    noises: tuple[str, ...] = ("none",)
    seeds: tuple[int, ...] = (0,)
    effects: tuple[Effect, ...] = field(default=())

    def __post_init__(self) -> None:
        put = object.__setattr__
        for axis in ("scenes", "lights", "motions", "noises", "seeds"):
            values = tuple(getattr(self, axis))
            if not values:
                raise InputError(f"grid axis {axis!r} is empty; give at least one value")
            if len(set(values)) != len(values):
                raise InputError(f"grid axis {axis!r} repeats a value: {list(values)}")
            put(self, axis, values)
        names = [s.name for s in self.scenes]
        if len(set(names)) != len(names):
            raise InputError(f"grid scenes repeat a name: {names}")
        for seed in self.seeds:
            checks.check_int("grid seeds", seed, minimum=0, what="whole numbers")
        for noise in self.noises:
            if noise not in NOISE_LEVELS:
                raise InputError(f"grid noise level {noise!r} is unknown; choose from {', '.join(NOISE_LEVELS)}")
        put(self, "effects", merge_effects(self.effects))
        # Condition validates light and motion values.
        for light in self.lights:
            Condition(light=light)
        for motion in self.motions:
            Condition(motion=motion)

    def check_planes(self, planes: int) -> None:
        """Raise :class:`InputError` unless every motion scale divides ``planes`` (Algorithm 1)."""
        bad = [s for s in self.motions if planes % s]
        if bad:
            raise InputError(
                f"motion scales {bad} do not divide the window of {planes} planes (Algorithm 1 holds each "
                f"of the S frames for T // S planes); choose S among the divisors of {planes}"
            )

    def conditions(self) -> list[Condition]:
        """Every condition, in the order (noise, light, motion)."""
        return [
            Condition(light=light, motion=motion, noise=noise, effects=self.effects)
            for noise, light, motion in itertools.product(self.noises, self.lights, self.motions)
        ]

    def cells(self) -> list[Cell]:
        """Every cell, in the order (scene, noise, light, motion, seed)."""
        return [
            Cell(scene, condition, seed)
            for scene in self.scenes
            for condition in self.conditions()
            for seed in self.seeds
        ]

    def as_dict(self) -> dict[str, Any]:
        return {
            "scenes": [{"name": s.name, "spec": s.spec.as_dict()} for s in self.scenes],
            "lights": list(self.lights),
            "motions": list(self.motions),
            "noises": list(self.noises),
            "seeds": list(self.seeds),
            "effects": [e.as_dict() for e in self.effects],
        }


def full_scene_names(photos: Sequence[str] = FULL_PHOTOS) -> tuple[str, ...]:
    """``KIND:PHOTO`` for every scene kind and photograph, kind-major."""
    return tuple(f"{kind}:{photo}" for kind in SCENE_KINDS for photo in photos)


def preset(
    axis: str,
    *,
    full: bool = False,
    size: tuple[int, int] | None = None,
    scenes: Sequence[str] | None = None,
    seeds: Sequence[int] | None = None,
    lights: Sequence[float] | None = None,
    motions: Sequence[int] | None = None,
    noises: Sequence[str] | None = None,
    effects: Iterable[Effect] | None = None,
) -> Grid:
    """The paper's grid for ``axis`` (one of :data:`PRESETS`), with overrides.

    Parameters
    ----------
    axis : str
        Which preset (module docstring): ``"light"``, ``"motion"``, ``"noise"`` or ``"light-noise"``.
    full : bool
        The paper-size run (400x250, every scene kind over :data:`FULL_PHOTOS`, :data:`FULL_SEEDS`)
        instead of the quick default.
    size, scenes, seeds, lights, motions, noises : optional
        Replace the preset's value of that axis (``None`` keeps it).
    effects : iterable of Effect, optional
        Stages declared in every condition; ``None`` means :data:`DEFAULT_EFFECTS`.

    Raises
    ------
    InputError
        Unknown axis, or an invalid axis value.
    """
    if axis not in PRESETS:
        raise InputError(f"axis must be one of {', '.join(PRESETS)}, got {axis!r}")
    size = _check_size(size if size is not None else (FULL_SIZE if full else QUICK_SIZE))
    if scenes is None:
        scenes = full_scene_names() if full else QUICK_SCENES
    if seeds is None:
        seeds = FULL_SEEDS if full else QUICK_SEEDS
    default_lights = PAPER_LIGHTS if axis in ("light", "light-noise") else (PAPER_FIXED_LIGHT,)
    default_motions = PAPER_MOTIONS if axis == "motion" else (PAPER_FIXED_MOTION,)
    default_noises = {"noise": PAPER_NOISE_LEVELS, "light-noise": LIGHT_NOISE_LEVELS}.get(axis, ("none",))
    return Grid(
        scenes=tuple(scene_entry(name, size) for name in scenes),
        lights=tuple(float(v) for v in (lights if lights is not None else default_lights)),
        motions=tuple(motions if motions is not None else default_motions),
        noises=tuple(noises if noises is not None else default_noises),
        seeds=tuple(seeds),
        effects=tuple(effects) if effects is not None else DEFAULT_EFFECTS,
    )


# ----------------------------------------------------------------------------------------------
# Parsing axis values from the command line
# ----------------------------------------------------------------------------------------------

def parse_size(text: str) -> tuple[int, int]:
    """``"160x100"`` -> ``(160, 100)`` (width, height)."""
    return _check_size(checks.parse_size(text))


def parse_fraction(text: str) -> float:
    """``"1/32"`` or ``"0.25"`` -> float."""
    try:
        value = float(Fraction(text.strip()))
    except (ValueError, ZeroDivisionError):
        raise InputError(f"expected a number or a fraction such as 1/32, got {text!r}") from None
    return value


def parse_list(text: str, convert=str) -> tuple:
    """Comma-separated values, converted one by one; empty items are errors."""
    items = [t.strip() for t in text.split(",")]
    if not items or any(not t for t in items):
        raise InputError(f"expected a comma-separated list, got {text!r}")
    return tuple(convert(t) for t in items)


def parse_int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(f"expected a whole number, got {text!r}") from None
