"""Held-out dead-leaves pictures for the harness: piecewise-smooth scenes like the test photographs'
large flat regions, which the training photographs' 16 harness cells lack.

    python reports/e2vid/candidates/leaves.py OUT_DIR

Writes ``leaves-1.png`` ... ``leaves-4.png`` (8-bit luma, 600x375, so a 400x250 view has room to
pan): the first frame of a dead-leaves scene (:mod:`neuspike.scenes.dead_leaves`) at seeds 900001
to 900004 (the first two since stage 13, the other two since stage 17). Training items draw their
dead-leaves seeds from the whole 31-bit range, so these pictures are, to a chance of about 2e-6,
never trained on. Their sweep cells are
``KIND:OUT_DIR/leaves-N.png``.
"""

import sys
from pathlib import Path

import cv2
import numpy as np

from neuspike.scenes import SceneSpec, make_scene

SEEDS = (900001, 900002, 900003, 900004)
SIZE = (600, 375)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(argv[0])
    out.mkdir(parents=True, exist_ok=True)
    for i, seed in enumerate(SEEDS, 1):
        scene = make_scene(SceneSpec("dead_leaves", size=SIZE, velocity_px_s=(0.0, 0.0), seed=seed))
        frame = np.clip(scene.render(np.array([0.0]))[0], 0.0, 1.0)
        cv2.imwrite(str(out / f"leaves-{i}.png"), np.round(frame * 255).astype(np.uint8))
        print(out / f"leaves-{i}.png", f"mean {frame.mean():.3f}, std {frame.std():.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
