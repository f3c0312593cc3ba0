"""Training data: cells drawn from (seed, split, index), simulated through the core's sample builder.

A cell is a scene (a training photograph panning in any direction, zooming, behind a fan, or still;
or a procedural dead-leaves scene with independently moving layers) and a condition (L
log-uniform over ``spec.light_range``, S from ``spec.motions``, a noise level from
``spec.noise_levels``, plus the sweeps' default effects: random initial charge and the clean
event-camera preset). Everything about cell ``index`` of ``split`` comes from
``derive_rng(seed, "train-cell", split, index)``, and the window is simulated by
:func:`neuspike.simulate.simulate_sample`, so the same seed gives the same bytes.

Photographs are seen at the scales the sweeps use: a random region of the training photograph is
cut and resized to the square view so that its scale is 0.3x to 1.2x the scale at which the
photograph covers the 400x250 sensor; the region is written as a ``.npy`` file in the shard folder
that the scene spec names (the test photographs are refused by the spec). The simulator's noise
draws depend on the scene spec, which names that file, so the same bytes need the same seed *and*
the same shard folder.

Simulation costs far more than a training step on this machine, so windows are simulated once into
a *shard* (one ``.npz`` per window: bit-packed spike planes, the window's events, the ground truth)
and reused across epochs with random crops, flips and quarter turns
(:func:`augment`), all drawn from ``derive_rng(seed, "augment", step)``.
"""

from __future__ import annotations

import io
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import cv2
import numpy as np
import torch

from neuspike.atomic import write_bytes
from neuspike.conditions import EVENT_PRESETS, Condition, effect
from neuspike.errors import FormatError
from neuspike.rng import derive_rng
from neuspike.sample import Sample
from neuspike.scenes import SceneSpec
from neuspike.scenes.photos import read_photo
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig
from neuspike.streams import EventStream, SpikeStream
from neuspike.train.spec import KIND_WEIGHTS, TrainSpec

__all__ = ["augment", "build_shard", "draw_cell", "load_sample", "save_sample", "shard_paths", "simulate_cell"]

#: Effects every training cell declares (the sweeps' defaults).
BASE_EFFECTS = (effect("initial_charge"),) + tuple(EVENT_PRESETS["clean"])
SENSOR_SIZE = (400, 250)


def _photo_source(spec: TrainSpec, rng: np.random.Generator, source_dir: Path, split: str, index: int) -> str:
    name = spec.photos[int(rng.integers(len(spec.photos)))]
    luma = read_photo(name)
    h, w = luma.shape
    scale = max(SENSOR_SIZE[0] / w, SENSOR_SIZE[1] / h) * float(np.exp(rng.uniform(np.log(0.3), np.log(1.2))))
    side = min(int(round(spec.view / scale)), h, w)
    y0, x0 = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
    region = luma[y0:y0 + side, x0:x0 + side]
    interp = cv2.INTER_AREA if side > spec.view else cv2.INTER_LINEAR
    region = np.clip(cv2.resize(region, (spec.view, spec.view), interpolation=interp), 0.0, 1.0).astype(np.float32)
    path = source_dir / f"{split}-{index:06d}-{name}.npy"
    if not path.exists():
        buf = io.BytesIO()
        np.save(buf, region)
        write_bytes(path, buf.getvalue())
    return str(path)


def draw_cell(spec: TrainSpec, split: str, index: int, source_dir: str | os.PathLike
              ) -> tuple[SceneSpec, Condition, int, dict[str, Any]]:
    """The (scene, condition, simulation seed) of cell ``index`` of ``split``, and a description."""
    rng = derive_rng(spec.seed, "train-cell", split, int(index))
    kinds = list(KIND_WEIGHTS)
    kind = kinds[int(rng.choice(len(kinds), p=np.array(list(KIND_WEIGHTS.values())) / sum(KIND_WEIGHTS.values())))]
    size = (spec.view, spec.view)
    angle = rng.uniform(0, 2 * np.pi)
    speed = float(np.exp(rng.uniform(np.log(100.0), np.log(4000.0)))) * spec.view / SENSOR_SIZE[0]
    velocity = (speed * np.cos(angle), speed * np.sin(angle))
    if kind == "dead_leaves":
        scene = SceneSpec(kind="dead_leaves", size=size, velocity_px_s=velocity, seed=int(rng.integers(2**31)))
    else:
        image = _photo_source(spec, rng, Path(source_dir), split, index)
        focus = (float(rng.uniform(0.2, 0.8) * spec.view), float(rng.uniform(0.2, 0.8) * spec.view))
        if kind == "pan":
            scene = SceneSpec(kind="pan", image=image, size=size, velocity_px_s=velocity)
        elif kind == "zoom":
            rate = float(rng.uniform(1.0, 20.0) * rng.choice([-1.0, 1.0]))
            scene = SceneSpec(kind="zoom", image=image, size=size, zoom_rate_hz=rate, focus=focus)
        elif kind == "fan":
            blades = int(rng.integers(2, 6))
            scene = SceneSpec(kind="fan", image=image, size=size, focus=focus, blades=blades,
                              rpm=float(rng.uniform(300, 3000) * rng.choice([-1.0, 1.0])),
                              blade_width_deg=float(rng.uniform(10, 300 / blades / 2)),
                              blade_contrast=float(rng.uniform(0.0, 2.0)))
        else:
            scene = SceneSpec(kind="still", image=image, size=size)
    lo, hi = spec.light_range
    light = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    motion = int(spec.motions[int(rng.integers(len(spec.motions)))])
    noise = spec.noise_levels[int(rng.integers(len(spec.noise_levels)))]
    condition = Condition(light=light, motion=motion, noise=noise, effects=BASE_EFFECTS)
    sim_seed = int(rng.integers(2**31))
    info = {"split": split, "index": int(index), "kind": kind, "light": light, "motion": motion, "noise": noise,
            "image": Path(scene.image).name if kind != "dead_leaves" else None}
    return scene, condition, sim_seed, info


def simulate_cell(spec: TrainSpec, split: str, index: int, source_dir: str | os.PathLike) -> Sample:
    """The simulated window of a cell (:func:`neuspike.simulate.simulate_sample`), ``meta['cell']`` set."""
    scene, condition, sim_seed, info = draw_cell(spec, split, index, source_dir)
    sample = simulate_sample(scene, condition, sensor=SensorConfig(), seed=sim_seed,
                             modalities=("spikes", "events"))
    sample.meta["cell"] = info
    return sample


def save_sample(path: str | os.PathLike, sample: Sample) -> None:
    """Write a simulated window compactly (bit-packed planes, window events only), atomically."""
    sp, ev = sample.spikes, sample.window_events()
    buf = io.BytesIO()
    np.savez(buf, planes=np.packbits(sp.planes, axis=None), shape=np.array(sp.planes.shape),
             plane_rate_hz=sp.plane_rate_hz, start_s=sp.start_s, gain=sp.gain, threshold=sp.threshold,
             t=ev.t_s, x=ev.x.astype(np.uint16), y=ev.y.astype(np.uint16), p=ev.p.astype(np.int8),
             window=np.array([sample.window_start_s, sample.key_time_s, sample.window_end_s]),
             event_threshold=np.nan if sample.event_threshold is None else sample.event_threshold,
             ground_truth=sample.ground_truth, cell=json.dumps(sample.meta.get("cell", {})))
    write_bytes(path, buf.getvalue())


def load_sample(path: str | os.PathLike) -> Sample:
    """The :class:`Sample` written by :func:`save_sample`."""
    try:
        with np.load(path) as z:
            shape = tuple(int(v) for v in z["shape"])
            planes = np.unpackbits(z["planes"], count=int(np.prod(shape))).reshape(shape).view(bool)
            spikes = SpikeStream(planes=planes, plane_rate_hz=float(z["plane_rate_hz"]), start_s=float(z["start_s"]),
                                 gain=float(z["gain"]), threshold=float(z["threshold"]))
            events = EventStream(t_s=z["t"], x=z["x"].astype(np.int64), y=z["y"].astype(np.int64),
                                 p=z["p"].astype(np.int8), width=shape[2], height=shape[1])
            w0, key, w1 = (float(v) for v in z["window"])
            theta = float(z["event_threshold"])
            return Sample(height=shape[1], width=shape[2], key_time_s=key, window_start_s=w0, window_end_s=w1,
                          spikes=spikes, events=events, event_threshold=None if np.isnan(theta) else theta,
                          ground_truth=z["ground_truth"].astype(np.float32), meta={"cell": json.loads(str(z["cell"]))})
    except (OSError, KeyError, ValueError) as exc:
        raise FormatError(f"{path}: not a training window ({exc})") from exc


def shard_paths(shard_dir: str | os.PathLike, split: str, count: int) -> list[Path]:
    return [Path(shard_dir) / split / f"{i:06d}.npz" for i in range(count)]


def _make_one(args: tuple[dict[str, Any], str, int, str, str]) -> str:
    spec_dict, split, index, source_dir, path = args
    torch.set_num_threads(1)
    spec = TrainSpec(**spec_dict)
    save_sample(path, simulate_cell(spec, split, index, source_dir))
    return path


def build_shard(spec: TrainSpec, shard_dir: str | os.PathLike, split: str, count: int, *,
                progress: Callable[[int], None] | None = None) -> list[Path]:
    """Simulate the windows of ``split`` not yet on disk (resumable); return every window's path."""
    shard_dir = Path(shard_dir)
    (shard_dir / split).mkdir(parents=True, exist_ok=True)
    (shard_dir / "sources").mkdir(parents=True, exist_ok=True)
    paths = shard_paths(shard_dir, split, count)
    todo = [(spec.as_dict(), split, i, str(shard_dir / "sources"), str(p)) for i, p in enumerate(paths) if not p.exists()]
    if progress:
        progress(count - len(todo))
    if todo:
        if spec.workers == 1:
            for job in todo:
                _make_one(job)
                if progress:
                    progress(1)
        else:
            with ProcessPoolExecutor(spec.workers) as pool:
                for _ in pool.map(_make_one, todo, chunksize=4):
                    if progress:
                        progress(1)
    return paths


def augment(tensors: Sequence[torch.Tensor], rng: np.random.Generator, crop: int, *, flip: bool = True
            ) -> list[torch.Tensor]:
    """The same random crop (``crop`` x ``crop``), flips and quarter turn of every (C, H, W) tensor."""
    h, w = tensors[0].shape[-2:]
    y0, x0 = int(rng.integers(0, h - crop + 1)), int(rng.integers(0, w - crop + 1))
    out = [t[..., y0:y0 + crop, x0:x0 + crop] for t in tensors]
    if flip:
        if rng.random() < 0.5:
            out = [t.flip(-1) for t in out]
        if rng.random() < 0.5:
            out = [t.flip(-2) for t in out]
        k = int(rng.integers(4))
        if k:
            out = [torch.rot90(t, k, dims=(-2, -1)) for t in out]
    return [t.contiguous() for t in out]
