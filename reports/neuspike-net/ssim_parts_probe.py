"""Where the networks lose SSIM to SNM on fast pans: luminance, contrast or structure.

    python reports/neuspike-net/ssim_parts_probe.py [--photos astronaut,coffee] [--speeds 8,16] [--light 0.25]

On pans of *training* photographs (400x250, S = 256, seed 0, no sensor noise; the test photographs are
for the fast-motion report only), reconstructs each cell with ``neuspike-net``, ``neuspike-net-spike``
and ``snm`` (float32, one thread) and splits the suite's SSIM (scikit-image's, Gaussian window sigma
1.5, :data:`neuspike.metrics.SSIM_SETTINGS`) into its three factors, each averaged over the image:
luminance ``(2 mu_x mu_y + C1) / (mu_x^2 + mu_y^2 + C1)``, contrast
``(2 s_x s_y + C2) / (s_x^2 + s_y^2 + C2)`` and structure ``(s_xy + C2 / 2) / (s_x s_y + C2 / 2)``
(their product, pixel by pixel, is the SSIM map; its mean without a 5-pixel border, printed as a
check, is the suite's SSIM up to the filter's edge handling). It also prints, on the moving edges (the top 10 % of
the truth's gradient, :func:`bench.fast_motion.edge_mask`), the ratio of the image's local standard
deviation to the truth's: below 1 the image is smoother than the scene there (blur), above 1 noisier.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.ndimage import gaussian_filter

from bench import grid as grids
from bench.fast_motion import edge_mask
from neuspike import metrics
from neuspike.conditions import Condition
from neuspike.methods import create
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

METHODS = ("neuspike-net", "neuspike-net-spike", "snm")


def ssim_parts(image: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """The SSIM map's three factors and the two local standard deviations (Gaussian window, sigma 1.5,
    truncated at 3.5 sigma as scikit-image does for its 11-pixel window)."""
    s = metrics.SSIM_SETTINGS
    c1, c2 = (s["K1"] * 1.0) ** 2, (s["K2"] * 1.0) ** 2

    def blur(x):
        return gaussian_filter(x, sigma=s["sigma"], truncate=3.5, mode="reflect")

    x, y = image.astype(np.float64), truth.astype(np.float64)
    mx, my = blur(x), blur(y)
    vx = np.maximum(blur(x * x) - mx * mx, 0.0)
    vy = np.maximum(blur(y * y) - my * my, 0.0)
    cxy = blur(x * y) - mx * my
    sx, sy = np.sqrt(vx), np.sqrt(vy)
    return {"luminance": (2 * mx * my + c1) / (mx * mx + my * my + c1),
            "contrast": (2 * sx * sy + c2) / (vx + vy + c2),
            "structure": (cxy + c2 / 2) / (sx * sy + c2 / 2),
            "sx": sx, "sy": sy}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--photos", default="astronaut,coffee", help="training photographs (comma-separated)")
    p.add_argument("--speeds", default="8,16", help="multiples of the sweeps' pan speed (comma-separated)")
    p.add_argument("--light", type=float, default=0.25, help="light scale L (default 0.25)")
    p.add_argument("--weights", default="../shared/weights", help="weights folder (the shipped ones are found anyway)")
    p.add_argument("--key-estimates", default="none", choices=("none", "isi-sequence"),
                   help="the candidate's key estimates (NeuSpike-Net's key_estimates)")
    args = p.parse_args(argv)
    from neuspike.scenes.photos import TEST_PHOTOS
    from neuspike.utils.parallel import set_threads

    photos = [x for x in args.photos.split(",") if x]
    if set(photos) & set(TEST_PHOTOS):
        p.error(f"--photos: {sorted(set(photos) & set(TEST_PHOTOS))} are test photographs; choose training ones")
    set_threads(1)
    learned = {"precision": "float32", "key_estimates": args.key_estimates}
    methods = {name: create(name, weights_dir=args.weights, **(learned if name != "snm" else {})) for name in METHODS}
    print("cell | method | SSIM (suite) | product of the factors | luminance | contrast | structure | edge std ratio")
    for photo in photos:
        for speed in (int(v) for v in args.speeds.split(",")):
            entry = grids.scene_entry(f"pan@{speed}x:{photo}" if speed != 1 else f"pan:{photo}", (400, 250))
            condition = Condition(light=args.light, motion=256, effects=grids.DEFAULT_EFFECTS)
            sample = simulate_sample(entry.spec, condition, sensor=SensorConfig(planes=256), seed=0,
                                     modalities=("spikes", "events"))
            truth = sample.ground_truth
            edges = edge_mask(truth)
            for name, method in methods.items():
                image = np.clip(method.reconstruct(sample), 0.0, 1.0)
                parts = ssim_parts(image, truth)
                ratio = float(np.mean(parts["sx"][edges] / np.maximum(parts["sy"][edges], 1e-6)))
                product = (parts["luminance"] * parts["contrast"] * parts["structure"])[5:-5, 5:-5].mean()
                print(f"{photo} {speed}x L={args.light:g} | {name} | {metrics.ssim(image, truth, data_range=1.0):.4f} | "
                      f"{product:.4f} | "
                      f"{parts['luminance'].mean():.4f} | {parts['contrast'].mean():.4f} | "
                      f"{parts['structure'].mean():.4f} | {ratio:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
