"""Soft procedural pictures for the one-window regime: smooth, low-contrast scenes that give so few events
within the methods' bounded history that a recurrent network answers from a single window cut short.

    python reports/e2vid/candidates/soft.py OUT_DIR

Writes ``soft-1.png`` and ``soft-2.png`` (8-bit luma, 512x320): a smooth random field (Gaussian-filtered
noise) and a few large ellipses a little brighter or darker than it, with softened rims, each drawn
from its own seeded generator. They are made from parameters alone (no photograph enters them), so no
network here trains on them and no test sweep scores them. Their sweep cells are ``KIND:OUT_DIR/NAME.png``.
"""

import sys
from pathlib import Path

import cv2
import numpy as np

SIZE = (320, 512)  # (height, width)


def soft_picture(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h, w = SIZE
    field = cv2.GaussianBlur(rng.normal(size=(h, w)), (0, 0), 40.0)
    field = 0.5 + 0.06 * field / (np.abs(field).max() + 1e-9)
    yy, xx = np.mgrid[0:h, 0:w]
    for _ in range(int(rng.integers(3, 6))):
        cy, cx = rng.uniform(0.15, 0.85) * h, rng.uniform(0.15, 0.85) * w
        ry, rx = rng.uniform(0.12, 0.3) * h, rng.uniform(0.08, 0.25) * w
        inside = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1.0
        field = field + rng.uniform(0.04, 0.12) * rng.choice([-1.0, 1.0]) * inside
    field = cv2.GaussianBlur(field, (0, 0), 2.0)
    return (np.clip(field, 0.0, 1.0) * 255).round().astype(np.uint8)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for seed in (1, 2):
        path = out / f"soft-{seed}.png"
        cv2.imwrite(str(path), soft_picture(seed))
        print(path)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
