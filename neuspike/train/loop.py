"""The training loop: data order, loss, schedule, validation, atomic checkpoints, resume, export.

Training protocol: the method named by ``spec.method`` must be a registered learned method whose
class offers ``module_for(params) -> nn.Module`` (an untrained module) and
``encode_sample(sample, params) -> tuple of (1, C, H, W) tensors`` (the module's inputs); the
target is the sample's ground truth (1, 1, H, W). Feed-forward only; recurrent sequence training
lives beside this module.

* **order**: step ``k`` uses the windows ``perm_e[j]`` of epoch ``e`` (a permutation drawn from
  ``derive_rng(seed, "order", e)``) and crops/flips from ``derive_rng(seed, "augment", k)``: the
  same seed gives the same batches, also after a resume.
* **loss**: L1 + ``ssim_weight`` * ``kornia.losses.SSIMLoss`` (window ``ssim_window``, data range 1).
* **optimiser**: AdamW (``lr``, ``weight_decay``), linear warm-up over ``warmup`` steps, cosine decay
  to ``lr_min`` at ``steps``; gradients clipped to norm 1.
* **spike-only steps**: for a fusion network (one with ``spike_only=False``), a fraction
  ``spike_only_fraction`` of the steps (drawn from ``derive_rng(seed, "modality", k)``) runs with the
  motion path silenced, so the same weights also train the spike-only variant.
* **validation** every ``val_every`` steps on the fixed validation windows (full 128x128, no
  augmentation): L1, PSNR, SSIM; for a fusion network also with the motion path silenced.
* **checkpoint** (model, optimiser, step, best scores) written atomically every ``checkpoint_every``
  steps and at the end; a run resumes from it with the same spec (a different spec is refused).
* **export**: the best-by-validation weights go to ``out_dir/best.safetensors`` (+ card) and, with
  ``spec.export``, into the package's ``neuspike/trained/``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from neuspike import atomic
from neuspike.errors import InputError
from neuspike.learned import native_bfloat16
from neuspike.methods import entry
from neuspike.rng import derive_rng
from neuspike.train.data import augment, build_shard, load_sample
from neuspike.train.spec import TrainSpec
from neuspike.weights import PACKAGE_WEIGHTS, load_safetensors, load_state_strict, save_safetensors

__all__ = ["LOG_COLUMNS", "Trainer", "learning_rate", "train"]

LOG_COLUMNS = ("step", "kind", "loss", "l1", "ssim_loss", "lr", "seconds", "samples_per_s",
               "val_l1", "val_psnr", "val_ssim", "variant")
#: Module tensors only the fusion network has (left out of the spike-only export).
MOTION_PREFIXES = ("motion.", "fuse1.", "fuse2.")


def learning_rate(spec: TrainSpec, step: int) -> float:
    """The schedule: linear warm-up to ``lr``, cosine decay to ``lr_min`` (``step`` counts from 0)."""
    if step < spec.warmup:
        return spec.lr * (step + 1) / spec.warmup
    frac = min(1.0, (step - spec.warmup) / max(1, spec.steps - spec.warmup))
    return spec.lr_min + 0.5 * (spec.lr - spec.lr_min) * (1.0 + math.cos(math.pi * frac))


def _psnr(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    mse = ((pred - target) ** 2).mean(dim=(1, 2, 3)).clamp_min(1e-10)
    return 10.0 * torch.log10(1.0 / mse)


class Trainer:
    """One training run of ``spec`` (see the module docstring)."""

    def __init__(self, spec: TrainSpec, *, quiet: bool = False) -> None:
        self.spec = spec
        self.quiet = quiet
        self.out = Path(spec.out_dir)
        self.entry = entry(spec.method)
        cls = self.entry.factory
        if not (hasattr(cls, "module_for") and hasattr(cls, "encode_sample")):
            raise InputError(f"method {spec.method!r} does not offer the training protocol (module_for, encode_sample)")
        self.cls = cls
        self.params = {**dict(self.entry.params), **spec.params}
        self.fusion = self.params.get("spike_only") is False
        torch.manual_seed(spec.seed)
        self.module = cls.module_for(self.params)
        if spec.init_from is not None:  # a second stage: start from earlier weights (a checkpoint still wins)
            load_state_strict(self.module, load_safetensors(spec.init_from), spec.init_from)
        self.optim = torch.optim.AdamW(self.module.parameters(), lr=spec.lr, weight_decay=spec.weight_decay)
        import kornia

        self.ssim_loss = kornia.losses.SSIMLoss(window_size=spec.ssim_window, max_val=1.0)
        bf16 = spec.precision == "bfloat16" or (spec.precision == "auto" and native_bfloat16())
        self.precision = "bfloat16" if bf16 else "float32"
        self.step = 0
        self.best: dict[str, float] = {}
        self.history: list[dict[str, Any]] = []

    # -- data ------------------------------------------------------------------------------------

    def prepare_data(self) -> None:
        spec = self.spec
        shard = Path(spec.shard_dir)
        shard.mkdir(parents=True, exist_ok=True)
        key_path = shard / "data_key.json"
        key = spec.data_key()
        if key_path.exists():
            have = json.loads(key_path.read_text())
            if have != key:
                raise InputError(f"{shard}: holds windows of another data spec {have}; use another shard_dir")
        else:
            atomic.write_json(key_path, key)
        bar = self._bar(total=spec.val_size + spec.shard_size, desc="simulating windows", unit="win")
        self.val_paths = build_shard(spec, shard, "val", spec.val_size, progress=bar.update)
        self.train_paths = build_shard(spec, shard, "train", spec.shard_size, progress=bar.update)
        bar.close()
        self.val_batch = self._encode([load_sample(p) for p in self.val_paths])

    def _encode(self, samples: list) -> tuple[list[torch.Tensor], torch.Tensor]:
        inputs = [self.cls.encode_sample(s, self.params) for s in samples]
        stacked = [torch.cat([x[k] for x in inputs]) for k in range(len(inputs[0]))]
        target = torch.stack([torch.from_numpy(s.ground_truth)[None] for s in samples])
        return stacked, target

    def batch(self, step: int) -> tuple[list[torch.Tensor], torch.Tensor]:
        """The inputs and targets of ``step`` (deterministic from the seed and the step)."""
        spec = self.spec
        n = len(self.train_paths)
        first = step * spec.batch
        idx = []
        for j in range(first, first + spec.batch):
            epoch, pos = divmod(j, n)
            perm = derive_rng(spec.seed, "order", epoch).permutation(n)
            idx.append(int(perm[pos]))
        rng = derive_rng(spec.seed, "augment", step)
        inputs, targets = [], []
        for i in idx:
            sample = load_sample(self.train_paths[i])
            x = [t[0] for t in self.cls.encode_sample(sample, self.params)]
            y = torch.from_numpy(sample.ground_truth)[None]
            *x, y = augment([*x, y], rng, spec.crop)
            inputs.append(x)
            targets.append(y)
        return [torch.stack([x[k] for x in inputs]) for k in range(len(inputs[0]))], torch.stack(targets)

    def spike_only_step(self, step: int) -> bool:
        return self.fusion and derive_rng(self.spec.seed, "modality", step).random() < self.spec.spike_only_fraction

    # -- model -----------------------------------------------------------------------------------

    def forward(self, inputs: list[torch.Tensor], *, spike_only: bool) -> torch.Tensor:
        if spike_only:
            return self.module.forward_texture_only(inputs[0])
        return self.module(*inputs)

    def _autocast(self):
        import contextlib

        if self.precision == "bfloat16":
            return torch.autocast("cpu", dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def loss(self, pred: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        pred = pred.float()
        l1 = (pred - target).abs().mean()
        ssim = self.ssim_loss(pred, target)
        return l1 + self.spec.ssim_weight * ssim, l1, ssim

    def train_step(self, inputs: list[torch.Tensor], target: torch.Tensor, *, spike_only: bool) -> dict[str, float]:
        self.module.train()
        for group in self.optim.param_groups:
            group["lr"] = learning_rate(self.spec, self.step)
        with self._autocast():
            pred = self.forward(inputs, spike_only=spike_only)
        loss, l1, ssim = self.loss(pred, target)
        self.optim.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.module.parameters(), 1.0)
        self.optim.step()
        return {"loss": loss.item(), "l1": l1.item(), "ssim_loss": ssim.item()}

    @torch.no_grad()
    def validate(self, *, spike_only: bool) -> dict[str, float]:
        self.module.eval()
        inputs, target = self.val_batch
        preds = []
        for i in range(0, target.shape[0], 8):
            with self._autocast():
                preds.append(self.forward([x[i:i + 8] for x in inputs], spike_only=spike_only).float())
        pred = torch.cat(preds).clamp(0, 1)
        import kornia

        ssim = kornia.metrics.ssim(pred, target, window_size=11, max_val=1.0).mean(dim=(1, 2, 3))
        return {"val_l1": float((pred - target).abs().mean()), "val_psnr": float(_psnr(pred, target).mean()),
                "val_ssim": float(ssim.mean())}

    # -- files -----------------------------------------------------------------------------------

    def _bar(self, **kw):
        from tqdm import tqdm

        return tqdm(disable=self.quiet, dynamic_ncols=True, **kw)

    def write_spec(self) -> None:
        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / "spec.json"
        mine = self.spec.as_dict()
        if path.exists():
            have = json.loads(path.read_text())
            if have != mine:
                raise InputError(f"{path}: this folder holds a run of another spec; resume with the same spec "
                                 f"or use another --out")
        else:
            atomic.write_json(path, mine)

    def save_checkpoint(self) -> None:
        buf = io.BytesIO()
        torch.save({"step": self.step, "model": self.module.state_dict(), "optim": self.optim.state_dict(),
                    "best": self.best, "torch_rng": torch.get_rng_state()}, buf)
        atomic.write_bytes(self.out / "checkpoint.pt", buf.getvalue())

    def load_checkpoint(self) -> bool:
        path = self.out / "checkpoint.pt"
        if not path.exists():
            return False
        state = torch.load(path, map_location="cpu", weights_only=True)
        self.module.load_state_dict(state["model"])
        self.optim.load_state_dict(state["optim"])
        self.step = int(state["step"])
        self.best = dict(state["best"])
        torch.set_rng_state(state["torch_rng"])
        return True

    def log(self, row: Mapping[str, Any]) -> None:
        path = self.out / "train_log.csv"
        new = not path.exists()
        with open(path, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=LOG_COLUMNS)
            if new:
                w.writeheader()
            w.writerow({k: row.get(k, "") for k in LOG_COLUMNS})

    def _truncate_log(self) -> None:
        """After a resume: drop log rows past the checkpoint's step (they will be redone)."""
        path = self.out / "train_log.csv"
        if not path.exists():
            return
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if int(r["step"]) <= self.step]
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=LOG_COLUMNS)
        w.writeheader()
        w.writerows(rows)
        atomic.write_text(path, buf.getvalue())

    def card(self, variant: str, scores: Mapping[str, float], params: Mapping[str, Any]) -> dict[str, Any]:
        return {"method": variant, "model": {"class": self.cls.__name__, "params": dict(params)},
                "training": {"spec": self.spec.as_dict(), "step": self.step, "precision": self.precision,
                             "command": f"python -m neuspike.train {self.spec.method} (spec.json beside the checkpoint)"},
                "data": {"simulator": "neuspike.simulate.simulate_sample", "train_windows": self.spec.shard_size,
                         "val_windows": self.spec.val_size, "photos": list(self.spec.photos),
                         "procedural": "dead_leaves"},
                "validation": dict(scores), "torch": torch.__version__}

    def export(self, variant: str, scores: Mapping[str, float]) -> None:
        params = dict(self.params)
        state = self.module.state_dict()
        name = self.entry.name
        if variant == "spike":
            state = {k: v for k, v in state.items() if not k.startswith(MOTION_PREFIXES)}
            params["spike_only"] = True
            name = f"{self.entry.name}-spike"
        file_name = f"{name}.safetensors"
        card = self.card(name, scores, params)
        save_safetensors(state, self.out / file_name, card=card)
        if self.spec.export:
            save_safetensors(state, Path(PACKAGE_WEIGHTS) / file_name, card=card)

    # -- the run ---------------------------------------------------------------------------------

    def run(self, *, until: int | None = None) -> dict[str, Any]:
        """Train up to ``spec.steps`` (or stop early after step ``until``, checkpointed, as a kill would)."""
        spec = self.spec
        last = spec.steps if until is None else min(int(until), spec.steps)
        torch.set_num_threads(spec.threads)
        self.write_spec()
        resumed = self.load_checkpoint()
        if resumed:
            self._truncate_log()
        self.prepare_data()
        if not resumed and spec.init_from is not None:
            # the starting weights set the bar: a second stage exports only what improves on them
            for variant, spike_only in self._variants():
                scores = self.validate(spike_only=spike_only)
                self.log({"step": 0, "kind": "val", "variant": variant, **scores})
                self.best[variant] = scores["val_psnr"]
        bar = self._bar(total=spec.steps, initial=self.step, desc=f"training {spec.method}", unit="step")
        t_last = time.perf_counter()
        while self.step < last:
            spike_only = self.spike_only_step(self.step)
            t0 = time.perf_counter()
            inputs, target = self.batch(self.step)
            t_data = time.perf_counter() - t0
            stats = self.train_step(inputs, target, spike_only=spike_only)
            self.step += 1
            now = time.perf_counter()
            row = {"step": self.step, "kind": "train", "lr": learning_rate(spec, self.step - 1),
                   "seconds": round(now - t_last, 4), "samples_per_s": round(spec.batch / max(t_data, 1e-9), 1),
                   "variant": "spike" if spike_only else ("fusion" if self.fusion else "single"), **stats}
            t_last = now
            self.log(row)
            bar.set_postfix(loss=f"{stats['loss']:.4f}", lr=f"{row['lr']:.1e}")
            bar.update(1)
            if self.step % spec.val_every == 0 or self.step == spec.steps:
                self._validate_and_export()
            if self.step % spec.checkpoint_every == 0 or self.step in (spec.steps, last):
                self.save_checkpoint()
        bar.close()
        return {"step": self.step, "best": dict(self.best), "resumed": resumed}

    def _variants(self) -> list[tuple[str, bool]]:
        """(variant name, spike_only) of every variant this run validates and exports."""
        return [("fusion", False), ("spike", True)] if self.fusion else [("single", False)]

    def _validate_and_export(self) -> None:
        for variant, spike_only in self._variants():
            scores = self.validate(spike_only=spike_only)
            self.log({"step": self.step, "kind": "val", "variant": variant, **scores})
            self.history.append({"step": self.step, "variant": variant, **scores})
            if scores["val_psnr"] > self.best.get(variant, -math.inf):
                self.best[variant] = scores["val_psnr"]
                self.export("spike" if variant == "spike" else "main", scores)
            if not self.quiet:
                from tqdm import tqdm

                tqdm.write(f"step {self.step} {variant}: val PSNR {scores['val_psnr']:.2f} dB, "
                           f"SSIM {scores['val_ssim']:.4f}, L1 {scores['val_l1']:.4f}")


def train(spec: TrainSpec, *, quiet: bool = False) -> dict[str, Any]:
    """Run (or resume) the training of ``spec``; returns the final step and the best validation PSNRs."""
    return Trainer(spec, quiet=quiet).run()
