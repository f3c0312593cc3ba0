"""A fusion file whose spike-only network is another spike-only file's (stage 42).

    python reports/neuspike-net/graft.py FUSION_DIR SPIKE_DIR OUT_DIR

Writes OUT_DIR/neuspike-net.safetensors: every tensor that the spike-only file holds (the texture path,
the residual blocks, the decoders, the head and the key refinement) taken from SPIKE_DIR's
``neuspike-net-spike.safetensors``, and the motion path (the tensors only the fusion file holds: motion
encoder, fusion modules, motion gate) from FUSION_DIR's ``neuspike-net.safetensors``; with FUSION_DIR's
card (without its validation scores) and a ``graft`` entry naming both sources' sha256. The spike-only
variant of the result (``forward_texture_only``) is then SPIKE_DIR's network exactly. Both files must
describe the same network (the spike-only card's parameters equal to the fusion card's apart from
``spike_only`` and ``motion_gate``), and every tensor of the spike-only file must be in the fusion file
with the same shape; anything else is refused.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from neuspike.errors import InputError
from neuspike.methods.weights import save_safetensors

from average import load_checked  # (this folder's average.py: the card-checked loading)

#: Parameters in which a fusion card and its spike-only card legitimately differ.
VARIANT_PARAMS = ("spike_only", "motion_gate")


def graft(fusion_dir: Path, spike_dir: Path, out_dir: Path) -> Path:
    fusion_path = Path(fusion_dir) / "neuspike-net.safetensors"
    spike_path = Path(spike_dir) / "neuspike-net-spike.safetensors"
    f_card, f_state, f_sha = load_checked(fusion_path)
    s_card, s_state, s_sha = load_checked(spike_path)
    f_params = {k: v for k, v in f_card["model"]["params"].items() if k not in VARIANT_PARAMS}
    s_params = {k: v for k, v in s_card["model"]["params"].items() if k not in VARIANT_PARAMS}
    if f_card["model"]["class"] != s_card["model"]["class"] or f_params != s_params:
        raise InputError(f"{fusion_path} and {spike_path} describe different networks: {f_card['model']} / "
                         f"{s_card['model']}")
    missing = sorted(k for k in s_state if k not in f_state or f_state[k].shape != s_state[k].shape)
    if missing:
        raise InputError(f"{spike_path}: tensors not in {fusion_path} with the same shape: {missing[:5]}")
    state = {k: (s_state[k] if k in s_state else v) for k, v in f_state.items()}
    card = dict(f_card)
    card.pop("validation", None)  # the fusion file's scores; the graft itself was not validated
    card["graft"] = {"motion_path": {"path": str(fusion_path), "sha256": f_sha},
                     "spike_network": {"path": str(spike_path), "sha256": s_sha},
                     "tensors_from_spike_file": len(s_state), "tensors_from_fusion_file": len(f_state) - len(s_state)}
    return save_safetensors(state, Path(out_dir) / "neuspike-net.safetensors", card=card, dtype=torch.bfloat16)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("fusion_dir", type=Path, help="folder with neuspike-net.safetensors (its motion path is kept)")
    p.add_argument("spike_dir", type=Path, help="folder with neuspike-net-spike.safetensors (its network is used)")
    p.add_argument("out_dir", type=Path)
    args = p.parse_args(argv)
    try:
        print(graft(args.fusion_dir, args.spike_dir, args.out_dir))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
