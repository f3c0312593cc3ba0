"""Scenes: continuous-time pictures of the world, rendered as radiance frames.

Build a :class:`SceneSpec` (plain data) and call :func:`make_scene`; the returned
:class:`Scene` renders ``float32 (T, H, W)`` linear radiance (1.0 = reference white) at any
scene times with ``render(times_s)``. Kinds: ``pan``, ``zoom``, ``fan``, ``still``, ``video``.
Photographs come from scikit-image's bundled images (:data:`BUNDLED_PHOTOS`, split into
:data:`TRAIN_PHOTOS` and :data:`TEST_PHOTOS`) or from any image file.
"""

from neuspike.scenes.fan import FAN_HUB_FRACTION, FAN_TIP_FRACTION, FanScene, fan_phase
from neuspike.scenes.pan import PanScene, pan_offsets
from neuspike.scenes.photos import (
    BUNDLED_PHOTOS,
    IMAGE_SUFFIXES,
    TEST_PHOTOS,
    TRAIN_PHOTOS,
    cover,
    cover_size,
    load_photo,
    luma,
    read_image_file,
    read_photo,
)
from neuspike.scenes.radiance import luma_to_radiance
from neuspike.scenes.sampling import mirror_index, sample_separable
from neuspike.scenes.make import BUILDERS, make_scene
from neuspike.scenes.scene import Scene, check_times
from neuspike.scenes.spec import CROP_KINDS, DEFAULT_FOLDER_FPS, DEFAULT_SIZE, KINDS, MAX_ZOOM_EXPONENT, SceneSpec
from neuspike.scenes.still import StillScene
from neuspike.scenes.video import VideoScene, read_timestamps, read_video_source
from neuspike.scenes.zoom import ZoomScene, zoom_coordinates

__all__ = [
    "BUNDLED_PHOTOS", "DEFAULT_FOLDER_FPS", "DEFAULT_SIZE", "FAN_HUB_FRACTION", "FAN_TIP_FRACTION",
    "CROP_KINDS", "IMAGE_SUFFIXES", "KINDS", "MAX_ZOOM_EXPONENT", "TEST_PHOTOS", "TRAIN_PHOTOS",
    "FanScene", "PanScene", "Scene", "SceneSpec", "StillScene", "VideoScene", "ZoomScene",
    "check_times", "cover", "cover_size", "fan_phase", "load_photo", "luma", "luma_to_radiance",
    "make_scene", "mirror_index", "pan_offsets", "read_image_file", "read_photo",
    "read_timestamps", "read_video_source", "sample_separable", "zoom_coordinates",
]
