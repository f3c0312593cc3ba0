"""The ``video`` scene: a real frame sequence, rendered at any instant by optical-flow warping.

Sources (``spec.video``):

- a video file, decoded with ``cv2.VideoCapture``; frame ``k`` is at ``k / fps`` with ``fps`` the
  spec's, else the file's own rate;
- a folder of images (suffixes in :data:`neuspike.scenes.photos.IMAGE_SUFFIXES`) taken in name
  order; frame ``k`` at ``k / fps`` (``fps`` default 25) unless a timestamps file applies;
- a timestamps file (``spec.timestamps``, or ``spec.video`` itself when it is a file ending in
  ``.txt``, or ``images.txt`` inside the ``spec.video`` folder): lines
  ``<t seconds> <path relative to the file's folder>``, blank lines and ``#`` comments skipped,
  times strictly increasing. ``fps`` may not be given together with a timestamps file.

Every frame is converted to luma (:func:`neuspike.scenes.photos.luma`), resized like a photograph
(uniform scale to cover ``spec.size``, centre crop; ``size=None`` keeps the source size) and
mapped to radiance with the spec's dynamic range. The whole sequence is held in memory.

Between frames ``k`` (time ``t0``) and ``k + 1`` (``t1``), at fraction ``a = (t - t0) / (t1 - t0)``,
the frame is ::

    (1 - a) * I0(x - a * F01(x)) + a * I1(x - (1 - a) * F10(x))

with ``F01``, ``F10`` the forward and backward dense flows (OpenCV DIS, ``MEDIUM`` preset, computed
on 8-bit luma and cached per pair), each evaluated at the target pixel (a first-order
approximation of the motion path), and the warps done by ``torch.nn.functional.grid_sample``
(the sampler under ``kornia.geometry.transform.remap``, called directly with a prebuilt
normalised grid, which halves the warp time; bilinear, ``align_corners=True``, border
replicate). At a real frame's time the real frame is returned exactly. With
``spec.upsample = U`` the fraction ``a`` snaps to the nearest multiple of ``1 / U``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch.nn.functional import grid_sample

from neuspike.errors import FormatError, InputError, SourceError
from neuspike.scenes.photos import IMAGE_SUFFIXES, cover, luma, read_image_file
from neuspike.scenes.radiance import luma_to_radiance
from neuspike.scenes.scene import Scene
from neuspike.scenes.spec import DEFAULT_FOLDER_FPS, SceneSpec

#: The timestamps file a frame folder may hold.
TIMESTAMPS_NAME = "images.txt"

_BATCH = 32  # instants warped together


def read_timestamps(path: str | os.PathLike) -> tuple[np.ndarray, list[Path]]:
    """Parse a timestamps file.

    Parameters
    ----------
    path : str or path
        Lines ``<t seconds> <relative/path>``; blank lines and lines starting with ``#`` skipped.

    Returns
    -------
    times_s : ndarray, float64, (N,), strictly increasing
    frames : list of Path, (N,)
        Resolved against the file's folder.

    Raises
    ------
    SourceError
        When the file cannot be read.
    FormatError
        For a malformed line, a non-finite time or times that do not strictly increase.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(f"cannot read timestamps file {str(p)!r}: {exc}") from None
    times: list[float] = []
    frames: list[Path] = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split(maxsplit=1)
        if len(parts) != 2:
            raise FormatError(f"{p}: line {number}: expected '<t seconds> <path>', got {line!r}")
        try:
            t = float(parts[0])
        except ValueError:
            raise FormatError(f"{p}: line {number}: expected a time in seconds, got {parts[0]!r}") from None
        if not math.isfinite(t):
            raise FormatError(f"{p}: line {number}: expected a finite time, got {parts[0]!r}")
        times.append(t)
        frames.append(p.parent / parts[1].strip())
    t_arr = np.asarray(times, dtype=np.float64)
    if t_arr.size >= 2 and not (np.diff(t_arr) > 0).all():
        k = int(np.argmin(np.diff(t_arr) > 0))
        raise FormatError(f"{p}: times must strictly increase, got {t_arr[k]} then {t_arr[k + 1]}")
    return t_arr, frames


def _read_capture(path: Path) -> tuple[list[np.ndarray], float]:
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise SourceError(f"cannot read video {str(path)!r}: OpenCV cannot open it")
        fps = float(capture.get(cv2.CAP_PROP_FPS))
        frames = []
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            frames.append(luma(frame, channel_order="bgr", source=f"{path} frame {len(frames)}"))
    finally:
        capture.release()
    return frames, fps


def read_video_source(spec: SceneSpec) -> tuple[list[np.ndarray], np.ndarray, dict[str, Any]]:
    """Read the frames of a video spec as luma, with their times.

    Returns
    -------
    frames : list of ndarray, float32, (Hs, Ws), values in [0, 1]
    times_s : ndarray, float64, (N,), strictly increasing, N >= 2
    info : dict
        ``source_type`` and the timestamps file or frame rate used.

    Raises
    ------
    SourceError
        For a missing or undecodable video, folder, timestamps file or frame, fewer than two
        frames, or frames of different sizes (the message names the path).
    FormatError
        For a malformed timestamps file.
    InputError
        For ``fps`` given together with a timestamps file, or invalid frame content.
    """
    video = Path(spec.video)
    timestamps = Path(spec.timestamps) if spec.timestamps is not None else None
    if timestamps is None and video.is_file() and video.suffix.lower() == ".txt":
        timestamps = video
    if timestamps is None and video.is_dir() and (video / TIMESTAMPS_NAME).is_file():
        timestamps = video / TIMESTAMPS_NAME
    if timestamps is not None:
        if spec.fps is not None:
            raise InputError(
                f"fps: the timestamps file {str(timestamps)!r} gives the frame times; got fps={spec.fps} too"
            )
        times_s, paths = read_timestamps(timestamps)
        frames = [read_image_file(p) for p in paths]
        info: dict[str, Any] = {"source_type": "timestamps", "timestamps": str(timestamps)}
    elif video.is_dir():
        paths = sorted(p for p in video.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        frames = [read_image_file(p) for p in paths]
        fps = DEFAULT_FOLDER_FPS if spec.fps is None else spec.fps
        times_s = np.arange(len(frames), dtype=np.float64) / fps
        info = {"source_type": "folder", "fps": fps}
    elif video.is_file():
        frames, file_fps = _read_capture(video)
        fps = spec.fps if spec.fps is not None else file_fps
        if not (math.isfinite(fps) and fps > 0):
            raise SourceError(f"cannot read video {str(video)!r}: it states no frame rate; give fps")
        times_s = np.arange(len(frames), dtype=np.float64) / fps
        info = {"source_type": "file", "fps": fps}
    else:
        raise SourceError(f"cannot read video {str(video)!r}: no such file or folder")
    if len(frames) < 2:
        raise SourceError(
            f"cannot read video {str(video)!r}: expected at least 2 frames, found {len(frames)}"
        )
    shapes = {f.shape for f in frames}
    if len(shapes) != 1:
        raise SourceError(f"cannot read video {str(video)!r}: frames differ in size: {sorted(shapes)}")
    return frames, times_s, info


def _to_normalised(flow: np.ndarray) -> torch.Tensor:
    """Pixel flow (H, W, 2) in the [-1, 1] units of ``align_corners=True`` grids."""
    h, w = flow.shape[:2]
    scale = np.array([2.0 / (w - 1) if w > 1 else 0.0, 2.0 / (h - 1) if h > 1 else 0.0], dtype=np.float32)
    return torch.from_numpy(np.ascontiguousarray(flow * scale, dtype=np.float32))


def identity_grid(height: int, width: int) -> torch.Tensor:
    """The identity sampling grid, float32 (H, W, 2), ``(x, y)`` in [-1, 1] (``align_corners=True``)."""
    gx = torch.linspace(-1.0, 1.0, width) if width > 1 else torch.zeros(1)
    gy = torch.linspace(-1.0, 1.0, height) if height > 1 else torch.zeros(1)
    return torch.stack(torch.meshgrid(gx, gy, indexing="xy"), dim=-1)


def interpolation_grids(identity: torch.Tensor, flow_01: torch.Tensor, flow_10: torch.Tensor,
                        fractions: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalised sampling grids of the two bracketing frames for the instants at ``fractions``.

    Parameters
    ----------
    identity : Tensor, float32, (H, W, 2)
        :func:`identity_grid`.
    flow_01, flow_10 : Tensor, float32, (H, W, 2)
        Forward and backward flow in normalised units.
    fractions : ndarray, float64, (B,), in (0, 1)

    Returns
    -------
    grid0, grid1 : Tensor, float32, (B, H, W, 2)
        Where to sample frame 0 (``x - a F01(x)``) and frame 1 (``x - (1 - a) F10(x)``).
    """
    a = torch.from_numpy(fractions.astype(np.float32))[:, None]
    shape = (a.shape[0], *identity.shape)
    flat = identity.reshape(1, -1)  # broadcasting over one long axis is much faster
    grid0 = torch.addcmul(flat, a, flow_01.reshape(1, -1), value=-1.0)
    grid1 = torch.addcmul(flat, 1 - a, flow_10.reshape(1, -1), value=-1.0)
    return grid0.view(shape), grid1.view(shape)


class VideoScene(Scene):
    """A real frame sequence rendered at any instant in its span.

    Parameters
    ----------
    spec : SceneSpec
        ``kind="video"``; uses ``video``, ``timestamps``, ``fps``, ``size``, ``upsample``,
        ``dynamic_range``, ``peak``.

    Attributes
    ----------
    frame_times_s : ndarray, float64, (N,)
        The real frames' times (read-only).
    start_s, end_s : float
        First and last frame time; :meth:`render` accepts times in ``[start_s, end_s]``.
    """

    def __init__(self, spec: SceneSpec) -> None:
        frames, times_s, self._info = read_video_source(spec)
        hs, ws = frames[0].shape
        width, height = (ws, hs) if spec.size is None else spec.size
        super().__init__(spec, width, height)
        self._source_hw = (int(hs), int(ws))
        lumas = np.stack([_crop(cover(f, (width, height)), width, height) for f in frames])
        self._gray8 = np.round(lumas * 255.0).astype(np.uint8)
        self._frames = luma_to_radiance(lumas, dynamic_range=spec.dynamic_range, peak=spec.peak)
        times_s.setflags(write=False)
        self.frame_times_s = times_s
        self.start_s = float(times_s[0])
        self.end_s = float(times_s[-1])
        self._flows: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        self._identity = identity_grid(height, width)

    def flows(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Forward and backward DIS flow between frames ``k`` and ``k + 1``, float32 (H, W, 2), cached."""
        if k not in self._flows:
            a, b = self._gray8[k], self._gray8[k + 1]
            self._flows[k] = (self._dis.calc(a, b, None), self._dis.calc(b, a, None))
        return self._flows[k]

    def _render(self, times_s: np.ndarray) -> np.ndarray:
        if times_s.size and (times_s.min() < self.start_s or times_s.max() > self.end_s):
            bad = times_s[(times_s < self.start_s) | (times_s > self.end_s)][0]
            raise InputError(
                f"times_s: expected times within the video's span [{self.start_s}, {self.end_s}] s, got {bad}"
            )
        ft = self.frame_times_s
        k = np.clip(np.searchsorted(ft, times_s, side="right") - 1, 0, ft.size - 2)
        frac = (times_s - ft[k]) / (ft[k + 1] - ft[k])
        if self.spec.upsample is not None:
            frac = np.round(frac * self.spec.upsample) / self.spec.upsample
        out = np.empty((times_s.size, self.height, self.width), dtype=np.float32)
        exact0, exact1 = frac <= 0, frac >= 1
        out[exact0] = self._frames[k[exact0]]
        out[exact1] = self._frames[k[exact1] + 1]
        between = ~(exact0 | exact1)
        for pair in np.unique(k[between]):
            where = np.flatnonzero(between & (k == pair))
            f01, f10 = (_to_normalised(f) for f in self.flows(int(pair)))
            img0 = torch.from_numpy(self._frames[pair])[None, None]
            img1 = torch.from_numpy(self._frames[pair + 1])[None, None]
            for start in range(0, where.size, _BATCH):
                idx = where[start:start + _BATCH]
                a = frac[idx]
                grid0, grid1 = interpolation_grids(self._identity, f01, f10, a)
                n = idx.size
                w0 = grid_sample(img0.expand(n, 1, -1, -1), grid0, mode="bilinear",
                                 padding_mode="border", align_corners=True)
                w1 = grid_sample(img1.expand(n, 1, -1, -1), grid1, mode="bilinear",
                                 padding_mode="border", align_corners=True)
                wa = torch.from_numpy(a.astype(np.float32))[:, None, None]
                out[idx] = torch.lerp(w0[:, 0], w1[:, 0], wa).numpy()
        return out

    def _details(self) -> dict[str, Any]:
        ft = self.frame_times_s
        return {**self._info, "frames": int(ft.size), "start_s": self.start_s, "end_s": self.end_s,
                "mean_fps": float((ft.size - 1) / (ft[-1] - ft[0])), "source_hw": list(self._source_hw),
                "flow": "OpenCV DIS preset MEDIUM on 8-bit luma, forward and backward",
                "warp": "grid_sample bilinear, align_corners, border replicate; blend by time fraction",
                "upsample": self.spec.upsample}


def _crop(covered: tuple[np.ndarray, tuple[int, int]], width: int, height: int) -> np.ndarray:
    plane, (x0, y0) = covered
    return plane[y0:y0 + height, x0:x0 + width]
