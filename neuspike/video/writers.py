"""Writing videos, frames and contact sheets so that nothing half-written looks complete.

Every output is written under a temporary name in its destination folder (a hidden name starting
with ``.`` and containing ``.partial``) and renamed to its final name only when complete:
:meth:`Mp4Writer.close` and :meth:`FrameFolder.close` publish, :meth:`~Mp4Writer.abort` removes.
A run that fails therefore leaves no file under a final name.

Images are float (H, W) in [0, 1]; 8-bit conversion is :func:`neuspike.formats.images.to_uint8` with ``clip=True``.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Sequence

import numpy as np

from neuspike.utils.atomic import publish
from neuspike.errors import InputError, SourceError
from neuspike.formats.images import encode_png, to_uint8

__all__ = [
    "label_image",
    "tile_row",
    "contact_sheet",
    "Mp4Writer",
    "FrameFolder",
    "check_writable",
]

#: Height in pixels of the band above each tile that carries its name.
LABEL_BAND_PX = 22


def label_image(image8: np.ndarray, text: str) -> np.ndarray:
    """uint8 (H, W) -> uint8 (H + LABEL_BAND_PX, W): a black band above with ``text`` in white."""
    import cv2

    h, w = image8.shape
    out = np.zeros((h + LABEL_BAND_PX, w), dtype=np.uint8)
    out[LABEL_BAND_PX:] = image8
    scale = 0.5 if w >= 160 else 0.35
    cv2.putText(out, text, (4, LABEL_BAND_PX - 7), cv2.FONT_HERSHEY_SIMPLEX, scale, 255, 1, cv2.LINE_AA)
    return out


def tile_row(tiles: Sequence[np.ndarray], gap_px: int = 4) -> np.ndarray:
    """Equal-height uint8 tiles side by side with grey gaps."""
    if not tiles:
        raise InputError("tile_row: no tiles")
    h = tiles[0].shape[0]
    if any(t.shape[0] != h for t in tiles):
        raise InputError(f"tile_row: tiles differ in height: {[t.shape for t in tiles]}")
    gap = np.full((h, gap_px), 128, dtype=np.uint8)
    parts: list[np.ndarray] = []
    for i, t in enumerate(tiles):
        if i:
            parts.append(gap)
        parts.append(t)
    return np.concatenate(parts, axis=1)


def contact_sheet(rows: Sequence[tuple[str, Sequence[np.ndarray]]], times_s: Sequence[float],
                  *, max_width_px: int = 1600) -> np.ndarray:
    """A grid: one row per method (its name on the first tile), one column per instant.

    Parameters
    ----------
    rows : sequence of (name, images)
        Each ``images`` holds float (H, W) images in [0, 1], one per instant.
    times_s : sequence of float
        The instants (shown on the tiles of the first row in milliseconds).
    max_width_px : int
        Tiles are shrunk (never enlarged) so the sheet is at most this wide.

    Returns
    -------
    ndarray uint8 (rows * (h + band) + gaps, cols * w + gaps)
    """
    import cv2

    if not rows or not times_s:
        raise InputError("contact_sheet: needs at least one row and one instant")
    cols = len(times_s)
    h, w = rows[0][1][0].shape
    scale = min(1.0, (max_width_px - 4 * (cols - 1)) / (cols * w))
    th, tw = max(1, int(round(h * scale))), max(1, int(round(w * scale)))
    lines = []
    for r, (name, images) in enumerate(rows):
        if len(images) != cols:
            raise InputError(f"contact_sheet: row {name!r} has {len(images)} images for {cols} instants")
        tiles = []
        for c, img in enumerate(images):
            small = cv2.resize(to_uint8(img, clip=True), (tw, th), interpolation=cv2.INTER_AREA) if scale < 1 else to_uint8(img, clip=True)
            text = name if c == 0 else ""
            if r == 0:
                text = f"{text}  t={1e3 * times_s[c]:.2f} ms" if text else f"t={1e3 * times_s[c]:.2f} ms"
            tiles.append(label_image(small, text))
        lines.append(tile_row(tiles))
    gap = np.full((4, lines[0].shape[1]), 128, dtype=np.uint8)
    out: list[np.ndarray] = []
    for i, line in enumerate(lines):
        if i:
            out.append(gap)
        out.append(line)
    return np.concatenate(out, axis=0)


def _partial(path: Path) -> Path:
    return path.with_name(f".{path.stem}.partial{path.suffix}")


def mp4_complete(path: Path) -> bool:
    """Whether ``path`` is a whole MPEG-4 file: its top-level boxes tile the file exactly and one is
    the ``moov`` index (written last: a truncated file lacks it or ends inside a box)."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            at, kinds = 0, set()
            while at < size:
                fh.seek(at)
                head = fh.read(16)
                if len(head) < 8:
                    return False
                box, kind = int.from_bytes(head[:4], "big"), head[4:8]
                if box == 1 and len(head) == 16:
                    box = int.from_bytes(head[8:16], "big")
                elif box == 0:
                    box = size - at
                if box < 8 or at + box > size:
                    return False
                kinds.add(kind)
                at += box
            return b"moov" in kinds
    except OSError:
        return False


class Mp4Writer:
    """An MPEG-4 video (OpenCV's writer, ``mp4v``) written under a temporary name, published on close.

    Parameters
    ----------
    path : path
        The final ``.mp4`` name.
    fps : float
        Playback frames per second.
    width, height : int
        Frame size; frames are uint8 (H, W) greyscale (written as 3 equal channels).
    """

    def __init__(self, path: str | os.PathLike, *, fps: float, width: int, height: int) -> None:
        import cv2

        self.path = Path(path)
        if self.path.suffix.lower() != ".mp4":
            raise InputError(f"Mp4Writer: expected a .mp4 path, got {self.path}")
        self.size = (int(width), int(height))
        self.tmp = _partial(self.path)
        self._writer = cv2.VideoWriter(str(self.tmp), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), self.size, True)
        if not self._writer.isOpened():
            self.tmp.unlink(missing_ok=True)
            raise SourceError(f"cannot open a video writer for {self.path} (OpenCV, mp4v)")
        self.frames = 0

    def write(self, image8: np.ndarray) -> None:
        import cv2

        if self._writer is None:
            raise InputError(f"Mp4Writer({self.path}): write after close")
        if image8.shape != (self.size[1], self.size[0]) or image8.dtype != np.uint8:
            raise InputError(f"Mp4Writer({self.path}): expected uint8 {self.size[1]}x{self.size[0]}, got {image8.dtype} {image8.shape}")
        self._writer.write(cv2.cvtColor(image8, cv2.COLOR_GRAY2BGR))
        self.frames += 1

    def close(self) -> Path:
        """Finish the file, check that it reads back whole, and publish it under its name.

        Raises
        ------
        SourceError
            The file is not a whole MPEG-4 file (:func:`mp4_complete`; OpenCV ignores failed writes:
            a full disk or a file size limit would otherwise publish a truncated, unplayable video).
        """
        if self._writer is not None:
            self._writer.release()
            self._writer = None
            if not mp4_complete(self.tmp):
                size = self.tmp.stat().st_size if self.tmp.exists() else 0
                self.tmp.unlink(missing_ok=True)
                raise SourceError(
                    f"{self.path}: the video was not written completely ({self.frames} frames, a file of "
                    f"{size} bytes without its whole index): is the disk full or a file size limit set?"
                )
            publish(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        self.tmp.unlink(missing_ok=True)


class FrameFolder:
    """Per-frame files (``frame_000000.png`` / ``.npy``) in a folder published whole on close.

    The folder is filled under a hidden temporary name; :meth:`close` replaces any folder of the
    final name with it, :meth:`abort` removes it.
    """

    def __init__(self, path: str | os.PathLike, *, png: bool, npy: bool) -> None:
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.partial")
        if self.tmp.exists():
            shutil.rmtree(self.tmp)
        self.tmp.mkdir(parents=True)
        self.png, self.npy = png, npy
        self.count = 0
        self._open = True

    def write(self, image: np.ndarray) -> None:
        name = f"frame_{self.count:06d}"
        if self.png:
            try:  # the folder is published whole by close(); its files need no rename of their own
                (self.tmp / f"{name}.png").write_bytes(encode_png(image, clip=True))
            except OSError as exc:
                raise SourceError(f"{self.path}: could not write {name}.png ({exc.strerror or exc}; is the disk full "
                                  "or a file size limit set?)") from None
        if self.npy:
            np.save(self.tmp / f"{name}.npy", np.asarray(image, dtype=np.float32))
        self.count += 1

    def close(self) -> Path:
        if self._open:
            self._open = False
            if self.path.exists():
                shutil.rmtree(self.path)
            os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        if self._open:
            self._open = False
            shutil.rmtree(self.tmp, ignore_errors=True)


def check_writable(folder: str | os.PathLike) -> Path:
    """Create ``folder`` if needed and prove a file can be written there (before any work starts).

    Raises
    ------
    SourceError
        The folder cannot be created or written to (the message names it and why).
    """
    p = Path(folder)
    try:
        p.mkdir(parents=True, exist_ok=True)
        probe = p / ".write-probe.partial"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise SourceError(f"output folder {p} is not writable ({exc.strerror or exc})") from None
    return p


