"""Fast motion: pans at multiples of the sweeps' speed, ``python -m bench.fast_motion``.

The sweeps pan at 1000 px/s (at a view 400 pixels wide), about 11 px over a 256-plane window at
S = 256. This test pans the test photographs at 1x, 2x, 4x, 8x and 16x that speed at S = 256 and
L = 1/4 and 1/16, and scores every requested method: TFP over every window length (8 to 64 planes
and the whole window), TFI, SNM and both NeuSpike-Net variants by default. A method that sees the
whole window must choose how much of it the motion allows.

Outputs in ``--out``, beside the sweep's (results.csv, config.json, metadata.json, parts/, cache/):

``fast_motion.md``   mean PSNR / SSIM per light and speed for each method, and for each learned
                     method its margin to the best TFP (any window), to TFI and to SNM
``fast_motion.csv``  the same means as a table (method, light, speed, psnr, ssim)
``support.csv``      the learned methods' effective temporal support at each light and speed: the
                     share of the output's sensitivity (|input x gradient|, summed over the image)
                     that falls on each of the 16 time bins of the spike representation (its rate
                     and interval channels of a bin together), on the first test photograph, seed 0,
                     and its width in planes (the participation ratio of the shares times the bin
                     length); over the whole image (``support_planes``, ``bin00`` ...), where flat
                     regions that motion does not blur dominate, and over the output's edge pixels
                     only (``edge_support_planes``, ``edge_bin00`` ...: the pixels whose ground-truth
                     gradient magnitude is in its top :data:`EDGE_FRACTION`, all of which move in a pan);
                     a network with key estimates (the interval sequence at the key instant) has their
                     share in ``key_share`` / ``edge_key_share``, counted half in each of bins 7 and 8

Options, resuming and exit status are those of :mod:`bench.sweep` (whose ``--lights``, ``--motions``,
``--scenes`` and ``--size`` override this test's defaults).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Sequence

from bench.harness import grid as grids
from bench.sweep import COMMON_EPILOG, add_common_arguments, run_command, spec_from_args
from neuspike.errors import InputError

#: Pan speeds, in multiples of the sweeps' (:data:`bench.harness.grid.PAN_SPEED_PX_S_AT_400`).
SPEEDS = (1, 2, 4, 8, 16)
LIGHTS = "1/4,1/16"
MOTION = "256"
METHODS = ("tfp-w8", "tfp-w16", "tfp-w32", "tfp-w64", "tfp", "tfi", "snm", "neuspike-net", "neuspike-net-spike")
LEARNED = ("neuspike-net", "neuspike-net-spike")
#: The rivals each learned method is compared with: every TFP window counts as one rival (its best).
RIVALS = {"tfp (best window)": ("tfp-w8", "tfp-w16", "tfp-w32", "tfp-w64", "tfp"), "tfi": ("tfi",), "snm": ("snm",)}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.fast_motion",
        description="Fast motion: pans of the test photographs at 1x-16x the sweeps' speed (1000 px/s at "
        "400 pixels wide) at S = 256, L = 1/4 and 1/16; TFP at every window, TFI, SNM and NeuSpike-Net, "
        "with each network's margins and its effective temporal support per speed.",
        epilog="examples:\n"
        "  python -m bench.fast_motion                          # quick: 160x100, camera and clock\n"
        "  python -m bench.fast_motion --full --workers 1       # 400x250, camera and clock, seeds 0,1\n"
        "  python -m bench.fast_motion --speeds 1,4,16 --photos camera,coins,moon\n\n" + COMMON_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--speeds", default=",".join(str(s) for s in SPEEDS),
                        help="pan speeds in multiples of the sweeps' (default: 1,2,4,8,16)")
    parser.add_argument("--photos", default=",".join(grids.FULL_PHOTOS),
                        help="test photographs to pan over (default: the sweeps' camera,clock)")
    add_common_arguments(parser)
    return parser


def scene_names(speeds: str, photos: str) -> tuple[str, ...]:
    """``pan@Fx:PHOTO`` for every speed factor and photograph."""
    factors = grids.parse_list(speeds, float)
    if any(not f > 0 for f in factors):
        raise InputError(f"--speeds: expected positive multiples of the default speed, got {speeds!r}")
    return tuple(f"pan@{f:g}x:{p}" for f in factors for p in grids.parse_list(photos))


def _spec(args: argparse.Namespace):
    if args.scenes is None:
        args.scenes = ",".join(scene_names(args.speeds, args.photos))
    if args.lights is None:
        args.lights = LIGHTS
    if args.motions is None:
        args.motions = MOTION
    if args.methods is None:
        args.methods = ",".join(METHODS)
    return spec_from_args(args, "fast-motion", "motion")


def speed_of(scene: str) -> float:
    """The speed factor of a scene name (``pan@8x:camera`` -> 8; a plain pan -> 1)."""
    kind = scene.partition(":")[0]
    return float(kind.partition("@")[2].removesuffix("x") or 1.0)


def summarise(out: Path) -> dict[str, Any]:
    """Write ``fast_motion.csv`` and ``fast_motion.md`` from ``out/results.csv``; return the table."""
    import pandas as pd

    from bench.harness.results import read_csv
    from neuspike.utils.atomic import write_text

    rows = read_csv(out / "results.csv")
    rows = rows[(rows["status"] == "ok") & rows["metric"].isin(["psnr", "ssim"])].copy()
    if rows.empty:
        raise InputError(f"{out}: no scored rows to summarise")
    rows["speed"] = rows["scene"].map(speed_of)
    means = (rows.groupby(["method", "light", "speed", "metric"])["value"].mean()
             .unstack("metric").reset_index().sort_values(["light", "speed", "method"], ascending=[False, True, True]))
    write_text(out / "fast_motion.csv", means.to_csv(index=False, float_format="%.4f"))
    lines = ["# Fast motion: pans at multiples of the sweeps' speed", "",
             f"S = {', '.join(str(m) for m in sorted(rows['motion'].unique()))}; scenes: "
             f"{', '.join(sorted(rows['scene'].unique()))}; mean over scenes and seeds.", ""]
    methods = [m for m in METHODS if m in set(means["method"])] + sorted(set(means["method"]) - set(METHODS))
    for metric, fmt in (("psnr", "{:.2f}"), ("ssim", "{:.3f}")):
        for light in sorted(means["light"].unique(), reverse=True):
            part = means[means["light"] == light].pivot(index="method", columns="speed", values=metric)
            speeds = list(part.columns)
            lines += [f"## {metric.upper()} at L = {_fraction(light)}", "",
                      "| method | " + " | ".join(f"{s:g}x" for s in speeds) + " |",
                      "|---|" + "---:|" * len(speeds)]
            for m in methods:
                if m in part.index:
                    lines.append(f"| `{m}` | " + " | ".join(fmt.format(part.loc[m, s]) for s in speeds) + " |")
            for learned in (m for m in LEARNED if m in part.index):
                for rival, names in RIVALS.items():
                    have = [n for n in names if n in part.index]
                    if have:
                        margin = part.loc[learned] - part.loc[have].max()
                        lines.append(f"| {learned} - {rival} | " + " | ".join(
                            f"**{margin[s]:+.3f}**" if margin[s] > 0 else f"{margin[s]:+.3f}" for s in speeds) + " |")
            lines.append("")
    support = out / "support.csv"
    if support.exists():
        sup = pd.read_csv(support)
        lines += ["## Effective temporal support (planes; first photograph, seed 0)", "",
                  "| method | L | " + " | ".join(f"{s:g}x" for s in sorted(sup["speed"].unique())) + " |",
                  "|---|---|" + "---:|" * sup["speed"].nunique()]
        for (m, light), g in sup.groupby(["method", "light"], sort=False):
            g = g.sort_values("speed")
            lines.append(f"| `{m}` | {_fraction(light)} | " + " | ".join(f"{w:.0f}" for w in g["support_planes"]) + " |")
        lines.append("")
        if "edge_support_planes" in sup:
            lines += [f"On the edge pixels only (the top {EDGE_FRACTION:.0%} of the ground truth's gradient "
                      "magnitude, all moving):", "",
                      "| method | L | " + " | ".join(f"{s:g}x" for s in sorted(sup["speed"].unique())) + " |",
                      "|---|---|" + "---:|" * sup["speed"].nunique()]
            for (m, light), g in sup.groupby(["method", "light"], sort=False):
                g = g.sort_values("speed")
                lines.append(f"| `{m}` | {_fraction(light)} | "
                             + " | ".join(f"{w:.0f}" for w in g["edge_support_planes"]) + " |")
            lines.append("")
    write_text(out / "fast_motion.md", "\n".join(lines))
    return {"means": means}


def _fraction(x: float) -> str:
    from fractions import Fraction

    f = Fraction(float(x)).limit_denominator(64)
    return str(f) if abs(float(f) - x) < 1e-9 else f"{x:g}"


#: The share of pixels, by ground-truth gradient magnitude, over which the edge support is measured.
EDGE_FRACTION = 0.1


def edge_mask(truth, fraction: float = EDGE_FRACTION):
    """Boolean (H, W): the pixels whose gradient magnitude in ``truth`` is in its top ``fraction``
    (at least one pixel)."""
    import numpy as np

    gy, gx = np.gradient(np.asarray(truth, dtype=np.float64))
    magnitude = np.hypot(gx, gy)
    count = max(1, int(round(fraction * magnitude.size)))
    threshold = np.partition(magnitude.ravel(), magnitude.size - count)[magnitude.size - count]
    return magnitude >= threshold


def _bin_shares(inputs, objective):
    """The 16 bins' shares of |input x gradient| of the scalar ``objective`` for the spike input
    ``inputs[0]`` (its rate and interval channels of a bin together), and the share of the key estimates
    (``key_estimates``; 0 without them), which is also split between the two bins that meet at the key
    instant (the intervals nearest to it; at low light the outer ones reach further); the graph is kept
    for another call."""
    import numpy as np
    import torch

    grad = torch.autograd.grad(objective, inputs[0], retain_graph=True)[0]
    share = (grad * inputs[0]).abs().sum(dim=(0, 2, 3)).detach().numpy().astype(np.float64)
    share = share / max(share.sum(), 1e-30)
    bins = share[:16] + (share[16:32] if share.size >= 32 else 0.0)
    key = float(share[32:].sum())  # the interval sequence at the key instant, on the boundary of bins 7 and 8
    bins[7:9] += key / 2
    return bins, key


def temporal_support(out: Path, spec, *, weights: str | None = None, threads: int = 1) -> Path | None:
    """Write ``support.csv``: each learned method's sensitivity to each time bin (module docstring)."""
    import numpy as np
    import pandas as pd
    import torch

    from neuspike.methods import create
    from neuspike.simulation.cell import simulate_sample
    from neuspike.utils.atomic import write_text
    from neuspike.utils.parallel import set_threads

    learned = [m for m in spec.methods if m in LEARNED]
    if not learned:
        return None
    set_threads(threads)
    cells = [c for c in spec.grid.cells() if c.seed == spec.grid.seeds[0]]
    first_photo = cells[0].scene.image
    cells = [c for c in cells if c.scene.image == first_photo]
    rows = []
    methods = {name: create(name, weights_dir=weights, precision="float32") for name in learned}
    for method in methods.values():
        method.module.float().eval()
    for cell in cells:
        sample = simulate_sample(cell.scene.spec, cell.condition, sensor=spec.sensor, seed=cell.seed,
                                 modalities=("spikes", "events"))
        edges = torch.from_numpy(edge_mask(sample.ground_truth))
        for name, method in methods.items():
            inputs = [x.clone().requires_grad_(True) for x in method.encode(sample)[0]]
            y = method.module(*inputs)[0, 0, : edges.shape[0], : edges.shape[1]]
            bins, key = _bin_shares(inputs, y.sum())
            edge_bins, edge_key = _bin_shares(inputs, y[edges].sum())
            planes_per_bin = spec.sensor.planes / 16
            rows.append({"method": name, "light": cell.condition.light, "speed": speed_of(cell.scene.name),
                         "scene": cell.scene.name,
                         "support_planes": float(planes_per_bin / np.sum(bins ** 2)),
                         "centre_share": float(bins[7] + bins[8]),
                         "edge_support_planes": float(planes_per_bin / np.sum(edge_bins ** 2)),
                         "key_share": key, "edge_key_share": edge_key,
                         **{f"bin{i:02d}": float(b) for i, b in enumerate(bins)},
                         **{f"edge_bin{i:02d}": float(b) for i, b in enumerate(edge_bins)}})
    path = out / "support.csv"
    write_text(path, pd.DataFrame(rows).to_csv(index=False, float_format="%.5f"))
    return path


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    default_out = "runs/fast-motion" + ("-full" if args.full else "")
    built: dict[str, Any] = {}

    def build(a: argparse.Namespace):
        built["spec"] = _spec(a)
        return built["spec"]

    code = run_command(build, args, default_out)
    out = Path(args.out or default_out)
    if code in (0, 1) and (out / "results.csv").exists() and "spec" in built:
        try:
            spec = built["spec"]
            temporal_support(out, spec, weights=spec.weights, threads=args.threads or 1)
            summarise(out)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(f"fast-motion summary: {out / 'fast_motion.md'}")
    return code


if __name__ == "__main__":
    sys.exit(main())
