"""The exact motion of analytic scenes: backward optical flow, image speed, and the scene instant
a simulated window shows at a sensor instant.

An analytic scene knows where every pixel came from, so a trainer (or a metric) needs no estimated
flow: :func:`backward_flow` is closed-form for ``pan``, ``zoom``, ``fan``, ``still`` and the
background layer of ``dead_leaves``. :func:`image_speed_px_s` is a scene's typical image speed,
and :func:`scene_time_s` inverts the simulator's timing (Algorithm 1: ``S`` frames, each held for
``planes // S`` planes, scene instants ``1 / upsampled_rate_hz`` apart around the key instant).
"""

from __future__ import annotations

import math

import numpy as np

from neuspike.errors import InputError
from neuspike.scenes.spec import SceneSpec

__all__ = ["backward_flow", "image_speed_px_s", "scene_time_s"]


def backward_flow(spec: SceneSpec, t0_s: float, t1_s: float) -> np.ndarray:
    """Exact backward flow of an analytic scene from scene time ``t1_s`` to ``t0_s``.

    Returns
    -------
    ndarray float32 (2, H, W)
        ``(dx, dy)`` in pixels such that view pixel ``(x, y)`` at ``t1_s`` shows what
        ``(x + dx, y + dy)`` showed at ``t0_s``. Pan, and the background layer of ``dead_leaves``
        (its foreground shapes move otherwise): ``-v (t1 - t0)``; zoom: the view maps to the plane
        as ``f + (p - f) exp(-r t)``, so ``p' = f + (p - f) exp(-r (t1 - t0))``; fan and still:
        zero (the background is static; moving blades are not described by any flow). For a spec
        with a ``crop`` the flow covers the crop (its pixel ``(x, y)`` is ``(x0 + x, y0 + y)`` of
        the view).

    Raises
    ------
    InputError
        For a kind without a closed-form flow (``video``).
    """
    w, h = spec.size
    x0 = y0 = 0
    if spec.crop is not None:
        x0, y0, w, h = spec.crop
    flow = np.zeros((2, h, w), dtype=np.float32)
    dt = t1_s - t0_s
    if spec.kind in ("pan", "dead_leaves"):
        flow[0] = -spec.velocity_px_s[0] * dt
        flow[1] = -spec.velocity_px_s[1] * dt
    elif spec.kind == "zoom":
        shrink = math.exp(-spec.zoom_rate_hz * dt) - 1.0
        vw, vh = spec.size
        fx, fy = spec.focus if spec.focus is not None else ((vw - 1) / 2.0, (vh - 1) / 2.0)
        flow[0] = ((x0 + np.arange(w, dtype=np.float64) - fx) * shrink)[None, :]
        flow[1] = ((y0 + np.arange(h, dtype=np.float64) - fy) * shrink)[:, None]
    elif spec.kind not in ("fan", "still"):
        raise InputError(f"backward_flow: no exact flow for scene kind {spec.kind!r}")
    return flow


def image_speed_px_s(spec: SceneSpec) -> float:
    """A typical image speed of the scene (pixels per scene second).

    Pan and dead leaves: ``|v|``; zoom: ``|r| * 0.35 * min(W, H)`` (a point about a third of the
    view from the focus); fan: the blade speed at 0.3 of the view's smaller side; still: 0.
    """
    w, h = spec.size
    if spec.kind in ("pan", "dead_leaves"):
        return math.hypot(*spec.velocity_px_s)
    if spec.kind == "zoom":
        return abs(spec.zoom_rate_hz) * 0.35 * min(w, h)
    if spec.kind == "fan":
        return abs(spec.rpm) / 60.0 * 2 * math.pi * 0.3 * min(w, h)
    if spec.kind == "still":
        return 0.0
    raise InputError(f"image_speed_px_s: no closed-form speed for scene kind {spec.kind!r}")


def scene_time_s(sensor_t_s: np.ndarray, *, motion: int, planes: int, plane_rate_hz: float,
                 upsampled_rate_hz: float) -> np.ndarray:
    """Scene time shown at sensor time ``sensor_t_s`` of a simulated window (key instant = scene time 0).

    Frame ``k`` sits at sensor time ``(k + 0.5) * hold / plane_rate_hz`` (``hold = planes // motion``)
    and shows scene time ``(k - (motion - 1) / 2) / upsampled_rate_hz``; the event camera
    interpolates linearly between frames, so the map is affine. Float64 seconds, any shape.
    """
    frame_dt_sensor = (planes // motion) / plane_rate_hz
    k = np.asarray(sensor_t_s, dtype=np.float64) / frame_dt_sensor - 0.5
    return (k - (motion - 1) / 2.0) / upsampled_rate_hz
