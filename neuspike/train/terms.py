"""The loss terms of single-window training: registered components with their own parameters.

A window spec names the terms its loss adds up, each with its parameters (the data section's
``losses``); a bare number is the term's weight, and what a spec leaves out keeps the term's default::

    "losses": {"l1": 1, "ssim": {"weight": 1, "window": 11}, "offset": 0.5,
               "spike_floor": {"weight": 2, "noise_weights": {"high": 16}}}

``--set data.losses.offset=0.5`` sets one from the command line. The terms below are the registry
(:data:`TERMS`, in the order the loss adds them up); a new experiment is one more :func:`register_term`
call here: its parameters, their check, what it needs of the network (``setup``), and the function
that computes it, not a spec field, a flag and a validator. This module imports nothing heavy: the
spec checks a ``losses`` mapping against the registry without torch; the computations import torch
when they run.

Each term's ``compute(step, weight=..., **params)`` gets the :class:`Step` (the task, the step's
variant, inputs, target, the network's image and, where a term asks for it, the support head's convex
part) and returns ``(contribution, logged)``: the weighted tensor the loss adds (``None`` when the
term does not apply to this step) and the numbers the training log records.

The earlier spec fields (``ssim_weight``, ``offset_weight``, ``spike_floor_weight``, ``teacher`` with
``distill_weight`` and the rest) are read into these terms by :func:`legacy_losses`, so every shipped
card's spec still trains and loads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

from neuspike.errors import InputError

__all__ = ["DEFAULT_LOSSES", "DEFAULT_SEQUENCE_LOSSES", "LEGACY_FIELDS", "LossTerm", "SEQUENCE_TERMS", "SequenceStep",
           "Step", "TERMS", "add_to_registry", "complete_terms", "edge_mask", "gate_targets", "legacy_losses",
           "move_fields", "register_term", "resolve_losses", "sum_terms"]

#: The noise levels a term may name (as :data:`neuspike.train.spec.NOISE_LEVELS`).
_NOISE_LEVELS = ("none", "small", "medium", "high")


@dataclass(frozen=True)
class LossTerm:
    """One registered loss term (module docstring).

    ``defaults``: every parameter besides the weight, with its default; ``weight``: the default
    weight when a spec names the term without one; ``check(params) -> params``: validates and
    normalises the parameters (raising :class:`InputError`); ``setup(task, params)``: refuses a
    network the term cannot score, and prepares what it needs (a teacher), once per run;
    ``needs_convex``: the forward must return the support head's convex part; ``before_forward(step,
    params) -> undo``: runs before the step's forward (a hook on the network), ``undo()`` after it.
    """

    name: str
    compute: Callable[..., tuple[Any, dict[str, float]]]
    defaults: Mapping[str, Any] = field(default_factory=dict)
    weight: float = 1.0
    check: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    setup: Callable[[Any, dict[str, Any]], None] | None = None
    needs_convex: bool = False
    before_forward: Callable[[Any, dict[str, Any]], Callable[[], None] | None] | None = None
    #: The term needs only the image, the convex part and the target (:meth:`WindowTask.loss` computes it).
    image_only: bool = False
    doc: str = ""


#: The registry of single-window terms, in the order the loss adds them up.
TERMS: dict[str, LossTerm] = {}
#: The registry of sequence terms (recurrent networks), likewise.
SEQUENCE_TERMS: dict[str, LossTerm] = {}
#: Each data kind's registry.
REGISTRIES: dict[str, dict[str, LossTerm]] = {"windows": TERMS, "sequences": SEQUENCE_TERMS}


def add_to_registry(registry: dict[str, Any], term: Any, what: str) -> Any:
    """Add ``term`` (anything with a ``name``) to ``registry``; a name registered twice is an error naming ``what``
    it is. Loss terms and data terms (:mod:`neuspike.train.mixture`) alike."""
    if term.name in registry:
        raise InputError(f"{what} {term.name!r} is registered already")
    registry[term.name] = term
    return term


def register_term(term: LossTerm, kind: str = "windows") -> LossTerm:
    """Add ``term`` to the registry of ``kind`` (``"windows"`` or ``"sequences"``; a name registered twice is an
    error)."""
    return add_to_registry(REGISTRIES[kind], term, "loss term")


def complete_terms(given: Any, registry: Mapping[str, Any], *, section: str, amount: str,
                   check_amount: Callable[[str, Any], float], default_amount: Callable[[Any], float]
                   ) -> list[tuple[str, Any, dict[str, Any]]]:
    """The terms a spec's ``section`` names, checked against ``registry`` and completed, in the registry's order:
    ``[(name, term, {amount: a, **every parameter})]`` (a bare number is the term's ``amount``: a loss term's
    weight, a data term's fraction; what is left out takes its default). The caller drops or refuses terms at 0.

    Raises
    ------
    InputError
        Naming an unknown term (with the registered ones), an unknown parameter (with the term's), or a bad amount.
    """
    if not isinstance(given, Mapping):
        raise InputError(f"{section}: expected {{term: {amount} or {{parameter: value}}}}, got {given!r}")
    unknown = sorted(set(given) - set(registry))
    if unknown:
        raise InputError(f"{section}: unknown terms {unknown}; the registered ones: {', '.join(registry) or 'none'}")
    out = []
    for name, term in registry.items():
        if name not in given:
            continue
        named = given[name]
        named = {amount: named} if not isinstance(named, Mapping) else dict(named)
        bad = sorted(set(named) - set(term.defaults) - {amount})
        if bad:
            raise InputError(f"{section}.{name}: unknown parameters {bad}; it takes {amount}"
                             + "".join(f", {k}" for k in term.defaults))
        params = {amount: check_amount(f"{section}.{name}.{amount}", named.get(amount, default_amount(term))),
                  **{k: named.get(k, v) for k, v in term.defaults.items()}}
        out.append((name, term, params))
    return out


@dataclass
class Step:
    """What a term sees of one training step (filled by :meth:`neuspike.train.windows.WindowTask.step_loss`)."""

    task: Any
    index: int
    variant: str
    inputs: list[Any]
    target: Any
    autocast: Callable[[], Any]
    image: Any = None
    convex: Any = None
    #: What a ``before_forward`` hook captured, by term name.
    captured: dict[str, Any] = field(default_factory=dict)


def sum_terms(terms: Any, step: Any) -> tuple[Any, dict[str, float]]:
    """``terms`` (``(term, parameters)`` pairs, in the registry's order) computed on ``step`` and added up:
    ``(loss, what they log)``; a term that does not apply to the step adds nothing."""
    loss: Any = 0.0
    parts: dict[str, float] = {}
    for term, params in terms:
        value, logged = term.compute(step, **params)
        if value is not None:
            loss = loss + value
        parts.update(logged)
    return loss, parts


# ----------------------------------------------------------------------------------------------
# The spec side: a ``losses`` mapping checked against the registry
# ----------------------------------------------------------------------------------------------

def _weight(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value >= 0):
        raise InputError(f"{where}: expected a finite weight >= 0, got {value!r}")
    return float(value)


def resolve_losses(losses: Any, kind: str = "windows") -> dict[str, dict[str, Any]]:
    """``losses`` checked and completed: ``{term: {"weight": w, **params}}`` in the registry's order,
    every parameter given (defaults filled in), terms of weight 0 with nothing else set left out.

    Raises
    ------
    InputError
        Naming an unknown term (with the registered ones), an unknown parameter (with the term's), or
        a bad value.
    """
    out: dict[str, dict[str, Any]] = {}
    for name, term, params in complete_terms(losses, REGISTRIES[kind], section="losses", amount="weight",
                                             check_amount=_weight, default_amount=lambda t: t.weight):
        if params["weight"] == 0 and all(params[k] == v for k, v in term.defaults.items()):
            continue  # a term at weight 0 with its defaults adds nothing: as if not named
        out[name] = term.check(params) if term.check is not None else params
    return out


#: The losses of a window spec that names none: L1 + the SSIM loss (window 11), as every spec before the registry.
DEFAULT_LOSSES: dict[str, Any] = {"l1": 1.0, "ssim": {"weight": 1.0, "window": 11}}

#: The losses of a sequence spec that names none, as every spec before the registry.
DEFAULT_SEQUENCE_LOSSES: dict[str, Any] = {"l1": 1.0, "ssim": 1.0, "temporal": {"weight": 1.0, "occlusion_alpha": 50.0}}

#: The earlier fields of a sequence spec and the (term, parameter) each became.
SEQUENCE_LEGACY_FIELDS: dict[str, tuple[str, str]] = {
    "l1": ("l1", "weight"), "ssim": ("ssim", "weight"), "temporal": ("temporal", "weight"),
    "occlusion_alpha": ("temporal", "occlusion_alpha"), "history": ("history", "weight"), "empty": ("empty", "weight"),
}

#: The earlier spec fields and the (term, parameter) each became.
LEGACY_FIELDS: dict[str, tuple[str, str]] = {
    "ssim_weight": ("ssim", "weight"), "ssim_window": ("ssim", "window"),
    "offset_weight": ("offset", "weight"), "support_weight": ("support", "weight"),
    "edge_ssim_weight": ("edge_ssim", "weight"),
    "spike_floor_weight": ("spike_floor", "weight"), "spike_floor_noise_weights": ("spike_floor", "noise_weights"),
    "spike_floor_terms": ("spike_floor", "terms"),
    "gate_target_weight": ("gate_target", "weight"), "gate_targets": ("gate_target", "targets"),
    "gate_forcing": ("gate_target", "forcing"),
    "distill_weight": ("distill", "weight"), "teacher": ("distill", "teacher"),
}


def legacy_losses(section: Mapping[str, Any], losses: Any = None, kind: str = "windows"
                  ) -> tuple[dict[str, Any], dict[str, Any]]:
    """Move the earlier fields of ``section`` into a ``losses`` mapping: ``(section without them, losses)``.

    ``losses`` (the section's own, if any) starts from the kind's defaults (:data:`DEFAULT_LOSSES`,
    :data:`DEFAULT_SEQUENCE_LOSSES`) where it is ``None``; an earlier field sets its term's parameter
    (``None`` values, the earlier "not set", are skipped).
    """
    defaults, fields = ((DEFAULT_LOSSES, LEGACY_FIELDS) if kind == "windows"
                        else (DEFAULT_SEQUENCE_LOSSES, SEQUENCE_LEGACY_FIELDS))
    return move_fields(section, fields, defaults if losses is None else losses, amount="weight",
                       default_amount=lambda term: 1.0 if term in ("l1", "ssim", "temporal") else 0.0)


def move_fields(section: Mapping[str, Any], fields: Mapping[str, tuple[str, str]], start: Mapping[str, Any], *,
                amount: str, default_amount: Callable[[str], float] | None = None
                ) -> tuple[dict[str, Any], dict[str, Any]]:
    """Move the earlier fields of ``section`` (``fields``: field -> (term, parameter)) into a copy of the terms
    mapping ``start``: ``(section without them, terms)``. A field of value ``None`` (the earlier "not set") is
    dropped; a term a field creates gets ``default_amount(term)`` as its ``amount`` where given."""
    rest = dict(section)
    out: dict[str, Any] = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in start.items()}
    for key, (term, param) in fields.items():
        if key not in rest:
            continue
        value = rest.pop(key)
        if value is None:
            continue
        current = out.get(term, {})
        current = {amount: current} if not isinstance(current, Mapping) else dict(current)
        current[param] = value
        if amount not in current and default_amount is not None:
            current[amount] = default_amount(term)
        out[term] = current
    return rest, out


# ----------------------------------------------------------------------------------------------
# The terms
# ----------------------------------------------------------------------------------------------

#: The motion levels a gate target may name (x_m^0 .. x_m^3).
GATE_LEVELS = ("0", "1", "2", "3")


def gate_targets(value: Any) -> dict[str, dict[str, float]]:
    """The ``gate_target`` loss term's targets checked: {noise level: {motion level: gain in [0, 2)}}, in
    _NOISE_LEVELS and level order."""
    shape = "{noise level: {motion level '0'..'3': gain in [0, 2)}}"
    if not isinstance(value, dict) or not value:
        raise InputError(f"gate_targets: expected {shape} with at least one level, got {value!r}")
    bad = sorted(set(value) - set(_NOISE_LEVELS))
    if bad:
        raise InputError(f"gate_targets: unknown noise levels {bad}; choose from {', '.join(_NOISE_LEVELS)}")
    out: dict[str, dict[str, float]] = {}
    for noise in (n for n in _NOISE_LEVELS if n in value):
        gains = value[noise]
        if not isinstance(gains, dict) or not gains:
            raise InputError(f"gate_targets[{noise!r}]: expected {{motion level: gain}} with at least one level, "
                             f"got {gains!r}")
        levels = {str(k): v for k, v in gains.items()}
        bad = sorted(set(levels) - set(GATE_LEVELS))
        if bad:
            raise InputError(f"gate_targets[{noise!r}]: unknown motion levels {bad}; choose from "
                             f"{', '.join(GATE_LEVELS)} (x_m^0 .. x_m^3)")
        for k, v in levels.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= float(v) < 2.0:
                raise InputError(f"gate_targets[{noise!r}][{k!r}]: expected a gain in [0, 2) (the gate's range), "
                                 f"got {v!r}")
        out[noise] = {k: float(levels[k]) for k in GATE_LEVELS if k in levels}
    return out


#: Share of a crop's pixels that :func:`edge_mask` marks (the fast-motion report's edge share).
EDGE_SHARE = 0.1


def edge_mask(target: Any, share: float = EDGE_SHARE) -> Any:
    """Boolean (B, 1, H, W): per crop, the pixels whose gradient magnitude (central differences inside,
    one-sided at the border, as ``numpy.gradient``) is in the crop's top ``share`` (at least one): the
    mask of ``bench.fast_motion.edge_mask``, batched in torch for the loss (the test holds them equal)."""
    import torch

    gy, gx = torch.gradient(target.double(), dim=(-2, -1))
    magnitude = torch.hypot(gx, gy).flatten(1)
    count = max(1, int(round(share * magnitude.shape[1])))
    threshold = magnitude.topk(count, dim=1).values[:, -1:]
    return (magnitude >= threshold).view_as(target)


def _l1(step: Step, *, weight: float) -> tuple[Any, dict[str, float]]:
    l1 = (step.image - step.target).abs().mean()
    return weight * l1, {"l1": l1.item()}


def _ssim(step: Step, *, weight: float, window: int, noise_weights: Any = None) -> tuple[Any, dict[str, float]]:
    if noise_weights is None:
        ssim = step.task.ssim_loss(step.image, step.target)
        return weight * ssim, {"ssim_loss": ssim.item()}
    import torch

    task = step.task
    per_crop = task.crop_losses(step.image, step.target, "ssim")
    w = torch.tensor([noise_weights.get(level, weight) for level in task.noise_levels(step.index)],
                     dtype=per_crop.dtype, device=per_crop.device)
    return (w * per_crop).mean(), {"ssim_loss": per_crop.mean().item()}


def _check_window(params: dict[str, Any]) -> dict[str, Any]:
    window = params["window"]
    if isinstance(window, bool) or not isinstance(window, int) or window < 3 or window % 2 == 0:
        raise InputError(f"losses.ssim.window: expected an odd whole number >= 3, got {window!r}")
    return _check_noise_weights("losses.ssim", params)


def _check_noise_weights(where: str, params: dict[str, Any]) -> dict[str, Any]:
    """``params["noise_weights"]`` (None, or {noise level: weight >= 0}) checked; levels in order."""
    w = params["noise_weights"]
    if w is None:
        return params
    if not isinstance(w, Mapping) or not w:
        raise InputError(f"{where}.noise_weights: expected {{noise level: weight}} with at least one level, got {w!r}")
    bad = sorted(set(w) - set(_NOISE_LEVELS))
    if bad:
        raise InputError(f"{where}.noise_weights: unknown noise levels {bad}; choose from {', '.join(_NOISE_LEVELS)}")
    return {**params, "noise_weights": {k: _weight(f"{where}.noise_weights[{k!r}]", w[k])
                                        for k in _NOISE_LEVELS if k in w}}


def _offset(step: Step, *, weight: float) -> tuple[Any, dict[str, float]]:
    image, target = step.image, step.target
    offset = (image.mean(dim=(-2, -1)) - target.mean(dim=(-2, -1))).abs().mean()
    return weight * offset, {}


def _support(step: Step, *, weight: float) -> tuple[Any, dict[str, float]]:
    if step.convex is None:
        raise InputError("losses.support: the loss needs the convex part (forward with parts=True)")
    support_l1 = (step.convex.float() - step.target).abs().mean()
    return weight * support_l1, {"support_l1": support_l1.item()}


def _support_setup(task: Any, params: dict[str, Any]) -> None:
    if getattr(task.module, "head", "tanh") == "tanh":
        raise InputError(f"losses.support {params['weight']}: the network's head has no convex part to score (give a "
                         "'support' or 'support-count' head, or leave the term out)")


def _edge_ssim(step: Step, *, weight: float) -> tuple[Any, dict[str, float]]:
    import kornia

    ssim_map = kornia.metrics.ssim(step.image, step.target, window_size=step.task.ssim_window, max_val=1.0)
    edges = edge_mask(step.target).to(ssim_map.dtype)
    edge_ssim = ((1.0 - ssim_map) / 2 * edges).sum() / edges.sum()
    return weight * edge_ssim, {"edge_ssim_loss": edge_ssim.item()}


def _fusion_only(task: Any, what: str) -> None:
    if not task.fusion:
        raise InputError(f"{what}: fusion networks only (the network has no motion path)")


def _check_gate(params: dict[str, Any]) -> dict[str, Any]:
    if params["targets"] is None:
        raise InputError("losses.gate_target: give its targets ({noise level: {motion level: gain}})")
    if not params["weight"] > 0:
        raise InputError("losses.gate_target: give a weight > 0 with the targets")
    if not isinstance(params["forcing"], bool):
        raise InputError(f"losses.gate_target.forcing: expected true or false, got {params['forcing']!r}")
    return {**params, "targets": gate_targets(params["targets"])}


def _gate_setup(task: Any, params: dict[str, Any]) -> None:
    _fusion_only(task, "losses.gate_target")
    if task.supervised_gate is None:
        raise InputError("losses.gate_target: the network has no motion gate to supervise (a fusion network with "
                         "params motion_gate 'stats', 'stats-local' or 'stats-noise')")


def _gate_before(step: Step, params: dict[str, Any]) -> Callable[[], None] | None:
    """Capture the supervised gate's gains of a fusion step (and with ``forcing``, replace those that
    have a target by the target: the rest of the network trains on the gains the targets say)."""
    if step.variant != "fusion":
        return None
    supervised = step.task.gate_targets(step.index, params["targets"])
    if supervised is None:
        return None
    gains: list[Any] = []
    forcing = params["forcing"]

    def capture(_module: Any, _inputs: Any, out: Any) -> Any:
        gains.append(out)
        if not forcing:
            return None
        import torch

        value, mask = supervised
        return torch.where(mask.bool(), value.to(out.dtype), out)

    step.captured["gate_target"] = (supervised, gains)
    return step.task.supervised_gate.register_forward_hook(capture).remove


def _gate_target(step: Step, *, weight: float, targets: Any, forcing: bool) -> tuple[Any, dict[str, float]]:
    if "gate_target" not in step.captured:
        return None, {}
    (value, mask), gains = step.captured["gate_target"]
    miss = ((gains[0].float() - value).square() * mask).sum() / mask.sum()
    return weight * miss, {"gate_target": miss.item()}


def _check_distill(params: dict[str, Any]) -> dict[str, Any]:
    teacher = params["teacher"]
    if teacher is None:
        raise InputError("losses.distill: give its teacher (a trained network's .safetensors with its JSON card)")
    if not str(teacher).endswith(".safetensors"):
        raise InputError(f"losses.distill.teacher: expected a .safetensors file, got {teacher!r}")
    if not params["weight"] > 0:
        raise InputError("losses.distill: give a weight > 0 (the weight of the teacher's term)")
    return {**params, "teacher": str(teacher)}


def _distill_setup(task: Any, params: dict[str, Any]) -> None:
    task.teacher = task.load_teacher(params["teacher"])


def _distill(step: Step, *, weight: float, teacher: str) -> tuple[Any, dict[str, float]]:
    with step.autocast():
        taught = step.task.teacher_image(step.inputs, step.variant).float()
    distill = step.task.crop_losses(step.image.float(), taught).mean()
    return weight * distill, {"distill": distill.item()}


def _check_floor(params: dict[str, Any]) -> dict[str, Any]:
    if params["terms"] not in ("both", "ssim"):
        raise InputError(f"losses.spike_floor.terms: expected both or ssim, got {params['terms']!r}")
    network = params["network"]
    if network is not None:
        if not isinstance(network, str) or not network.endswith(".safetensors"):
            raise InputError(f"losses.spike_floor.network: expected a spike-only network's .safetensors file, "
                             f"got {network!r}")
    return _check_noise_weights("losses.spike_floor", {**params, "emphasis": _check_emphasis(params["emphasis"])})


_EMPHASIS_RANGES = ("light", "motion")


def _check_emphasis(emphasis: Any) -> list[dict[str, Any]] | None:
    """``losses.spike_floor.emphasis`` checked: None, or a list of {"light": [lo, hi], "motion": [lo, hi],
    "factor": f > 0}, each range optional (closed; a window's cell must lie in every range given)."""
    if emphasis is None:
        return None
    where = "losses.spike_floor.emphasis"
    if not isinstance(emphasis, Sequence) or isinstance(emphasis, str) or not emphasis:
        raise InputError(f"{where}: expected a list of {{light: [lo, hi], motion: [lo, hi], factor: f}}, "
                         f"got {emphasis!r}")
    out = []
    for k, entry in enumerate(emphasis):
        if not isinstance(entry, Mapping) or "factor" not in entry:
            raise InputError(f"{where}[{k}]: expected {{light: [lo, hi], motion: [lo, hi], factor: f}} with a "
                             f"factor, got {entry!r}")
        unknown = sorted(set(entry) - {"factor", *_EMPHASIS_RANGES})
        if unknown:
            raise InputError(f"{where}[{k}]: unknown keys {unknown}; give light, motion and factor")
        if not any(name in entry for name in _EMPHASIS_RANGES):
            raise InputError(f"{where}[{k}]: give a light or a motion range (else raise the term's weight)")
        checked: dict[str, Any] = {"factor": _weight(f"{where}[{k}].factor", entry["factor"])}
        if not checked["factor"] > 0:
            raise InputError(f"{where}[{k}].factor: expected > 0, got {entry['factor']!r}")
        for name in _EMPHASIS_RANGES:
            if name not in entry:
                continue
            r = entry[name]
            try:
                lo, hi = (float(v) for v in r)
            except (TypeError, ValueError):
                raise InputError(f"{where}[{k}].{name}: expected [low, high], got {r!r}") from None
            if not lo <= hi:
                raise InputError(f"{where}[{k}].{name}: expected low <= high, got {r!r}")
            checked[name] = [lo, hi]
        out.append(checked)
    return out


def _emphasis_factors(cells: list[dict[str, Any]], emphasis: list[dict[str, Any]]) -> list[float]:
    """Each window's product of the factors of the emphasis entries whose ranges hold its cell."""
    factors = []
    for cell in cells:
        f = 1.0
        for entry in emphasis:
            if all(entry[name][0] <= float(cell[name]) <= entry[name][1] for name in _EMPHASIS_RANGES
                   if name in entry):
                f *= entry["factor"]
        factors.append(f)
    return factors


def _floor_setup(task: Any, params: dict[str, Any]) -> None:
    _fusion_only(task, "losses.spike_floor")
    if params["network"] is not None:
        task.floor_network = task.load_teacher(params["network"], "losses.spike_floor.network", spike_only=True)


def _spike_floor(step: Step, *, weight: float, noise_weights: Any, terms: str, network: Any, emphasis: Any
                 ) -> tuple[Any, dict[str, float]]:
    import torch

    if step.variant != "fusion":
        return None, {}
    task = step.task
    if noise_weights is None and emphasis is None:
        weights: Any = weight or None
    else:
        cells = task.cells(step.index)
        w = [weight if noise_weights is None else noise_weights.get(cell["noise"], weight) for cell in cells]
        if emphasis is not None:
            w = [a * b for a, b in zip(w, _emphasis_factors(cells, emphasis))]
        weights = torch.tensor(w, dtype=torch.float32, device=task.device) if any(w) else None
    if weights is None:
        return None, {}
    with torch.no_grad(), step.autocast():
        if network is None:  # the network's own spike-only self
            floor = task.forward(step.inputs, "spike")
        else:  # a trained spike-only network, held: the variant the fusion ships beside
            floor = task.floor_network(step.inputs[0], *step.inputs[2:])
    excess = (task.crop_losses(step.image, step.target, terms)
              - task.crop_losses(floor, step.target, terms)).clamp_min(0.0)
    if isinstance(weights, torch.Tensor):
        value = (weights * excess).mean()
    else:  # (one weight: the sum as every spec before the noise weights computed it)
        value = weights * excess.mean()
    return value, {"spike_floor": excess.mean().item()}


register_term(LossTerm("l1", _l1, image_only=True, doc="mean absolute error of the image"))
register_term(LossTerm("ssim", _ssim, image_only=True, defaults={"window": 11, "noise_weights": None},
                       check=_check_window,
                       doc="kornia's SSIM loss (1 - SSIM) / 2 over windows of the given side, data range 1; with "
                           "noise_weights each crop's loss weighted by its noise level's weight (others: weight)"))
register_term(LossTerm("offset", _offset, image_only=True, weight=0.0,
                       doc="|mean(image) - mean(truth)| per crop, averaged: an error of the whole image's level, to "
                           "which the SSIM term is blind"))
register_term(LossTerm("support", _support, image_only=True, weight=0.0, setup=_support_setup, needs_convex=True,
                       doc="mean absolute error of the support head's convex part (before the correction)"))
register_term(LossTerm("edge_ssim", _edge_ssim, image_only=True, weight=0.0,
                       doc="the SSIM loss over each crop's edge pixels only (the top 10 % of the truth's gradient)"))
register_term(LossTerm("gate_target", _gate_target, defaults={"targets": None, "forcing": False}, weight=0.0,
                       check=_check_gate, setup=_gate_setup, before_forward=_gate_before,
                       doc="fusion steps: mean squared miss of the motion (or noise) gate's gains against targets "
                           "per noise level and motion level; with forcing the forward uses the targets"))
register_term(LossTerm("distill", _distill, defaults={"teacher": None}, weight=0.0, check=_check_distill,
                       setup=_distill_setup,
                       doc="the student's L1 + SSIM-term loss against a trained network's image (the teacher, run on "
                           "each step's inputs in the step's variant)"))
register_term(LossTerm("spike_floor", _spike_floor, defaults={"noise_weights": None, "terms": "both", "network": None,
                                                              "emphasis": None},
                       weight=0.0, check=_check_floor, setup=_floor_setup,
                       doc="fusion steps: relu(l_fusion - l_spike) per crop, l a crop's L1 + SSIM-term loss (terms "
                           "'both') or SSIM loss alone ('ssim'), weighted per crop by its noise level's weight; l_spike "
                           "the network's own spike-only self, or with network (a spike-only network's .safetensors "
                           "with its JSON card) that trained network's image, held; with emphasis (a list of "
                           "{light: [lo, hi], motion: [lo, hi], factor}) the weight of each crop whose window's cell "
                           "lies in an entry's ranges multiplied by its factor"))


# ----------------------------------------------------------------------------------------------
# The sequence terms (recurrent networks: :mod:`neuspike.train.sequences`)
# ----------------------------------------------------------------------------------------------

@dataclass
class SequenceStep:
    """What a sequence term sees of one training step: ``outputs`` (the network's image after each window of
    the batch, K of (B, 1, H, W)), ``batch`` (``voxels``, ``targets``, ``flow``), ``data`` (the spec's data
    section) and ``task`` (the :class:`~neuspike.train.sequences.SequenceTask`; ``None`` where only the
    images are scored)."""

    outputs: list[Any]
    batch: dict[str, Any]
    data: Any
    task: Any = None
    #: ``warp(image, flow) -> (warped, valid)`` (:func:`neuspike.train.sequences.warp`).
    warp: Callable[..., Any] | None = None
    #: ``run(voxels) -> outputs``: the task's network over a sequence of voxel grids from a zero state.
    run: Callable[[Any], list[Any]] | None = None


def _scored(step: SequenceStep) -> range:
    """The windows the loss scores: those after ``warmup_windows``."""
    return range(step.data.warmup_windows, len(step.outputs))


def _seq_l1(step: SequenceStep, *, weight: float) -> tuple[Any, dict[str, float]]:
    targets, l1 = step.batch["targets"], 0.0
    for k in _scored(step):
        l1 = l1 + (step.outputs[k].float() - targets[k]).abs().mean()
    l1 = l1 / len(_scored(step))
    return weight * l1, {"l1": float(l1.detach()) if hasattr(l1, "detach") else float(l1)}


def _seq_ssim(step: SequenceStep, *, weight: float) -> tuple[Any, dict[str, float]]:
    import kornia

    targets, ssim = step.batch["targets"], 0.0
    for k in _scored(step):
        ssim = ssim + 2 * kornia.losses.ssim_loss(step.outputs[k].float(), targets[k], window_size=7, max_val=1.0)
    ssim = ssim / len(_scored(step))
    return weight * ssim, {"ssim_loss": float(ssim.detach()) if hasattr(ssim, "detach") else float(ssim)}


def _seq_temporal(step: SequenceStep, *, weight: float, occlusion_alpha: float) -> tuple[Any, dict[str, float]]:
    import torch

    warp = step.warp
    targets, flow, tc = step.batch["targets"], step.batch["flow"], 0.0
    for k in _scored(step):
        if k > 0:
            o, y = step.outputs[k].float(), targets[k]
            prev_o, valid = warp(step.outputs[k - 1].float(), flow[k])
            prev_y, _ = warp(targets[k - 1], flow[k])
            mask = valid * torch.exp(-occlusion_alpha * (y - prev_y) ** 2)
            tc = tc + (mask * (o - prev_o).abs()).mean()
    tc = tc / len(_scored(step))
    return weight * tc, {"temporal": float(tc.detach()) if hasattr(tc, "detach") else float(tc)}


def _check_alpha(params: dict[str, Any]) -> dict[str, Any]:
    _weight("losses.temporal.occlusion_alpha", params["occlusion_alpha"])
    return {**params, "occlusion_alpha": float(params["occlusion_alpha"])}


def _history(step: SequenceStep, *, weight: float) -> tuple[Any, dict[str, float]]:
    start = step.data.length // 2
    short = step.run(step.batch["voxels"][start:])
    gap = (step.outputs[-1].float() - short[-1].float()).abs().mean()
    return weight * gap, {}


def _empty(step: SequenceStep, *, weight: float) -> tuple[Any, dict[str, float]]:
    import torch

    blank = torch.zeros((1, 1, *step.batch["voxels"].shape[2:]), device=step.batch["voxels"].device)
    image = step.run(blank)[0].float()
    spread = (image - image.mean()).abs().mean()
    return weight * spread, {"empty_spread": float(spread.detach())}


register_term(LossTerm("l1", _seq_l1, image_only=True, doc="mean absolute error over the scored windows"),
              "sequences")
register_term(LossTerm("ssim", _seq_ssim, image_only=True, doc="1 - SSIM (window 7) over the scored windows"),
              "sequences")
register_term(LossTerm("temporal", _seq_temporal, defaults={"occlusion_alpha": 50.0}, image_only=True,
                       check=_check_alpha,
                       doc="|o_k - warp(o_{k-1})| under the exact flow, masked where the truth changes (occlusions)"),
              "sequences")
register_term(LossTerm("history", _history, weight=0.0,
                       doc="the gap between the last image and the same image from a second pass over the last "
                           "length - length // 2 windows started from a zero state"), "sequences")
register_term(LossTerm("empty", _empty, weight=0.0,
                       doc="the spatial spread of the image one window without events gives from a zero state"),
              "sequences")
