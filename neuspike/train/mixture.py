"""The data terms of training: registered parts of the data's draw, with their own parameters.

The base draw of a data section (light, motion, noise level, scene kind and picture, drawn over the
section's ranges) is what every spec gets. A data term changes a share of it: a share of the cells
drawn at the sweeps' points, a share of pictures swapped for broad leaves, a share of training runs
whose first window is cut short. A spec names the terms it mixes in, each with its parameters (the
data section's ``mixture``); a bare number is the term's fraction, and what a spec leaves out keeps
the term's default::

    "mixture": {"sweep": {"fraction": 0.5, "grid": "light-noise", "scenes": true,
                          "scene_weights": [1, 1, 4, 1]},
                "broad": 0.2}

``--set data.mixture.sweep.fraction=0.5`` sets one from the command line. A new way of drawing data is
one more :func:`register_data_term` call: its parameters, their check and what it adds to the shard's
key (the simulated items depend on it), read where the items are drawn
(:func:`neuspike.train.windows.draw_cell`, :func:`neuspike.train.sequences.make_batch`); not a spec
field, a flag and a validator. A term at fraction 0 with its defaults is left out, so a spec without it
draws exactly what it drew before the term existed, and its shard keeps its key.

The earlier spec fields (``sweep_fraction``, ``sweep_grid``, ``sweep_scenes``, ``sweep_scene_weights``,
``broad_fraction``; a sequence spec's ``partial_first``) are read into these terms by
:func:`legacy_mixture`, so every shipped card's spec still trains and loads. This module imports
nothing heavy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from neuspike.errors import InputError
from neuspike.train.terms import add_to_registry, complete_terms, move_fields

__all__ = ["DATA_TERMS", "DataTerm", "LEGACY_DATA_FIELDS", "SEQUENCE_DATA_TERMS", "SWEEP_GRID_NAMES", "legacy_mixture",
           "mixture_key", "register_data_term", "resolve_mixture"]

#: The point sets a ``sweep`` term may draw from (:data:`neuspike.train.spec.SWEEP_GRIDS`; a test holds them equal).
SWEEP_GRID_NAMES = ("sweeps", "light-noise")


@dataclass(frozen=True)
class DataTerm:
    """One registered data term (module docstring).

    ``defaults``: every parameter besides the fraction, with its default; ``check(params) -> params``:
    validates and normalises them (raising :class:`InputError`); ``key(params) -> dict``: the entries the
    term adds to the shard's key (what the simulated items depend on; empty for a term that acts on
    batches, not items).
    """

    name: str
    defaults: Mapping[str, Any] = field(default_factory=dict)
    check: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    key: Callable[[dict[str, Any]], dict[str, Any]] = lambda params: {}
    doc: str = ""


#: The registry of single-window data terms, in the order a spec lists them.
DATA_TERMS: dict[str, DataTerm] = {}
#: The registry of sequence data terms (recurrent networks), likewise.
SEQUENCE_DATA_TERMS: dict[str, DataTerm] = {}
_REGISTRIES: dict[str, dict[str, DataTerm]] = {"windows": DATA_TERMS, "sequences": SEQUENCE_DATA_TERMS}


def register_data_term(term: DataTerm, kind: str = "windows") -> DataTerm:
    """Add ``term`` to the registry of ``kind`` (``"windows"`` or ``"sequences"``; a name registered twice is an
    error)."""
    return add_to_registry(_REGISTRIES[kind], term, "data term")


def _fraction(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and 0 <= value <= 1):
        raise InputError(f"{where}: expected a fraction in [0, 1], got {value!r}")
    return float(value)


def resolve_mixture(mixture: Any, kind: str = "windows") -> dict[str, dict[str, Any]]:
    """``mixture`` checked and completed: ``{term: {"fraction": f, **params}}`` in the registry's order, every
    parameter given, terms at fraction 0 with nothing else set left out.

    Raises
    ------
    InputError
        Naming an unknown term (with the registered ones), an unknown parameter (with the term's), or a
        bad value.
    """
    out: dict[str, dict[str, Any]] = {}
    for name, term, params in complete_terms(mixture, _REGISTRIES[kind], section="mixture", amount="fraction",
                                             check_amount=_fraction, default_amount=lambda t: 0.0):
        if params["fraction"] == 0:
            changed = [k for k, v in term.defaults.items() if params[k] != v]
            if not changed:
                continue  # a term at fraction 0 with its defaults draws nothing: as if not named
            raise InputError(f"mixture.{name}.{changed[0]}: applies to the term's share of the data; give "
                             f"mixture.{name}.fraction > 0 too")
        out[name] = term.check(params) if term.check is not None else params
    return out


def mixture_key(mixture: Mapping[str, Mapping[str, Any]], kind: str = "windows") -> dict[str, Any]:
    """The entries a resolved ``mixture`` adds to the shard's key, term by term (empty without terms)."""
    registry = _REGISTRIES[kind]
    key: dict[str, Any] = {}
    for name, params in mixture.items():
        key.update(registry[name].key(dict(params)))
    return key


#: The earlier data fields of each kind and the (term, parameter) each became.
LEGACY_DATA_FIELDS: dict[str, dict[str, tuple[str, str]]] = {
    "windows": {"sweep_fraction": ("sweep", "fraction"), "sweep_grid": ("sweep", "grid"),
                "sweep_scenes": ("sweep", "scenes"), "sweep_scene_weights": ("sweep", "scene_weights"),
                "broad_fraction": ("broad", "fraction")},
    "sequences": {"partial_first": ("partial_first", "fraction")},
}


def legacy_mixture(section: Mapping[str, Any], mixture: Any = None, kind: str = "windows"
                   ) -> tuple[dict[str, Any], dict[str, Any]]:
    """Move the earlier fields of ``section`` into a ``mixture`` mapping: ``(section without them, mixture)``.

    ``mixture`` (the section's own, if any) starts empty where it is ``None``; an earlier field sets its
    term's parameter (``None`` values, the earlier "not set", are skipped).
    """
    return move_fields(section, LEGACY_DATA_FIELDS[kind], mixture or {}, amount="fraction")


# ----------------------------------------------------------------------------------------------
# The terms
# ----------------------------------------------------------------------------------------------

def _check_sweep(params: dict[str, Any]) -> dict[str, Any]:
    if params["grid"] not in SWEEP_GRID_NAMES:
        raise InputError(f"mixture.sweep.grid: expected one of {', '.join(SWEEP_GRID_NAMES)}, got {params['grid']!r}")
    if not isinstance(params["scenes"], bool):
        raise InputError(f"mixture.sweep.scenes: expected true or false, got {params['scenes']!r}")
    w = params["scene_weights"]
    if w is not None:
        if isinstance(w, (str, bytes)) or not hasattr(w, "__len__") or len(w) != 4 or not all(
                not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and v >= 0
                for v in w) or not sum(w) > 0:
            raise InputError("mixture.sweep.scene_weights: expected four weights >= 0 (pan, zoom, fan, still), "
                             f"not all zero, got {w!r}")
        if not params["scenes"]:
            raise InputError("mixture.sweep.scene_weights: applies to the sweeps' scenes; give "
                             "mixture.sweep.scenes true too")
        params = {**params, "scene_weights": tuple(float(v) for v in w)}
    return params


def _sweep_key(params: dict[str, Any]) -> dict[str, Any]:
    # the earlier fields' names and values: every shard drawn before the registry keeps its key
    key: dict[str, Any] = {"sweep_fraction": params["fraction"]}
    if params["grid"] != "sweeps":
        key["sweep_grid"] = params["grid"]
    if params["scenes"]:
        key["sweep_scenes"] = True
    if params["scene_weights"] is not None:
        key["sweep_scene_weights"] = list(params["scene_weights"])
    return key


register_data_term(DataTerm(
    "sweep", defaults={"grid": "sweeps", "scenes": False, "scene_weights": None}, check=_check_sweep, key=_sweep_key,
    doc="a share of the cells at the sweeps' points: (L, S, noise) one of the grid's points (grid 'sweeps': the three "
        "sweeps' 12; 'light-noise': those and the light x noise report's, 24) and pans at the sweeps' 1000 px/s; "
        "with scenes, the sweeps' own four scenes (pan, zoom, fan, still; shares scene_weights, default equal)"))
register_data_term(DataTerm(
    "broad", key=lambda params: {"broad_fraction": params["fraction"]},
    doc="a share of the picture cells whose picture is a broad-leaves image (a still dead-leaves scene whose "
        "smallest leaf is 5-15 % of the view's side) in place of a training photograph's region"))
def _check_smooth(params: dict[str, Any]) -> dict[str, Any]:
    sigma = params["sigma"]
    if isinstance(sigma, (str, bytes)) or not hasattr(sigma, "__len__") or len(sigma) != 2 or not all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in sigma) \
            or not sigma[0] <= sigma[1]:
        raise InputError(f"mixture.smooth.sigma: expected [low, high] blur widths > 0 in pixels of a 400-pixel-wide "
                         f"view, low <= high, got {sigma!r}")
    return {**params, "sigma": (float(sigma[0]), float(sigma[1]))}


register_data_term(DataTerm(
    "smooth", defaults={"sigma": (4.0, 24.0)}, check=_check_smooth,
    key=lambda params: {"smooth": [params["fraction"], list(params["sigma"])]},
    doc="a share of the photograph cells whose picture is smooth around a sharp object: the region blurred by a "
        "Gaussian of a width drawn log-uniformly in sigma (pixels of a 400-pixel-wide view) outside an ellipse "
        "covering 10-40 % of the view, where the photograph stays sharp (a clock on a wall, a car under a sky): "
        "flat and slowly varying regions beside texture, which the training photographs rarely hold"))


def _check_fast(params: dict[str, Any]) -> dict[str, Any]:
    speeds = params["speeds"]
    if isinstance(speeds, (str, bytes)) or not hasattr(speeds, "__len__") or not speeds or not all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in speeds):
        raise InputError(f"mixture.fast_pans.speeds: expected multiples of the sweeps' pan speed > 0, got {speeds!r}")
    motion = params["motion"]
    if isinstance(motion, bool) or not isinstance(motion, int) or motion < 1:
        raise InputError(f"mixture.fast_pans.motion: expected a motion scale S >= 1, got {motion!r}")
    return {**params, "speeds": tuple(float(v) for v in speeds)}


register_data_term(DataTerm(
    "fast_pans", defaults={"speeds": (2.0, 4.0, 8.0, 16.0), "motion": 256}, check=_check_fast,
    key=lambda params: {"fast_pans": [params["fraction"], list(params["speeds"]), params["motion"]]},
    doc="a share of the cells (of those not at the sweeps' points) panning a training photograph at a multiple of "
        "the sweeps' 1000 px/s (one of speeds, uniformly) at motion scale S = motion, at one of the sweeps' five "
        "light scales, without sensor noise: the fast-motion reports' conditions on the training photographs"))
register_data_term(DataTerm(
    "partial_first",
    doc="a share of the training runs whose first window is cut short (a run that starts mid-window, as a "
        "recording opened at any instant does)"), kind="sequences")
