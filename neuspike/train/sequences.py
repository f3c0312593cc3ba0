"""Sequence training data (:class:`~neuspike.train.spec.SequenceData`): items of consecutive event
windows of one moving scene, and the batches, loss and validation of a recurrent network trained on
them (:class:`SequenceTask`).

A training *item* is one moving scene seen through ``windows`` consecutive event windows, exactly as
the method reads a sample at inference: the cell (scene, condition, sensor, seed) goes through
:func:`neuspike.simulation.cell.simulate_sample` (the one cell-to-sample path) with enough event history,
the method's own :meth:`windows`/:meth:`encode` cut it into fixed-count windows (``0.35 * H * W``
events, counted back from the key instant) and voxel grids, and the last ``windows`` of them form
the item. Each window's target is the scene rendered at the scene instant of the window's end
(:func:`neuspike.scenes.motion.scene_time_s`; the last one is the sample's own ground truth),
clipped to [0, 1]. The scenes are analytic, so the exact backward optical flow between consecutive
window ends is known (:func:`neuspike.scenes.motion.backward_flow`).

Data (:func:`draw_cell`): the training photographs only, pan / zoom / fan scenes with random
direction, speed, zoom rate, focus, rpm and blades, and on request procedural ``dead_leaves``
scenes (``broad_leaves``: the same scene with its smallest leaf drawn in 5-15 % of the item's side,
so wide uniform regions), linear or high-dynamic-range radiance (``hdr_fraction`` of the items), motion scale S in
{16, ..., 256}, light L in {1/2, ..., 1/32}, event contrast threshold log-uniform in
``threshold_range``, and noise levels drawn uniformly over ``noise_levels``. Items are simulated
once into a *shard* (``<shard_root>/<key>/``, one ``.npz`` per item, written atomically, resumable)
shared by every network with the same data; training takes random crops and flips of them.

Loss, on every step after ``warmup_windows`` steps of each sequence (the state carried, from zeros):
``l1 * |o - y| + ssim * (1 - SSIM(o, y)) + temporal * M * |o_k - warp(o_{k-1})|`` where warp uses the
exact flow, and ``M = valid * exp(-alpha * (y_k - warp(y_{k-1}))^2)`` masks pixels whose source is
outside the frame or that the exact flow does not explain (occlusions, blades). SSIM is kornia's
(Gaussian window 7, sigma 1.5).

History term (``history`` > 0, default 0): the batch's last ``length - length // 2`` windows are run
again from a zero state, and ``history * |o_last - o'_last|`` (the mean absolute difference of the
two passes' last images) is added: an image after a long warm-up should not depend on where the
history started (a new frame of a stream, a recording cut at any instant). It costs half a pass more.

Empty-window term (``empty`` > 0, default 0): one window without events (all-zero voxels, the crop's
size) is run from a zero state, and ``empty`` times the image's mean absolute deviation from its own
mean is added. Without events an image has no structure to show, yet a network whose windows always
hold events never learns that: its answer to a scene that gives almost none (a still scene, a wide
uniform region far from any edge, a recording's first window) is whatever pattern its biases and
zero padding leave. The term says nothing about the image's level. It costs one window more per step.
(On ``e2vid`` it flattened that pattern to FireNet's within 120 steps without changing a score: the pattern was
broader than SSIM's window, and the scores of such scenes follow the blank image's level;
``61a150f8:reports/e2vid/candidates/README.md``, stage 26.)

Partial first windows (the ``partial_first`` data term, :mod:`neuspike.train.mixture`; default none):
every item's windows hold their full count, but a scene that gives few events, evaluated with the
methods' bounded history, hands the network a single window cut short, from a zero state. That share
of the training runs have their first window cut to the events of its last 1-4 of 5 bins, spread over
the five (:func:`partial_window`); the target is unchanged (the scene at the window's end).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from neuspike.utils import atomic
from neuspike.conditions import Condition, Effect, effect
from neuspike.errors import InputError
from neuspike.methods.representations import normalize_voxel_grid
from neuspike.utils.rng import derive_rng
from neuspike.scenes import SceneSpec, make_scene
from neuspike.scenes.motion import backward_flow, image_speed_px_s, scene_time_s
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig
from neuspike.train.spec import LIGHTS, MOTIONS, SequenceData, TrainSpec
from neuspike.train.terms import SEQUENCE_TERMS, SequenceStep, sum_terms

__all__ = [
    "Cell", "SequenceItem", "SequenceTask", "build_shard", "draw_cell", "load_shard", "make_batch", "partial_window",
    "run_sequence", "sequence_loss", "simulate_item", "validate_sequences", "warp",
]


@dataclass(frozen=True)
class Cell:
    """One drawn training cell: what :func:`simulate_sample` receives, plus the seed."""

    scene: SceneSpec
    condition: Condition
    sensor: SensorConfig
    seed: int


def draw_cell(data: SequenceData, rng: np.random.Generator) -> Cell:
    """A random cell of ``data`` (every draw from ``rng``)."""
    kind = str(rng.choice(data.kinds))
    photo = str(rng.choice(data.photos))
    view = data.view
    if view is not None and data.view_fraction < 1.0:  # drawn only then: earlier specs' draws are unchanged
        view = view if rng.random() < data.view_fraction else None
    size = (data.size, data.size) if view is None else view
    # linear when u < 1 - hdr_fraction: the default 0.5 draws exactly as before the field existed
    linear = rng.random() < 1.0 - data.hdr_fraction
    dynamic_range = None if linear else float(np.exp(rng.uniform(np.log(10), np.log(1000))))
    common: dict[str, Any] = dict(image=photo, size=size, dynamic_range=dynamic_range)
    if view is not None:  # drawn only with a view: the draws of a spec without one are unchanged
        x0, y0 = (int(rng.integers(0, v - data.size + 1)) for v in view)
        common["crop"] = (x0, y0, data.size, data.size)
    if kind in ("pan", "dead_leaves", "broad_leaves"):
        angle = rng.uniform(0, 2 * np.pi)
        speed = float(np.exp(rng.uniform(np.log(1000), np.log(6000))))
        velocity = (speed * np.cos(angle), speed * np.sin(angle))
        if kind == "pan":
            scene = SceneSpec("pan", velocity_px_s=velocity, **common)
        else:  # procedural: no photograph and no larger view to cut from, so drawn at the item's size;
            # the layers' own draws come from the scene seed
            broad = {} if kind == "dead_leaves" else {"leaf_min_radius": float(rng.uniform(0.05, 0.15))}
            scene = SceneSpec("dead_leaves", size=(data.size, data.size), dynamic_range=dynamic_range,
                              velocity_px_s=velocity, seed=int(rng.integers(0, 2**31 - 1)), **broad)
    elif kind == "zoom":
        rate = float(rng.uniform(4.0, 20.0) * rng.choice([-1.0, 1.0]))
        focus = tuple(float(v) for v in rng.uniform(0.25, 0.75, 2) * (np.asarray(size) - 1))
        scene = SceneSpec("zoom", zoom_rate_hz=rate, focus=focus, **common)
    else:
        scene = SceneSpec("fan", rpm=float(rng.uniform(500, 2600) * rng.choice([-1.0, 1.0])),
                          blades=int(rng.integers(2, 6)), blade_width_deg=float(rng.uniform(15, 40)),
                          blade_contrast=float(np.exp(rng.uniform(np.log(0.1), np.log(3.0)))), **common)
    light, motion = float(rng.choice(LIGHTS)), int(rng.choice(MOTIONS))
    noise = str(rng.choice(data.noise_levels))
    lo, hi = data.threshold_range
    sensor = SensorConfig(event_threshold=float(np.exp(rng.uniform(np.log(lo), np.log(hi)))))
    seed = int(rng.integers(0, 2**31 - 1))
    # drawn after every earlier draw, and only when asked for: a nominal spec's items are unchanged
    effects = SENSOR_DRAWS[data.sensor](rng, noise)
    return Cell(scene, Condition(light=light, motion=motion, noise=noise, effects=effects), sensor, seed)


def nominal_sensor(rng: np.random.Generator, noise: str) -> tuple[Effect, ...]:
    """The event camera as the noise level declares it: no further stage, no draw."""
    return ()


def randomised_sensor(rng: np.random.Generator, noise: str) -> tuple[Effect, ...]:
    """An event camera drawn per sequence, as real DAVIS pixels differ (REFERENCE.md §3.2, after
    Stoffregen et al. 2020; the threshold itself comes from ``threshold_range``).

    Always a frozen per-pixel threshold mismatch, sigma uniform in [0.01, 0.1] (v2e's presets: 0.02
    clean, 0.05 noisy); each with probability 1/2, log-uniform: a refractory period of 0.1-1 ms (v2e's
    default 0.5 ms), a leak of 0.01-1 Hz, a photoreceptor bandwidth of 10-300 Hz (v2e's noisy preset
    30 Hz) and, where the noise level declares none, shot noise of 0.1-10 Hz.
    """
    def log_uniform(a: float, b: float) -> float:
        return float(np.exp(rng.uniform(np.log(a), np.log(b))))

    drawn = [effect("threshold_mismatch", sigma=float(rng.uniform(0.01, 0.1)))]
    for name, key, lo, hi in (("refractory", "period_s", 1e-4, 1e-3), ("leak", "rate_hz", 0.01, 1.0),
                              ("bandwidth", "cutoff_hz", 10.0, 300.0), ("shot_noise", "rate_hz", 0.1, 10.0)):
        take, value = rng.random() < 0.5, log_uniform(lo, hi)  # both drawn always: the draws stay aligned
        if take and not (name == "shot_noise" and noise != "none"):
            drawn.append(effect(name, **{key: value}))
    return tuple(drawn)


def mixed_sensor(rng: np.random.Generator, noise: str) -> tuple[Effect, ...]:
    """Half the sequences the nominal event camera, half one drawn as :func:`randomised_sensor` draws it:
    a network that meets real pixels keeps the simulator's own camera too. The randomised stages are
    drawn always, so the same seed draws the same pixels whichever half a sequence falls in."""
    nominal = rng.random() < 0.5
    drawn = randomised_sensor(rng, noise)
    return () if nominal else drawn


#: How a sequence's event camera is drawn (``SequenceData.sensor``): name -> ``draw(rng, noise level)``
#: returning the declared event stages. A new way to draw sensors is one entry here.
SENSOR_DRAWS: dict[str, Callable[[np.random.Generator, str], tuple[Effect, ...]]] = {
    "nominal": nominal_sensor, "randomised": randomised_sensor, "mixed": mixed_sensor,
}


@dataclass(frozen=True)
class SequenceItem:
    """``voxels`` (K, 5, H, W), ``targets`` (K, H, W) in [0, 1], ``flow`` (K, 2, H, W) (step 0: zeros)."""

    voxels: np.ndarray
    targets: np.ndarray
    flow: np.ndarray
    meta: dict[str, Any]


def _history_s(cell: Cell, displacement_px: float) -> float:
    """Sensor seconds of event history in which the scene moves about ``displacement_px`` pixels."""
    scene_span = displacement_px / max(image_speed_px_s(cell.scene), 1e-9)
    frame_dt_sensor = (cell.sensor.planes // cell.condition.motion) / cell.sensor.plane_rate_hz
    return scene_span * cell.sensor.upsampled_rate_hz * frame_dt_sensor


def simulate_item(method: Any, cell: Cell, data: SequenceData) -> SequenceItem | None:
    """The sequence of ``data.windows`` full windows ending at the key instant, or ``None`` if the scene gives too few events.

    ``method`` is a method object with ``windows(sample)`` and ``encode(sample)`` (the trainer's
    untrained method); its ``max_windows`` must be at least ``data.windows + 1``.
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
    times = scene_time_s(ends, motion=cell.condition.motion, planes=cell.sensor.planes,
                         plane_rate_hz=cell.sensor.plane_rate_hz, upsampled_rate_hz=cell.sensor.upsampled_rate_hz)
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


def _write_item(method: Any, data: SequenceData, seed: int, split: str, index: int, folder: Path) -> None:
    """Simulate item ``index`` of ``split`` from ``derive_rng(seed, "sequences", split, index)`` (cells
    redrawn until one gives enough events) and write it atomically."""
    rng = derive_rng(seed, "sequences", split, index)
    item = None
    while item is None:
        cell = draw_cell(data, rng)
        try:
            item = simulate_item(method, cell, data)
        except ArithmeticError as exc:  # a simulator defect on this cell: recorded, the cell redrawn
            with open(folder / "failures.txt", "a") as f:
                f.write(f"{split} {index}: {type(exc).__name__}: {exc}: {cell!r}\n")
    buf = io.BytesIO()
    np.savez(buf, voxels=item.voxels, targets=item.targets, flow=item.flow, meta=np.array(json.dumps(item.meta)))
    atomic.write_bytes(_item_path(folder, split, index), buf.getvalue())


#: A shard worker's own method and data, built once per process by :func:`_start_worker`.
_WORKER: dict[str, Any] = {}


def _start_worker(spec_dict: dict[str, Any]) -> None:
    """Build this process's method for encoding (its module's weights play no part in an item)."""
    from neuspike.train.method import training_method
    from neuspike.train.spec import spec_from_dict
    from neuspike.utils.parallel import set_threads

    set_threads(1)
    spec = spec_from_dict(spec_dict)
    _WORKER["method"], _WORKER["data"] = training_method(spec, "cpu"), spec.data


def _worker_item(job: tuple[int, str, int, str]) -> int:
    seed, split, index, folder = job
    _write_item(_WORKER["method"], _WORKER["data"], seed, split, index, Path(folder))
    return index


def build_shard(method: Any, data: SequenceData, *, seed: int, split: str, count: int, folder: Path,
                bar_factory: Callable[..., Any] | None = None, workers: int = 1,
                spec: TrainSpec | None = None) -> list[Path]:
    """Simulate ``count`` items of ``split`` into ``folder`` (resumable: existing items are kept).

    Item ``i`` draws its cells from ``derive_rng(seed, "sequences", split, i)`` (redrawn until one gives
    enough events), so the same seed gives the same items whatever was built before and however many
    processes build them. ``workers`` > 1 simulates in that many fresh processes, each building its own
    copy of ``spec``'s method on the CPU (``spec`` is then required); the items are the same as one
    process's.
    """
    folder.mkdir(parents=True, exist_ok=True)
    paths = [_item_path(folder, split, i) for i in range(count)]
    todo = [i for i, p in enumerate(paths) if not p.is_file()]
    if not todo:
        return paths
    bar = bar_factory(total=len(todo), desc=f"simulating {split}", unit="seq") if bar_factory is not None else None
    if workers <= 1 or len(todo) == 1:
        for i in todo:
            _write_item(method, data, seed, split, i, folder)
            if bar is not None:
                bar.update(1)
    else:
        if spec is None:
            raise ValueError("build_shard: workers > 1 needs the spec, to build each worker's method")
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        jobs = [(seed, split, i, str(folder)) for i in todo]
        # fresh processes (not forked): the parent may hold a CUDA context and torch's thread pools
        with ProcessPoolExecutor(min(workers, len(todo)), mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_start_worker, initargs=(spec.as_dict(),)) as pool:
            for _ in pool.map(_worker_item, jobs):
                if bar is not None:
                    bar.update(1)
    if bar is not None:
        bar.close()
    return paths


def _stack_manifest(paths: Sequence[Path]) -> list[list[Any]]:
    """What a stack was built from: each item's name, size and modification time."""
    out = []
    for p in paths:
        st = Path(p).stat()
        out.append([Path(p).name, st.st_size, st.st_mtime_ns])
    return out


def load_shard(paths: Sequence[Path], *, stack_dir: Path | None = None) -> dict[str, np.ndarray]:
    """Stack items: ``voxels`` (N, K, 5, H, W), ``targets`` (N, K, 1, H, W), ``flow`` (N, K, 2, H, W), float16.

    With ``stack_dir`` the stacks are written there once (``<first item>-<N>.<array>.npy``) and
    returned memory-mapped, read only: a shard larger than the memory the training's activations leave
    (600 items of 240 pixels are 8.8 GB) is then paged from disk instead of held whole, and later runs
    open it at once. Each array is written under a temporary name of this process's own (cleaned up
    with the shard's other temporaries) and renamed, then ``<first item>-<N>.items.json`` records the
    items it was built from (name, size, modification time): a stack without it, or whose items
    changed since, is built again. Two runs building at once each write their own copy; the last
    rename wins, with the same content.
    """
    if stack_dir is None or not paths:
        parts: dict[str, list[np.ndarray]] = {"voxels": [], "targets": [], "flow": []}
        for p in paths:
            with np.load(p) as z:
                parts["voxels"].append(z["voxels"])
                parts["targets"].append(z["targets"][:, None])
                parts["flow"].append(z["flow"])
        return {k: np.stack(v) for k, v in parts.items()}
    import tempfile

    stack_dir = Path(stack_dir)
    stem = f"{Path(paths[0]).stem}-{len(paths)}"
    files = {k: stack_dir / f"{stem}.{k}.npy" for k in ("voxels", "targets", "flow")}
    manifest_path = stack_dir / f"{stem}.items.json"
    manifest = _stack_manifest(paths)
    try:
        current = json.loads(manifest_path.read_text()) == manifest and all(f.is_file() for f in files.values())
    except (OSError, ValueError):
        current = False
    if not current:
        manifest_path.unlink(missing_ok=True)
        with np.load(paths[0]) as z:
            first = {"voxels": z["voxels"], "targets": z["targets"][:, None], "flow": z["flow"]}
        temps, outs = {}, {}
        try:
            for k, a in first.items():
                fd, name = tempfile.mkstemp(dir=stack_dir, prefix=f".{files[k].name}.", suffix=".tmp")
                os.close(fd)
                temps[k] = Path(name)
                outs[k] = np.lib.format.open_memmap(temps[k], mode="w+", dtype=a.dtype, shape=(len(paths), *a.shape))
            for i, p in enumerate(paths):
                with np.load(p) as z:
                    outs["voxels"][i] = z["voxels"]
                    outs["targets"][i] = z["targets"][:, None]
                    outs["flow"][i] = z["flow"]
            for out in outs.values():
                out.flush()
            outs.clear()  # unmapped before the rename
            for k, tmp in temps.items():
                tmp.replace(files[k])
            temps.clear()
        finally:
            outs.clear()
            for tmp in temps.values():
                tmp.unlink(missing_ok=True)
        atomic.write_text(manifest_path, json.dumps(manifest) + "\n")
    shard = {k: np.load(f, mmap_mode="r") for k, f in files.items()}
    n = {a.shape[0] for a in shard.values()}
    if n != {len(paths)}:
        raise InputError(f"the stacked shard in {stack_dir} holds {sorted(n)} items, expected {len(paths)}; "
                         f"delete {stem}.* there to rebuild it")
    return shard


def partial_window(voxels: np.ndarray, kept: int) -> np.ndarray:
    """A normalised voxel grid (B, H, W) as if its window had been cut short: the events of its last
    ``kept`` of B bins, spread over all B bins (linear interpolation along time) and normalised again.

    A window whose event history runs out before its count is reached (a scene that gives few events,
    evaluated with the methods' bounded history) spans only the latest part of a full window's time, and
    its B bins divide that shorter span. The stored grids are normalised already, so this is an
    approximation of the grid the shorter window would give (exact for ``kept`` = B).
    """
    b = voxels.shape[0]
    if not 1 <= kept <= b:
        raise InputError(f"kept: expected 1..{b} bins, got {kept}")
    pos = (b - kept) + np.arange(b) * (kept - 1) / max(b - 1, 1)
    lo = np.floor(pos).astype(int)
    hi = np.minimum(lo + 1, b - 1)
    frac = (pos - lo)[:, None, None].astype(np.float32)
    return normalize_voxel_grid(voxels[lo] * (1 - frac) + voxels[hi] * frac)


def make_batch(shard: dict[str, np.ndarray], rng: np.random.Generator, *, batch: int,
               crop: int, length: int | None = None, partial_first: float = 0.0) -> dict[str, torch.Tensor]:
    """Random items, a random run of ``length`` consecutive windows (default all), random crops of
    ``crop`` pixels, random horizontal/vertical flips (flow signs follow); with ``partial_first`` > 0,
    that share of the runs have their first window cut short (:func:`partial_window`, the last 1 to
    B - 1 of its B bins, drawn uniformly), as a scene that gives few events hands a network its first window.

    Returns float32 CPU tensors ``voxels`` (K, B, 5, c, c), ``targets`` (K, B, 1, c, c), ``flow`` (K, B, 2, c, c).
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
    if partial_first > 0:  # drawn after the crops, so that the runs themselves are the ones drawn without it
        for run in out["voxels"]:
            if rng.random() < partial_first:
                run[0] = partial_window(run[0], int(rng.integers(1, run.shape[1])))
    return {k: torch.from_numpy(np.stack(v, axis=1)) for k, v in out.items()}


# --- loss ---------------------------------------------------------------------------------------


def warp(image: torch.Tensor, flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Sample ``image`` (B, C, H, W) at ``(x + dx, y + dy)`` (bilinear); also the in-frame mask (B, 1, H, W).

    ``flow`` (B, 2, H, W) in pixels, on ``image``'s device.
    """
    b, _, h, w = image.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32, device=image.device),
                            torch.arange(w, dtype=torch.float32, device=image.device), indexing="ij")
    sx = xs[None] + flow[:, 0]
    sy = ys[None] + flow[:, 1]
    grid = torch.stack([2 * sx / max(w - 1, 1) - 1, 2 * sy / max(h - 1, 1) - 1], dim=-1)
    out = F.grid_sample(image, grid.to(image.dtype), mode="bilinear", padding_mode="border", align_corners=True)
    valid = ((sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)).to(image.dtype)[:, None]
    return out, valid


def sequence_loss(outputs: Sequence[torch.Tensor], batch: dict[str, torch.Tensor], data: SequenceData
                  ) -> tuple[torch.Tensor, dict[str, float]]:
    """The image terms of ``data.losses`` (those that score the outputs alone: l1, SSIM, temporal) over the
    steps after ``data.warmup_windows``; also their parts as floats."""
    return sum_terms([(SEQUENCE_TERMS[n], p) for n, p in data.losses.items() if SEQUENCE_TERMS[n].image_only],
                SequenceStep(outputs=list(outputs), batch=batch, data=data, warp=warp))


def run_sequence(module: torch.nn.Module, voxels: torch.Tensor, *, precision: str) -> list[torch.Tensor]:
    """Feed ``voxels`` (K, B, 5, H, W) step by step from a zero state; the K outputs (B, 1, H, W).

    ``voxels`` are on the module's device; bfloat16 autocasts on that device.
    """
    state = None
    outputs = []
    ctx = (torch.autocast(voxels.device.type, dtype=torch.bfloat16) if precision == "bfloat16"
           else contextlib.nullcontext())
    with ctx:
        for k in range(voxels.shape[0]):
            out, state = module(voxels[k], state)
            outputs.append(out)
    return outputs


def validate_sequences(module: torch.nn.Module, shard: dict[str, np.ndarray], data: SequenceData, *,
                       precision: str) -> dict[str, float]:
    """Mean L1 and SSIM (:func:`neuspike.metrics.ssim`, data range 1) of ``module`` over the items of
    ``shard`` (:func:`load_shard`), on the steps after ``data.warmup_windows`` and on the last step.

    The items go to the module's device one at a time; the outputs are scored on the CPU. Leaves
    ``module`` in eval mode.
    """
    from neuspike.metrics import ssim as ssim_metric

    device = next(module.parameters()).device
    module.eval()
    l1s, ssims, last = [], [], []
    with torch.no_grad():
        for i in range(shard["voxels"].shape[0]):
            vox = torch.from_numpy(shard["voxels"][i].astype(np.float32))[:, None].to(device)
            outs = run_sequence(module, vox, precision=precision)
            for k in range(data.warmup_windows, len(outs)):
                o = outs[k][0, 0].float().clamp(0, 1).cpu().numpy()
                y = shard["targets"][i, k, 0].astype(np.float32)
                l1s.append(float(np.abs(o - y).mean()))
                s = float(ssim_metric(o, y, data_range=1.0))
                ssims.append(s)
                if k == len(outs) - 1:
                    last.append(s)
    return {"val_l1": float(np.mean(l1s)), "val_ssim": float(np.mean(ssims)), "val_ssim_last": float(np.mean(last))}


class SequenceTask:
    """Batches, loss and validation of a recurrent network on sequences (module docstring).

    Step ``k``'s batch comes from ``derive_rng(seed, "batch", k)`` (drawn on the CPU, then moved to
    the method's device, ``method.device``, where the loss runs); validation scores the mean SSIM
    (and L1) over the held-out sequences' steps after the warm-up, and the last step's SSIM; the
    best mean SSIM exports.
    """

    score_key = "val_ssim"

    def __init__(self, spec: TrainSpec, method) -> None:
        self.spec = spec
        self.data: SequenceData = spec.data
        self.method = method
        self.module = method.module
        self.device = method.device
        self.precision = "float32"
        if method.params.get("max_windows", 0) <= self.data.windows:
            raise InputError(f"method {spec.method!r}: max_windows must exceed the sequence's "
                             f"{self.data.windows} windows")

    @property
    def shard_dir(self) -> Path:
        return Path(self.data.shard_root) / self.data.key(self.spec.seed)

    def shard_folders(self) -> list[Path]:
        return [self.shard_dir]

    def prepare(self, bar_factory: Callable[..., Any]) -> None:
        data, folder = self.data, self.shard_dir
        common = dict(seed=self.spec.seed, folder=folder, bar_factory=bar_factory, workers=data.workers, spec=self.spec)
        self.train_paths = build_shard(self.method, data, split="train", count=data.train_items, **common)
        self.val_paths = build_shard(self.method, data, split="val", count=data.val_items, **common)
        item = {k: v for k, v in json.loads(json.dumps(self.data.__dict__)).items() if k in SequenceData.KEY_FIELDS}
        atomic.write_text(folder / "data.json", json.dumps(item, indent=2) + "\n")

    def load_validation(self) -> None:
        self.train_shard = load_shard(self.train_paths, stack_dir=self.shard_dir)
        self.val_shard = load_shard(self.val_paths)

    def variants(self) -> list[str]:
        return ["main"]

    def held(self, name: str) -> bool:
        """Whether parameter ``name`` is held in this run: never (every parameter learns)."""
        return False

    def step_loss(self, step: int, autocast: Callable[[], Any]) -> tuple[torch.Tensor, dict[str, Any]]:
        spec = self.spec
        batch = make_batch(self.train_shard, derive_rng(spec.seed, "batch", step), batch=spec.batch, crop=spec.crop,
                           length=self.data.length,
                           partial_first=self.data.mixture.get("partial_first", {}).get("fraction", 0.0))
        batch = {k: v.to(self.device) for k, v in batch.items()}
        outputs = run_sequence(self.module, batch["voxels"], precision=self.precision)
        step_ctx = SequenceStep(outputs=outputs, batch=batch, data=self.data, task=self, warp=warp,
                                run=lambda voxels: run_sequence(self.module, voxels, precision=self.precision))
        loss, parts = sum_terms([(SEQUENCE_TERMS[n], p) for n, p in self.data.losses.items()], step_ctx)
        return loss, {**parts, "variant": "main"}

    def validate(self, variant: str, autocast: Callable[[], Any]) -> dict[str, float]:
        scores = validate_sequences(self.module, self.val_shard, self.data, precision=self.precision)
        self.module.train()
        return scores

    def exported(self, variant: str, name: str) -> tuple[str, dict[str, torch.Tensor], dict[str, Any]]:
        return name, self.module.state_dict(), dict(self.method.params)

    def describe_data(self) -> dict[str, Any]:
        return {"simulator": "neuspike.simulation.cell.simulate_sample", "kind": "sequences", "shard": self.shard_dir.name,
                "train_items": self.data.train_items, "val_items": self.data.val_items,
                "photos": list(self.data.photos), "kinds": list(self.data.kinds)}
