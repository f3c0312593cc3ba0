"""A weighted average of two NeuSpike-Net weight files of one architecture (stage 37).

    python reports/neuspike-net/average.py DIR_A DIR_B WEIGHT OUT_DIR [--name neuspike-net]

Writes OUT_DIR/NAME.safetensors = (1 - WEIGHT) x A + WEIGHT x B, tensor by tensor, computed in float32
and stored in bfloat16, with a card: B's card (its model parameters, which both files must share) without
B's validation scores, the two sources' sha256 and the weight. Both files must hold the same tensors with the same shapes and
cards naming the same model; anything else is refused. The spike-only file is not touched.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from neuspike.errors import InputError
from neuspike.methods.weights import check_card, file_sha256, load_safetensors, read_card, save_safetensors


def load_checked(path: Path) -> tuple[dict, dict[str, torch.Tensor], str]:
    """``(card, tensors, sha256)`` of a weights file that has a card whose recorded sha256 it matches."""
    if not path.is_file():
        raise InputError(f"{path}: no such weights file")
    card = read_card(path)
    if card is None:
        raise InputError(f"{path}: no JSON card beside it")
    digest = file_sha256(path)
    check_card(path, digest)
    return card, load_safetensors(path), digest


def average(dir_a: Path, dir_b: Path, weight: float, out_dir: Path, name: str = "neuspike-net") -> Path:
    if not 0.0 <= weight <= 1.0:
        raise InputError(f"weight: expected a number in [0, 1], got {weight}")
    paths = [Path(d) / f"{name}.safetensors" for d in (dir_a, dir_b)]
    cards, states, digests = zip(*(load_checked(p) for p in paths))
    if cards[0]["model"] != cards[1]["model"]:
        raise InputError(f"{paths[0]} and {paths[1]} name different models: {cards[0]['model']} / {cards[1]['model']}")
    a, b = states
    if set(a) != set(b) or any(a[k].shape != b[k].shape for k in a):
        raise InputError(f"{paths[0]} and {paths[1]} do not hold the same tensors")
    mixed = {k: ((1.0 - weight) * a[k].float() + weight * b[k].float()) if a[k].is_floating_point() else b[k]
             for k in a}
    card = dict(cards[1])
    card.pop("validation", None)  # B's scores; the average itself was not validated
    card["average"] = {"weight_of_b": weight, "a": {"path": str(paths[0]), "sha256": digests[0]},
                       "b": {"path": str(paths[1]), "sha256": digests[1]},
                       "formula": "(1 - weight_of_b) * a + weight_of_b * b, in float32, stored in bfloat16"}
    return save_safetensors(mixed, Path(out_dir) / f"{name}.safetensors", card=card, dtype=torch.bfloat16)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dir_a", type=Path)
    p.add_argument("dir_b", type=Path)
    p.add_argument("weight", type=float, help="share of B, in [0, 1]")
    p.add_argument("out_dir", type=Path)
    p.add_argument("--name", default="neuspike-net")
    args = p.parse_args(argv)
    try:
        print(average(args.dir_a, args.dir_b, args.weight, args.out_dir, args.name))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
