"""The ``fan`` scene: rotating blades over a photograph, analytic at any instant.

Geometry (view pixels, ``y`` down; ``m = min(width, height)``):

- hub centre: ``spec.focus`` (default the view centre);
- ``blades`` blades, each an angular sector of ``blade_width_deg`` from the hub out to the tip
  radius ``FAN_TIP_FRACTION * m``; blade ``k`` is centred at angle
  ``2 pi (rpm / 60 * t + k / blades)`` from the +x axis, increasing clockwise on screen; at
  ``t = 0`` blade 0 points along +x;
- a static hub disc of radius ``FAN_HUB_FRACTION * m`` with the blades' contrast.

The pattern repeats every ``60 / (rpm * blades)`` seconds. Each pixel's blade coverage ``c`` in
[0, 1] is the area fraction of a one-pixel box cut by the nearest straight edge,
``clip(0.5 + d, 0, 1)`` with ``d`` the signed distance in pixels from the pixel centre to the edge
(positive inside; the sector's edges, the tip circle and the hub circle each give one term; the
blade takes the minimum of its terms and the hub the union). Radiance is
``background * (1 + c * (blade_contrast - 1))``: inside a blade the background's radiance times
``blade_contrast``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from neuspike.scenes.scene import Scene, focus_of, photo_plane
from neuspike.scenes.spec import SceneSpec

#: Blade tip radius as a fraction of min(width, height).
FAN_TIP_FRACTION: float = 0.45
#: Hub radius as a fraction of min(width, height).
FAN_HUB_FRACTION: float = 0.08


def fan_phase(times_s: np.ndarray, *, rpm: float, blades: int) -> np.ndarray:
    """Rotation phase in units of the blade spacing, reduced to [0, 1).

    Parameters
    ----------
    times_s : ndarray, float64, (T,)
    rpm : float
    blades : int

    Returns
    -------
    ndarray, float64, (T,), in [0, 1)
        ``(rpm / 60 * t * blades) mod 1``; the pattern at phase p equals the one at t = 0
        rotated by ``p * 360 / blades`` degrees.
    """
    return np.mod(rpm / 60.0 * blades * times_s, 1.0)


class FanScene(Scene):
    """Blades turning at ``spec.rpm`` over the photograph's still view.

    Parameters
    ----------
    spec : SceneSpec
        ``kind="fan"``; uses ``image``, ``size``, ``focus``, ``rpm``, ``blades``,
        ``blade_width_deg``, ``blade_contrast``, ``dynamic_range``, ``peak``.
    """

    def __init__(self, spec: SceneSpec) -> None:
        width, height = spec.size
        super().__init__(spec, width, height)
        plane, (x0, y0), self._source_hw = photo_plane(spec)
        (cx, cy), w, h = self.crop_xy, self.width, self.height  # the rendered window of the view
        self._background = np.ascontiguousarray(plane[y0 + cy:y0 + cy + h, x0 + cx:x0 + cx + w])
        self._hub_xy = focus_of(spec, width, height)
        m = min(width, height)
        self.tip_radius_px = FAN_TIP_FRACTION * m
        self.hub_radius_px = FAN_HUB_FRACTION * m
        dx = np.arange(cx, cx + w, dtype=np.float64)[None, :] - self._hub_xy[0]
        dy = np.arange(cy, cy + h, dtype=np.float64)[:, None] - self._hub_xy[1]
        r = np.hypot(dx, dy)
        tip_cover = np.clip(0.5 + self.tip_radius_px - r, 0.0, 1.0)
        hub_cover = np.clip(0.5 + self.hub_radius_px - r, 0.0, 1.0)
        # Pixels whose coverage does not depend on the blades' angle: outside the tip circle
        # (0) or fully inside the hub (1). Only the others are evaluated per instant.
        self._static_cover = hub_cover.astype(np.float32)
        active = (tip_cover > 0) & (hub_cover < 1)
        self._active = np.flatnonzero(active)
        self._radius = r[active].astype(np.float32)
        # pixel angle in units of the blade spacing, in [0, blades)
        angle_units = np.mod(np.arctan2(dy, dx) / (2 * math.pi), 1.0) * spec.blades
        self._angle_units = np.broadcast_to(angle_units, r.shape)[active].astype(np.float32)
        self._tip_cover = tip_cover[active].astype(np.float32)
        self._hub_cover = hub_cover[active].astype(np.float32)

    @property
    def period_s(self) -> float:
        """Time after which the pattern repeats, ``60 / (rpm * blades)`` (inf when rpm is 0)."""
        rpm = abs(self.spec.rpm)
        return math.inf if rpm == 0 else 60.0 / (rpm * self.spec.blades)

    def coverage(self, times_s: np.ndarray) -> np.ndarray:
        """Blade-and-hub coverage of each pixel, float32 (T, H, W) in [0, 1]."""
        spec = self.spec
        phase = fan_phase(np.asarray(times_s, dtype=np.float64), rpm=spec.rpm, blades=spec.blades)
        radians_per_unit = np.float32(2 * math.pi / spec.blades)
        half_width = np.float32(math.radians(spec.blade_width_deg) / 2)
        half_pi = np.float32(math.pi / 2)
        out = np.empty((phase.shape[0], self.height * self.width), dtype=np.float32)
        out[:] = self._static_cover.reshape(1, -1)
        for t in range(phase.shape[0]):
            # signed angular offset from the nearest blade centre, in blade spacings, [-1/2, 1/2]
            off = self._angle_units - np.float32(phase[t])
            off -= np.floor(off + np.float32(0.5))
            inside = half_width - np.abs(off) * radians_per_unit  # radians inside the edge
            np.clip(inside, -half_pi, half_pi, out=inside)
            cover = np.sin(inside, out=inside)
            cover *= self._radius  # signed distance to the edge, pixels
            cover += np.float32(0.5)
            np.clip(cover, 0.0, 1.0, out=cover)
            np.minimum(cover, self._tip_cover, out=cover)
            np.maximum(cover, self._hub_cover, out=cover)
            out[t, self._active] = cover
        return out.reshape(phase.shape[0], self.height, self.width)

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        cover = self.coverage(times_s)
        cover *= np.float32(self.spec.blade_contrast - 1.0)
        cover += np.float32(1.0)
        cover *= self._background
        return cover

    def _details(self) -> dict[str, Any]:
        return {"source_hw": list(self._source_hw), "hub_xy": list(self._hub_xy),
                "tip_radius_px": self.tip_radius_px, "hub_radius_px": self.hub_radius_px,
                "period_s": None if math.isinf(self.period_s) else self.period_s,
                "contrast": "radiance ratio blade / background",
                "antialiasing": "analytic edge coverage clip(0.5 + signed distance)"}
