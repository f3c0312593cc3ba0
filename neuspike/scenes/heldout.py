"""Held-out pictures: sources unlike the training photographs, never trained or selected on.

The learned methods train on :data:`~neuspike.scenes.photos.TRAIN_PHOTOS` and procedural dead
leaves, and the sweeps score them on :data:`~neuspike.scenes.photos.TEST_PHOTOS`. These pictures are
a third set, for the held-out report: what a new user would point the camera at. Each is named like
a bundled photograph (``pan:portrait``) and the trainer refuses them as it refuses the test
photographs.

``portrait``   a real photograph of a face and shoulders (Grace Hopper, the sample image matplotlib
               ships in ``mpl-data/sample_data``).
``terrain``    real elevation data (matplotlib's Jacksboro fault digital elevation model) lit as a
               hillshade: the fractal, everywhere-textured statistics of a landscape from above.
``typeset``    a page of printed words in matplotlib's bundled DejaVu fonts, from 9 to 40 pixels
               high: thin strokes, sharp edges, high contrast.
``night``      a night street: a dark sky, unlit facades with a few lit windows, street lamps with
               their glow and a road that reflects them; almost all of the view is below a tenth of
               white, the lamps at white.
``foliage``    overlapping leaves (elongated, with midribs) in many grey levels, from large in front
               to small behind: dense occlusion at every scale. Procedural, as dead leaves are, but
               shaped and veined.

The procedural ones are drawn from fixed seeds: the same picture on every machine. matplotlib (a
dependency of the suite's reports) supplies the two real ones and the fonts; it is imported only when
one of these pictures is loaded. Each loader
returns luma in [0, 1] at its own size (at least 600x400, so the sweeps' 400x250 view is cropped
from it, never enlarged).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Callable, Mapping

import cv2
import numpy as np

__all__ = ["HELDOUT_LOADERS", "HELDOUT_PICTURES"]

_SIZE = (640, 420)  # (W, H) of the procedural pictures


def _sample_data(name: str) -> str:
    import matplotlib.cbook

    return str(matplotlib.cbook.get_sample_data(name, asfileobj=False))


def portrait() -> np.ndarray:
    """The photograph, RGB uint8 as stored."""
    bgr = cv2.imread(_sample_data("grace_hopper.jpg"), cv2.IMREAD_COLOR)
    return np.ascontiguousarray(bgr[..., ::-1])


def terrain() -> np.ndarray:
    """Hillshade of the elevation model, lit from the north-west at 45 degrees, enlarged to cover 640x420."""
    from matplotlib.colors import LightSource

    with np.load(_sample_data("jacksboro_fault_dem.npz")) as dem:
        elevation = dem["elevation"].astype(np.float64)
        dx, dy = float(dem["dx"]), float(dem["dy"])
    shade = LightSource(azdeg=315, altdeg=45).hillshade(elevation, vert_exag=0.05, dx=dx, dy=dy)
    h, w = shade.shape
    scale = max(_SIZE[0] / w, _SIZE[1] / h)
    size = (int(np.ceil(w * scale)), int(np.ceil(h * scale)))
    return np.clip(cv2.resize(shade, size, interpolation=cv2.INTER_CUBIC), 0.0, 1.0).astype(np.float32)


_WORDS = ("spike", "event", "camera", "integrate", "fire", "plane", "threshold", "photon", "pixel", "light",
          "motion", "noise", "window", "interval", "reconstruct", "sensor", "bright", "dark", "fast", "scene",
          "frame", "signal", "charge", "contrast")


def typeset() -> np.ndarray:
    """Lines of words in several sizes, dark on light paper, rendered with matplotlib's Agg."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # no pyplot: the process's backend is left alone
    from matplotlib.figure import Figure

    rng = np.random.default_rng(20261206)
    w, h = _SIZE
    fig = Figure(figsize=(w / 100, h / 100), dpi=100)
    FigureCanvasAgg(fig)
    fig.patch.set_facecolor((0.93, 0.93, 0.91))
    y = 0.97
    while y > 0.02:
        size = float(rng.choice([7, 9, 12, 16, 22, 30]))
        words = " ".join(rng.choice(_WORDS, 12))
        weight = "bold" if rng.random() < 0.25 else "normal"
        fig.text(0.02, y, words, fontsize=size, family="DejaVu Sans", weight=weight, va="top",
                 color=(0.08, 0.08, 0.1))
        y -= (size * 1.45) / h
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    return np.ascontiguousarray(rgba[..., :3])


def night() -> np.ndarray:
    """A night street of facades, lit windows, lamps with glow and their reflections on the road."""
    rng = np.random.default_rng(1957)
    w, h = _SIZE
    yy = np.linspace(0.0, 1.0, h)[:, None]
    img = np.repeat(0.015 + 0.03 * yy, w, axis=1)  # sky brightening to the horizon (city glow)
    horizon = int(0.62 * h)
    x = 0
    while x < w:  # facades: dark blocks of random height with a faint texture, a few lit windows
        bw = int(rng.integers(50, 130))
        top = int(rng.integers(int(0.12 * h), int(0.45 * h)))
        level = float(rng.uniform(0.02, 0.06))
        block = img[top:horizon, x:x + bw]
        block[...] = level + 0.004 * rng.standard_normal(block.shape)
        for wy in range(top + 10, horizon - 14, 22):
            for wx in range(x + 6, min(x + bw, w) - 10, 16):
                if rng.random() < 0.18:
                    img[wy:wy + 11, wx:wx + 8] = float(rng.uniform(0.35, 0.8))
        x += bw
    img[horizon:] = 0.025 + 0.02 * (yy[horizon:] - yy[horizon])  # road
    glow = np.zeros_like(img)
    for lx in np.linspace(40, w - 40, 5) + rng.uniform(-20, 20, 5):
        ly = int(0.35 * h)
        img[ly:horizon, int(lx) - 1:int(lx) + 2] = 0.05  # the pole
        spot = np.zeros_like(img)
        cv2.circle(spot, (int(lx), ly), 6, 1.0, -1, lineType=cv2.LINE_AA)
        glow += cv2.GaussianBlur(spot, (0, 0), 14) * 6.0 + spot
        refl = np.zeros_like(img)  # a streak on the wet road below the lamp
        cv2.ellipse(refl, (int(lx), int(0.82 * h)), (5, 28), 0, 0, 360, 1.0, -1, lineType=cv2.LINE_AA)
        glow += 0.35 * cv2.GaussianBlur(refl, (0, 0), 4)
    img = img + glow
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def foliage() -> np.ndarray:
    """Leaves drawn back to front: many small dim ones behind, fewer large bright ones in front."""
    rng = np.random.default_rng(3011)
    w, h = _SIZE
    scale = 2  # drawn at twice the size and area-averaged: anti-aliased edges
    canvas = np.full((h * scale, w * scale), 0.08, np.float32)
    count = 2600
    for i in range(count):
        depth = i / count  # 0 far .. 1 near
        length = scale * rng.uniform(10, 26) * (0.6 + 1.6 * depth ** 2)
        width = length * rng.uniform(0.28, 0.45)
        cx, cy = rng.uniform(0, w * scale), rng.uniform(0, h * scale)
        angle = rng.uniform(0, 180)
        level = float(np.clip(rng.normal(0.18 + 0.45 * depth, 0.08), 0.03, 0.95))
        cv2.ellipse(canvas, (int(cx), int(cy)), (int(length), int(width)), angle, 0, 360, level, -1)
        if length > 14 * scale:  # the midrib, a little darker
            t = np.deg2rad(angle)
            dx, dy = length * 0.9 * np.cos(t), length * 0.9 * np.sin(t)
            cv2.line(canvas, (int(cx - dx), int(cy - dy)), (int(cx + dx), int(cy + dy)), 0.8 * level,
                     max(1, scale), lineType=cv2.LINE_AA)
    small = cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA)
    return np.clip(small, 0.0, 1.0).astype(np.float32)


#: Name -> loader of each held-out picture, in a fixed order.
HELDOUT_LOADERS: Mapping[str, Callable[[], np.ndarray]] = MappingProxyType({
    "portrait": portrait, "terrain": terrain, "typeset": typeset, "night": night, "foliage": foliage,
})
#: The held-out pictures' names.
HELDOUT_PICTURES: tuple[str, ...] = tuple(HELDOUT_LOADERS)
