"""Float images in [0, 1] as 8-bit pictures: one conversion and one PNG writer for the whole suite.

The conversion is ``round(255 * x)``. What happens to values outside [0, 1] is the caller's explicit
choice (``clip``): ground truth of an HDR scene legitimately exceeds 1 and is saturated on purpose
(``clip=True``); a method's output must already lie in [0, 1], and anything else is refused
(``clip=False``) rather than hidden.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from neuspike.utils.atomic import write_bytes
from neuspike.errors import InputError, NeuSpikeError

__all__ = ["encode_png", "to_uint8", "write_png"]


def to_uint8(image01: np.ndarray, *, clip: bool) -> np.ndarray:
    """``round(255 * image)`` as uint8 (H, W).

    Parameters
    ----------
    image01 : ndarray (H, W), float
        Values in [0, 1] (see ``clip``).
    clip : bool
        ``True`` saturates values outside [0, 1]; ``False`` raises :class:`InputError` for them and
        for non-finite values.
    """
    img = np.asarray(image01, dtype=np.float64)
    if img.ndim != 2:
        raise InputError(f"image: expected a 2-D image (H, W), got shape {img.shape}")
    if not np.isfinite(img).all():
        raise InputError("image: has non-finite values")
    if clip:
        img = np.clip(img, 0.0, 1.0)
    elif img.size and (img.min() < 0 or img.max() > 1):
        raise InputError(f"image: expected values in [0, 1], got values in [{img.min()}, {img.max()}]")
    return np.round(img * 255.0).astype(np.uint8)


def encode_png(image01: np.ndarray, *, clip: bool) -> bytes:
    """The 8-bit greyscale PNG of a [0, 1] image (:func:`to_uint8`), or of a uint8 (H, W) image as it
    is (a picture already composed in 8 bits, e.g. a labelled contact sheet; ``clip`` is moot)."""
    image = np.asarray(image01)
    if image.dtype == np.uint8:
        if image.ndim != 2:
            raise InputError(f"image: expected a 2-D image (H, W), got shape {image.shape}")
        image8 = image
    else:
        image8 = to_uint8(image, clip=clip)
    import cv2  # here, so that importing this module stays cheap for the commands' --help

    ok, buf = cv2.imencode(".png", image8)
    if not ok:
        raise NeuSpikeError("could not encode the image as PNG")
    return buf.tobytes()


def write_png(path: str | os.PathLike, image01: np.ndarray, *, clip: bool) -> Path:
    """Write :func:`encode_png` of ``image01`` to ``path`` atomically; returns the path."""
    return write_bytes(path, encode_png(image01, clip=clip))
