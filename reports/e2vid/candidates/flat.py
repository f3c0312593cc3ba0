"""Flat synthetic pictures outside the photograph split, for scoring candidates on wide flat regions.

    python reports/e2vid/candidates/flat.py OUT_DIR

Writes ``horse.png``, ``shepp_logan_phantom.png`` and ``logo.png`` (8-bit luma, as stored): scikit-image's
synthetic pictures, which :mod:`neuspike.scenes.photos` leaves out of both the training and the test
photographs, so no network here trains on them and no test sweep scores them. Their sweep cells are
``KIND:OUT_DIR/NAME.png`` (README.md beside this file).
"""

import sys
from pathlib import Path

import cv2
import numpy as np
import skimage.data

from neuspike.scenes.photos import luma

NAMES = ("horse", "shepp_logan_phantom", "logo")


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for name in NAMES:
        image = getattr(skimage.data, name)()
        if image.dtype == bool:
            image = image.astype(np.uint8) * 255
        elif image.dtype.kind == "f":
            image = (np.clip(image, 0.0, 1.0) * 255).round().astype(np.uint8)
        if image.ndim == 3:
            image = (luma(image, channel_order="rgb") * 255).round().astype(np.uint8)
        cv2.imwrite(str(out / f"{name}.png"), image)
        print(out / f"{name}.png")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
