"""The ``zoom`` scene: forward, driving-like motion as an expansion about a focus point.

The view scale is ``s(t) = exp(zoom_rate_hz * t)``: view pixel ``(x, y)`` shows the photograph at
``focus + ((x, y) - focus) / s(t)`` (plus the centred view's origin), so the focus stays fixed and
everything else streams outward. ``t = 0`` is the ``still`` scene; negative times (or a negative
rate) zoom out. Outside the photograph the mirror extension is shown; sampling is bilinear with
exact sub-pixel positions and no prefilter (zooming far out, ``s < 1/2``, aliases fine texture). ``|zoom_rate_hz * t|`` is limited to
:data:`neuspike.scenes.spec.MAX_ZOOM_EXPONENT`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.errors import InputError
from neuspike.scenes.sampling import sample_separable
from neuspike.scenes.scene import Scene, focus_of, photo_plane
from neuspike.scenes.spec import MAX_ZOOM_EXPONENT, SceneSpec


def zoom_coordinates(times_s: np.ndarray, *, rate_hz: float, focus: tuple[float, float],
                     origin: tuple[int, int], width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Plane columns and rows seen by the view at each instant.

    Parameters
    ----------
    times_s : ndarray, float64, (T,)
    rate_hz : float
        Zoom rate; scale ``exp(rate_hz * t)``.
    focus : (float, float)
        Fixed point in view pixels.
    origin : (int, int)
        The centred view's top-left pixel in the plane.
    width, height : int

    Returns
    -------
    xs : ndarray, float64, (T, W)
    ys : ndarray, float64, (T, H)

    Raises
    ------
    InputError
        When ``|rate_hz * t|`` exceeds :data:`MAX_ZOOM_EXPONENT` for some time.
    """
    exponent = rate_hz * times_s
    if exponent.size and np.abs(exponent).max() > MAX_ZOOM_EXPONENT:
        worst = float(times_s[np.argmax(np.abs(exponent))])
        raise InputError(
            f"times_s: the zoom scale exp({rate_hz} * t) must stay within exp(+-{MAX_ZOOM_EXPONENT}), "
            f"got t = {worst} s"
        )
    inv = np.exp(-exponent)[:, None]
    fx, fy = focus
    xs = origin[0] + fx + (np.arange(width, dtype=np.float64)[None, :] - fx) * inv
    ys = origin[1] + fy + (np.arange(height, dtype=np.float64)[None, :] - fy) * inv
    return xs, ys


class ZoomScene(Scene):
    """A photograph expanding about ``spec.focus`` at ``spec.zoom_rate_hz``.

    Parameters
    ----------
    spec : SceneSpec
        ``kind="zoom"``; uses ``image``, ``size``, ``zoom_rate_hz``, ``focus``,
        ``dynamic_range``, ``peak``.
    """

    def __init__(self, spec: SceneSpec) -> None:
        width, height = spec.size
        super().__init__(spec, width, height)
        self._plane, self._origin, self._source_hw = photo_plane(spec)
        self._focus = focus_of(spec, width, height)

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        xs, ys = zoom_coordinates(times_s, rate_hz=self.spec.zoom_rate_hz, focus=self._focus,
                                  origin=self._origin, width=self.view_width, height=self.view_height)
        (cx, cy), w, h = self.crop_xy, self.width, self.height
        return sample_separable(self._plane, xs[:, cx:cx + w], ys[:, cy:cy + h])

    def _details(self) -> dict[str, Any]:
        return {"source_hw": list(self._source_hw), "plane_hw": list(self._plane.shape),
                "view_origin_xy": list(self._origin), "focus_xy": list(self._focus),
                "extension": "mirror (reflect-101)",
                "interpolation": "bilinear, exact sub-pixel positions"}
