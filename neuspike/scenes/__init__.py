"""Scenes: continuous-time pictures of the world, rendered as radiance frames.

Build a :class:`SceneSpec` (plain data) and call :func:`make_scene`; the returned
:class:`Scene` renders ``float32 (T, H, W)`` linear radiance (1.0 = reference white) at any
scene times with ``render(times_s)``. Kinds: ``pan``, ``zoom``, ``fan``, ``still``, ``video``.
Photographs come from scikit-image's bundled images (:data:`BUNDLED_PHOTOS`, split into
:data:`TRAIN_PHOTOS` and :data:`TEST_PHOTOS`) or from any image file.
"""

# Names resolve on first use (PEP 562), so that ``from neuspike.scenes import SceneSpec`` does not
# import OpenCV and torch (the video scene's) into a command that only parses its arguments.
import importlib
from typing import Any

_EXPORTS = {
    "BUILDERS": "neuspike.scenes.make",
    "BUNDLED_PHOTOS": "neuspike.scenes.photos",
    "CROP_KINDS": "neuspike.scenes.spec",
    "DEFAULT_FOLDER_FPS": "neuspike.scenes.spec",
    "DEFAULT_SIZE": "neuspike.scenes.spec",
    "FAN_HUB_FRACTION": "neuspike.scenes.fan",
    "FAN_TIP_FRACTION": "neuspike.scenes.fan",
    "FanScene": "neuspike.scenes.fan",
    "HELDOUT_PICTURES": "neuspike.scenes.photos",
    "IMAGE_SUFFIXES": "neuspike.scenes.photos",
    "KINDS": "neuspike.scenes.spec",
    "MAX_ZOOM_EXPONENT": "neuspike.scenes.spec",
    "PanScene": "neuspike.scenes.pan",
    "Scene": "neuspike.scenes.scene",
    "SceneSpec": "neuspike.scenes.spec",
    "StillScene": "neuspike.scenes.still",
    "TEST_PHOTOS": "neuspike.scenes.photos",
    "TRAIN_PHOTOS": "neuspike.scenes.photos",
    "VideoScene": "neuspike.scenes.video",
    "ZoomScene": "neuspike.scenes.zoom",
    "check_times": "neuspike.scenes.scene",
    "cover": "neuspike.scenes.photos",
    "cover_size": "neuspike.scenes.photos",
    "fan_phase": "neuspike.scenes.fan",
    "load_photo": "neuspike.scenes.photos",
    "luma": "neuspike.scenes.photos",
    "luma_to_radiance": "neuspike.scenes.radiance",
    "make_scene": "neuspike.scenes.make",
    "mirror_index": "neuspike.scenes.sampling",
    "pan_offsets": "neuspike.scenes.pan",
    "read_image_file": "neuspike.scenes.photos",
    "read_photo": "neuspike.scenes.photos",
    "read_timestamps": "neuspike.scenes.video",
    "read_video_source": "neuspike.scenes.video",
    "sample_separable": "neuspike.scenes.sampling",
    "zoom_coordinates": "neuspike.scenes.zoom",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'neuspike.scenes' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
