"""The scene interface: a continuous-time picture rendered as radiance frames."""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.errors import InputError
from neuspike.scenes.photos import cover, read_photo
from neuspike.scenes.radiance import luma_to_radiance
from neuspike.scenes.spec import SceneSpec


def check_times(times_s: Any) -> np.ndarray:
    """Validate scene times.

    Parameters
    ----------
    times_s : array-like, (T,)
        Scene times in seconds (any order, any sign, T >= 0).

    Returns
    -------
    ndarray, float64, (T,)

    Raises
    ------
    InputError
        Unless ``times_s`` is a 1-D array of finite real numbers.
    """
    try:
        t = np.asarray(times_s)
    except Exception:  # noqa: BLE001 - anything that is not array-like
        raise InputError(f"times_s: expected a 1-D array of seconds, got {type(times_s).__name__}") from None
    if t.ndim != 1:
        raise InputError(f"times_s: expected a 1-D array of seconds, got shape {t.shape}")
    if t.dtype == bool or not (np.issubdtype(t.dtype, np.floating) or np.issubdtype(t.dtype, np.integer)):
        raise InputError(f"times_s: expected real numbers, got dtype {t.dtype}")
    t = t.astype(np.float64)
    if not np.isfinite(t).all():
        bad = int(np.count_nonzero(~np.isfinite(t)))
        raise InputError(f"times_s: expected finite times, got {bad} NaN or infinite")
    return t


class Scene:
    """A deterministic, continuous-time scene (base of every kind).

    Attributes
    ----------
    spec : SceneSpec
        What the scene was made from.
    width, height : int
        Size of the rendered frames in pixels: the view, or its ``spec.crop``.
    view_width, view_height : int
        Size of the whole view (the crop's frame of reference).
    crop_xy : (int, int)
        Top-left of the rendered window in the view.
    """

    def __init__(self, spec: SceneSpec, width: int, height: int) -> None:
        self.spec = spec
        self.view_width = int(width)
        self.view_height = int(height)
        crop = spec.crop
        #: ``(x, y)`` of the rendered window in the view (``(0, 0)`` without a crop).
        self.crop_xy = (0, 0) if crop is None else (int(crop[0]), int(crop[1]))
        self.width = self.view_width if crop is None else int(crop[2])
        self.height = self.view_height if crop is None else int(crop[3])

    def render(self, times_s: Any) -> np.ndarray:
        """Radiance of the view at each instant.

        Parameters
        ----------
        times_s : array-like, float, (T,)
            Scene times in seconds.

        Returns
        -------
        ndarray, float32, (T, H, W)
            Linear radiance >= 0, finite; 1.0 is the reference white.

        Raises
        ------
        InputError
            For times that are not a finite 1-D array, or that the kind cannot render
            (outside a video's span, a zoom beyond its scale limit).
        """
        return self._render(check_times(times_s))

    def describe(self) -> dict[str, Any]:
        """JSON-serialisable description: kind, size, the spec's fields and derived facts."""
        crop = {} if self.spec.crop is None else {"view": [self.view_width, self.view_height],
                                                   "crop_xy": list(self.crop_xy)}
        return {"kind": self.spec.kind, "width": self.width, "height": self.height, **crop,
                "spec": self.spec.as_dict(), **self._details()}

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _details(self) -> dict[str, Any]:
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.width}x{self.height}, spec={self.spec!r})"


def photo_plane(spec: SceneSpec) -> tuple[np.ndarray, tuple[int, int], tuple[int, int]]:
    """The spec's photograph as a radiance plane that covers the view.

    Returns
    -------
    plane : ndarray, float32, (Hc, Wc)
        Radiance of the whole photograph, uniformly resized to just cover ``spec.size``.
    origin : (int, int)
        ``(x0, y0)``: the centred view's top-left pixel in ``plane``.
    source_hw : (int, int)
        The photograph's stored (height, width).
    """
    luma = read_photo(spec.image)
    plane, origin = cover(luma, spec.size)
    radiance = luma_to_radiance(plane, dynamic_range=spec.dynamic_range, peak=spec.peak)
    return radiance, origin, (int(luma.shape[0]), int(luma.shape[1]))


def focus_of(spec: SceneSpec, width: int, height: int) -> tuple[float, float]:
    """The spec's focus, or the view centre ``((W - 1) / 2, (H - 1) / 2)``."""
    if spec.focus is None:
        return (width - 1) / 2.0, (height - 1) / 2.0
    return spec.focus
