"""Training recurrent event networks on sequences of simulated event windows (``e2vid``, ``firenet-sim``).

A training *item* is one moving scene seen through ``windows`` consecutive event windows, exactly as
the method reads a sample at inference: the cell (scene, condition, sensor, seed) goes through
:func:`neuspike.simulate.simulate_sample` (the one cell-to-sample path) with enough event history,
the method's own :meth:`windows`/:meth:`encode` cut it into fixed-count windows (``0.35 * H * W``
events, counted back from the key instant) and voxel grids (5 bins, non-zero entries normalised to
mean 0 and std 1 as E2VID does), and the last ``windows`` of them form the item. Each window's
target is the scene rendered at the scene instant of the window's end (the last one is the
sample's own ground truth), clipped to [0, 1]. The scenes are analytic, so the exact backward
optical flow between consecutive window ends is known (:func:`backward_flow`): a pan translates, a
zoom scales about its focus; for a fan the background is static and the blades' pixels are left to
the occlusion mask (flow zero).

Data (:func:`draw_cell`): the training photographs only (``TRAIN_PHOTOS``; the test photographs are
refused), pan / zoom / fan scenes with random direction, speed, zoom rate, focus, rpm and blades,
and on request procedural ``dead_leaves`` scenes (occluding layers, endless variety),
linear or high-dynamic-range radiance (``hdr_fraction`` of the items), motion scale S in {16, ..., 256}, light L in {1/2, ..., 1/32},
event contrast threshold log-uniform in ``threshold_range``, and noise level none..high drawn
uniformly over ``noise_levels`` (the event shot noise of the paper's levels; a level listed twice is
drawn twice as often). Items are simulated once into a *shard*
(``runs/shards/<hash>/``, one ``.npz`` per item, written atomically, resumable) shared by every
network with the same data spec; training takes random crops and flips of them.

Loss, on every step after ``warmup`` steps of each sequence (the state carried, from zeros):
``l1 * |o - y| + ssim * (1 - SSIM(o, y)) + temporal * M * |o_k - warp(o_{k-1})|`` where warp uses the
exact flow, and ``M = valid * exp(-alpha * (y_k - warp(y_{k-1}))^2)`` masks pixels whose source is
outside the frame or that the exact flow does not explain (occlusions, blades). SSIM is kornia's
(Gaussian window 7, sigma 1.5).

The command ``python -m neuspike.train.sequences NAME`` (``NAME`` a registered method whose class has
``for_training``): frozen JSON spec beside the checkpoint (a resumed run must have the same spec),
tqdm progress with loss and ETA, ``train_log.csv``, validation every ``val_every`` steps on held-out
sequences of training photographs, checkpoint written atomically (resume continues where it
stopped; the data order depends only on the seed and the step), and the best-by-validation weights
exported to ``neuspike/trained/<name>.safetensors`` with their JSON card.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import io
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from neuspike import atomic
from neuspike.conditions import NOISE_LEVELS, Condition
from neuspike.errors import InputError
from neuspike.learned import resolve_precision
from neuspike.rng import derive_rng
from neuspike.scenes import TEST_PHOTOS, TRAIN_PHOTOS, SceneSpec, make_scene
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

__all__ = [
    "DataSpec", "TrainSpec", "Cell", "SequenceItem", "draw_cell", "scene_time", "backward_flow",
    "simulate_item", "build_shard", "load_shard", "make_batch", "warp", "sequence_loss",
    "run_sequence", "training_method", "validate", "export", "train", "main",
]

MOTIONS = (16, 32, 64, 128, 256)
LIGHTS = (1 / 2, 1 / 4, 1 / 8, 1 / 16, 1 / 32)
KINDS = ("pan", "zoom", "fan")
#: Every kind a sequence item can be drawn from (``dead_leaves``: procedural occluding layers, see
#: :mod:`neuspike.scenes.dead_leaves`); the default data keep :data:`KINDS`.
ALL_KINDS = KINDS + ("dead_leaves",)


# --- specifications ---------------------------------------------------------------------------


@dataclass(frozen=True)
class DataSpec:
    """What the simulated sequences are (part of the shard's identity).

    ``size`` is the simulated item (width = height, pixels); ``windows`` the windows per item;
    ``events_per_pixel`` the fixed window count per pixel (the methods' 0.35); ``threshold_range``
    the event contrast thresholds (log units, drawn log-uniformly); ``displacement_px`` the scene
    displacement aimed at for the history (doubled until the windows fit, at most 4 times).

    ``view`` (width, height) or None: the scene view the photograph is fitted to. With a view, each
    item is a ``size`` x ``size`` crop of it at a random position (the scene renders only the
    crop), so the photographs are seen at the scale of an evaluation at that view size (the
    sweeps' 400x250); without one the whole photograph is fitted to ``size`` x ``size``, about
    three times smaller than in the sweeps. Left out of the shard key when unset.
    """

    size: int = 128
    windows: int = 8
    events_per_pixel: float = 0.35
    threshold_range: tuple[float, float] = (0.1, 0.4)
    noise_levels: tuple[str, ...] = ("none", "small", "medium", "high")
    kinds: tuple[str, ...] = KINDS
    photos: tuple[str, ...] = TRAIN_PHOTOS
    displacement_px: float = 8.0
    view: tuple[int, int] | None = None
    #: Share of items whose photograph is mapped to radiance through a drawn dynamic range of 10 to
    #: 1,000 (darker, high-contrast targets); the rest are linear in luma, like the sweeps' scenes.
    #: Left out of the shard key at its default.
    hdr_fraction: float = 0.5

    # ``kinds`` and ``noise_levels`` are drawn uniformly over the tuple, so a repeated entry is drawn
    # more often (``("none", "none", "small", "medium", "high")``: clean events two times in five).

    def __post_init__(self) -> None:
        bad = sorted(set(self.photos) & set(TEST_PHOTOS))
        if bad:
            raise InputError(f"photos: the test photographs {bad} are for evaluation only")
        unknown = sorted(set(self.noise_levels) - set(NOISE_LEVELS))
        if unknown:
            raise InputError(f"noise_levels: unknown {unknown}; choose from {sorted(NOISE_LEVELS)}")
        if not set(self.kinds) <= set(ALL_KINDS) or not self.kinds:
            raise InputError(f"kinds: expected a non-empty subset of {ALL_KINDS}, got {self.kinds}")
        if not self.noise_levels:
            raise InputError("noise_levels: expected at least one level")
        if self.view is not None and "dead_leaves" in self.kinds:
            raise InputError("view: dead_leaves scenes do not render a crop of a larger view; drop one of the two")
        if self.size < 16 or self.windows < 2:
            raise InputError(f"size >= 16 and windows >= 2 expected, got {self.size}, {self.windows}")
        if self.view is not None:
            try:
                vw, vh = (int(v) for v in self.view)
            except (TypeError, ValueError):
                raise InputError(f"view: expected (width, height), got {self.view!r}") from None
            if vw < self.size or vh < self.size:
                raise InputError(f"view: {vw}x{vh} is smaller than the {self.size}x{self.size} items cut from it")
            object.__setattr__(self, "view", (vw, vh))
        if not 0.0 <= self.hdr_fraction <= 1.0:
            raise InputError(f"hdr_fraction: expected a share in [0, 1], got {self.hdr_fraction}")
        lo, hi = self.threshold_range
        if not 0 < lo <= hi:
            raise InputError(f"threshold_range: expected 0 < low <= high, got {self.threshold_range}")

    def key(self) -> str:
        d = dataclasses.asdict(self)
        if d["view"] is None:  # absent rather than null: shards made before the field keep their key
            del d["view"]
        if d["hdr_fraction"] == 0.5:  # likewise
            del d["hdr_fraction"]
        text = json.dumps(d, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class TrainSpec:
    """A training run: the method, its data, the optimisation, the schedule (saved frozen as JSON)."""

    method: str
    data: DataSpec = field(default_factory=DataSpec)
    seed: int = 0
    train_items: int = 300
    val_items: int = 16
    crop: int = 96
    batch: int = 4
    length: int = 8
    warmup: int = 2
    lr: float = 2e-4
    lr_warmup_steps: int = 50
    #: None: the rate stays at ``lr`` after the warm-up (the first stages were trained so); a value:
    #: cosine decay from ``lr`` to ``lr_min`` at ``steps``, which a run of fixed length ends better with
    lr_min: float | None = None
    l1: float = 1.0
    ssim: float = 1.0
    temporal: float = 1.0
    occlusion_alpha: float = 50.0
    steps: int = 2000
    val_every: int = 100
    checkpoint_every: int = 25
    precision: str = "auto"
    #: Weights (.safetensors, e.g. the shipped ones) to start from instead of a random draw: a later
    #: stage, or a run continued on a machine that has the repository but not the checkpoint.
    init_from: str | None = None

    def __post_init__(self) -> None:
        if self.crop > self.data.size or self.crop < 8:
            raise InputError(f"crop: expected 8..{self.data.size}, got {self.crop}")
        if not 1 <= self.length <= self.data.windows:
            raise InputError(f"length: expected 1..{self.data.windows} windows, got {self.length}")
        if not 0 <= self.warmup < self.length:
            raise InputError(f"warmup: expected 0..{self.length - 1}, got {self.warmup}")
        if self.precision not in ("auto", "float32", "bfloat16"):
            raise InputError(f"precision: expected auto, float32 or bfloat16, got {self.precision!r}")
        if self.init_from is not None and not str(self.init_from).endswith(".safetensors"):
            raise InputError(f"init_from: expected a .safetensors file, got {self.init_from!r}")
        if self.lr_min is not None and not 0 <= self.lr_min <= self.lr:
            raise InputError(f"lr_min: expected 0 <= lr_min <= lr ({self.lr}), got {self.lr_min}")

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainSpec":
        d = dict(d)
        data = dict(d.pop("data"))
        for k in ("threshold_range", "noise_levels", "kinds", "photos"):
            data[k] = tuple(data[k])
        if data.get("view") is not None:
            data["view"] = tuple(data["view"])
        return cls(data=DataSpec(**data), **d)


# --- one item -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cell:
    """One drawn training cell: what :func:`simulate_sample` receives, plus the seed."""

    scene: SceneSpec
    condition: Condition
    sensor: SensorConfig
    seed: int


def draw_cell(data: DataSpec, rng: np.random.Generator) -> Cell:
    """A random cell of ``data`` (every draw from ``rng``)."""
    kind = str(rng.choice(data.kinds))
    photo = str(rng.choice(data.photos))
    size = (data.size, data.size) if data.view is None else data.view
    # linear when u < 1 - hdr_fraction: the default 0.5 draws exactly as before the field existed
    linear = rng.random() < 1.0 - data.hdr_fraction
    dynamic_range = None if linear else float(np.exp(rng.uniform(np.log(10), np.log(1000))))
    common: dict[str, Any] = dict(image=photo, size=size, dynamic_range=dynamic_range)
    if data.view is not None:  # drawn only with a view: the draws of a spec without one are unchanged
        x0, y0 = (int(rng.integers(0, v - data.size + 1)) for v in data.view)
        common["crop"] = (x0, y0, data.size, data.size)
    if kind in ("pan", "dead_leaves"):
        angle = rng.uniform(0, 2 * np.pi)
        speed = float(np.exp(rng.uniform(np.log(1000), np.log(6000))))
        velocity = (speed * np.cos(angle), speed * np.sin(angle))
        if kind == "pan":
            scene = SceneSpec("pan", velocity_px_s=velocity, **common)
        else:  # procedural: no photograph; the layers' own draws come from the scene seed
            scene = SceneSpec("dead_leaves", size=size, dynamic_range=dynamic_range, velocity_px_s=velocity,
                              seed=int(rng.integers(0, 2**31 - 1)))
    elif kind == "zoom":
        rate = float(rng.uniform(4.0, 20.0) * rng.choice([-1.0, 1.0]))
        focus = tuple(float(v) for v in rng.uniform(0.25, 0.75, 2) * (np.asarray(size) - 1))
        scene = SceneSpec("zoom", zoom_rate_hz=rate, focus=focus, **common)
    else:
        scene = SceneSpec("fan", rpm=float(rng.uniform(500, 2600) * rng.choice([-1.0, 1.0])),
                          blades=int(rng.integers(2, 6)), blade_width_deg=float(rng.uniform(15, 40)),
                          blade_contrast=float(np.exp(rng.uniform(np.log(0.1), np.log(3.0)))), **common)
    condition = Condition(light=float(rng.choice(LIGHTS)), motion=int(rng.choice(MOTIONS)),
                          noise=str(rng.choice(data.noise_levels)))
    lo, hi = data.threshold_range
    sensor = SensorConfig(event_threshold=float(np.exp(rng.uniform(np.log(lo), np.log(hi)))))
    return Cell(scene, condition, sensor, int(rng.integers(0, 2**31 - 1)))


def scene_time(sensor_t_s: np.ndarray, condition: Condition, sensor: SensorConfig) -> np.ndarray:
    """Scene time seen at sensor time ``sensor_t_s`` in a simulated window (key instant = scene time 0).

    Frame ``k`` sits at sensor time ``(k + 0.5) * hold / plane_rate`` and shows scene time
    ``(k - (S - 1) / 2) / upsampled_rate``; the event camera interpolates linearly between frames,
    so the map is affine.
    """
    frame_dt_sensor = (sensor.planes // condition.motion) / sensor.plane_rate_hz
    k = np.asarray(sensor_t_s, dtype=np.float64) / frame_dt_sensor - 0.5
    return (k - (condition.motion - 1) / 2.0) / sensor.upsampled_rate_hz


def backward_flow(scene: SceneSpec, t0_s: float, t1_s: float) -> np.ndarray:
    """Exact backward flow of an analytic scene from scene time ``t1_s`` to ``t0_s``.

    Returns float32 (2, H, W): ``(dx, dy)`` such that view pixel ``(x, y)`` at ``t1_s`` shows what
    ``(x + dx, y + dy)`` showed at ``t0_s``. Pan, and the background layer of ``dead_leaves`` (its
    foreground shapes move otherwise and are left to the loss's occlusion mask): ``-v (t1 - t0)``; zoom: the view maps to the plane
    as ``f + (p - f) exp(-r t)``, so ``p' = f + (p - f) exp(-r (t1 - t0))``; fan and still: zero (the
    background is static; moving blades are left to the occlusion mask). For a scene with a
    ``crop`` the flow covers the crop (pixel ``(x, y)`` of it is ``(x0 + x, y0 + y)`` of the view).
    """
    w, h = scene.size
    x0 = y0 = 0
    if scene.crop is not None:
        x0, y0, w, h = scene.crop
    flow = np.zeros((2, h, w), dtype=np.float32)
    dt = t1_s - t0_s
    if scene.kind in ("pan", "dead_leaves"):
        flow[0] = -scene.velocity_px_s[0] * dt
        flow[1] = -scene.velocity_px_s[1] * dt
    elif scene.kind == "zoom":
        shrink = math.exp(-scene.zoom_rate_hz * dt) - 1.0
        vw, vh = scene.size
        fx, fy = scene.focus if scene.focus is not None else ((vw - 1) / 2.0, (vh - 1) / 2.0)
        flow[0] = ((x0 + np.arange(w, dtype=np.float64) - fx) * shrink)[None, :]
        flow[1] = ((y0 + np.arange(h, dtype=np.float64) - fy) * shrink)[:, None]
    elif scene.kind not in ("fan", "still"):
        raise InputError(f"backward_flow: no exact flow for scene kind {scene.kind!r}")
    return flow


@dataclass(frozen=True)
class SequenceItem:
    """``voxels`` (K, 5, H, W), ``targets`` (K, H, W) in [0, 1], ``flow`` (K, 2, H, W) (step 0: zeros)."""

    voxels: np.ndarray
    targets: np.ndarray
    flow: np.ndarray
    meta: dict[str, Any]


def _history_s(cell: Cell, displacement_px: float) -> float:
    """Sensor seconds of event history in which the scene moves about ``displacement_px`` pixels."""
    s = cell.scene
    w, h = s.size
    if s.kind in ("pan", "dead_leaves"):
        speed = math.hypot(*s.velocity_px_s)
    elif s.kind == "zoom":
        speed = abs(s.zoom_rate_hz) * 0.35 * min(w, h)
    else:
        speed = abs(s.rpm) / 60.0 * 2 * math.pi * 0.3 * min(w, h)
    scene_span = displacement_px / max(speed, 1e-9)
    frame_dt_sensor = (cell.sensor.planes // cell.condition.motion) / cell.sensor.plane_rate_hz
    return scene_span * cell.sensor.upsampled_rate_hz * frame_dt_sensor


def simulate_item(method: Any, cell: Cell, data: DataSpec) -> SequenceItem | None:
    """The sequence of ``data.windows`` full windows ending at the key instant, or ``None`` if the scene gives too few events.

    ``method`` is a method object with ``windows(sample)`` and ``encode(sample)`` (the trainer's
    :meth:`for_training` instance); its ``max_windows`` must be at least ``data.windows + 1``.
    """
    k = data.windows
    hw = data.size * data.size
    per = max(1, int(round(data.events_per_pixel * hw)))
    displacement = data.displacement_px
    for _ in range(4):
        sample = simulate_sample(cell.scene, cell.condition, sensor=cell.sensor, seed=cell.seed,
                                 modalities={"events"}, history_s=_history_s(cell, displacement))
        wins = method.windows(sample)
        full = [w for w in wins if w[1] - w[0] == per]
        if len(full) >= k:
            break
        displacement *= 2
    else:
        return None
    steps = method.encode(sample)[-k:]
    wins = wins[-k:]
    voxels = np.stack([s[0][0].numpy() for s in steps]).astype(np.float16)
    ends = np.array([w[3] for w in wins], dtype=np.float64)
    times = scene_time(ends, cell.condition, cell.sensor)
    scene = make_scene(cell.scene)
    targets = np.clip(scene.render(times), 0.0, 1.0).astype(np.float16)
    flow = np.stack([np.zeros((2, data.size, data.size), np.float32)]
                    + [backward_flow(cell.scene, times[i - 1], times[i]) for i in range(1, k)]).astype(np.float16)
    meta = {"scene": cell.scene.kind, "photo": cell.scene.image if cell.scene.kind != "dead_leaves" else None, "noise": cell.condition.noise,
            "motion": cell.condition.motion, "light": cell.condition.light,
            "threshold": cell.sensor.event_threshold, "seed": cell.seed, "events": int(len(sample.events))}
    return SequenceItem(voxels, targets, flow, meta)


# --- shards -------------------------------------------------------------------------------------


def _item_path(folder: Path, split: str, index: int) -> Path:
    return folder / f"{split}-{index:05d}.npz"


def build_shard(method: Any, data: DataSpec, *, seed: int, split: str, count: int, folder: Path,
                progress: bool = True) -> list[Path]:
    """Simulate ``count`` items of ``split`` into ``folder`` (resumable: existing items are kept).

    Item ``i`` draws its cells from ``derive_rng(seed, "sequences", split, i)`` (redrawn until one gives
    enough events), so the same seed gives the same bytes whatever was built before.
    """
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    todo = [i for i in range(count) if not _item_path(folder, split, i).is_file()]
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=f"simulating {split}", unit="seq", file=sys.stderr)
    for i in range(count):
        path = _item_path(folder, split, i)
        paths.append(path)
        if path.is_file():
            continue
        rng = derive_rng(seed, "sequences", split, i)
        item = None
        while item is None:
            cell = draw_cell(data, rng)
            try:
                item = simulate_item(method, cell, data)
            except ArithmeticError as exc:  # a simulator defect on this cell: recorded, the cell redrawn
                with open(folder / "failures.txt", "a") as f:
                    f.write(f"{split} {i}: {type(exc).__name__}: {exc}: {cell!r}\n")
        buf = io.BytesIO()
        np.savez(buf, voxels=item.voxels, targets=item.targets, flow=item.flow,
                 meta=np.array(json.dumps(item.meta)))
        atomic.write_bytes(path, buf.getvalue())
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return paths


def load_shard(paths: Sequence[Path]) -> dict[str, np.ndarray]:
    """Stack items: ``voxels`` (N, K, 5, H, W), ``targets`` (N, K, 1, H, W), ``flow`` (N, K, 2, H, W), float16."""
    parts: dict[str, list[np.ndarray]] = {"voxels": [], "targets": [], "flow": []}
    for p in paths:
        with np.load(p) as z:
            parts["voxels"].append(z["voxels"])
            parts["targets"].append(z["targets"][:, None])
            parts["flow"].append(z["flow"])
    return {k: np.stack(v) for k, v in parts.items()}


def make_batch(shard: dict[str, np.ndarray], rng: np.random.Generator, *, batch: int,
               crop: int, length: int | None = None) -> dict[str, torch.Tensor]:
    """Random items, a random run of ``length`` consecutive windows (default all), random crops of
    ``crop`` pixels, random horizontal/vertical flips (flow signs follow).

    Returns float32 tensors ``voxels`` (K, B, 5, c, c), ``targets`` (K, B, 1, c, c), ``flow`` (K, B, 2, c, c).
    """
    n, k, _, h, w = shard["voxels"].shape
    length = k if length is None else length
    idx = rng.integers(0, n, batch)
    out: dict[str, list[np.ndarray]] = {"voxels": [], "targets": [], "flow": []}
    for i in idx:
        y0 = int(rng.integers(0, h - crop + 1))
        x0 = int(rng.integers(0, w - crop + 1))
        flip_x, flip_y = bool(rng.integers(2)), bool(rng.integers(2))
        k0 = int(rng.integers(0, k - length + 1))
        for key in out:
            a = shard[key][i, k0:k0 + length, :, y0:y0 + crop, x0:x0 + crop].astype(np.float32)
            if flip_x:
                a = a[..., ::-1]
            if flip_y:
                a = a[..., ::-1, :]
            if key == "flow":
                a = a.copy()
                if flip_x:
                    a[:, 0] *= -1
                if flip_y:
                    a[:, 1] *= -1
            out[key].append(np.ascontiguousarray(a))
    return {k: torch.from_numpy(np.stack(v, axis=1)) for k, v in out.items()}


# --- loss ---------------------------------------------------------------------------------------


def warp(image: torch.Tensor, flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Sample ``image`` (B, C, H, W) at ``(x + dx, y + dy)`` (bilinear); also the in-frame mask (B, 1, H, W)."""
    b, _, h, w = image.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32),
                            indexing="ij")
    sx = xs[None] + flow[:, 0]
    sy = ys[None] + flow[:, 1]
    grid = torch.stack([2 * sx / max(w - 1, 1) - 1, 2 * sy / max(h - 1, 1) - 1], dim=-1)
    out = F.grid_sample(image, grid.to(image.dtype), mode="bilinear", padding_mode="border", align_corners=True)
    valid = ((sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)).to(image.dtype)[:, None]
    return out, valid


def sequence_loss(outputs: Sequence[torch.Tensor], batch: dict[str, torch.Tensor], spec: TrainSpec
                  ) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean loss over the steps after the warm-up (module docstring); also its parts as floats."""
    import kornia

    targets, flow = batch["targets"], batch["flow"]
    l1 = ssim = tc = 0.0
    n = 0
    for k in range(spec.warmup, len(outputs)):
        o = outputs[k].float()
        y = targets[k]
        l1 = l1 + (o - y).abs().mean()
        ssim = ssim + 2 * kornia.losses.ssim_loss(o, y, window_size=7, max_val=1.0)  # = 1 - SSIM
        if k > 0 and spec.temporal > 0:
            prev_o, valid = warp(outputs[k - 1].float(), flow[k])
            prev_y, _ = warp(targets[k - 1], flow[k])
            mask = valid * torch.exp(-spec.occlusion_alpha * (y - prev_y) ** 2)
            tc = tc + (mask * (o - prev_o).abs()).mean()
        n += 1
    l1, ssim, tc = l1 / n, ssim / n, tc / n
    total = spec.l1 * l1 + spec.ssim * ssim + spec.temporal * tc
    parts = {k: float(v.detach()) if torch.is_tensor(v) else float(v)
             for k, v in (("l1", l1), ("ssim_loss", ssim), ("temporal", tc))}
    return total, parts


def run_sequence(module: torch.nn.Module, voxels: torch.Tensor, *, precision: str) -> list[torch.Tensor]:
    """Feed ``voxels`` (K, B, 5, H, W) step by step from a zero state; the K outputs (B, 1, H, W)."""
    state = None
    outputs = []
    ctx = torch.autocast("cpu", dtype=torch.bfloat16) if precision == "bfloat16" else _null()
    with ctx:
        for k in range(voxels.shape[0]):
            out, state = module(voxels[k], state)
            outputs.append(out)
    return outputs


class _null:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: Any) -> None:
        return None


# --- the run ------------------------------------------------------------------------------------


def training_method(name: str) -> Any:
    """The registered method ``name`` built for training (untrained module, no weights file)."""
    from neuspike.methods import entry

    e = entry(name)
    factory = getattr(e.factory, "for_training", None)
    if factory is None:
        raise InputError(f"method {name!r} cannot be trained here: its class has no for_training()")
    return factory(name, **dict(e.params))


def validate(module: torch.nn.Module, shard: dict[str, np.ndarray], spec: TrainSpec) -> dict[str, float]:
    """Mean L1 and SSIM over the validation items, on the steps after the warm-up and on the last step."""
    from neuspike.metrics import ssim as ssim_metric

    module.eval()
    l1s, ssims, last = [], [], []
    with torch.no_grad():
        for i in range(shard["voxels"].shape[0]):
            vox = torch.from_numpy(shard["voxels"][i].astype(np.float32))[:, None]
            outs = run_sequence(module, vox, precision=spec.precision)
            for k in range(spec.warmup, len(outs)):
                o = outs[k][0, 0].float().clamp(0, 1).numpy()
                y = shard["targets"][i, k, 0].astype(np.float32)
                l1s.append(float(np.abs(o - y).mean()))
                s = float(ssim_metric(o, y, data_range=1.0))
                ssims.append(s)
                if k == len(outs) - 1:
                    last.append(s)
    module.train()
    return {"val_l1": float(np.mean(l1s)), "val_ssim": float(np.mean(ssims)), "val_ssim_last": float(np.mean(last))}


def _commit() -> str | None:
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                              cwd=Path(__file__).resolve().parent).stdout.strip() or None
    except Exception:
        return None


def _save_checkpoint(path: Path, module: torch.nn.Module, opt: torch.optim.Optimizer, step: int,
                     best: dict[str, Any], wall_s: float) -> None:
    buf = io.BytesIO()
    torch.save({"module": module.state_dict(), "optimizer": opt.state_dict(), "step": step, "best": best,
                "wall_s": wall_s}, buf)
    atomic.write_bytes(path, buf.getvalue())


def train(spec: TrainSpec, *, run_dir: Path, shard_root: Path, export_dir: Path | None,
          max_minutes: float | None = None, threads: int | None = None, progress: bool = True,
          simulate_only: bool = False, snapshot_every: int | None = None) -> dict[str, Any]:
    """Run (or resume) ``spec`` in ``run_dir``; returns the final state (step, best validation, wall time).

    The spec is frozen as ``run_dir/spec.json``; a different spec in an existing run folder is an
    error. ``max_minutes`` stops the run early (after a checkpoint) so a later call resumes it.
    ``snapshot_every``: also keep the weights of every N-th step as
    ``run_dir/snapshots/step-NNNNN/<method>.safetensors`` (with its card), for choosing between them
    afterwards by another measure than the sequence validation (the sweep harness on training
    photographs, ``reports/e2vid/candidates``).
    """
    if snapshot_every is not None and snapshot_every < 1:
        raise InputError(f"snapshot_every: expected a positive step count, got {snapshot_every}")
    if threads is not None:
        torch.set_num_threads(threads)
    run_dir.mkdir(parents=True, exist_ok=True)
    spec_path = run_dir / "spec.json"
    if spec_path.is_file():
        # through from_dict, so a spec frozen before a field existed reads with that field's default
        frozen = json.loads(json.dumps(TrainSpec.from_dict(json.loads(spec_path.read_text())).as_dict()))
        if frozen != json.loads(json.dumps(spec.as_dict())):
            raise InputError(f"{spec_path}: this run folder holds a different spec; use another --run-dir")
    else:
        atomic.write_text(spec_path, json.dumps(spec.as_dict(), indent=2, sort_keys=True) + "\n")

    torch.manual_seed(spec.seed)  # initial weights: the entry point's seed
    method = training_method(spec.method)
    if method.params.get("max_windows", 0) <= spec.data.windows:
        raise InputError(f"method {spec.method!r}: max_windows must exceed the sequence's {spec.data.windows} windows")
    shard_dir = shard_root / spec.data.key()
    train_paths = build_shard(method, spec.data, seed=spec.seed, split="train", count=spec.train_items,
                              folder=shard_dir, progress=progress)
    val_paths = build_shard(method, spec.data, seed=spec.seed, split="val", count=spec.val_items,
                            folder=shard_dir, progress=progress)
    atomic.write_text(shard_dir / "data.json", json.dumps(dataclasses.asdict(spec.data), indent=2) + "\n")
    if simulate_only:
        return {"step": 0, "shard": str(shard_dir), "items": len(train_paths) + len(val_paths)}
    train_shard = load_shard(train_paths)
    val_shard = load_shard(val_paths)

    module = method.module.float().train()
    # "auto": bfloat16 only where the CPU computes it natively (emulated bfloat16 is many times slower)
    spec = dataclasses.replace(spec, precision=resolve_precision(spec.precision, torch.device("cpu")))
    opt = torch.optim.Adam(module.parameters(), lr=spec.lr)
    ckpt_path = run_dir / "checkpoint.pt"
    step, wall_s = 0, 0.0
    best: dict[str, Any] = {"val_ssim": -1.0}
    if ckpt_path.is_file():
        ck = torch.load(ckpt_path, map_location="cpu", weights_only=True)
        module.load_state_dict(ck["module"])
        opt.load_state_dict(ck["optimizer"])
        step, best, wall_s = int(ck["step"]), dict(ck["best"]), float(ck["wall_s"])
    elif spec.init_from is not None:  # the checkpoint, when there is one, wins: a resumed run goes on
        from neuspike.weights import load_safetensors, load_state_strict

        load_state_strict(module, load_safetensors(spec.init_from), spec.init_from)
        # the starting weights set the bar: an export must beat what the run started from
        best = {"step": 0, **validate(module, val_shard, spec)}
        print(f"{spec.method}: starting from {spec.init_from} (validation SSIM {best['val_ssim']:.4f})", file=sys.stderr)
    log_path = run_dir / "train_log.csv"
    fields = ["step", "loss", "l1", "ssim_loss", "temporal", "lr", "seconds_per_step", "wall_s",
              "val_l1", "val_ssim", "val_ssim_last"]
    if not log_path.is_file():
        atomic.write_text(log_path, ",".join(fields) + "\n")
    params = sum(p.numel() for p in module.parameters())
    print(f"{spec.method}: {params:,} parameters; {len(train_paths)} training and {len(val_paths)} validation "
          f"sequences of {spec.data.windows} windows at {spec.data.size}x{spec.data.size}"
          f"{'' if spec.data.view is None else ' cut from %dx%d views' % spec.data.view}; crop {spec.crop}, "
          f"batch {spec.batch}, {torch.get_num_threads()} thread(s), {spec.precision}; resuming at step {step}",
          file=sys.stderr)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=spec.steps, initial=step, desc=spec.method, unit="step", file=sys.stderr)
    started = time.perf_counter()
    wall0 = wall_s
    with open(log_path, "a", newline="") as log:
        writer = csv.DictWriter(log, fieldnames=fields)
        while step < spec.steps:
            if max_minutes is not None and time.perf_counter() - started > 60 * max_minutes:
                break
            t0 = time.perf_counter()
            lr = learning_rate(spec, step)
            for g in opt.param_groups:
                g["lr"] = lr
            batch = make_batch(train_shard, derive_rng(spec.seed, "batch", step), batch=spec.batch, crop=spec.crop,
                               length=spec.length)
            outputs = run_sequence(module, batch["voxels"], precision=spec.precision)
            loss, parts = sequence_loss(outputs, batch, spec)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(module.parameters(), 1.0)
            opt.step()
            step += 1
            dt = time.perf_counter() - t0
            wall_s = wall0 + time.perf_counter() - started
            row: dict[str, Any] = {"step": step, "loss": float(loss.detach()), **parts, "lr": lr,
                                   "seconds_per_step": dt, "wall_s": wall_s}
            if step % spec.val_every == 0 or step == spec.steps:
                metrics = validate(module, val_shard, spec)
                row.update(metrics)
                if metrics["val_ssim"] > best["val_ssim"]:
                    best = {"step": step, **metrics}
                    if export_dir is not None:
                        export(module, spec, best, step=step, wall_s=wall_s, folder=export_dir)
            writer.writerow(row)
            log.flush()
            if snapshot_every is not None and step % snapshot_every == 0:
                export(module, spec, {"step": step, **{k: row[k] for k in ("val_l1", "val_ssim", "val_ssim_last") if k in row}},
                       step=step, wall_s=wall_s, folder=run_dir / "snapshots" / f"step-{step:05d}")
            if step % spec.checkpoint_every == 0 or "val_ssim" in row or step == spec.steps:
                _save_checkpoint(ckpt_path, module, opt, step, best, wall_s)
            if bar is not None:
                bar.set_postfix(loss=f"{float(loss.detach()):.4f}", val_ssim=f"{best['val_ssim']:.3f}")
                bar.update(1)
    _save_checkpoint(ckpt_path, module, opt, step, best, wall_s)
    if bar is not None:
        bar.close()
    return {"step": step, "best": best, "wall_s": wall_s}


def learning_rate(spec: TrainSpec, step: int) -> float:
    """The rate of step ``step`` (from 0): linear warm-up over ``lr_warmup_steps``, then ``lr``, or a
    cosine from ``lr`` down to ``lr_min`` at ``steps`` when ``lr_min`` is set."""
    warm = max(1, spec.lr_warmup_steps)
    if step < warm:
        return spec.lr * (step + 1) / warm
    if spec.lr_min is None:
        return spec.lr
    frac = min(1.0, (step - warm) / max(1, spec.steps - warm))
    return spec.lr_min + 0.5 * (spec.lr - spec.lr_min) * (1.0 + math.cos(math.pi * frac))


def export(module: torch.nn.Module, spec: TrainSpec, best: dict[str, Any], *, step: int, wall_s: float,
           folder: Path) -> Path:
    """Write ``folder/<method>.safetensors`` and its card (training spec, steps, validation, wall time).

    Networks under a million parameters are stored in float32 (a few hundred kB); larger ones in
    bfloat16, which halves the repository's copy (the card records the dtype).
    """
    from neuspike.weights import save_safetensors

    params = sum(p.numel() for p in module.parameters())

    card = {
        "method": spec.method,
        "trained_with": f"python -m neuspike.train.sequences {spec.method} (spec below)",
        "spec": spec.as_dict(),
        "steps": step,
        "wall_s": round(wall_s, 1),
        "validation": {k: v for k, v in best.items() if k != "step"},
        "validation_note": "mean over held-out sequences of training photographs, steps after the warm-up; "
                           "SSIM of neuspike.metrics.ssim with data_range 1",
        "threads": torch.get_num_threads(),
        "commit": _commit(),
        "torch": torch.__version__,
    }
    dtype = None if params < 1_000_000 else torch.bfloat16
    card["validation_note"] += "; measured with the float32 weights before storage"
    return save_safetensors(module, folder / f"{spec.method}.safetensors", card=card, dtype=dtype)


# --- command line -------------------------------------------------------------------------------

PRESETS: dict[str, dict[str, Any]] = {
    # lr per network size: FireNet's 38k parameters take a larger step than E2VID's 10.7M
    "firenet-sim": {"lr": 1e-3, "crop": 64, "batch": 4, "length": 8, "steps": 3000, "val_every": 50,
                    "checkpoint_every": 25, "precision": "float32", "val_items": 8},
    "e2vid": {"lr": 5e-4, "crop": 48, "batch": 4, "length": 6, "steps": 4000, "val_every": 50,
              "checkpoint_every": 10, "val_items": 8},
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m neuspike.train.sequences",
        description="Train a recurrent event network (e2vid, firenet-sim) on simulated event sequences; "
                    "resumable, logged, exports the best-by-validation weights to neuspike/trained/.")
    p.add_argument("method", help="registered method to train (e2vid or firenet-sim)")
    p.add_argument("--run-dir", type=Path, default=None, help="checkpoint, spec.json, train_log.csv (default runs/<method>)")
    p.add_argument("--shards", type=Path, default=Path("runs/shards"), help="folder of simulated sequence shards")
    p.add_argument("--export-dir", type=Path, default=None,
                   help="where the best weights go (default: the package's neuspike/trained/)")
    p.add_argument("--no-export", action="store_true", help="do not write weights")
    p.add_argument("--steps", type=int, default=None, help="total optimiser steps")
    p.add_argument("--max-minutes", type=float, default=None, help="stop after this many minutes (resume later)")
    p.add_argument("--crop", type=int, default=None)
    p.add_argument("--batch", type=int, default=None)
    p.add_argument("--lr", type=float, default=None, help="peak learning rate (after a 50-step warm-up)")
    p.add_argument("--lr-min", type=float, default=None,
                   help="decay the rate along a cosine to this value at --steps (default: constant rate)")
    p.add_argument("--val-every", type=int, default=None, help="validate (and export a new best) every N steps")
    p.add_argument("--train-items", type=int, default=None, help="simulated training sequences")
    p.add_argument("--val-items", type=int, default=None, help="simulated validation sequences")
    p.add_argument("--windows", type=int, default=None, help="event windows per sequence")
    p.add_argument("--size", type=int, default=None, help="simulated item size (pixels, square)")
    p.add_argument("--view", default=None, metavar="WxH",
                   help="fit the photographs to a WxH view and cut each item from it at a random position "
                        "(e.g. 400x250, the sweeps' scale); default: the photograph fitted to the item itself")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=None, help="torch threads (1 when another job shares the CPU)")
    p.add_argument("--precision", choices=("auto", "bfloat16", "float32"), default=None,
                   help="arithmetic of training (default: float32 for firenet-sim; auto for e2vid, which is "
                        "bfloat16 where the CPU computes it natively)")
    p.add_argument("--length", type=int, default=None, help="windows per training sequence (<= --windows)")
    p.add_argument("--init-from", metavar="FILE.safetensors", default=None,
                   help="start from these weights (a later stage, or a run continued where its checkpoint is "
                        "gone: copy the shipped neuspike/trained/<method>.safetensors elsewhere first, since "
                        "exports overwrite it); a checkpoint in --run-dir still wins")
    p.add_argument("--kinds", default=None, metavar="K1,K2,...",
                   help=f"scene kinds drawn for the items, from {','.join(ALL_KINDS)} (default {','.join(KINDS)}); "
                        "a kind listed twice is drawn twice as often")
    p.add_argument("--noise-levels", default=None, metavar="N1,N2,...",
                   help="event noise levels drawn for the items (default none,small,medium,high); a level listed "
                        "twice is drawn twice as often")
    p.add_argument("--hdr-fraction", type=float, default=None, metavar="F",
                   help="share of items with high-dynamic-range radiance (dark, high-contrast targets; default 0.5); "
                        "the rest are linear in luma like the sweeps' scenes")
    p.add_argument("--snapshot-every", type=int, default=None, metavar="N",
                   help="also keep every N-th step's weights under RUN_DIR/snapshots/ (to choose between them later)")
    p.add_argument("--simulate-only", action="store_true", help="build the sequence shard and stop")
    p.add_argument("--quick", action="store_true", help="a tiny run that finishes in a minute (smoke test)")
    return p


def spec_from_args(args: argparse.Namespace) -> TrainSpec:
    kw: dict[str, Any] = dict(PRESETS.get(args.method, {}))
    data_kw: dict[str, Any] = {}
    if args.quick:
        kw.update(steps=20, val_every=10, checkpoint_every=10, crop=32, batch=2, train_items=8, val_items=2)
        data_kw.update(size=48, windows=4)
    if args.quick:
        kw["length"] = 4
    for name in ("steps", "crop", "batch", "lr", "lr_min", "train_items", "val_items", "val_every", "length"):
        if getattr(args, name) is not None:
            kw[name] = getattr(args, name)
    if args.windows is not None:
        data_kw["windows"] = args.windows
    if args.size is not None:
        data_kw["size"] = args.size
    if args.view is not None:
        from neuspike.checks import parse_size

        data_kw["view"] = parse_size(args.view)
    if args.hdr_fraction is not None:
        data_kw["hdr_fraction"] = args.hdr_fraction
    for name in ("kinds", "noise_levels"):
        text = getattr(args, name)
        if text is not None:
            data_kw[name] = tuple(v.strip() for v in text.split(",") if v.strip())
    if args.precision is not None:
        kw["precision"] = args.precision
    if args.init_from is not None:
        kw["init_from"] = str(args.init_from)
    return TrainSpec(method=args.method, data=DataSpec(**data_kw), seed=args.seed, **kw)


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from neuspike.weights import PACKAGE_WEIGHTS

    spec = spec_from_args(args)
    run_dir = args.run_dir or Path("runs") / (spec.method + ("-quick" if args.quick else ""))
    export_dir = None if args.no_export else (args.export_dir or PACKAGE_WEIGHTS)
    result = train(spec, run_dir=run_dir, shard_root=args.shards, export_dir=export_dir,
                   max_minutes=args.max_minutes, threads=args.threads, simulate_only=args.simulate_only,
                   snapshot_every=args.snapshot_every)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
