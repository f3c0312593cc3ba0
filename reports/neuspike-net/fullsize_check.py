"""Full-size validation on *training* photographs: raw and affine-aligned PSNR of NeuSpike-Net weights.

    python reports/neuspike-net/fullsize_check.py [WEIGHTS_DIR ...] [--references snm,tfi] [--grid sweeps]
        [--level counts|network] [--method neuspike-net|neuspike-net-spike]

The training validation windows are 128x128, but the sweeps reconstruct 400x250 frames. There the
instance-normalised features see other statistics, and the correction channel of the support
head can shift a whole image. This check simulates 400x250 pans and stills of four training
photographs (astronaut, brick, coffee, rocket) at L = 1/32, 1/8, 1/2, without noise and at the high
noise level, seed 0, and prints the mean PSNR, affine-aligned PSNR and SSIM of `neuspike-net` (or, with
``--method neuspike-net-spike``, of the spike-only variant) for each weights folder (default: the shipped weights), with the head and motion gate its card names. It decides between
candidate weights without touching the test photographs.

``--grid sweeps`` replaces that small grid by the full sweeps' own points on the same four training
photographs, each through all four scene kinds (pan, zoom, fan, still) at seed 0: L = 1/32 ... 1/2 at
S = 128 without noise, S = 16 ... 256 at L = 1/4, and the noise levels small, medium and high at L = 1/4,
S = 128 (192 windows). For each point it prints the raw and aligned PSNR and the margin to the best
reference, and at the end the worst margin and the largest aligned-minus-raw gap, the two quantities
that the issue's targets 1 and 2 ask of the test sweeps. Each point also shows the range of the
error of the image's mean level (image mean minus truth mean) over its windows.

``--grid fast`` scores the fast-motion test's points instead (``bench.fast_motion``: pans at 1x, 2x,
4x, 8x and 16x the sweeps' speed, S = 256, L = 1/4 and 1/16, no noise) on the same four training
photographs (40 windows): the selection check for fast motion, which the test itself runs on the
test photographs.

``--grid heldout`` scores the noise test's points (none, small, medium, high at L = 1/4, S = 128) on
pictures that no network here trains on, each through the four scene kinds (112 windows): the four
held-out dead-leaves pictures and the three flat synthetic pictures of e2vid's selection harness
(``reports/e2vid/candidates/leaves.py`` and ``flat.py``, written into ``--pictures``, default
``runs/heldout-pictures``). The sweeps' grid judges a candidate's noisy points on the training
photographs, which the network has seen; this grid judges them on unseen pictures (with
``--spike-beside``, the fusion's margin over its spike-only file there).

``--spike-beside`` also scores each folder's spike-only file and prints the fusion's margin over it at
every point: issue 20 asks the fusion to be above its spike-only variant, which the margins to the
references do not show.

``--level network`` scores the images as the network makes them; the default, ``counts``, as the
method returns them (the mean level counted from the spikes where the gain and dark rate are known).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

import numpy as np
import torch

from bench import grid as grids
from neuspike.conditions import Condition
from neuspike.methods import create
from neuspike.methods.weights import read_card
from neuspike.nets.method import CARD_DEFAULTS
from neuspike.metrics import ssim
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

PHOTOS = ("astronaut", "brick", "coffee", "rocket")
LIGHTS = (1 / 32, 1 / 8, 1 / 2)
NOISES = ("none", "high")
#: ``--grid sweeps``: the full sweeps' points, (axis, point label, light, motion S, noise).
SWEEP_POINTS = ([("light", f"L = 1/{round(1 / l)}", l, 128, "none") for l in (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2)]
                + [("motion", f"S = {m}", 1 / 4, m, "none") for m in (16, 32, 64, 256)]
                + [("noise", f"noise {n}", 1 / 4, 128, n) for n in ("small", "medium", "high")])


#: ``--grid heldout``: the noise test's points (L = 1/4, S = 128) on pictures outside both photograph splits.
HELDOUT_NOISES = ("none", "small", "medium", "high")
HELDOUT_PICTURES = ("leaves-1", "leaves-2", "leaves-3", "leaves-4", "horse", "shepp_logan_phantom", "logo")
_HARNESS = Path(__file__).resolve().parents[1] / "e2vid" / "candidates"


def heldout_pictures(out: Path) -> list[Path]:
    """The held-out pictures' files in ``out``, written by e2vid's harness scripts where missing."""
    paths = [out / f"{name}.png" for name in HELDOUT_PICTURES]
    if not all(path.is_file() for path in paths):
        for script, call in (("leaves.py", lambda m: m.main([str(out)])), ("flat.py", lambda m: m.main(out))):
            spec = importlib.util.spec_from_file_location(f"_harness_{script[:-3]}", _HARNESS / script)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            call(module)
    return paths


#: The parameters a candidate's card may set beyond the registry's defaults.
DESIGN_PARAMS = ("head", "motion_gate", "transformer", "support_cue", "key_estimates")


def trained_design(folder: str | None, method: str) -> dict[str, str]:
    """The design parameters (head, motion gate, input transformer, support cue, key estimates) that
    ``folder``'s weights of ``method`` were trained with (their card; empty for the shipped weights), so
    that any candidate loads."""
    card = read_card(f"{folder}/{method}.safetensors") if folder else None
    if card is None:
        return {}
    trained = card.get("model", {}).get("params", {})
    # a card written before a parameter existed means that parameter's old default
    return {k: trained.get(k, CARD_DEFAULTS[k]) for k in DESIGN_PARAMS}


def probe_start(doc: str, argv: list[str] | None):
    """The probes' common start (``size_probe.py``, ``padding_probe.py``): parse ``[FOLDER] [--threads N]``,
    set the torch threads and build ``neuspike-net`` in float32 from the folder's weights with their
    design (default: the shipped weights). Returns ``(args, method)``."""
    p = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    p.add_argument("folder", nargs="?", help="weights folder (default: the shipped weights)")
    p.add_argument("--spike-beside", action="store_true",
                   help="with the fusion (the default --method): also score each folder's spike-only file and print "
                        "the fusion's margin over it at every point (issue 20 asks the fusion to be the better one)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    return args, create("neuspike-net", weights_dir=args.folder, precision="float32",
                        **trained_design(args.folder, "neuspike-net"))


def _psnr(x: np.ndarray, truth: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / max(float(np.mean((x - truth) ** 2)), 1e-12)))


def _score(method, samples) -> tuple[list[float], list[float], list[float], list[float]]:
    """Raw PSNR, affine-aligned PSNR, the error of the mean level (image mean - truth mean) and raw
    SSIM (the sweeps' own, :func:`neuspike.metrics.ssim`)."""
    raw, aligned, level, structure = [], [], [], []
    for sample in samples:
        y, truth = method.reconstruct(sample), sample.ground_truth
        design = np.stack([y.ravel(), np.ones(y.size)], 1)
        (a, b), *_ = np.linalg.lstsq(design, truth.ravel(), rcond=None)
        raw.append(_psnr(y, truth))
        aligned.append(_psnr(np.clip(a * y + b, 0, 1), truth))
        level.append(float(y.mean(dtype=np.float64) - truth.mean(dtype=np.float64)))
        structure.append(ssim(y, truth, data_range=1.0))
    return raw, aligned, level, structure


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="*", help="weights folders (default: the shipped weights)")
    p.add_argument("--references", default="snm", help="methods scored beside them (default: snm)")
    p.add_argument("--grid", choices=("quick", "sweeps", "fast", "heldout"), default="quick",
                   help="quick: 48 windows, L = 1/32, 1/8, 1/2 without and with high noise (the default); "
                   "sweeps: the full sweeps' 12 points over four scene kinds (192 windows); "
                   "fast: the fast-motion test's pans at 1x-16x, L = 1/4 and 1/16, S = 256 (40 windows); "
                   "heldout: the noise test's four levels on seven pictures no network trains on (112 windows)")
    p.add_argument("--method", choices=("neuspike-net", "neuspike-net-spike"), default="neuspike-net",
                   help="which variant's weights file each folder is read for (default neuspike-net)")
    p.add_argument("--level", choices=("counts", "network"), default="counts",
                   help="how the image's mean level is set (the method's `level`; default counts)")
    p.add_argument("--spike-beside", action="store_true",
                   help="with the fusion (the default --method): also score each folder's spike-only file and print "
                        "the fusion's margin over it at every point (issue 20 asks the fusion to be the better one)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    p.add_argument("--pictures", type=Path, default=Path("runs/heldout-pictures"),
                   help="--grid heldout: folder for the held-out pictures (written there if missing; "
                        "default runs/heldout-pictures)")
    p.add_argument("--digits", type=int, default=2,
                   help="decimals of each folder's mean PSNR (default 2; a rule's 'not lower' may need more)")
    args = p.parse_args(argv)
    if args.spike_beside and args.method != "neuspike-net":
        p.error("--spike-beside compares the fusion with its spike-only file: give --method neuspike-net")
    folders = args.folders or [None]
    torch.set_num_threads(args.threads)
    samples, keys = [], []
    if args.grid == "quick":
        cells = [(f"{kind}:{photo}", (light, noise), light, 128, noise)
                 for photo in PHOTOS for kind in ("pan", "still") for light in LIGHTS for noise in NOISES]
    elif args.grid == "sweeps":
        cells = [(f"{kind}:{photo}", label, light, motion, noise) for (_, label, light, motion, noise) in SWEEP_POINTS
                 for photo in PHOTOS for kind in ("pan", "zoom", "fan", "still")]
    elif args.grid == "heldout":
        cells = [(f"{kind}:{path}", f"noise {noise}", 1 / 4, 128, noise) for noise in HELDOUT_NOISES
                 for path in heldout_pictures(args.pictures) for kind in ("pan", "zoom", "fan", "still")]
    else:  # the fast-motion test's own speeds, lights and S (bench.fast_motion), on training photographs
        from bench import fast_motion as fm

        scenes = fm.scene_names(",".join(str(f) for f in fm.SPEEDS), ",".join(PHOTOS))
        cells = [(name, f"L = 1/{round(1 / light)}, {fm.speed_of(name):g}x", light, int(fm.MOTION), "none")
                 for light in grids.parse_list(fm.LIGHTS, grids.parse_fraction) for name in scenes]
    for scene_name, key, light, motion, noise in cells:
        scene = grids.scene_entry(scene_name, (400, 250))
        cond = Condition(light=light, motion=motion, noise=noise, effects=grids.DEFAULT_EFFECTS)
        keys.append(key)
        samples.append(simulate_sample(scene.spec, cond, sensor=SensorConfig(), seed=0, modalities=("spikes", "events")))
    groups = {key: [i for i, k in enumerate(keys) if k == key] for key in dict.fromkeys(keys)}
    best_ref = {key: -np.inf for key in groups}
    best_ssim = {key: -np.inf for key in groups}
    for name in filter(None, args.references.split(",")):
        raw, _, _, structure = _score(create(name), samples)
        print(f"{name}: PSNR {np.mean(raw):.2f}, SSIM {np.mean(structure):.4f}")
        for key, pick in groups.items():
            best_ref[key] = max(best_ref[key], float(np.mean([raw[i] for i in pick])))
            best_ssim[key] = max(best_ssim[key], float(np.mean([structure[i] for i in pick])))
    for folder in folders:
        method = create(args.method, weights_dir=folder, precision="float32", level=args.level,
                        **trained_design(folder, args.method))
        raw, aligned, level, structure = _score(method, samples)
        print(f"{folder or 'shipped'}: {len(samples)} windows, PSNR {np.mean(raw):.{args.digits}f}, "
              f"affine-aligned {np.mean(aligned):.2f}, SSIM {np.mean(structure):.4f}")
        margins, gaps, ssim_margins = [], [], []
        for key, pick in groups.items():  # each point: raw / aligned, margin to the references
            r, a = float(np.mean([raw[i] for i in pick])), float(np.mean([aligned[i] for i in pick]))
            q = float(np.mean([structure[i] for i in pick]))
            lo, hi = min(level[i] for i in pick), max(level[i] for i in pick)
            gaps.append(a - r)
            margin = ""
            if np.isfinite(best_ref[key]):
                margins.append(r - best_ref[key])
                ssim_margins.append(q - best_ssim[key])
                margin = f", {r - best_ref[key]:+.2f} dB / {q - best_ssim[key]:+.4f} SSIM over the best reference"
            label = key if isinstance(key, str) else f"L = 1/{round(1 / key[0])}, noise {key[1]}"
            print(f"    {label}: {r:.2f} / {a:.2f}, SSIM {q:.4f}{margin}; mean level error {lo:+.4f} to {hi:+.4f}")
        if margins:
            print(f"    worst margin {min(margins):+.2f} dB, {min(ssim_margins):+.4f} SSIM; "
                  f"largest aligned - raw gap {max(gaps):.2f} dB")
        if args.spike_beside:
            spike = create("neuspike-net-spike", weights_dir=folder, precision="float32", level=args.level,
                           **trained_design(folder, "neuspike-net-spike"))
            s_raw, _, _, s_structure = _score(spike, samples)
            print(f"    fusion - its spike-only file ({np.mean(s_raw):.2f} / {np.mean(s_structure):.4f} "
                  "over the windows):")
            worst = []
            for key, pick in groups.items():
                d_psnr = float(np.mean([raw[i] - s_raw[i] for i in pick]))
                d_ssim = float(np.mean([structure[i] - s_structure[i] for i in pick]))
                worst.append((d_psnr, d_ssim))
                label = key if isinstance(key, str) else f"L = 1/{round(1 / key[0])}, noise {key[1]}"
                print(f"        {label}: {d_psnr:+.2f} dB / {d_ssim:+.4f} SSIM")
            print(f"        worst {min(w[0] for w in worst):+.2f} dB, {min(w[1] for w in worst):+.4f} SSIM; "
                  f"points where the fusion is not above it in both: "
                  f"{sum(1 for w in worst if w[0] < 0 or w[1] < 0)} of {len(worst)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
