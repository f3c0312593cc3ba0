"""The training loop, one for every learned method and data kind.

The method named by ``spec.method`` is a registered :class:`~neuspike.methods.learned.LearnedMethod`; the
trainer creates it untrained (:func:`neuspike.methods.create` with ``trained=False``: a fresh module from
``torch.manual_seed(spec.seed)``, no weights file; ``init_from`` goes through its ``load_file``) and reads samples through the method's own
:meth:`~neuspike.methods.learned.LearnedMethod.encode`. The data section of the spec picks the task:
:class:`~neuspike.train.windows.WindowTask` (single windows) or
:class:`~neuspike.train.sequences.SequenceTask` (sequences, for recurrent methods); the task draws
each step's batch from the seed and the step alone, so a resumed run computes what a straight one
does.

Device: ``spec.device`` is resolved by :func:`~neuspike.methods.learned.resolve_device` before
anything else (a device this machine lacks is an :class:`~neuspike.errors.InputError` naming it,
before any data are simulated or any file written). The module, each batch (moved there once it is
drawn), the loss and the validation run on it; the data, their shard and every random generator of
data and order stay on the CPU, so the same seed gives the same batches on any device. Checkpoints
hold CPU tensors and load onto the run's device, so a run checkpointed on a GPU resumes on a CPU and
the other way round; exported weights are written from CPU tensors and their card names the device.
Step times synchronise a CUDA device before the clock is read.

Precision: ``"auto"`` trains in float32 on a device without native bfloat16; where the device has it
(:func:`~neuspike.methods.learned.resolve_precision`), one training step (forward and backward of step
0's batch) is timed in both and bfloat16 is used only when it takes at most 0.9 times as long (on some
CPUs with the instructions it is slower). The choice and its measurement are written to
``precision.json`` in the run folder, and a resumed run keeps it.

Each step: the rate of :func:`~neuspike.train.spec.learning_rate`, the task's loss (under bfloat16
autocast where the precision says so), AdamW or Adam, gradients clipped to norm 1. Every
``val_every`` steps (and at the last) each variant is validated; a better score than the best so
far (or than the starting weights' with ``init_from``) exports the weights into the run folder
(and the package's or another folder with ``export`` / ``export_dir``). The checkpoint is written
every ``checkpoint_every`` steps, after each validation and when the run stops
(:mod:`neuspike.train.checkpoint`).
"""

from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path
from typing import Any, Iterator

import torch

from neuspike.errors import FormatError, InputError, one_line
from neuspike.methods.learned import resolve_device, resolve_precision, synchronize
from neuspike.train import checkpoint as ck
from neuspike.train.method import training_method
from neuspike.train.spec import TrainSpec, WindowData, learning_rate
from neuspike.utils.checks import check_positive_int
from neuspike.utils.parallel import set_threads

__all__ = ["STALE_SHARD_S", "Trainer", "train", "training_method"]

#: A shard's temporaries older than this are a killed run's (one item is written in well under a second).
STALE_SHARD_S = 600.0


#: bfloat16 is chosen only when its measured step takes at most this fraction of float32's.
BF16_FASTER = 0.9


class Trainer:
    """One training run of ``spec`` (module docstring)."""

    def __init__(self, spec: TrainSpec, *, quiet: bool = False) -> None:
        self.device = resolve_device(spec.device)  # first: a missing device is refused before any work
        self.spec = spec
        self.quiet = quiet
        self.out = Path(spec.out_dir)
        self.method = training_method(spec, self.device)
        self.module = self.method.module.float().train()
        if isinstance(spec.data, WindowData):
            from neuspike.train.windows import WindowTask

            self.task = WindowTask(spec, self.method)
        else:
            from neuspike.train.sequences import SequenceTask

            self.task = SequenceTask(spec, self.method)
        lacked: set[str] = set()  # parameters the starting weights did not have (parts added since)
        if spec.init_from is not None:  # a later stage: start from earlier weights (a checkpoint still wins)
            if not Path(spec.init_from).is_file():
                raise InputError(f"init_from {spec.init_from}: no such file. The spec continues earlier weights; "
                                 "put them there first (the model card names the file and the commit it comes "
                                 "from)")
            from neuspike.methods.weights import tensor_names

            self.method.load_file(spec.init_from, may_lack=getattr(self.module, "STARTS_AS_IDENTITY", ()))
            held = tensor_names(spec.init_from)
            lacked = {n for n, _ in self.module.named_parameters() if n not in held}
        named = []
        for n, p in self.module.named_parameters():
            if self.task.held(n):
                p.requires_grad_(False)  # held as init_from gave it (train_parts)
            else:
                named.append((n, p))
        scaled = {}  # part_lr_scales: the first matching prefix of each parameter
        for prefix in spec.part_lr_scales:
            hits = [n for n, _ in named if n.startswith(prefix) and n not in lacked]
            if not hits:
                raise InputError(f"part_lr_scales: {prefix!r} names no parameter of {spec.method} that learns "
                                 f"in this run")
            scaled.update({n: prefix for n in hits if n not in scaled})
        groups = [{"params": [p for n, p in named if n not in lacked and n not in scaled], "lr_scale": 1.0}]
        if lacked:  # new parts start from nothing: they learn at new_parts_lr_scale times the rate
            groups.append({"params": [p for n, p in named if n in lacked], "lr_scale": spec.new_parts_lr_scale})
        for prefix, scale in spec.part_lr_scales.items():
            if prefix not in scaled.values():  # (a prefix whose parameters an earlier one took has no group)
                continue
            part = [p for n, p in named if scaled.get(n) == prefix]
            if scale == 0:  # held as init_from gave it
                for p in part:
                    p.requires_grad_(False)
            else:
                groups.append({"params": part, "lr_scale": scale})
        if spec.optimizer == "adamw":
            self.optim = torch.optim.AdamW(groups, lr=spec.lr, weight_decay=spec.weight_decay)
        else:
            self.optim = torch.optim.Adam(groups, lr=spec.lr)
        self.precision = resolve_precision(spec.precision, self.device)
        self.task.precision = self.precision
        self.step = 0
        self.wall_s = 0.0
        self.best: dict[str, dict[str, float]] = {}
        self.last_scores: dict[str, dict[str, float]] = {}

    # -- pieces ------------------------------------------------------------------------------------

    @contextlib.contextmanager
    def autocast(self) -> Iterator[None]:
        if self.precision == "bfloat16":
            with torch.autocast(self.device.type, dtype=torch.bfloat16):
                yield
        else:
            yield

    def _bar(self, **kw):
        from tqdm import tqdm

        return tqdm(disable=self.quiet, dynamic_ncols=True, **kw)

    def train_step(self) -> dict[str, Any]:
        """One optimiser step (``self.step`` -> ``self.step + 1``); returns the log row."""
        t0 = time.perf_counter()
        lr = learning_rate(self.spec, self.step)
        for group in self.optim.param_groups:
            group["lr"] = lr * group.get("lr_scale", 1.0)
        self.module.train()
        loss, info = self.task.step_loss(self.step, self.autocast)
        self.optim.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.module.parameters(), 1.0)
        self.optim.step()
        self.step += 1
        synchronize(self.device)
        return {"step": self.step, "kind": "train", "loss": float(loss.detach()), "lr": lr,
                "seconds": round(time.perf_counter() - t0, 4), **info}

    def validate_and_export(self, *, force_bar: bool = False) -> None:
        """Validate every variant; log the scores; export the variants that beat their best."""
        for variant in self.task.variants():
            scores = self.task.validate(variant, self.autocast)
            self.last_scores[variant] = scores
            ck.append_log(self.out, {"step": self.step, "kind": "val", "variant": variant, **scores})
            if scores[self.task.score_key] > ck.best_score(self.best, variant, self.task.score_key):
                self.best[variant] = {"step": self.step, **scores}
                if not force_bar:
                    self.export(variant, scores, self._targets())
            if not self.quiet:
                from tqdm import tqdm

                tqdm.write(f"step {self.step} {variant}: " + ", ".join(f"{k} {v:.4f}" for k, v in scores.items()))

    def _targets(self) -> list[Path]:
        from neuspike.methods.weights import PACKAGE_WEIGHTS

        targets = [self.out]
        if self.spec.export:
            targets.append(Path(PACKAGE_WEIGHTS))
        if self.spec.export_dir is not None:
            targets.append(Path(self.spec.export_dir))
        return targets

    def _export_line(self) -> str:
        """Where improving weights will be written, said before the first step: ``export`` replaces
        the package's shipped weights, which a run meant as an experiment should not do."""
        from neuspike.methods.weights import PACKAGE_WEIGHTS

        folders = [str(p) + (" (the package's shipped weights: replaced)" if p == Path(PACKAGE_WEIGHTS) else "")
                   for p in self._targets()]
        return "best weights are exported to: " + "; ".join(folders)

    def export(self, variant: str, scores: dict[str, float], folders: list[Path]) -> None:
        name, state, params = self.task.exported(variant, self.spec.method)
        # not the design: the file, the precision and the read-out (the registry entry sets despeckling and smoothing)
        params = {k: v for k, v in params.items() if k not in ("weights_file", "precision", "despeckle", "wiener")}
        card = ck.make_card(self.spec, name=name, model_class=type(self.method).__name__, params=params,
                            step=self.step, precision=self.precision, device=self.device, wall_s=self.wall_s,
                            scores=scores, data=self.task.describe_data())
        ck.export_weights(state, folders, name, card)

    def save(self) -> None:
        ck.save_checkpoint(self.out, step=self.step, module=self.module, optimizer=self.optim, best=self.best,
                           wall_s=self.wall_s)

    def resume(self) -> bool:
        state = ck.load_checkpoint(self.out)
        if state is None:
            return False
        # CPU tensors: the module copies them onto its device, the optimiser moves its state to its parameters'
        self.module.load_state_dict(state["module"])
        self.optim.load_state_dict(state["optimizer"])
        self.step = int(state["step"])
        self.best = {k: dict(v) for k, v in state["best"].items()}
        self.wall_s = float(state["wall_s"])
        if state.get("torch_rng") is not None:
            torch.set_rng_state(state["torch_rng"])
        return True

    def choose_precision(self) -> dict[str, Any]:
        """Settle ``"auto"`` (module docstring); write or reuse ``precision.json``; return its record."""
        from neuspike.utils import atomic

        path = self.out / "precision.json"
        if path.exists():  # a resumed run keeps the arithmetic it started with
            try:
                record = json.loads(path.read_text())
            except (OSError, ValueError) as exc:
                raise FormatError(f"{path}: not readable JSON ({one_line(exc)}); delete it to measure the "
                                  f"precision again") from None
            if not isinstance(record, dict) or record.get("choice") not in ("float32", "bfloat16"):
                raise FormatError(f"{path}: expected an object whose 'choice' is float32 or bfloat16; delete it "
                                  f"to measure the precision again")
        elif self.spec.precision != "auto" or self.precision == "float32":
            record = {"choice": self.precision, "requested": self.spec.precision, "measured": False}
        else:
            times = {p: self._step_ms(p) for p in ("float32", "bfloat16")}
            choice = "bfloat16" if times["bfloat16"] <= BF16_FASTER * times["float32"] else "float32"
            record = {"choice": choice, "requested": "auto", "measured": True, "device": str(self.device),
                      "ms_per_step": {k: round(v, 1) for k, v in times.items()}, "rule": f"bfloat16 if <= {BF16_FASTER} x float32"}
        self.out.mkdir(parents=True, exist_ok=True)
        atomic.write_json(path, record)
        self.precision = self.task.precision = record["choice"]
        return record

    def _step_ms(self, precision: str, repeats: int = 3) -> float:
        """Median ms of a forward and backward pass of step 0's batch in ``precision`` (no update)."""
        self.precision = self.task.precision = precision
        self.module.train()
        times = []
        for i in range(repeats + 1):
            t0 = time.perf_counter()
            loss, _ = self.task.step_loss(0, self.autocast)
            loss.backward()
            self.optim.zero_grad(set_to_none=True)
            synchronize(self.device)
            if i:  # the first pass warms up
                times.append(1e3 * (time.perf_counter() - t0))
        return sorted(times)[len(times) // 2]

    # -- the run -----------------------------------------------------------------------------------

    def run(self, *, until: int | None = None, max_minutes: float | None = None,
            snapshot_every: int | None = None, simulate_only: bool = False) -> dict[str, Any]:
        """Train up to ``spec.steps``, or stop (checkpointed, as a kill would) after step ``until`` or
        after ``max_minutes``; ``snapshot_every`` also keeps every N-th step's weights under
        ``out_dir/snapshots/step-NNNNN/``; ``simulate_only`` builds the data and stops."""
        spec = self.spec
        if snapshot_every is not None:
            snapshot_every = check_positive_int("snapshot_every", snapshot_every)
        if max_minutes is not None and not max_minutes > 0:
            raise InputError(f"max_minutes: expected a positive number, got {max_minutes}")
        last = spec.steps if until is None else min(int(until), spec.steps)
        if spec.threads is not None:
            set_threads(spec.threads)
        ck.remove_temporaries(self.out)
        ck.check_spec(spec)
        for folder in self.task.shard_folders():  # shared with other runs: only writes long dead
            ck.remove_temporaries(folder, older_than_s=STALE_SHARD_S)
        self.task.prepare(self._bar)
        if simulate_only:
            return {"step": 0, "simulated": {"train": len(self.task.train_paths), "val": len(self.task.val_paths)}}
        resumed = self.resume()
        self.task.load_validation()  # before choose_precision: timing a step needs the loaded data
        self.choose_precision()
        ck.trim_log(self.out, self.step)
        if not self.quiet or spec.export:  # replacing the shipped weights is said even when quiet
            from tqdm import tqdm

            tqdm.write(self._export_line())
        if not resumed and spec.init_from is not None:
            # the starting weights set the bar: a later stage exports only what improves on them
            self.validate_and_export(force_bar=True)
        bar = self._bar(total=spec.steps, initial=self.step, desc=f"training {spec.method}", unit="step")
        started = time.perf_counter()
        wall0 = self.wall_s
        while self.step < last:
            if max_minutes is not None and time.perf_counter() - started > 60 * max_minutes:
                break
            row = self.train_step()
            self.wall_s = wall0 + time.perf_counter() - started
            row["wall_s"] = round(self.wall_s, 3)
            ck.append_log(self.out, row)
            bar.set_postfix(loss=f"{row['loss']:.4f}", lr=f"{row['lr']:.1e}")
            bar.update(1)
            validated = self.step % spec.val_every == 0 or self.step == spec.steps
            if validated:
                self.validate_and_export()
            if snapshot_every is not None and self.step % snapshot_every == 0:
                folder = self.out / "snapshots" / f"step-{self.step:05d}"
                for variant in self.task.variants():
                    self.export(variant, self.last_scores.get(variant, {}) if validated else {}, [folder])
            if validated or self.step % spec.checkpoint_every == 0 or self.step == last:
                self.save()
        self.save()
        bar.close()
        return {"step": self.step, "best": self.best, "resumed": resumed, "wall_s": round(self.wall_s, 1)}


def train(spec: TrainSpec, *, quiet: bool = False, **run: Any) -> dict[str, Any]:
    """Run (or resume) the training of ``spec`` (:meth:`Trainer.run`'s options); returns the final
    step, the best validation scores per variant and the wall time."""
    return Trainer(spec, quiet=quiet).run(**run)
