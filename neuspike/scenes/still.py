"""The ``still`` scene: a photograph, constant in time."""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.scenes.scene import Scene, photo_plane
from neuspike.scenes.spec import SceneSpec


class StillScene(Scene):
    """The photograph's centred view, the same at every instant.

    Parameters
    ----------
    spec : SceneSpec
        ``kind="still"``; uses ``image``, ``size``, ``dynamic_range``, ``peak``.
    """

    def __init__(self, spec: SceneSpec) -> None:
        width, height = spec.size
        super().__init__(spec, width, height)
        plane, (x0, y0), self._source_hw = photo_plane(spec)
        x0, y0 = x0 + self.crop_xy[0], y0 + self.crop_xy[1]
        self._frame = np.ascontiguousarray(plane[y0:y0 + self.height, x0:x0 + self.width])

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        return np.repeat(self._frame[None], times_s.shape[0], axis=0)

    def _details(self) -> dict[str, Any]:
        return {"source_hw": list(self._source_hw),
                "radiance_range": [float(self._frame.min()), float(self._frame.max())]}
