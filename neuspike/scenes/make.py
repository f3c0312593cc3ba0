"""Building a scene from its spec: one table from kind to class (the kinds import the base, not this)."""

from __future__ import annotations

from typing import Callable

from neuspike.errors import InputError
from neuspike.scenes.dead_leaves import DeadLeavesScene
from neuspike.scenes.fan import FanScene
from neuspike.scenes.pan import PanScene
from neuspike.scenes.scene import Scene
from neuspike.scenes.spec import SceneSpec
from neuspike.scenes.still import StillScene
from neuspike.scenes.video import VideoScene
from neuspike.scenes.zoom import ZoomScene

__all__ = ["BUILDERS", "make_scene"]

#: Scene class of every kind of :data:`neuspike.scenes.spec.KINDS`.
BUILDERS: dict[str, Callable[[SceneSpec], Scene]] = {
    "pan": PanScene, "zoom": ZoomScene, "fan": FanScene, "still": StillScene, "video": VideoScene,
    "dead_leaves": DeadLeavesScene,
}


def make_scene(spec: SceneSpec) -> Scene:
    """Build the scene a spec describes.

    Parameters
    ----------
    spec : SceneSpec

    Returns
    -------
    Scene
        Of the spec's kind; renders radiance frames of ``spec.size`` (for video, the source
        size when ``spec.size`` is None).

    Raises
    ------
    InputError
        For a spec that is not a :class:`SceneSpec`, or image content that is not valid.
    SourceError
        For an image or video that cannot be read (the message names the path).
    """
    if not isinstance(spec, SceneSpec):
        raise InputError(f"spec: expected a SceneSpec, got {type(spec).__name__}")
    return BUILDERS[spec.kind](spec)
