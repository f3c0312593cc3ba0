"""Vidar spike camera ``.dat`` files: read and write, bit-exact with the field's convention.

Layout (no header): the file is a sequence of planes of ``H * W / 8`` bytes (12,500 for the
250 x 400 Vidar). Within a plane, pixel ``p`` (row-major index of the *stored* plane) is bit
``p % 8`` of byte ``p // 8``, least significant bit first. Rows are stored upside down: the first
stored row is the bottom row of the image, so readers flip vertically after unpacking and writers
before packing. Some captures are 416 pixels wide with 16 extra columns at the right, which
readers drop (``raw_width=416``).

Readers return C-contiguous ``bool`` arrays (T, H, W) with row 0 at the top of the image, read
only the requested plane range (seek, then read), and report a trailing partial plane as a
:class:`~neuspike.errors.FormatError`. Writers write to a temporary file in the target folder and
rename it into place only when everything was written, so a failure leaves no partial file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.utils.atomic import publish, temp_beside
from neuspike.utils.checks import check_int, check_positive, check_positive_int
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.streams import VIDAR_PLANE_RATE_HZ, SpikeStream

__all__ = ["DatWriter", "count_planes", "plane_bytes", "read_dat", "read_spike_stream", "write_dat"]

#: Planes are packed and unpacked in chunks of about this many pixels, to bound temporary memory.
_CHUNK_PIXELS = 1 << 24


def plane_bytes(height: int, width: int) -> int:
    """Bytes per stored plane, ``height * width / 8``.

    Raises
    ------
    InputError
        If ``height * width`` is not a multiple of 8 (such a sensor cannot be stored in this format).
    """
    h = check_positive_int("height", height)
    w = check_positive_int("width", width)
    if (h * w) % 8:
        raise InputError(
            f"a .dat plane packs 8 pixels per byte: height x width must be a multiple of 8, "
            f"got {h} x {w} = {h * w} pixels"
        )
    return h * w // 8


def _chunk_planes(height: int, width: int) -> int:
    return max(1, _CHUNK_PIXELS // (height * width))


def _bool_planes(planes: Any) -> np.ndarray:
    """``planes`` (array or SpikeStream) as a bool (T, H, W) array, validating 0/1 content."""
    if isinstance(planes, SpikeStream):
        return planes.planes
    a = np.asarray(planes)
    if a.ndim != 3:
        raise InputError(f"planes: expected shape (T, H, W), got {a.shape}")
    if a.dtype == np.bool_:
        return a
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise InputError(f"planes: expected bool or 0/1 numbers, got dtype {a.dtype}")
    if a.size and not ((a == 0) | (a == 1)).all():
        raise InputError("planes: expected only 0 and 1 values")
    return a.astype(np.bool_)


def _pack(planes: np.ndarray) -> bytes:
    """Stored bytes of bool planes (n, H, W): flip rows, flatten, pack LSB first."""
    stored = np.ascontiguousarray(planes[:, ::-1, :]).reshape(-1)
    return np.packbits(stored, bitorder="little").tobytes()  # H * W % 8 == 0: planes end on a byte


def _unpack(raw: np.ndarray, out: np.ndarray, raw_width: int) -> None:
    """Fill ``out`` (n, H, W) bool from stored bytes ``raw`` (n, H * raw_width / 8) uint8."""
    n, h, w = out.shape
    bits = np.unpackbits(raw.reshape(-1), bitorder="little").view(np.bool_).reshape(n, h, raw_width)
    out[...] = bits[:, ::-1, :w]


class DatWriter:
    """Append planes to a ``.dat`` file that appears only when :meth:`close` succeeds.

    Planes go to a temporary file in the target's folder; :meth:`close` renames it into place
    (``os.replace``), :meth:`abort` (or an exception inside a ``with`` block, or an error while
    writing) deletes it. An existing file at ``path`` is left untouched until the rename.

    Parameters
    ----------
    path : str or os.PathLike
        The final file.

    Examples
    --------
    >>> with DatWriter(folder / "spikes.dat") as w:  # doctest: +SKIP
    ...     for chunk in chunks:
    ...         w.write(chunk)
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self._path = Path(path)
        fd, tmp = temp_beside(self._path)
        self._tmp = Path(tmp)
        self._file = os.fdopen(fd, "wb")
        self._shape: tuple[int, int] | None = None
        self._planes = 0
        self._state = "open"

    @property
    def path(self) -> Path:
        return self._path

    @property
    def planes_written(self) -> int:
        return self._planes

    def write(self, planes: np.ndarray | SpikeStream) -> None:
        """Append bool planes (T, H, W) (or a SpikeStream's planes); every call must have the same H, W.

        Raises
        ------
        InputError
            For planes that are not 0/1, a size whose ``H * W`` is not a multiple of 8, or a size
            that differs from earlier calls (nothing is written then, and the writer stays usable).
        """
        self._check_open()
        p = _bool_planes(planes)
        t, h, w = p.shape
        plane_bytes(h, w)
        if self._shape is None:
            self._shape = (h, w)
        elif self._shape != (h, w):
            raise InputError(
                f"DatWriter: expected planes of {self._shape[1]}x{self._shape[0]} (W x H) like the earlier ones, "
                f"got {w}x{h}"
            )
        try:
            step = _chunk_planes(h, w)
            for i in range(0, t, step):
                self._file.write(_pack(p[i:i + step]))
        except BaseException:
            self.abort()
            raise
        self._planes += t

    def write_packed(self, data: np.ndarray, *, height: int, width: int) -> None:
        """Append planes already packed in this format's layout, written as they are.

        ``data`` is uint8 (T, H * W / 8), e.g. ``SpikeCamera.capture_packed(...)[0].data``: each
        plane flipped vertically, pixel ``p`` bit ``p % 8`` of byte ``p // 8``. Same size rules as
        :meth:`write`, with which it can be mixed.
        """
        self._check_open()
        nbytes = plane_bytes(height, width)
        d = np.asarray(data)
        if d.dtype != np.uint8 or d.ndim != 2 or d.shape[1] != nbytes:
            raise InputError(f"packed planes: expected uint8 of shape (T, {nbytes}) for {width}x{height} "
                             f"(W x H), got {d.dtype} {d.shape}")
        if self._shape is None:
            self._shape = (int(height), int(width))
        elif self._shape != (int(height), int(width)):
            raise InputError(f"DatWriter: expected planes of {self._shape[1]}x{self._shape[0]} (W x H) like the "
                             f"earlier ones, got {width}x{height}")
        try:
            self._file.write(np.ascontiguousarray(d).data)
        except BaseException:
            self.abort()
            raise
        self._planes += d.shape[0]

    def close(self) -> Path:
        """Finish the file and move it into place; returns its path."""
        self._check_open()
        try:
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            publish(self._tmp, self._path)
        except BaseException:
            self.abort()
            raise
        self._state = "closed"
        return self._path

    def abort(self) -> None:
        """Discard everything written; no file appears. Safe to call more than once."""
        if self._state != "open":
            return
        self._state = "aborted"
        try:
            self._file.close()
        finally:
            self._tmp.unlink(missing_ok=True)

    def _check_open(self) -> None:
        if self._state != "open":
            raise InputError(f"DatWriter for {self._path}: the writer is {self._state}")

    def __enter__(self) -> "DatWriter":
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:  # a writer dropped without close() leaves no temporary file
        try:
            self.abort()
        except Exception:
            pass


def write_dat(path: str | os.PathLike, planes: np.ndarray | SpikeStream) -> Path:
    """Write bool planes (T, H, W) as a Vidar ``.dat`` file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; replaced only when the whole file was written.
    planes : ndarray (T, H, W) of bool or 0/1 numbers, or SpikeStream
        Row 0 is the top of the image; ``H * W`` must be a multiple of 8.

    Returns
    -------
    Path
        The written file.
    """
    p = _bool_planes(planes)
    plane_bytes(p.shape[1], p.shape[2])
    with DatWriter(path) as writer:
        writer.write(p)
    return Path(path)


def _geometry(height: int, width: int, raw_width: int | None) -> tuple[int, int, int, int]:
    h = check_positive_int("height", height)
    w = check_positive_int("width", width)
    rw = w if raw_width is None else check_positive_int("raw_width", raw_width)
    if rw < w:
        raise InputError(f"raw_width: expected at least width ({w}) stored columns, got {rw}")
    return h, w, rw, plane_bytes(h, rw)


def _file_planes(path: Path, h: int, rw: int, nbytes: int) -> int:
    if not path.is_file():
        raise SourceError(f"no such .dat file: {path}")
    size = path.stat().st_size
    planes, remainder = divmod(size, nbytes)
    if remainder:
        raise FormatError(
            f"{path}: size {size} bytes is not a whole number of {nbytes}-byte planes "
            f"({rw} x {h} pixels): {planes} planes and a remainder of {remainder} bytes; "
            "check the height and width (and raw_width for 416-wide captures)"
        )
    return planes


def count_planes(path: str | os.PathLike, *, height: int, width: int, raw_width: int | None = None) -> int:
    """Number of planes in a ``.dat`` file of the given sensor size (from its size alone).

    Raises
    ------
    FormatError
        If the size is not a whole number of planes (a wrong width or height usually shows this way).
    """
    h, _, rw, nbytes = _geometry(height, width, raw_width)
    return _file_planes(Path(path), h, rw, nbytes)


def read_dat(
    path: str | os.PathLike,
    *,
    height: int,
    width: int,
    start: int = 0,
    stop: int | None = None,
    raw_width: int | None = None,
) -> np.ndarray:
    """Read planes ``[start, stop)`` of a Vidar ``.dat`` file without loading the rest.

    Parameters
    ----------
    path : str or os.PathLike
    height, width : int
        Sensor size of the returned planes.
    start, stop : int
        Plane range; ``stop=None`` reads to the end. Must satisfy ``0 <= start <= stop <= T``.
    raw_width : int, optional
        Stored columns per row when it differs from ``width`` (416 for some Vidar captures); the
        ``raw_width - width`` columns at the right are dropped.

    Returns
    -------
    ndarray of bool, shape (stop - start, height, width), C-contiguous
        Row 0 is the top row of the image.

    Raises
    ------
    FormatError
        If the file size is not a whole number of planes, or the file shrank while reading.
    InputError
        For a range outside the file, or ``height * raw_width`` not a multiple of 8.
    """
    p = Path(path)
    h, w, rw, nbytes = _geometry(height, width, raw_width)
    total = _file_planes(p, h, rw, nbytes)
    for name, value in (("start", start), ("stop", stop)):
        if value is None and name == "stop":
            continue
        check_int(name, value, what="a whole plane index")
    first = int(start)
    last = total if stop is None else int(stop)
    if not 0 <= first <= last <= total:
        raise InputError(
            f"plane range [{start}, {stop}) is outside the file's {total} planes (0 <= start <= stop <= {total})"
        )
    n = last - first
    out = np.empty((n, h, w), dtype=np.bool_)
    step = _chunk_planes(h, rw)
    with open(p, "rb") as f:
        f.seek(first * nbytes)
        for i in range(0, n, step):
            m = min(step, n - i)
            raw = np.fromfile(f, dtype=np.uint8, count=m * nbytes)
            if raw.size != m * nbytes:
                raise FormatError(f"{p}: expected {m * nbytes} bytes at plane {first + i}, got {raw.size}")
            _unpack(raw.reshape(m, nbytes), out[i:i + m], rw)
    return out


def read_spike_stream(
    path: str | os.PathLike,
    *,
    height: int,
    width: int,
    plane_rate_hz: float = VIDAR_PLANE_RATE_HZ,
    gain: float | None = None,
    threshold: float | None = None,
    start: int = 0,
    stop: int | None = None,
    raw_width: int | None = None,
) -> SpikeStream:
    """Read planes ``[start, stop)`` of a ``.dat`` file as a :class:`SpikeStream`.

    The file's plane 0 is taken as sensor time 0, so the stream starts at ``start / plane_rate_hz``.
    ``gain`` and ``threshold`` are not stored in the format: pass them when known (simulations)
    and leave them ``None`` for real recordings.
    """
    rate = check_positive("plane_rate_hz", plane_rate_hz)
    planes = read_dat(path, height=height, width=width, start=start, stop=stop, raw_width=raw_width)
    return SpikeStream(
        planes,
        plane_rate_hz=rate,
        start_s=int(start) / rate,
        gain=gain,
        threshold=threshold,
        meta={"source": str(path), "format": "vidar_dat", "first_plane": int(start),
              "raw_width": int(raw_width) if raw_width is not None else int(width)},
    )
