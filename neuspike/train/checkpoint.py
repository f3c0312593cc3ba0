"""A run folder's files: the frozen spec, the checkpoint, the log, the exported weights and their card.

Everything is written atomically (:mod:`neuspike.utils.atomic`); a killed run leaves either the old file
or the new one, and the temporaries a kill leaves behind are removed when the run starts again
(:func:`remove_temporaries`).

* ``spec.json``: :meth:`TrainSpec.as_dict`; a folder holding another run's spec is refused, and so is a
  spec of the earlier trainers (:func:`neuspike.train.spec.spec_from_dict`).
* ``checkpoint.pt``: ``{"format": 2, "step", "module", "optimizer", "best", "wall_s", "torch_rng"}``,
  every tensor on the CPU whatever device trained, read with ``map_location="cpu"``, so a run
  resumes on any device. The earlier trainers' checkpoints are refused by name
  (:func:`checked_checkpoint`; commit 61a150f8 still resumes them).
* ``train_log.csv``: one row per step (``kind`` ``train``) and per validation (``kind`` ``val``),
  columns :data:`LOG_COLUMNS`. On resume the rows after the checkpoint's step are dropped
  (:func:`trim_log`), so the log never repeats a step; an earlier trainer's log is rewritten in these
  columns.
* weights: ``<name>.safetensors`` and its card ``<name>.json`` (:func:`export_weights`): float32 for
  networks under a million parameters, bfloat16 above (the card records which), written from CPU
  tensors; the card's ``training.device`` names the device the exported step ran on.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import subprocess
from pathlib import Path
from typing import Any, Iterable, Mapping

from neuspike.utils import atomic
from neuspike.errors import FormatError, InputError
from neuspike.train.spec import TrainSpec, load_spec

__all__ = [
    "CHECKPOINT", "CHECKPOINT_FORMAT", "LOG", "LOG_COLUMNS", "SPEC", "append_log", "check_spec", "read_checkpoint_file",
    "export_weights", "load_checkpoint", "make_card", "remove_temporaries", "save_checkpoint", "trim_log",
    "checked_checkpoint",
]

SPEC, CHECKPOINT, LOG = "spec.json", "checkpoint.pt", "train_log.csv"
CHECKPOINT_FORMAT = 2
LOG_COLUMNS = ("step", "kind", "variant", "loss", "l1", "ssim_loss", "temporal", "lr", "seconds", "samples_per_s",
               "wall_s", "val_l1", "val_psnr", "val_ssim", "val_ssim_last", "support_l1",
               "edge_ssim_loss", "spike_floor", "gate_target", "empty_spread", "distill")
#: Validation scores of the log (a row of the sequence trainer held them beside the step's loss).
_VAL_COLUMNS = ("val_l1", "val_psnr", "val_ssim", "val_ssim_last")


def remove_temporaries(folder: str | os.PathLike, *, older_than_s: float | None = None) -> list[Path]:
    """Remove the temporaries (``.<name>.*.tmp``) an atomic write killed midway left in ``folder``; return them.

    ``older_than_s``: only those not modified for that long (a folder other runs may be writing into
    at the same time, such as a shared shard, keeps the temporaries of writes in progress).
    """
    import time

    folder = Path(folder)
    if not folder.is_dir():
        return []
    now = time.time()
    stale = [p for p in folder.glob(".*.tmp")
             if p.is_file() and (older_than_s is None or now - p.stat().st_mtime > older_than_s)]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def check_spec(spec: TrainSpec) -> None:
    """Write ``spec.json`` into the run folder, or check that the one there is the same run.

    Raises
    ------
    InputError
        When the folder holds a run of another spec (fields that change no result, such as the run
        folder, threads and export targets, may differ).
    """
    out = Path(spec.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / SPEC
    if path.exists():
        have = load_spec(path, out_dir=spec.out_dir)
        if have.identity() != spec.identity():
            mine, theirs = spec.identity(), have.identity()
            diff = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
            raise InputError(f"{path}: this folder holds a run of another spec (differs in {', '.join(diff)}); "
                             f"resume with the same spec or use another --out")
    else:
        atomic.write_text(path, json.dumps(spec.as_dict(), indent=2, sort_keys=True) + "\n")


# --- checkpoints ----------------------------------------------------------------------------------


def checked_checkpoint(state: Mapping[str, Any]) -> dict[str, Any]:
    """A checkpoint of this trainer (``format`` 2) as a dict.

    Raises
    ------
    FormatError
        When ``state`` is not one: a checkpoint of the earlier single-window or sequence trainers (resume
        those at commit 61a150f8, which still reads them) or something else.
    """
    if state.get("format") == CHECKPOINT_FORMAT:
        return dict(state)
    if ("model" in state and "optim" in state) or ("module" in state and "optimizer" in state):
        raise FormatError("a checkpoint of an earlier trainer, which this one no longer resumes: resume it at commit "
                          "61a150f8, or start the run again (a new --out, or init_from its exported weights)")
    raise FormatError(f"not a training checkpoint (keys {sorted(state)})")


def _on_cpu(value: Any) -> Any:
    """``value`` with every tensor inside (dicts, lists, tuples) moved to the CPU (CPU tensors as they are)."""
    import torch

    if isinstance(value, torch.Tensor):
        return value.detach().cpu()
    if isinstance(value, dict):
        return {k: _on_cpu(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_on_cpu(v) for v in value)
    return value


def save_checkpoint(out_dir: str | os.PathLike, *, step: int, module, optimizer, best: Mapping[str, Any],
                    wall_s: float) -> Path:
    """Write ``checkpoint.pt`` atomically, every tensor on the CPU (with torch's global CPU RNG state)."""
    import torch

    inner = io.BytesIO()
    torch.save({"format": CHECKPOINT_FORMAT, "step": int(step), "module": _on_cpu(module.state_dict()),
                "optimizer": _on_cpu(optimizer.state_dict()), "best": dict(best), "wall_s": float(wall_s),
                "torch_rng": torch.get_rng_state()}, inner)
    data = inner.getvalue()
    # sealed with its sha256: a file damaged after it was written is refused on resume, not trained on
    buf = io.BytesIO()
    torch.save({"sealed": data, "sha256": hashlib.sha256(data).hexdigest()}, buf)
    return atomic.write_bytes(Path(out_dir) / CHECKPOINT, buf.getvalue())


def read_checkpoint_file(path: str | os.PathLike) -> Any:
    """The content of a ``checkpoint.pt`` as written, its seal checked (:func:`save_checkpoint`); an
    unsealed file of an earlier trainer is returned as read.

    Raises
    ------
    FormatError
        An unreadable file, or one whose content no longer matches the checksum written with it.
    """
    import torch

    path = Path(path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        if isinstance(state, dict) and "sealed" in state:  # written since checkpoints were sealed
            data = state.get("sealed")
            if not isinstance(data, bytes) or hashlib.sha256(data).hexdigest() != state.get("sha256"):
                raise FormatError(f"{path}: damaged (its content no longer matches the checksum written with "
                                  f"it); delete it to start the run again from its spec, or restore it")
            state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except FormatError:
        raise
    except Exception as exc:
        first = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
        raise FormatError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {first})") from None
    return state


def load_checkpoint(out_dir: str | os.PathLike) -> dict[str, Any] | None:
    """The run folder's checkpoint (:func:`checked_checkpoint`), or ``None``."""
    path = Path(out_dir) / CHECKPOINT
    if not path.exists():
        return None
    state = read_checkpoint_file(path)
    if not isinstance(state, dict):
        raise FormatError(f"{path}: not a training checkpoint")
    try:
        return checked_checkpoint(state)
    except FormatError as exc:
        raise FormatError(f"{path}: {exc}") from None


# --- the log --------------------------------------------------------------------------------------


def _rows_now(row: Mapping[str, str]) -> list[dict[str, str]]:
    """A log row of any trainer in :data:`LOG_COLUMNS` (a sequence row with scores becomes two rows)."""
    row = {k: v for k, v in row.items() if k is not None}
    if "kind" in row:
        return [{k: row.get(k, "") for k in LOG_COLUMNS}]
    train = {k: row.get(k, "") for k in LOG_COLUMNS if k not in _VAL_COLUMNS}
    train.update(kind="train", variant="main", seconds=row.get("seconds_per_step", ""))
    out = [train]
    if row.get("val_ssim", "") != "":
        val = {k: "" for k in LOG_COLUMNS}
        val.update({k: row.get(k, "") for k in _VAL_COLUMNS}, step=row["step"], kind="val", variant="main")
        out.append(val)
    return out


def trim_log(out_dir: str | os.PathLike, step: int) -> None:
    """Keep the log's rows up to ``step`` (those after it are redone on resume), in :data:`LOG_COLUMNS`."""
    path = Path(out_dir) / LOG
    if not path.exists():
        return
    with open(path, newline="") as f:
        rows = [r for old in csv.DictReader(f) for r in _rows_now(old)]
    kept = [r for r in rows if r.get("step", "") != "" and int(r["step"]) <= step]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=LOG_COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(kept)
    atomic.write_text(path, buf.getvalue())


def append_log(out_dir: str | os.PathLike, row: Mapping[str, Any]) -> None:
    """Append one row (header first in a new log; a log begun before a column was added is rewritten in
    the current columns by :func:`trim_log` when its run starts)."""
    path = Path(out_dir) / LOG
    new = not path.exists()
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=LOG_COLUMNS, lineterminator="\n")
        if new:
            w.writeheader()
        w.writerow({k: row.get(k, "") for k in LOG_COLUMNS})


# --- weights and card -----------------------------------------------------------------------------


def _commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                              cwd=Path(__file__).resolve().parent).stdout.strip() or None
    except Exception:
        return None


def make_card(spec: TrainSpec, *, name: str, model_class: str, params: Mapping[str, Any], step: int,
              precision: str, device: Any, wall_s: float, scores: Mapping[str, float],
              data: Mapping[str, Any]) -> dict[str, Any]:
    """The JSON card of exported weights: what was trained, how, on what, and how well it validated.

    ``device`` (a torch device or its name): where the exported step ran; a CUDA device's card also
    names the GPU (``device_name``).
    """
    import torch

    device = torch.device(device)
    where = {"device": str(device)}
    if device.type == "cuda":
        where["device_name"] = torch.cuda.get_device_name(device)
    return {"method": name, "model": {"class": model_class, "params": dict(params)},
            "training": {"spec": spec.as_dict(), "step": int(step), "precision": precision, **where,
                         "wall_s": round(float(wall_s), 1), "threads": torch.get_num_threads(), "commit": _commit(),
                         "command": f"python -m neuspike.train {spec.method} --spec SPEC (the spec above)"},
            "data": dict(data), "validation": {k: v for k, v in scores.items() if k != "step"}, "torch": torch.__version__}


def export_weights(state: Mapping[str, Any], folders: Iterable[str | os.PathLike], name: str,
                   card: Mapping[str, Any]) -> list[Path]:
    """Write ``<name>.safetensors`` and its card into every folder; float32 under a million parameters,
    bfloat16 above (tensors on any device: the file is written from CPU copies)."""
    import torch

    from neuspike.methods.weights import save_safetensors

    count = sum(v.numel() for v in state.values() if v.is_floating_point())
    dtype = None if count < 1_000_000 else torch.bfloat16
    return [save_safetensors(state, Path(folder) / f"{name}.safetensors", card=card, dtype=dtype)
            for folder in folders]


def best_score(best: Mapping[str, Any], variant: str, score_key: str) -> float:
    """The best ``score_key`` of ``variant`` so far (-inf before the first validation)."""
    return float(best.get(variant, {}).get(score_key, -math.inf))
