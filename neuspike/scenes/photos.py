"""Photographs: scikit-image's bundled images or any image file, as luma in [0, 1].

Luma is the Rec. 601 weighted sum ``0.299 R + 0.587 G + 0.114 B`` of the stored (gamma-encoded)
values divided by the type's maximum; there is no gamma linearisation, like the luma frames the
NeuSpike-Net simulator feeds its sensors. An alpha channel is ignored.

Bundled photographs and their split
-----------------------------------
:data:`BUNDLED_PHOTOS` lists the photographs (natural scenes, objects, textures, micrographs,
astronomy, scanned text) that ship inside scikit-image and load without a download. Synthetic
pictures (``checkerboard``, ``colorwheel``, ``horse``, ``logo``, ``shepp_logan_phantom``) and the
duplicate ``chelsea`` (= ``cat``) are left out. The split is fixed: learned methods train only on
:data:`TRAIN_PHOTOS`; :data:`TEST_PHOTOS` (which holds ``camera``, the standard benchmark input) is
for evaluation only. Each half mixes scenes, textures and micrographs. :data:`HELDOUT_PICTURES`
(:mod:`neuspike.scenes.heldout`: a portrait, terrain, type, a night street, foliage) are a third
set, named the same way, for the held-out report; like the test photographs they are never trained on.

Cover and crop
--------------
A photograph is resized (uniform scale, ``cv2.INTER_AREA`` when shrinking, bilinear when
enlarging, so values never leave [0, 1]) to the smallest size that covers the view, then centre
cropped. A photograph that already has the view's size is used as stored.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping

import cv2
import numpy as np

from neuspike.errors import InputError, SourceError
from neuspike.scenes.heldout import HELDOUT_LOADERS


def _skimage(name: str, pick: int | None = None) -> Callable[[], np.ndarray]:
    def load() -> np.ndarray:
        import skimage.data

        image = getattr(skimage.data, name)()
        return image[pick] if pick is not None else image

    return load


#: Name -> loader of every bundled photograph (RGB or grey, integer), in a fixed order.
_LOADERS: Mapping[str, Callable[[], np.ndarray]] = MappingProxyType({
    "astronaut": _skimage("astronaut"),
    "brick": _skimage("brick"),
    "camera": _skimage("camera"),
    "cat": _skimage("cat"),
    "cell": _skimage("cell"),
    "clock": _skimage("clock"),
    "coffee": _skimage("coffee"),
    "coins": _skimage("coins"),
    "grass": _skimage("grass"),
    "gravel": _skimage("gravel"),
    "hubble_deep_field": _skimage("hubble_deep_field"),
    "immunohistochemistry": _skimage("immunohistochemistry"),
    "microaneurysms": _skimage("microaneurysms"),
    "moon": _skimage("moon"),
    "page": _skimage("page"),
    "retina": _skimage("retina"),
    "rocket": _skimage("rocket"),
    "stereo_motorcycle": _skimage("stereo_motorcycle", pick=0),  # the left view
    "text": _skimage("text"),
})

#: Every bundled photograph's name.
BUNDLED_PHOTOS: tuple[str, ...] = tuple(_LOADERS)
#: The held-out pictures (:mod:`neuspike.scenes.heldout`), named like the bundled photographs: neither
#: trained nor selected on, and not in the sweeps' test set.
HELDOUT_PICTURES: tuple[str, ...] = tuple(HELDOUT_LOADERS)
_PICTURES: Mapping[str, Callable[[], np.ndarray]] = MappingProxyType({**_LOADERS, **HELDOUT_LOADERS})

#: The photographs learned methods may train on.
TRAIN_PHOTOS: tuple[str, ...] = (
    "astronaut", "brick", "cat", "cell", "coffee", "grass", "hubble_deep_field",
    "immunohistochemistry", "page", "rocket",
)

#: The photographs kept for evaluation (never trained on).
TEST_PHOTOS: tuple[str, ...] = (
    "camera", "clock", "coins", "gravel", "microaneurysms", "moon", "retina",
    "stereo_motorcycle", "text",
)

_LUMA_WEIGHTS_RGB = np.array([0.299, 0.587, 0.114])

#: File endings read as images when a folder is a frame sequence.
IMAGE_SUFFIXES: frozenset[str] = frozenset(
    {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pbm", ".webp", ".exr"}
)


def luma(image: np.ndarray, *, channel_order: str, source: str = "image") -> np.ndarray:
    """Convert a stored image to luma in [0, 1].

    Parameters
    ----------
    image : ndarray, (H, W), (H, W, 1), (H, W, 3) or (H, W, 4)
        Integer (unsigned or bool) values are divided by the type's maximum; float values must
        already lie in [0, 1]. A fourth channel (alpha) is ignored.
    channel_order : {"rgb", "bgr"}
        Order of the colour channels (OpenCV decodes to BGR).
    source : str
        Named in error messages.

    Returns
    -------
    ndarray, float32, (H, W), values in [0, 1]

    Raises
    ------
    InputError
        For a shape or dtype that is not an image, NaN or infinite values, or float values
        outside [0, 1].
    """
    if channel_order not in ("rgb", "bgr"):
        raise InputError(f"channel_order: expected 'rgb' or 'bgr', got {channel_order!r}")
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))):
        raise InputError(f"{source}: expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {a.shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise InputError(f"{source}: expected a non-empty image, got shape {a.shape}")
    if a.dtype == bool:
        v = a.astype(np.float64)
    elif np.issubdtype(a.dtype, np.unsignedinteger):
        v = a.astype(np.float64) / float(np.iinfo(a.dtype).max)
    elif np.issubdtype(a.dtype, np.floating):
        v = a.astype(np.float64)
        if not np.isfinite(v).all():
            bad = int(np.count_nonzero(~np.isfinite(v)))
            raise InputError(f"{source}: expected finite values, got {bad} NaN or infinite entries")
        lo, hi = float(v.min()), float(v.max())
        if lo < 0 or hi > 1:
            raise InputError(f"{source}: expected float luma in [0, 1], got values in [{lo}, {hi}]")
    else:
        raise InputError(f"{source}: expected unsigned-integer, bool or float pixels, got dtype {a.dtype}")
    if v.ndim == 3:
        weights = _LUMA_WEIGHTS_RGB if channel_order == "rgb" else _LUMA_WEIGHTS_RGB[::-1]
        v = v[:, :, :3] @ weights
    return np.clip(v, 0.0, 1.0).astype(np.float32)  # only removes rounding of the weighted sum


def read_image_file(path: str | os.PathLike) -> np.ndarray:
    """Read one image file (any format OpenCV decodes, or a ``.npy`` array) as luma.

    Returns
    -------
    ndarray, float32, (H, W), values in [0, 1]

    Raises
    ------
    SourceError
        When the file is missing or cannot be decoded (the message names the path).
    InputError
        When the decoded content is not a valid image (NaN, float values outside [0, 1]).
    """
    p = Path(path)
    if not p.is_file():
        raise SourceError(f"cannot read image {str(p)!r}: no such file")
    if p.suffix.lower() == ".npy":
        try:
            array = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise SourceError(f"cannot read image {str(p)!r}: {exc}") from None
        return luma(array, channel_order="rgb", source=str(p))
    try:
        data = np.fromfile(p, dtype=np.uint8)
    except OSError as exc:
        raise SourceError(f"cannot read image {str(p)!r}: {exc}") from None
    decoded = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if decoded is None:
        raise SourceError(f"cannot read image {str(p)!r}: not an image format OpenCV can decode")
    return luma(decoded, channel_order="bgr", source=str(p))


@functools.lru_cache(maxsize=len(_PICTURES))
def _bundled_luma(name: str) -> np.ndarray:
    """A bundled photograph's (or held-out picture's) luma, decoded once per process (every simulated
    window reads one)."""
    image = luma(_PICTURES[name](), channel_order="rgb", source=name)
    image.flags.writeable = False
    return image


def read_photo(name_or_path: str | os.PathLike) -> np.ndarray:
    """A bundled photograph (by name) or an image file (by path), as luma at its stored size.

    Returns
    -------
    ndarray, float32, (H, W), values in [0, 1]

    Raises
    ------
    SourceError
        For a path that is missing or cannot be decoded.
    InputError
        For decoded content that is not a valid image.
    """
    if isinstance(name_or_path, str) and name_or_path in _PICTURES:
        return _bundled_luma(name_or_path).copy()
    try:
        return read_image_file(name_or_path)
    except SourceError as exc:
        raise SourceError(f"{exc}; bundled photographs are {', '.join(BUNDLED_PHOTOS)}; held-out pictures "
                          f"{', '.join(HELDOUT_PICTURES)}") from None


def cover_size(source_hw: tuple[int, int], size: tuple[int, int]) -> tuple[int, int]:
    """Height and width of a source of ``source_hw`` scaled uniformly to just cover ``size``.

    Parameters
    ----------
    source_hw : (int, int)
        Source (height, width).
    size : (int, int)
        View (width, height).

    Returns
    -------
    (int, int)
        Scaled (height, width), each at least the view's.
    """
    h, w = source_hw
    width, height = size
    scale = max(width / w, height / h)
    return max(height, int(round(h * scale))), max(width, int(round(w * scale)))


def cover(image: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, tuple[int, int]]:
    """Resize ``image`` uniformly to just cover ``size``; also return the centred view's origin.

    Parameters
    ----------
    image : ndarray, float32, (Hs, Ws)
    size : (int, int)
        View (width, height).

    Returns
    -------
    plane : ndarray, float32, (Hc, Wc) with Hc >= height and Wc >= width
        The resized image (the same array when no resize is needed).
    origin : (int, int)
        ``(x0, y0)``: the centred view's top-left pixel in ``plane``.
    """
    hc, wc = cover_size(image.shape, size)
    if (hc, wc) != image.shape:
        shrink = hc * wc < image.shape[0] * image.shape[1]
        interp = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
        image = cv2.resize(image, (wc, hc), interpolation=interp)
    width, height = size
    return np.ascontiguousarray(image, dtype=np.float32), ((wc - width) // 2, (hc - height) // 2)


def load_photo(name_or_path: str | os.PathLike, size: tuple[int, int]) -> np.ndarray:
    """A photograph as luma, resized to cover ``size`` and centre-cropped.

    Parameters
    ----------
    name_or_path : str or path
        A name in :data:`BUNDLED_PHOTOS` or a path to an image file.
    size : (int, int)
        View (width, height) in pixels.

    Returns
    -------
    ndarray, float32, (height, width), values in [0, 1]
        Gamma-encoded luma (no linearisation).

    Raises
    ------
    SourceError
        For a path that is missing or cannot be decoded (the message names it).
    InputError
        For a bad size, or image content with NaN / values outside [0, 1].
    """
    from neuspike.scenes.spec import _size

    width, height = _size(size)
    plane, (x0, y0) = cover(read_photo(name_or_path), (width, height))
    return np.ascontiguousarray(plane[y0:y0 + height, x0:x0 + width])
