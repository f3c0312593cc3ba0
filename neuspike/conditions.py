"""Conditions: how the sensors see a scene (light, motion, noise level, declared effects).

An *effect* is a named sensor stage with its parameters. Only declared effects run: a stage that
is not in a condition's effect list is never executed (not "executed with zero strength").

Spike-camera effects (Algorithm 1 of NeuSpike-Net and its measured dark statistics):

``initial_charge``
    the integrator starts at ``I = N * threshold`` with N a per-pixel standard normal draw.
``dark_current(isi_mean_planes=180, isi_std_planes=50)``
    fixed-pattern dark charge: each pixel receives ``threshold / isi`` per plane, so that in total
    darkness it fires every ``isi`` planes; ``isi ~ Normal(mean, std**2)`` per pixel, redrawn while
    below 1.

Event-camera effects (v2e's DVS pixel model, units in the names):

``threshold_mismatch(sigma=0.02)``  per-pixel Gaussian spread of the ON/OFF thresholds, frozen.
``bandwidth(cutoff_hz=30)``         intensity-dependent first-order low-pass of the log intensity.
``refractory(period_s=5e-4)``       a pixel cannot emit again within this time of its last event.
``leak(rate_hz=0.1)``               the memorised level drifts down: spurious ON events at about this rate.
``shot_noise(rate_hz=5)``           intensity-dependent ON/OFF noise events, total rate in the dark.

Noise levels are the paper's (Table 3): ``small`` = spike sigma 10 and event shot noise 0.001 Hz,
``medium`` = 50 and 10 Hz, ``high`` = 90 and 100 Hz; each also declares ``initial_charge``.
``none`` declares nothing, so a ``none`` simulation is a deterministic function of the scene.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Iterable, Mapping

import numpy as np

from neuspike.utils.checks import check_int, check_nonnegative
from neuspike.errors import InputError

SPIKES = "spikes"
EVENTS = "events"

#: Every known effect: its modality and its default parameters (units in the names).
EFFECT_DEFAULTS: Mapping[str, tuple[str, Mapping[str, float]]] = MappingProxyType({
    "initial_charge": (SPIKES, MappingProxyType({})),
    "dark_current": (SPIKES, MappingProxyType({"isi_mean_planes": 180.0, "isi_std_planes": 50.0})),
    "threshold_mismatch": (EVENTS, MappingProxyType({"sigma": 0.02})),
    "bandwidth": (EVENTS, MappingProxyType({"cutoff_hz": 30.0})),
    "refractory": (EVENTS, MappingProxyType({"period_s": 5e-4})),
    "leak": (EVENTS, MappingProxyType({"rate_hz": 0.1})),
    "shot_noise": (EVENTS, MappingProxyType({"rate_hz": 5.0})),
})


@dataclass(frozen=True)
class Effect:
    """A declared sensor stage: its name and its parameters (sorted, hashable)."""

    name: str
    params: tuple[tuple[str, float], ...] = ()

    @property
    def modality(self) -> str:
        return EFFECT_DEFAULTS[self.name][0]

    def param(self, key: str) -> float:
        return dict(self.params)[key]

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, **dict(self.params)}


def effect(name: str, **params: float) -> Effect:
    """Build a validated :class:`Effect`, filling in the defaults of parameters not given.

    Raises
    ------
    InputError
        For an unknown effect, an unknown parameter, or a negative or non-finite value.
    """
    if name not in EFFECT_DEFAULTS:
        raise InputError(f"unknown effect {name!r}; known effects: {', '.join(EFFECT_DEFAULTS)}")
    defaults = EFFECT_DEFAULTS[name][1]
    unknown = set(params) - set(defaults)
    if unknown:
        raise InputError(
            f"effect {name!r}: unknown parameter(s) {sorted(unknown)}; it takes {sorted(defaults) or 'none'}"
        )
    merged: dict[str, float] = {}
    for key, default in defaults.items():
        merged[key] = check_nonnegative(f"effect {name!r}: {key}", params.get(key, default))
    return Effect(name, tuple(sorted(merged.items())))


def parse_effects(text: str) -> tuple[Effect, ...]:
    """Parse ``"refractory:period_s=1e-3,shot_noise:rate_hz=5;leak"`` style declarations.

    Effects are separated by ``;`` or by ``,`` before a new name; parameters follow ``name:`` as
    ``key=value`` pairs separated by ``,``. An empty text declares nothing.

    Raises
    ------
    InputError
        An empty entry (``"leak,,refractory"``, ``",,"``), an effect or a parameter given twice
        (one would silently replace the other), or anything else that does not parse.
    """
    effects: list[Effect] = []
    text = text.strip()
    if not text:
        return ()
    current: str | None = None
    params: dict[str, float] = {}

    def close() -> None:
        if current is not None:
            if any(e.name == current for e in effects):
                raise InputError(f"effects {text!r}: {current!r} is declared twice (give it once, with every parameter)")
            effects.append(effect(current, **params))

    for token in (t.strip() for t in text.replace(";", ",").split(",")):
        if not token:
            raise InputError(f"effects {text!r}: an empty entry between separators")
        if ":" in token or "=" not in token:
            close()
            name, _, first = token.partition(":")
            current, params = name.strip(), {}
            token = first.strip()
            if not token:
                continue
        if current is None or "=" not in token:
            raise InputError(f"cannot parse effect declaration {text!r} near {token!r}")
        key, _, value = token.partition("=")
        if key.strip() in params:
            raise InputError(f"effect {current!r}: {key.strip()} is given twice")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            raise InputError(f"effect {current!r}: {key.strip()} must be a number, got {value!r}") from None
    close()
    return tuple(effects)


def declared_stages(effects: Iterable[Effect] | Effect, *, stages: Iterable[str], camera: str) -> dict[str, Effect]:
    """Check a camera's declared effects and index them by name.

    Parameters
    ----------
    effects : Effect or iterable of Effect
    stages : iterable of str
        The effect names this camera implements.
    camera : str
        The camera's name for messages, e.g. ``"spike-camera"``.

    Raises
    ------
    InputError
        For something that is not an :class:`Effect`, an effect this camera does not implement,
        or an effect declared twice.
    """
    names = tuple(stages)
    if isinstance(effects, Effect):
        effects = (effects,)
    try:
        items = tuple(effects)
    except TypeError:
        raise InputError(f"effects: expected a sequence of Effect objects, got {effects!r}") from None
    article = "an" if camera[:1] in "aeiou" else "a"
    by_name: dict[str, Effect] = {}
    for e in items:
        if not isinstance(e, Effect):
            raise InputError(f"effects: expected Effect objects (neuspike.conditions.effect), got {e!r}")
        if e.name not in names:
            raise InputError(
                f"effects: {e.name!r} is a {e.modality} effect, not {article} {camera} effect; "
                f"the {camera} has {', '.join(names)}"
            )
        if e.name in by_name:
            raise InputError(f"effects: {e.name!r} is declared twice")
        by_name[e.name] = e
    return by_name


#: The paper's noise levels (supplement §3; Table 3), each a preset that declares its stages.
NOISE_LEVELS: Mapping[str, tuple[Effect, ...]] = MappingProxyType({
    "none": (),
    "small": (effect("initial_charge"), effect("dark_current", isi_std_planes=10.0),
              effect("shot_noise", rate_hz=0.001)),
    "medium": (effect("initial_charge"), effect("dark_current", isi_std_planes=50.0),
               effect("shot_noise", rate_hz=10.0)),
    "high": (effect("initial_charge"), effect("dark_current", isi_std_planes=90.0),
             effect("shot_noise", rate_hz=100.0)),
})

#: v2e's event-camera presets (REFERENCE §3.1).
EVENT_PRESETS: Mapping[str, tuple[Effect, ...]] = MappingProxyType({
    "clean": (effect("threshold_mismatch", sigma=0.02),),
    "noisy": (effect("threshold_mismatch", sigma=0.05), effect("bandwidth", cutoff_hz=30.0),
              effect("leak", rate_hz=0.1), effect("shot_noise", rate_hz=5.0)),
})


def merge_effects(*groups: Iterable[Effect]) -> tuple[Effect, ...]:
    """Join effect lists; a later declaration of the same name replaces an earlier one."""
    by_name: dict[str, Effect] = {}
    for group in groups:
        for e in group:
            if not isinstance(e, Effect):
                raise InputError(f"expected Effect objects, got {e!r}")
            by_name.pop(e.name, None)
            by_name[e.name] = e
    return tuple(by_name.values())


@dataclass(frozen=True)
class Condition:
    """How the sensors see a scene.

    Parameters
    ----------
    light : float
        Light scale L (the paper uses 1/2 ... 1/32): radiance is multiplied by L before either sensor.
    motion : int
        Motion scale S: the number of scene instants (upsampled frames) spread over one spike
        window; each is held for ``planes // S`` planes (Algorithm 1).
    noise : str
        A key of :data:`NOISE_LEVELS`.
    effects : tuple of Effect
        Further declared stages; they replace a noise-level stage of the same name.
    """

    light: float = 0.25
    motion: int = 128
    noise: str = "none"
    effects: tuple[Effect, ...] = field(default=())

    def __post_init__(self) -> None:
        light = float(self.light)
        if not np.isfinite(light) or light <= 0:
            raise InputError(f"light scale L must be a positive number, got {self.light!r}")
        object.__setattr__(self, "light", light)
        object.__setattr__(self, "motion", check_int("motion scale S", self.motion, minimum=1))
        if self.noise not in NOISE_LEVELS:
            raise InputError(f"unknown noise level {self.noise!r}; choose one of {', '.join(NOISE_LEVELS)}")
        object.__setattr__(self, "effects", merge_effects(self.effects))

    def all_effects(self) -> tuple[Effect, ...]:
        """The noise level's stages followed by the extra declared ones (later wins)."""
        return merge_effects(NOISE_LEVELS[self.noise], self.effects)

    def effects_for(self, modality: str) -> tuple[Effect, ...]:
        """The declared stages of one modality (``"spikes"`` or ``"events"``)."""
        if modality not in (SPIKES, EVENTS):
            raise InputError(f"modality must be {SPIKES!r} or {EVENTS!r}, got {modality!r}")
        return tuple(e for e in self.all_effects() if e.modality == modality)

    def as_dict(self) -> dict[str, Any]:
        return {
            "light": self.light,
            "motion": self.motion,
            "noise": self.noise,
            "effects": [e.as_dict() for e in self.effects],
        }
