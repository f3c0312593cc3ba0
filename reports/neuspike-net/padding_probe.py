"""How the zero padding of a 400x250 frame changes NeuSpike-Net's image, on training photographs.

    python reports/neuspike-net/padding_probe.py [WEIGHTS_FOLDER] [--threads N]

The grid check's cells at L = 1/4, S = 128 (four training photographs x pan, zoom, fan, still; seed
0), at the high noise level and without noise, rendered at 400x250. The network pads a frame to
multiples of 8 (6 zero rows here) and normalises its features over the padded maps; the training
crops are never padded. Each frame is run four ways and scored on the region all four cover (the
top-left 384x192): whole (padded), cut to 400x248 (no padding), and in 192x192 and 96x96 tiles (the
training crop). Prints the mean PSNR of the fusion network and of the spike-only network inside the
same weights (its texture path alone). Default: the shipped weights.
"""

from __future__ import annotations

import numpy as np
import torch

from bench import grid as grids
from fullsize_check import probe_start  # beside this script
from neuspike.conditions import Condition
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

PHOTOS = ("astronaut", "brick", "coffee", "rocket")
KINDS = ("pan", "zoom", "fan", "still")
REGION = (slice(0, 192), slice(0, 384))
WAYS = {"whole frame (6 zero rows)": None, "cut to 400x248": (slice(0, 248), slice(0, 400)),
        "192x192 tiles": 192, "96x96 tiles": 96}


def _psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(10 * torch.log10(1 / ((a.clamp(0, 1) - b) ** 2).mean()))


def _cut(inputs: list[torch.Tensor], where: tuple) -> list[torch.Tensor]:
    return [t[(..., *where)] for t in inputs]  # a (B, 1, 1, 1) quantum stays as it is


def main(argv: list[str] | None = None) -> int:
    args, method = probe_start(__doc__, argv)
    net = method.module.eval()
    both = (lambda x: net(*x), lambda x: net.forward_texture_only(x[0], *x[2:]))
    for noise in ("high", "none"):
        scores: dict[str, list[tuple[float, float]]] = {w: [] for w in WAYS}
        for photo in PHOTOS:
            for kind in KINDS:
                scene = grids.scene_entry(f"{kind}:{photo}", (400, 250))
                cond = Condition(light=0.25, motion=128, noise=noise, effects=grids.DEFAULT_EFFECTS)
                s = simulate_sample(scene.spec, cond, sensor=SensorConfig(), seed=0, modalities=("spikes", "events"))
                x = [t.float() for t in method.encode(s)[0]]
                truth = torch.from_numpy(s.ground_truth)[None, None].float()[(..., *REGION)]
                with torch.inference_mode():
                    for way, how in WAYS.items():
                        if not isinstance(how, int):  # the whole frame or one cut of it
                            outs = [f(x if how is None else _cut(x, how)) for f in both]
                        else:
                            outs = [torch.zeros(1, 1, 192, 384) for _ in both]
                            for r in range(0, 192, how):
                                for c in range(0, 384, how):
                                    tile = (slice(r, r + how), slice(c, c + how))
                                    for out, f in zip(outs, both):
                                        out[(..., *tile)] = f(_cut(x, tile))
                        scores[way].append(tuple(_psnr(o[(..., *REGION)], truth) for o in outs))
        for way, v in scores.items():
            a = np.array(v)
            print(f"noise {noise}, {way}: fusion {a[:, 0].mean():.2f}, spike-only path {a[:, 1].mean():.2f}, "
                  f"fusion - spike {np.mean(a[:, 0] - a[:, 1]):+.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
