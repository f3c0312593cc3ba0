"""The ``pan`` scene: a photograph translating at constant velocity.

At ``t = 0`` the view is the photograph's centred crop (the ``still`` scene). At time ``t`` view
pixel ``(x, y)`` shows the photograph at ``(x + x0 - vx t, y + y0 - vy t)``: the content moves by
``+v t``. The photograph is extended without bound by mirroring about its border pixels, which is
continuous, so no seam appears inside the view at any time (past the photograph the view shows its
mirror image). Sampling is bilinear with exact sub-pixel positions (see
:mod:`neuspike.scenes.sampling`). A ``crop`` renders only its window: the same integer offset is
added after the position is split into pixel and fraction, so its pixels equal the full view's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.scenes.sampling import mirror_extend, sample_translated
from neuspike.scenes.scene import Scene, photo_plane
from neuspike.scenes.spec import SceneSpec


def pan_offsets(times_s: np.ndarray, origin: tuple[int, int],
                velocity_px_s: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Plane position of the view's top-left pixel at each instant.

    Parameters
    ----------
    times_s : ndarray, float64, (T,)
    origin : (int, int)
        ``(x0, y0)`` at ``t = 0``.
    velocity_px_s : (float, float)
        ``(vx, vy)`` in pixels per second.

    Returns
    -------
    x0s, y0s : ndarray, float64, (T,)
    """
    return origin[0] - velocity_px_s[0] * times_s, origin[1] - velocity_px_s[1] * times_s


class PanScene(Scene):
    """A photograph panning at ``spec.velocity_px_s``.

    Parameters
    ----------
    spec : SceneSpec
        ``kind="pan"``; uses ``image``, ``size``, ``velocity_px_s``, ``dynamic_range``, ``peak``.
    """

    def __init__(self, spec: SceneSpec) -> None:
        width, height = spec.size
        super().__init__(spec, width, height)
        plane, self._origin, self._source_hw = photo_plane(spec)
        self._plane_hw = plane.shape
        self._extended = mirror_extend(plane, width, height)

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        x0s, y0s = pan_offsets(times_s, self._origin, self.spec.velocity_px_s)
        return sample_translated(self._extended, self._plane_hw, x0s, y0s, self.width, self.height,
                                 offset_px=self.crop_xy)

    def _details(self) -> dict[str, Any]:
        return {"source_hw": list(self._source_hw), "plane_hw": list(self._plane_hw),
                "view_origin_xy": list(self._origin), "extension": "mirror (reflect-101)",
                "interpolation": "bilinear, exact sub-pixel positions"}
