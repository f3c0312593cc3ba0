"""Starting weights for a new prediction head: an earlier network with its head replaced.

    git show 044d9e3:neuspike/trained/neuspike-net.safetensors > runs/nsn-stage3.safetensors
    python reports/neuspike-net/support_start.py runs/nsn-stage3.safetensors runs/nsn-support-start.safetensors
    python reports/neuspike-net/support_start.py neuspike/trained/neuspike-net.safetensors \\
        runs/nsn-count-start.safetensors --head support-count

Every tensor of the source fusion network is kept except the prediction convolution.

* From a ``tanh`` head (stage 3 to stage 4): the ``support`` head's 33 outputs start at zero, so the
  network starts as the mean of the spike representation's 32 radiance estimates.
* From a ``support`` head to ``support-count`` (stage 5 to stage 6): the 32 softmax outputs, which
  choose the temporal support, are kept; the correction output, which was in radiance and is now
  counted in spikes per group, starts at zero.
"""

from __future__ import annotations

import argparse
import sys

from safetensors.torch import load_file, save_file

from neuspike.nets import NeuSpikeNet
from neuspike.nets.network import HEADS


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src", help="safetensors of the source fusion network")
    p.add_argument("dst", help="safetensors to write")
    p.add_argument("--head", default="support", choices=[h for h in HEADS if h != "tanh"], help="the new head")
    args = p.parse_args(argv)
    old = load_file(args.src)
    state = NeuSpikeNet(head=args.head).state_dict()
    for key, value in old.items():
        if key.startswith("predict."):
            continue
        if state[key].shape != value.shape:
            raise SystemExit(f"{args.src}: {key} has shape {tuple(value.shape)}, expected {tuple(state[key].shape)}")
        state[key] = value.float()
    kept = old["predict.weight"].shape[0] == state["predict.weight"].shape[0]
    if kept:  # a support head: keep the softmax rows, zero the correction row
        for key in ("predict.weight", "predict.bias"):
            state[key] = old[key].float().clone()
            state[key][0] = 0
    save_file({k: v.contiguous() for k, v in state.items()}, args.dst)
    print(f"{args.dst}: {len(state)} tensors, {args.head} head of {state['predict.weight'].shape[0]} outputs "
          f"({'softmax rows kept, correction zero' if kept else 'zero'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
