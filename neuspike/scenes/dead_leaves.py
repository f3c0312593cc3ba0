"""The ``dead_leaves`` scene: procedural occluding layers that move independently.

A dead-leaves image is a stack of opaque random shapes whose sizes follow a power law
(density of radius ``r`` proportional to ``r**-3``), which gives the scale invariance, the
sharp occlusion edges and the flat regions of natural images. Photographs alone (ten of them for
training) do not make a world; these scenes add endless variety and, above all, *occlusions*:

* a **background** layer fills the view and translates at ``spec.velocity_px_s``;
* ``FOREGROUND_LAYERS`` sparse **foreground** layers of a few larger shapes each translate with
  their own velocity (random direction, speed 0.25x to 1.5x the background's speed, or the
  reference speed 1000 px/s when the background is still), so shapes slide over and uncover each
  other. The composite is ``out = out * (1 - alpha) + alpha * value`` from back to front.

Every shape carries a mild linear shading and the layers a little smooth texture, so regions are
not perfectly flat. All randomness comes from ``spec.seed`` (:func:`neuspike.utils.rng.derive_rng`):
the same spec renders the same bytes. Layer planes are drawn at twice the resolution and
area-averaged (anti-aliased edges), mirror-extended and sampled bilinearly at exact sub-pixel
positions like the ``pan`` scene, so any motion stays seamless. Luma in [0, 1] becomes radiance
through ``dynamic_range`` and ``peak`` like every photograph kind.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from neuspike.utils.rng import derive_rng
from neuspike.scenes.radiance import luma_to_radiance
from neuspike.scenes.sampling import mirror_extend, sample_translated
from neuspike.scenes.scene import Scene
from neuspike.scenes.spec import SceneSpec

__all__ = ["FOREGROUND_LAYERS", "DeadLeavesScene", "dead_leaves_layers"]

#: Foreground layers over the background.
FOREGROUND_LAYERS = 3
#: Speed of the foreground layers when the background is still, pixels per second.
REFERENCE_SPEED_PX_S = 1000.0
_SUPERSAMPLE = 2


def _power_law_radii(rng: np.random.Generator, n: int, r_min: float, r_max: float) -> np.ndarray:
    """``n`` radii with density proportional to ``r**-3`` on [r_min, r_max] (inverse CDF)."""
    u = rng.random(n)
    a, b = r_min ** -2, r_max ** -2
    return (a - u * (a - b)) ** -0.5


def _paint_shapes(rng: np.random.Generator, value: np.ndarray, alpha: np.ndarray | None,
                  count: int, r_min: float, r_max: float) -> None:
    """Paint ``count`` shaded ellipses (back to front) into ``value`` (and ``alpha`` when given), in place."""
    h, w = value.shape
    for r in _power_law_radii(rng, count, r_min, r_max):
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        axes = (max(1, int(round(r))), max(1, int(round(r * rng.uniform(0.4, 1.0)))))
        angle = rng.uniform(0, 180)
        level = rng.uniform(0.0, 1.0)
        gx, gy = rng.normal(0.0, 0.25 / max(r, 1.0), size=2)
        # draw in the shape's bounding box only
        x0, x1 = max(int(cx - r) - 1, 0), min(int(cx + r) + 2, w)
        y0, y1 = max(int(cy - r) - 1, 0), min(int(cy + r) + 2, h)
        if x0 >= x1 or y0 >= y1:
            continue
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.ellipse(mask, (int(cx) - x0, int(cy) - y0), axes, angle, 0, 360, 1, thickness=-1)
        inside = mask.astype(bool)
        yy, xx = np.nonzero(inside)
        shade = level + gx * (xx + x0 - cx) + gy * (yy + y0 - cy)
        value[y0:y1, x0:x1][inside] = np.clip(shade, 0.0, 1.0)
        if alpha is not None:
            alpha[y0:y1, x0:x1][inside] = 1.0


def _smooth_texture(rng: np.random.Generator, h: int, w: int, amplitude: float) -> np.ndarray:
    noise = rng.normal(0.0, 1.0, size=(h, w)).astype(np.float32)
    noise = cv2.GaussianBlur(noise, (0, 0), 1.5)
    return amplitude * noise / max(float(noise.std()), 1e-6)


def dead_leaves_layers(spec: SceneSpec) -> list[tuple[np.ndarray, np.ndarray | None, tuple[float, float]]]:
    """The layers of a dead-leaves scene, back to front.

    Returns
    -------
    list of (value, alpha, velocity_px_s)
        ``value`` float32 (Hp, Wp) luma in [0, 1]; ``alpha`` float32 (Hp, Wp) in [0, 1] or ``None``
        for the opaque background; ``velocity_px_s`` ``(vx, vy)``. Planes are 1.5x the view size.
    """
    rng = derive_rng(spec.seed, "dead_leaves")
    width, height = spec.size
    hp, wp = int(np.ceil(1.5 * height)) * _SUPERSAMPLE, int(np.ceil(1.5 * width)) * _SUPERSAMPLE
    short = min(hp, wp)
    layers = []
    background = np.full((hp, wp), rng.uniform(0.2, 0.8), np.float32)
    if spec.leaf_min_radius is None:  # the classic picture (its draws unchanged)
        count, r_min = int(rng.integers(250, 600)), 1.5 * _SUPERSAMPLE
    else:  # broad leaves: tens of shapes from the given radius, wide uniform regions
        count, r_min = int(rng.integers(15, 40)), spec.leaf_min_radius * min(width, height) * _SUPERSAMPLE
    _paint_shapes(rng, background, None, count=count, r_min=r_min, r_max=0.3 * short)
    layers.append((background, None, tuple(float(v) for v in spec.velocity_px_s)))
    base_speed = float(np.hypot(*spec.velocity_px_s)) or REFERENCE_SPEED_PX_S
    for _ in range(FOREGROUND_LAYERS):
        value = np.zeros((hp, wp), np.float32)
        alpha = np.zeros((hp, wp), np.float32)
        _paint_shapes(rng, value, alpha, count=int(rng.integers(2, 7)), r_min=0.06 * short, r_max=0.25 * short)
        direction = rng.uniform(0, 2 * np.pi)
        speed = base_speed * rng.uniform(0.25, 1.5)
        layers.append((value, alpha, (float(speed * np.cos(direction)), float(speed * np.sin(direction)))))
    out = []
    for value, alpha, velocity in layers:
        value = np.clip(value + _smooth_texture(rng, hp, wp, 0.03), 0.0, 1.0)
        size = (wp // _SUPERSAMPLE, hp // _SUPERSAMPLE)
        value = cv2.resize(value, size, interpolation=cv2.INTER_AREA)
        if alpha is not None:
            alpha = cv2.resize(alpha, size, interpolation=cv2.INTER_AREA)
        out.append((value.astype(np.float32), None if alpha is None else alpha.astype(np.float32), velocity))
    return out


class DeadLeavesScene(Scene):
    """Independently moving dead-leaves layers (module docstring).

    Parameters
    ----------
    spec : SceneSpec
        ``kind="dead_leaves"``; uses ``size``, ``velocity_px_s`` (the background's), ``seed``,
        ``dynamic_range``, ``peak`` and ``leaf_min_radius``; ``image`` is ignored.
    """

    def __init__(self, spec: SceneSpec) -> None:
        width, height = spec.size
        super().__init__(spec, width, height)
        self._layers = []
        for value, alpha, velocity in dead_leaves_layers(spec):
            hw = value.shape
            origin = ((hw[1] - width) // 2, (hw[0] - height) // 2)
            ext_v = mirror_extend(value, width, height)
            ext_a = None if alpha is None else mirror_extend(alpha, width, height)
            self._layers.append((ext_v, ext_a, hw, origin, velocity))

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        out = None
        for ext_v, ext_a, hw, origin, (vx, vy) in self._layers:
            x0s, y0s = origin[0] - vx * times_s, origin[1] - vy * times_s
            value = sample_translated(ext_v, hw, x0s, y0s, self.width, self.height)
            if ext_a is None:
                out = value
                continue
            alpha = sample_translated(ext_a, hw, x0s, y0s, self.width, self.height)
            out += alpha * (value - out)
        return luma_to_radiance(np.clip(out, 0.0, 1.0), dynamic_range=self.spec.dynamic_range, peak=self.spec.peak).astype(np.float32)

    def _details(self) -> dict[str, Any]:
        return {"layers": len(self._layers), "velocities_px_s": [list(layer[4]) for layer in self._layers],
                "interpolation": "bilinear, exact sub-pixel positions"}
