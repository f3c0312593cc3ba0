"""The starting weights of stage 4: the stage-3 network with the ``support`` prediction head.

    git show 044d9e3:neuspike/trained/neuspike-net.safetensors > runs/nsn-stage3.safetensors
    python reports/neuspike-net/support_start.py runs/nsn-stage3.safetensors runs/nsn-support-start.safetensors

Every tensor of the stage-3 fusion network (tanh head) is kept except the prediction convolution,
which the ``support`` head replaces by one of 33 outputs initialised to zero: the network then starts
as the mean of the spike representation's 32 radiance estimates, with the stage-3 encoders, fusion
and decoders in place.
"""

from __future__ import annotations

import sys

from safetensors.torch import load_file, save_file

from neuspike.nets import NeuSpikeNet


def main(argv: list[str] | None = None) -> int:
    src, dst = (argv if argv is not None else sys.argv[1:])[:2]
    old = load_file(src)
    state = NeuSpikeNet(head="support").state_dict()
    for key, value in old.items():
        if key.startswith("predict."):
            continue
        if state[key].shape != value.shape:
            raise SystemExit(f"{src}: {key} has shape {tuple(value.shape)}, expected {tuple(state[key].shape)}")
        state[key] = value.float()
    save_file({k: v.contiguous() for k, v in state.items()}, dst)
    print(f"{dst}: {len(state)} tensors, prediction head of {state['predict.weight'].shape[0]} outputs (zero)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
