"""Exact sub-pixel sampling of a mirror-extended plane.

The plane is extended without bound by mirroring about its border pixels (``... 2 1 0 1 2 ...``,
OpenCV's ``BORDER_REFLECT_101``), which is continuous everywhere, so no seam can appear however
far a view travels. Sampling is bilinear, with sample positions kept in float64 and split into an
integer index (reduced modulo the mirror period, ``2 (n - 1)``) and a fraction, so sub-pixel
positions are exact to float32 rounding at any distance (OpenCV's warps quantise positions to
1/32 pixel). Integer positions return plane values exactly.
"""

from __future__ import annotations

import numpy as np

from neuspike.errors import InputError
from neuspike.utils.parallel import KERNEL_LOCK, resolve_backend

try:  # numba is a dependency, but scenes must still render where it cannot be imported
    from neuspike.scenes import sampling_kernels as _kernels
except ImportError:  # pragma: no cover - exercised only without numba
    _kernels = None

#: Accepted values of the samplers' ``backend``: the compiled kernels, the NumPy reference, or numba
#: where it can be imported (both give the same frames bit for bit).
BACKENDS: tuple[str, ...] = ("auto", "numba", "numpy")


def _compiled(backend: str) -> bool:
    return resolve_backend(backend, compiled=_kernels is not None) == "numba"

#: Largest sample coordinate (pixels) accepted: beyond it float64 loses sub-pixel precision.
MAX_COORDINATE_PX: float = 2.0**40


def mirror_period(n: int) -> int:
    """Period of the mirror extension of an axis of length ``n`` (1 for ``n == 1``)."""
    return max(1, 2 * (n - 1))


def mirror_index(index: np.ndarray, n: int) -> np.ndarray:
    """Fold integer positions into ``[0, n)`` by mirroring about the end pixels.

    Parameters
    ----------
    index : ndarray of int, any shape
    n : int
        Length of the axis, >= 1.

    Returns
    -------
    ndarray of int64, same shape, values in ``[0, n)``
    """
    index = np.asarray(index, dtype=np.int64)
    if n == 1:
        return np.zeros_like(index)
    period = mirror_period(n)
    m = np.mod(index, period)
    return np.where(m >= n, period - m, m)


def _split(coords: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Integer part (int64) and fraction (float32, in [0, 1)) of float64 positions."""
    if coords.size and (not np.isfinite(coords).all() or np.abs(coords).max() > MAX_COORDINATE_PX):
        raise InputError(
            f"{name}: sample positions must be finite and within +-{MAX_COORDINATE_PX:.3g} px; "
            "the requested times move the view too far"
        )
    base = np.floor(coords)
    return base.astype(np.int64), (coords - base).astype(np.float32)


def sample_separable(plane: np.ndarray, xs: np.ndarray, ys: np.ndarray, *, backend: str = "auto") -> np.ndarray:
    """Bilinear samples of the mirror-extended ``plane`` on per-instant separable grids.

    Output pixel ``(t, i, j)`` is the plane's value at ``(x = xs[t, j], y = ys[t, i])``.

    Parameters
    ----------
    plane : ndarray, float32, (Hs, Ws)
    xs : ndarray, float64, (T, W)
        Sample columns in plane pixels (pixel centres at integers).
    ys : ndarray, float64, (T, H)
        Sample rows in plane pixels.
    backend : {"auto", "numba", "numpy"}
        The compiled kernel (:mod:`neuspike.scenes.sampling_kernels`) or the NumPy reference; the
        same frames bit for bit.

    Returns
    -------
    ndarray, float32, (T, H, W), values within the plane's range

    Raises
    ------
    InputError
        For non-finite positions or positions beyond :data:`MAX_COORDINATE_PX`.
    """
    plane = np.ascontiguousarray(plane, dtype=np.float32)
    xs = np.asarray(xs, dtype=np.float64)
    ys = np.asarray(ys, dtype=np.float64)
    if xs.ndim != 2 or ys.ndim != 2 or xs.shape[0] != ys.shape[0]:
        raise InputError(f"xs (T, W) and ys (T, H) must share T, got shapes {xs.shape} and {ys.shape}")
    hs, ws = plane.shape
    bx, fx = _split(xs, "x")
    by, fy = _split(ys, "y")
    x0, x1 = mirror_index(bx, ws), mirror_index(bx + 1, ws)
    y0, y1 = mirror_index(by, hs), mirror_index(by + 1, hs)
    out = np.empty((xs.shape[0], ys.shape[1], xs.shape[1]), dtype=np.float32)
    if _compiled(backend):
        with KERNEL_LOCK:
            _kernels.sample_separable_frames(plane, x0, x1, fx, y0, y1, fy, out)
        return out
    for t in range(out.shape[0]):
        wy = fy[t][:, None]
        rows = plane[y0[t]] * (1 - wy) + plane[y1[t]] * wy  # (H, Ws)
        wx = fx[t]
        np.add(rows[:, x0[t]] * (1 - wx), rows[:, x1[t]] * wx, out=out[t])
    return out


def mirror_extend(plane: np.ndarray, width: int, height: int) -> np.ndarray:
    """The mirror extension of ``plane`` large enough for any translated ``width x height`` view.

    Parameters
    ----------
    plane : ndarray, float32, (Hs, Ws)
    width, height : int
        View size in pixels.

    Returns
    -------
    ndarray, float32, (Py + height + 1, Px + width + 1)
        ``E[i, j] = plane[mirror(i), mirror(j)]`` with ``Px, Py`` the mirror periods; a view whose
        top-left lies anywhere in one period is a slice of it.
    """
    hs, ws = plane.shape
    rows = mirror_index(np.arange(mirror_period(hs) + height + 1), hs)
    cols = mirror_index(np.arange(mirror_period(ws) + width + 1), ws)
    return np.ascontiguousarray(plane[rows][:, cols], dtype=np.float32)


def sample_translated(extended: np.ndarray, plane_hw: tuple[int, int], x0s: np.ndarray,
                      y0s: np.ndarray, width: int, height: int, *, offset_px: tuple[int, int] = (0, 0),
                      backend: str = "auto") -> np.ndarray:
    """Bilinear samples of translated views of a mirror-extended plane.

    Output pixel ``(t, i, j)`` is the plane's value at ``(x = x0s[t] + j, y = y0s[t] + i)``.

    Parameters
    ----------
    extended : ndarray, float32
        :func:`mirror_extend` of a plane of shape ``plane_hw`` for this ``width`` and ``height``.
    plane_hw : (int, int)
        (Hs, Ws) of the original plane.
    x0s, y0s : ndarray, float64, (T,)
        Plane position of each view's top-left pixel.
    width, height : int
        View size (of the crop, with ``offset_px``).
    offset_px : (int, int)
        ``(x, y)`` whole pixels added to every position after it is split into pixel and fraction:
        the window ``offset_px`` of a larger view, whose pixels equal that view's exactly. The
        extension must cover the larger view (:func:`mirror_extend` with its size).
    backend : {"auto", "numba", "numpy"}
        The compiled kernel (:mod:`neuspike.scenes.sampling_kernels`) or the NumPy reference; the
        same frames bit for bit.

    Returns
    -------
    ndarray, float32, (T, height, width)

    Raises
    ------
    InputError
        For non-finite offsets or offsets beyond :data:`MAX_COORDINATE_PX`.
    """
    hs, ws = plane_hw
    bx, fx = _split(np.asarray(x0s, dtype=np.float64), "x")
    by, fy = _split(np.asarray(y0s, dtype=np.float64), "y")
    ix = np.mod(bx, mirror_period(ws)) + int(offset_px[0])
    iy = np.mod(by, mirror_period(hs)) + int(offset_px[1])
    out = np.empty((bx.shape[0], height, width), dtype=np.float32)
    if _compiled(backend):
        with KERNEL_LOCK:
            _kernels.sample_translated_frames(np.ascontiguousarray(extended, dtype=np.float32), iy, ix, fy, fx, out)
        return out
    e = extended
    for t in range(out.shape[0]):
        a, b = int(iy[t]), int(ix[t])
        wx, wy = fx[t], fy[t]
        top = e[a:a + height, b:b + width] * (1 - wx) + e[a:a + height, b + 1:b + width + 1] * wx
        below = e[a + 1:a + height + 1]
        bottom = below[:, b:b + width] * (1 - wx) + below[:, b + 1:b + width + 1] * wx
        np.add(top * (1 - wy), bottom * wy, out=out[t])
    return out
