"""Single-window training data (:class:`~neuspike.train.spec.WindowData`): cells drawn from (seed,
split, index), simulated through the core's sample builder, and the batches, loss and validation of
a feed-forward network trained on them (:class:`WindowTask`).

A cell is a scene (a training photograph panning in any direction, zooming, behind a fan, or still;
or a procedural dead-leaves scene with independently moving layers) and a condition (L
log-uniform over ``data.light_range``, S from ``data.motions``, a noise level from
``data.noise_levels``, plus the sweeps' default effects: random initial charge and the clean
event-camera preset). Everything about cell ``index`` of ``split`` comes from
``derive_rng(seed, "train-cell", split, index)``, and the window is simulated by
:func:`neuspike.simulation.cell.simulate_sample`, so the same seed gives the same bytes.

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

import contextlib
import io
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2
import numpy as np
import torch

from neuspike.utils import atomic
from neuspike.utils.atomic import write_bytes
from neuspike.conditions import EVENT_PRESETS, Condition, effect
from neuspike.errors import FormatError, InputError
from neuspike.utils.parallel import set_threads
from neuspike.utils.rng import derive_rng
from neuspike.sample import Sample
from neuspike.scenes import SceneSpec
from neuspike.scenes.photos import read_photo
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig
from neuspike.streams import EventStream, SpikeStream
from neuspike.train.spec import KIND_WEIGHTS, SWEEP_GRIDS, SWEEP_SPEED_PX_S, TrainSpec, WindowData, spec_from_dict
from neuspike.train.terms import TERMS, Step, sum_terms

__all__ = ["MOTION_PREFIXES", "WindowTask", "augment", "build_shard", "draw_cell", "load_sample", "save_sample",
           "shard_paths", "simulate_cell"]

#: The sweeps' scene kinds (``bench.harness.grid.SCENE_KINDS``), drawn alike for the sweep data term's scene cells.
SWEEP_SCENE_KINDS = ("pan", "zoom", "fan", "still")
#: The light scales of fast-pan cells: the sweeps' five (``bench.harness.grid.PAPER_LIGHTS``).
FAST_PAN_LIGHTS = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2)
#: Effects every training cell declares (the sweeps' defaults).
BASE_EFFECTS = (effect("initial_charge"),) + tuple(EVENT_PRESETS["clean"])
SENSOR_SIZE = (400, 250)


#: The region's scale relative to the sweeps' without ``scale_range`` (the original draw).
LEGACY_SCALE_RANGE = (0.3, 1.2)


def _photo_source(spec: TrainSpec, rng: np.random.Generator, source_dir: Path, split: str, index: int,
                  size: tuple[int, int], relative_scale: float | None = None, save: bool = True) -> str | None:
    """A region of a training photograph resized to ``size`` (width, height), saved under ``source_dir``;
    ``relative_scale`` (drawn here from :data:`LEGACY_SCALE_RANGE` when None) is its scale relative to
    the photograph filling the 400x250 sensor. ``save=False``: only the region's draws are made (so the
    cell's later draws stay the same), nothing is cut or written, and None is returned."""
    data: WindowData = spec.data
    name = data.photos[int(rng.integers(len(data.photos)))]
    luma = read_photo(name)
    h, w = luma.shape
    vw, vh = size
    if relative_scale is None:
        relative_scale = float(np.exp(rng.uniform(*np.log(LEGACY_SCALE_RANGE))))
    scale = max(SENSOR_SIZE[0] / w, SENSOR_SIZE[1] / h) * relative_scale
    if vw == vh:  # the square training view (the shards' original draw)
        sw = sh = min(int(round(vw / scale)), h, w)
    else:  # a full-size validation view: the same scale where the photograph allows, its aspect kept
        sw, sh = int(round(vw / scale)), int(round(vh / scale))
        shrink = min(1.0, w / sw, h / sh)
        sw, sh = max(1, min(w, int(sw * shrink))), max(1, min(h, int(sh * shrink)))
    y0, x0 = int(rng.integers(0, h - sh + 1)), int(rng.integers(0, w - sw + 1))
    if not save:
        return None
    region = luma[y0:y0 + sh, x0:x0 + sw]
    interp = cv2.INTER_AREA if sw > vw else cv2.INTER_LINEAR
    region = np.clip(cv2.resize(region, (vw, vh), interpolation=interp), 0.0, 1.0).astype(np.float32)
    path = source_dir / f"{split}-{index:06d}-{name}.npy"
    if not path.exists():
        _save_picture(path, region)
    return str(path)


def _save_picture(path: Path, picture: np.ndarray) -> None:
    """Write a cell's picture (float32 (H, W)) as a .npy file, whole or not at all."""
    buf = io.BytesIO()
    np.save(buf, picture)
    write_bytes(path, buf.getvalue())


def _picture_term(spec: TrainSpec, term: str, split: str, index: int
                  ) -> tuple[dict[str, Any], np.random.Generator] | None:
    """``(the term's parameters, its stream for the cell)`` where the picture data term ``term`` takes cell
    ``index`` of ``split`` (its share, drawn first from a stream of its own, ``<term>-picture``), else None."""
    params = spec.data.mixture.get(term)
    if params is None:
        return None
    rng = derive_rng(spec.seed, f"{term}-picture", split, int(index))
    return (params, rng) if rng.random() < params["fraction"] else None


def _smooth_source(spec: TrainSpec, photo: str, split: str, index: int, size: tuple[int, int]) -> str:
    """With the ``smooth`` data term: for its share of the photograph cells, the region ``photo`` blurred outside
    an ellipse where it stays sharp (the term's doc), saved beside it, from a stream of its own; ``photo``
    itself for the other cells."""
    drawn = _picture_term(spec, "smooth", split, index)
    if drawn is None:
        return photo
    smooth, rng = drawn
    lo, hi = smooth["sigma"]
    sigma = float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) * size[0] / SENSOR_SIZE[0]
    area = float(rng.uniform(0.1, 0.4))
    aspect = float(np.exp(rng.uniform(np.log(0.5), np.log(2.0))))
    cx, cy = float(rng.uniform(0.25, 0.75) * size[0]), float(rng.uniform(0.25, 0.75) * size[1])
    path = Path(photo).with_name(f"{Path(photo).stem}-smooth-{index:06d}.npy")
    if not path.exists():
        region = np.load(photo)
        h, w = region.shape
        rx = np.sqrt(area * w * h / np.pi * aspect)
        ry = area * w * h / np.pi / rx
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        inside = (((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 <= 1.0).astype(np.float32)
        edge = max(1.0, 0.02 * w)  # a soft rim, as an object's edge is not one pixel wide
        mask = cv2.GaussianBlur(inside, (0, 0), edge)
        blurred = cv2.GaussianBlur(region, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        picture = np.clip(mask * region + (1.0 - mask) * blurred, 0.0, 1.0).astype(np.float32)
        _save_picture(path, picture)
    return str(path)


def _broad_source(spec: TrainSpec, source_dir: Path, split: str, index: int, size: tuple[int, int]) -> str | None:
    """With the ``broad`` data term: for its share of the cells, a broad-leaves picture of ``size`` saved
    under ``source_dir`` (the first frame of a still ``dead_leaves`` scene, smallest leaf 5-15 % of the
    side), from a stream of its own; None for the other cells."""
    drawn = _picture_term(spec, "broad", split, index)
    if drawn is None:
        return None
    _, rng = drawn
    radius, seed = float(rng.uniform(0.05, 0.15)), int(rng.integers(2**31))
    path = source_dir / f"{split}-{index:06d}-broad-{seed}.npy"
    if not path.exists():
        from neuspike.scenes import make_scene

        scene = make_scene(SceneSpec("dead_leaves", size=size, velocity_px_s=(0.0, 0.0), seed=seed,
                                     leaf_min_radius=radius))
        picture = np.clip(scene.render(np.array([0.0]))[0], 0.0, 1.0).astype(np.float32)
        _save_picture(path, picture)
    return str(path)


def draw_cell(spec: TrainSpec, split: str, index: int, source_dir: str | os.PathLike
              ) -> tuple[SceneSpec, Condition, int, dict[str, Any]]:
    """The (scene, condition, simulation seed) of cell ``index`` of ``split``, and a description."""
    data: WindowData = spec.data
    rng = derive_rng(spec.seed, "train-cell", split, int(index))
    kinds = list(KIND_WEIGHTS)
    kind = kinds[int(rng.choice(len(kinds), p=np.array(list(KIND_WEIGHTS.values())) / sum(KIND_WEIGHTS.values())))]
    # validation at the sweeps' frame when asked (whole-frame offsets show only there), else the square view
    size = tuple(data.val_view) if split == "val" and data.val_view is not None else (data.view, data.view)
    # a cell at one of the sweeps' points (the sweep data term; only drawn when asked, so earlier specs draw
    # what they drew)
    sweep = data.mixture.get("sweep")
    at_sweep = sweep is not None and bool(rng.random() < sweep["fraction"])
    sweep_scene = at_sweep and sweep["scenes"]
    if sweep_scene:  # the sweeps' four kinds alike, from a stream of its own (the cell's later draws follow the kind)
        kind_rng = derive_rng(spec.seed, "sweep-kind", split, int(index))
        if sweep["scene_weights"] is None:  # equal shares (the draw of specs without the weights)
            kind = SWEEP_SCENE_KINDS[int(kind_rng.integers(len(SWEEP_SCENE_KINDS)))]
        else:
            w = np.asarray(sweep["scene_weights"], dtype=float)
            kind = SWEEP_SCENE_KINDS[int(kind_rng.choice(len(SWEEP_SCENE_KINDS), p=w / w.sum()))]
    # a fast pan (the fast_pans data term), from a stream of its own among the cells not at a sweep point: the
    # kind becomes a pan (the cell's later draws follow it, as for the sweep scenes), and the speed and the
    # condition are drawn as without the term and then replaced; the other cells are drawn as without it
    fast = data.mixture.get("fast_pans")
    fast_rng = derive_rng(spec.seed, "fast-pan", split, int(index)) if fast is not None and not at_sweep else None
    at_fast = fast_rng is not None and bool(fast_rng.random() < fast["fraction"])
    if at_fast:
        kind = "pan"
    angle = rng.uniform(0, 2 * np.pi)
    lo, hi = data.speed_range
    speed = SWEEP_SPEED_PX_S if at_sweep else float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    if at_fast:
        speed = SWEEP_SPEED_PX_S * float(fast["speeds"][int(fast_rng.integers(len(fast["speeds"])))])
    if data.scale_range is None:  # the original draw: the sensor shrunk to the view
        relative_scale = None
        speed *= size[0] / SENSOR_SIZE[0]
    else:  # the region at a drawn scale of the sweeps' frame, moving as a sweep's scene would at that scale
        relative_scale = float(np.exp(rng.uniform(*np.log(data.scale_range))))
        speed *= relative_scale
    velocity = (speed * np.cos(angle), speed * np.sin(angle))
    if kind == "dead_leaves":
        scene = SceneSpec(kind="dead_leaves", size=size, velocity_px_s=velocity, seed=int(rng.integers(2**31)))
    else:
        broad = _broad_source(spec, Path(source_dir), split, index, size)
        # the photograph's draws are made either way, so the cell's later draws do not depend on the picture
        photo = _photo_source(spec, rng, Path(source_dir), split, index, size, relative_scale, save=broad is None)
        image = broad or _smooth_source(spec, photo, split, index, size)
        focus = (float(rng.uniform(0.2, 0.8) * size[0]), float(rng.uniform(0.2, 0.8) * size[1]))
        if kind == "pan":
            scene = SceneSpec(kind="pan", image=image, size=size, velocity_px_s=velocity)
        elif kind == "zoom":
            rate = float(rng.uniform(1.0, 20.0) * rng.choice([-1.0, 1.0]))
            scene = SceneSpec(kind="zoom", image=image, size=size, zoom_rate_hz=rate, focus=focus)
            if sweep_scene:  # the sweeps' zoom (SceneSpec's defaults, as bench.harness.grid builds it)
                scene = SceneSpec(kind="zoom", image=image, size=size)
        elif kind == "fan":
            blades = int(rng.integers(2, 6))
            scene = SceneSpec(kind="fan", image=image, size=size, focus=focus, blades=blades,
                              rpm=float(rng.uniform(300, 3000) * rng.choice([-1.0, 1.0])),
                              blade_width_deg=float(rng.uniform(10, 300 / blades / 2)),
                              blade_contrast=float(rng.uniform(0.0, 2.0)))
            if sweep_scene:  # the sweeps' fan
                scene = SceneSpec(kind="fan", image=image, size=size)
        else:
            scene = SceneSpec(kind="still", image=image, size=size)
    if at_sweep:
        points = SWEEP_GRIDS[sweep["grid"]]
        light, motion, noise = points[int(rng.integers(len(points)))]
    else:
        lo, hi = data.light_range
        light = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        motion = int(data.motions[int(rng.integers(len(data.motions)))])
        noise = data.noise_levels[int(rng.integers(len(data.noise_levels)))]
        if at_fast:
            light, motion, noise = float(fast_rng.choice(FAST_PAN_LIGHTS)), int(fast["motion"]), "none"
    condition = Condition(light=light, motion=motion, noise=noise, effects=BASE_EFFECTS)
    sim_seed = int(rng.integers(2**31))
    info = {"split": split, "index": int(index), "kind": kind, "light": light, "motion": motion, "noise": noise,
            "image": Path(scene.image).name if kind != "dead_leaves" else None}
    if "broad" in data.mixture:  # (the descriptions of earlier specs' cells stay as they were)
        info["broad"] = kind != "dead_leaves" and "-broad-" in Path(scene.image).name
    if "smooth" in data.mixture:  # (likewise)
        info["smooth"] = kind != "dead_leaves" and "-smooth-" in Path(scene.image).name
    if fast is not None:  # (likewise)
        info["fast_pan"] = at_fast
    if sweep is not None:  # (the descriptions of earlier specs' cells stay as they were)
        info["at_sweep"] = at_sweep
        if sweep["scenes"]:
            info["sweep_scene"] = sweep_scene
    return scene, condition, sim_seed, info


def simulate_cell(spec: TrainSpec, split: str, index: int, source_dir: str | os.PathLike) -> Sample:
    """The simulated window of a cell (:func:`neuspike.simulation.cell.simulate_sample`), ``meta['cell']`` set."""
    scene, condition, sim_seed, info = draw_cell(spec, split, index, source_dir)
    sample = simulate_sample(scene, condition, sensor=SensorConfig(), seed=sim_seed,
                             modalities=("spikes", "events"))
    sample.meta["cell"] = info
    return sample


def save_sample(path: str | os.PathLike, sample: Sample) -> None:
    """Write a simulated window compactly (bit-packed planes, window events only, the sensor's dark rate), atomically."""
    sp, ev = sample.spikes, sample.window_events()
    buf = io.BytesIO()
    np.savez(buf, planes=np.packbits(sp.planes, axis=None), shape=np.array(sp.planes.shape),
             plane_rate_hz=sp.plane_rate_hz, start_s=sp.start_s, gain=sp.gain, threshold=sp.threshold,
             dark_rate=np.nan if sp.dark_rate is None else sp.dark_rate,
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
            dark = float(z["dark_rate"]) if "dark_rate" in z.files else np.nan  # (windows written before it was kept)
            spikes = SpikeStream(planes=planes, plane_rate_hz=float(z["plane_rate_hz"]), start_s=float(z["start_s"]),
                                 gain=float(z["gain"]), threshold=float(z["threshold"]),
                                 dark_rate=None if np.isnan(dark) else dark)
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
    set_threads(1)
    spec = spec_from_dict(spec_dict)
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
        if spec.data.workers == 1:
            for job in todo:
                _make_one(job)
                if progress:
                    progress(1)
        else:
            with ProcessPoolExecutor(spec.data.workers) as pool:
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


#: Module tensors only the fusion network has (left out of the spike-only export).
MOTION_PREFIXES = ("motion.", "fuse1.", "fuse2.", "motion_gate.", "local_gate.", "noise_gate.", "event_transformer.")


def _psnr(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    mse = ((pred - target) ** 2).mean(dim=(1, 2, 3)).clamp_min(1e-10)
    return 10.0 * torch.log10(1.0 / mse)


class WindowTask:
    """Batches, loss and validation of a feed-forward network on single windows.

    * **order**: step ``k`` uses the windows ``perm_e[j]`` of epoch ``e`` (a permutation drawn from
      ``derive_rng(seed, "order", e)``) and crops/flips from ``derive_rng(seed, "augment", k)``.
    * **inputs**: the method's own :meth:`~neuspike.methods.learned.LearnedMethod.encode` (one step), the
      target the sample's ground truth (1, 1, H, W), cut by ``crop_trim`` where it is set; drawn and
      augmented on the CPU, then moved to the method's device (``method.device``), where the loss and
      the validation run.
    * **loss**: the sum of the spec's registered terms (``data.losses``, :mod:`neuspike.train.terms`), in
      the registry's order: by default L1 + the SSIM loss (``kornia.losses.SSIMLoss``, window 11, data
      range 1); the others (level offset, support, edge SSIM, gate targets, distillation, spike floor)
      where a spec names them.
    * **spike-only steps**: for a fusion network (``spike_only=False``), a fraction
      ``spike_only_fraction`` of the steps (drawn from ``derive_rng(seed, "modality", k)``) runs with
      the motion path silenced, so the same weights also train the spike-only variant, validated and
      exported as ``<name>-spike``.
    * **held parts**: with ``train_parts="motion"`` only the parameters under ``MOTION_PREFIXES``
      learn (:meth:`held`); the rest stay as ``init_from`` gave them.
    * **validation**: the fixed validation windows (full size, no augmentation): L1, PSNR, SSIM;
      the best PSNR exports.
    """

    score_key = "val_psnr"

    def __init__(self, spec: TrainSpec, method) -> None:
        import kornia

        self.spec = spec
        self.data: WindowData = spec.data
        self.method = method
        self.module = method.module
        self.device = method.device
        self.fusion = method.params.get("spike_only") is False
        self._cells: dict[int, dict[str, Any]] = {}  # training window -> its cell (light, motion, noise), read once
        self.losses = self.data.losses
        #: The SSIM term's weight and window: also what a crop's own loss weighs (distillation, spike floor).
        self.ssim_weight = self.losses["ssim"]["weight"] if "ssim" in self.losses else 0.0
        self.ssim_window = self.losses["ssim"]["window"] if "ssim" in self.losses else 11
        self.ssim_loss = kornia.losses.SSIMLoss(window_size=self.ssim_window, max_val=1.0).to(self.device)
        fusion_only = [f"train_parts {self.data.train_parts!r}"] if self.data.train_parts != "all" else []
        if fusion_only and not self.fusion:
            raise InputError(f"{', '.join(fusion_only)}: fusion networks only (the network has no motion path)")
        # the gate a gate_target term supervises: the noise gate where there is one, else the motion gate
        self.supervised_gate = getattr(self.module, "noise_gate", None) or getattr(self.module, "motion_gate", None)
        self.teacher: torch.nn.Module | None = None
        self.floor_network: torch.nn.Module | None = None  # the spike_floor term's held spike-only network
        self.terms = [(TERMS[name], params) for name, params in self.losses.items()]
        for term, params in self.terms:
            if term.setup is not None:
                term.setup(self, params)
        self.needs_convex = any(term.needs_convex for term, _ in self.terms)

    def load_teacher(self, path: str, role: str = "teacher", *, spike_only: bool = False) -> torch.nn.Module:
        """A trained network's module (the ``distill`` term's ``teacher``, or the ``spike_floor`` term's spike-only
        ``network``): created untrained from its JSON card's parameters, the file loaded by the same loader as
        every learned method's, held in eval mode without gradient. ``role`` names the file in errors;
        ``spike_only``: the file must hold a spike-only network (else one that answers in every variant this
        run trains)."""

        weights, card = Path(path), Path(path).with_suffix(".json")
        if not weights.is_file():
            raise InputError(f"{role} {path}: no such file")
        if not card.is_file():
            raise InputError(f"{role} {path}: no JSON card beside it ({card.name}), which says its architecture")
        try:
            meta = json.loads(card.read_text())
            params = dict(meta["model"]["params"])
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(f"{role} {path}: its card {card.name} has no model parameters ({exc})") from None
        if meta.get("method", self.spec.method).replace("-spike", "") != self.spec.method.replace("-spike", ""):
            raise InputError(f"{role} {path}: a {meta.get('method')!r} network; the student is {self.spec.method!r}")
        if spike_only and not params.get("spike_only", False):
            raise InputError(f"{role} {path}: a fusion network; the floor is a spike-only network's image "
                             "(give a spike-only network's weights, such as neuspike-net-spike's)")
        if not spike_only and self.fusion and params.get("spike_only", True):
            raise InputError(f"{role} {path}: a spike-only network cannot teach the fusion network's fusion steps "
                             "(give the full fusion network's weights)")
        from neuspike.methods import create

        teacher = create(self.spec.method, trained=False, device=str(self.device), precision="float32", **params)
        module = teacher.load_file(weights).module.float().eval()
        for p in module.parameters():
            p.requires_grad_(False)
        return module

    def teacher_image(self, inputs: Sequence[torch.Tensor], variant: str) -> torch.Tensor:
        """The teacher's image of ``inputs`` in ``variant`` (no gradient)."""
        with torch.no_grad():
            if variant == "spike" and not getattr(self.teacher, "spike_only", False):
                return self.teacher.forward_texture_only(inputs[0], *inputs[2:])
            return self.teacher(*inputs)

    # -- data --------------------------------------------------------------------------------------

    def shard_folders(self) -> list[Path]:
        root = Path(self.data.shard_dir)
        return [root, root / "train", root / "val", root / "sources"]

    def prepare(self, bar_factory: Callable[..., Any]) -> None:
        spec, data = self.spec, self.data
        shard = Path(data.shard_dir)
        shard.mkdir(parents=True, exist_ok=True)
        key_path = shard / "data_key.json"
        key = data.key(spec.seed)
        if key_path.exists():
            have = json.loads(key_path.read_text())
            if have != key:
                raise InputError(f"{shard}: holds windows of another data spec {have}; use another shard folder")
        else:
            atomic.write_json(key_path, key)
        bar = bar_factory(total=data.val_items + data.train_items, desc="simulating windows", unit="win")
        self.val_paths = build_shard(spec, shard, "val", data.val_items, progress=bar.update)
        self.train_paths = build_shard(spec, shard, "train", data.train_items, progress=bar.update)
        bar.close()

    def load_validation(self) -> None:
        samples = [load_sample(p) for p in self.val_paths]
        inputs = [self.encode(s) for s in samples]
        stacked = [torch.cat([x[k] for x in inputs]) for k in range(len(inputs[0]))]
        target = torch.stack([torch.from_numpy(s.ground_truth)[None] for s in samples])
        self.val_batch = ([x.to(self.device) for x in stacked], target.to(self.device))

    def encode(self, sample: Sample) -> tuple[torch.Tensor, ...]:
        return tuple(self.method.encode(sample)[0])

    def batch_indices(self, step: int) -> list[int]:
        """The training windows of ``step``, in batch order (deterministic from the seed and the step)."""
        spec = self.spec
        n = len(self.train_paths)
        first = step * spec.batch
        idx = []
        for j in range(first, first + spec.batch):
            epoch, pos = divmod(j, n)
            perm = derive_rng(spec.seed, "order", epoch).permutation(n)
            idx.append(int(perm[pos]))
        return idx

    def cells(self, step: int) -> list[dict[str, Any]]:
        """The cell each window of ``step``'s batch was simulated under (its ``light``, ``motion`` and ``noise``
        among others), in batch order, read from the shard."""
        cache = self._cells
        cells = []
        for i in self.batch_indices(step):
            if i not in cache:
                path = self.train_paths[i]
                try:
                    with np.load(path) as z:
                        cell = json.loads(str(z["cell"]))
                except (OSError, KeyError, ValueError) as exc:
                    raise FormatError(f"{path}: no cell recorded with the window ({exc})") from exc
                missing = sorted({"light", "motion", "noise"} - set(cell))
                if missing:
                    raise FormatError(f"{path}: the window's cell records no {', '.join(missing)}")
                cache[i] = cell
            cells.append(cache[i])
        return cells

    def noise_levels(self, step: int) -> list[str]:
        """The sensor-noise level of each window of ``step``'s batch, in batch order (read from the shard)."""
        return [cell["noise"] for cell in self.cells(step)]

    def gate_targets(self, step: int, targets: dict[str, dict[str, float]]) -> tuple[torch.Tensor, torch.Tensor] | None:
        """The ``gate_target`` term's ``targets`` for ``step``'s batch as ``(target, mask)``, each (B, 4) in the
        gate's order (x_m^3, x_m^2, x_m^1, x_m^0) on the device, mask 1 where a crop's noise level names a
        target for that level; None where no crop of the batch has one."""
        value = torch.zeros(self.spec.batch, 4)
        mask = torch.zeros(self.spec.batch, 4)
        for i, level in enumerate(self.noise_levels(step)):
            for name, gain in targets.get(level, {}).items():
                column = 3 - int(name)  # the gate lists x_m^3 first
                value[i, column], mask[i, column] = gain, 1.0
        if not mask.any():
            return None
        return value.to(self.device), mask.to(self.device)

    def batch(self, step: int) -> tuple[list[torch.Tensor], torch.Tensor]:
        """The inputs and targets of ``step`` (deterministic from the seed and the step), on the CPU."""
        spec = self.spec
        idx = self.batch_indices(step)
        rng = derive_rng(spec.seed, "augment", step)
        inputs, targets = [], []
        for i in idx:
            sample = load_sample(self.train_paths[i])
            x = [t[0] for t in self.encode(sample)]
            y = torch.from_numpy(sample.ground_truth)[None]
            *x, y = augment([*x, y], rng, spec.crop)
            inputs.append(x)
            targets.append(y)
        if self.data.crop_trim:  # one size per batch: rows and columns cut off the bottom and right
            th, tw = (int(v) for v in derive_rng(spec.seed, "trim", step).integers(0, self.data.crop_trim + 1, size=2))
            h, w = spec.crop - th, spec.crop - tw
            inputs = [[t[..., :h, :w] for t in x] for x in inputs]  # a (1, 1, 1, 1) quantum stays as it is
            targets = [y[..., :h, :w] for y in targets]
        return [torch.stack([x[k] for x in inputs]) for k in range(len(inputs[0]))], torch.stack(targets)

    # -- model -------------------------------------------------------------------------------------

    def variants(self) -> list[str]:
        """The variants this run validates and exports."""
        return ["fusion", "spike"] if self.fusion else ["single"]

    def step_variant(self, step: int) -> str:
        if not self.fusion:
            return "single"
        if self.data.train_parts == "motion":  # a spike-only step would train nothing
            return "fusion"
        spike = derive_rng(self.spec.seed, "modality", step).random() < self.data.spike_only_fraction
        return "spike" if spike else "fusion"

    def held(self, name: str) -> bool:
        """Whether parameter ``name`` is held (does not learn) in this run (``train_parts``)."""
        return self.data.train_parts == "motion" and not name.startswith(MOTION_PREFIXES)

    def crop_losses(self, pred: torch.Tensor, target: torch.Tensor, terms: str = "both") -> torch.Tensor:
        """Each crop's own L1 + the SSIM term's weight * SSIM loss, (B,) (what distillation and the spike
        floor compare). ``terms="ssim"``: each crop's SSIM loss alone."""
        import kornia

        pred = pred.float()
        ssim_map = kornia.metrics.ssim(pred, target, window_size=self.ssim_window, max_val=1.0)
        structure = ((1.0 - ssim_map) / 2).mean(dim=(1, 2, 3))
        if terms == "ssim":
            return structure
        return (pred - target).abs().mean(dim=(1, 2, 3)) + self.ssim_weight * structure

    def forward(self, inputs: Sequence[torch.Tensor], variant: str, *, parts: bool = False
                ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """The network's image for ``variant``; with ``parts``, ``(image, convex part)``."""
        kw = {"parts": True} if parts else {}
        if variant == "spike":
            return self.module.forward_texture_only(inputs[0], *inputs[2:], **kw)
        return self.module(*inputs, **kw)

    def loss(self, pred: torch.Tensor | tuple[torch.Tensor, torch.Tensor], target: torch.Tensor
             ) -> tuple[torch.Tensor, dict[str, float]]:
        """The image terms of the loss of ``pred`` (an image, or ``(image, convex part)`` where a term
        needs the convex part): those that need nothing but the image and the target."""
        step = Step(task=self, index=-1, variant="single", inputs=[], target=target, autocast=contextlib.nullcontext)
        step.image, step.convex = (pred if isinstance(pred, tuple) else (pred, None))
        step.image = step.image.float()
        return sum_terms([(t, p) for t, p in self.terms if t.image_only], step)

    def step_loss(self, step: int, autocast: Callable[[], Any]) -> tuple[torch.Tensor, dict[str, Any]]:
        """The loss of step ``step`` (its batch, variant and forward pass) and what the log records."""
        import time

        variant = self.step_variant(step)
        t0 = time.perf_counter()
        inputs, target = self.batch(step)
        t_data = time.perf_counter() - t0
        inputs, target = [x.to(self.device) for x in inputs], target.to(self.device)
        ctx = Step(task=self, index=step, variant=variant, inputs=inputs, target=target, autocast=autocast)
        undo = [u for u in (t.before_forward(ctx, p) for t, p in self.terms if t.before_forward is not None)
                if u is not None]
        try:
            with autocast():
                pred = self.forward(inputs, variant, parts=self.needs_convex)
        finally:
            for u in undo:
                u()
        image, ctx.convex = pred if isinstance(pred, tuple) else (pred, None)
        ctx.image = image.float()
        loss, parts = sum_terms(self.terms, ctx)
        return loss, {**parts, "variant": variant, "samples_per_s": round(self.spec.batch / max(t_data, 1e-9), 1)}

    @torch.no_grad()
    def validate(self, variant: str, autocast: Callable[[], Any]) -> dict[str, float]:
        import kornia

        self.module.eval()
        inputs, target = self.val_batch
        preds = []
        for i in range(0, target.shape[0], 8):
            with autocast():
                preds.append(self.forward([x[i:i + 8] for x in inputs], variant).float())
        pred = torch.cat(preds).clamp(0, 1)
        ssim = kornia.metrics.ssim(pred, target, window_size=11, max_val=1.0).mean(dim=(1, 2, 3))
        self.module.train()
        return {"val_l1": float((pred - target).abs().mean()), "val_psnr": float(_psnr(pred, target).mean()),
                "val_ssim": float(ssim.mean())}

    def exported(self, variant: str, name: str) -> tuple[str, dict[str, torch.Tensor], dict[str, Any]]:
        """``(method name, tensors, parameters)`` of the weights ``variant`` exports."""
        params = dict(self.method.params)
        state = self.module.state_dict()
        if variant == "spike":
            state = {k: v for k, v in state.items() if not k.startswith(MOTION_PREFIXES)}
            params["spike_only"] = True
            params["motion_gate"] = "none"
            name = f"{name}-spike"
        return name, state, params

    def describe_data(self) -> dict[str, Any]:
        return {"simulator": "neuspike.simulation.cell.simulate_sample", "kind": "windows",
                "train_items": self.data.train_items, "val_items": self.data.val_items,
                "photos": list(self.data.photos), "procedural": "dead_leaves"}
