"""The frozen training specification: plain data, validated, saved as JSON beside the checkpoint."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from neuspike.conditions import NOISE_LEVELS
from neuspike.errors import InputError
from neuspike.scenes.photos import TEST_PHOTOS, TRAIN_PHOTOS

__all__ = ["KIND_WEIGHTS", "TrainSpec", "load_spec"]

#: Scene kinds drawn for training and their probabilities (``dead_leaves`` is procedural).
KIND_WEIGHTS: dict[str, float] = {"pan": 0.3, "zoom": 0.12, "fan": 0.13, "still": 0.05, "dead_leaves": 0.4}


@dataclass(frozen=True)
class TrainSpec:
    """Everything a training run depends on (the JSON beside the checkpoint).

    Parameters
    ----------
    method : str
        A registered learned method offering the training protocol (:mod:`neuspike.train`).
    out_dir : str
        Folder of the run: spec.json, checkpoint.pt, train_log.csv.
    shard_dir : str
        Folder of the simulated windows (shared by runs with the same :meth:`data_key`).
    seed : int
        Seeds the data (cells, order, crops) and the initial weights.
    steps : int
        Optimiser steps.
    batch : int
        Samples per step.
    crop : int
        Side of the square training crops (pixels).
    view : int
        Side of the simulated square views the crops come from.
    shard_size, val_size : int
        Training windows simulated once and reused (with random crops, flips and quarter turns);
        validation windows (never augmented).
    lr, lr_min : float
        AdamW learning rate: linear warm-up over ``warmup`` steps to ``lr``, cosine decay to ``lr_min``.
    weight_decay : float
    ssim_weight : float
        Loss = L1 + ssim_weight * kornia SSIM loss (window ``ssim_window``).
    spike_only_fraction : float
        Fraction of steps (for a fusion network) run with the motion path silenced, which trains the
        spike-only variant inside the same weights.
    val_every, checkpoint_every : int
        Steps between validations / checkpoints.
    threads : int
        torch threads.
    precision : str
        ``"auto"`` (bfloat16 autocast where the CPU has it natively), ``"float32"`` or ``"bfloat16"``.
    light_range : (float, float)
        L drawn log-uniformly in this range.
    motions : tuple of int
        S drawn uniformly from these.
    noise_levels : tuple of str
        Noise levels drawn uniformly.
    photos : tuple of str
        Training photographs (test photographs are refused).
    params : dict
        Overrides of the method's registered parameters (the ablation's candidates).
    export : bool
        Write the best-by-validation weights into the package (``neuspike/trained/``).
    workers : int
        Processes that simulate the shard.
    """

    method: str = "neuspike-net"
    out_dir: str = "runs/neuspike-net"
    shard_dir: str = "runs/shard"
    seed: int = 0
    steps: int = 9000
    batch: int = 8
    crop: int = 128
    view: int = 128
    shard_size: int = 4000
    val_size: int = 48
    lr: float = 5e-4
    lr_min: float = 1e-5
    warmup: int = 200
    weight_decay: float = 1e-4
    ssim_weight: float = 1.0
    ssim_window: int = 11
    spike_only_fraction: float = 0.3
    val_every: int = 250
    checkpoint_every: int = 100
    threads: int = 1
    precision: str = "auto"
    light_range: tuple[float, float] = (1 / 40, 0.6)
    motions: tuple[int, ...] = (16, 32, 64, 128, 256)
    noise_levels: tuple[str, ...] = ("none", "small", "medium", "high")
    photos: tuple[str, ...] = TRAIN_PHOTOS
    params: dict[str, Any] = field(default_factory=dict)
    export: bool = False
    workers: int = 2
    #: Weights (a ``.safetensors`` of the full module) the run starts from instead of a fresh
    #: initialisation: a second stage of an earlier run. ``None``: fresh weights from ``seed``.
    init_from: str | None = None

    def __post_init__(self) -> None:
        put = object.__setattr__
        for name in ("steps", "batch", "crop", "view", "shard_size", "val_size", "val_every",
                     "checkpoint_every", "threads", "workers", "ssim_window"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise InputError(f"{name}: expected a whole number >= 1, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InputError(f"seed: expected a whole number >= 0, got {self.seed!r}")
        if self.crop > self.view:
            raise InputError(f"crop: {self.crop} is larger than the simulated view {self.view}")
        if self.crop % 8:
            raise InputError(f"crop: expected a multiple of 8, got {self.crop}")
        if not 0 < self.lr_min <= self.lr:
            raise InputError(f"lr, lr_min: expected 0 < lr_min <= lr, got {self.lr_min}, {self.lr}")
        if not 0.0 <= self.spike_only_fraction <= 1.0:
            raise InputError(f"spike_only_fraction: expected a fraction in [0, 1], got {self.spike_only_fraction}")
        lo, hi = (float(v) for v in self.light_range)
        if not 0 < lo <= hi:
            raise InputError(f"light_range: expected 0 < low <= high, got {self.light_range}")
        put(self, "light_range", (lo, hi))
        motions = tuple(int(m) for m in self.motions)
        if not motions or any(m < 1 for m in motions):
            raise InputError(f"motions: expected motion scales >= 1, got {self.motions}")
        put(self, "motions", motions)
        levels = tuple(self.noise_levels)
        bad = [n for n in levels if n not in NOISE_LEVELS]
        if not levels or bad:
            raise InputError(f"noise_levels: unknown {bad}; choose from {', '.join(NOISE_LEVELS)}")
        put(self, "noise_levels", levels)
        photos = tuple(self.photos)
        refused = [p for p in photos if p in TEST_PHOTOS]
        if refused:
            raise InputError(f"photos: {refused} are test photographs; training may use only {TRAIN_PHOTOS}")
        unknown = [p for p in photos if p not in TRAIN_PHOTOS]
        if unknown:
            raise InputError(f"photos: {unknown} are not training photographs ({', '.join(TRAIN_PHOTOS)})")
        if not photos:
            raise InputError("photos: at least one training photograph is needed")
        put(self, "photos", photos)
        put(self, "params", dict(self.params))
        if self.init_from is not None and not str(self.init_from).endswith(".safetensors"):
            raise InputError(f"init_from: expected a .safetensors file, got {self.init_from!r}")
        if self.precision not in ("auto", "float32", "bfloat16"):
            raise InputError(f"precision: expected auto, float32 or bfloat16, got {self.precision!r}")

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        for k in ("light_range", "motions", "noise_levels", "photos"):
            out[k] = list(out[k])
        return out

    def data_key(self) -> dict[str, Any]:
        """What the simulated data depends on (a shard is reused only when this matches)."""
        return {k: v for k, v in self.as_dict().items()
                if k in ("seed", "view", "light_range", "motions", "noise_levels", "photos")}
        # (shard_size and val_size only say how many of the same deterministic cells exist)


def load_spec(path: str | Path) -> TrainSpec:
    """A spec from its JSON file (unknown keys are an error)."""
    data = json.loads(Path(path).read_text())
    known = {f.name for f in fields(TrainSpec)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"{path}: unknown spec keys {unknown}")
    return TrainSpec(**data)
