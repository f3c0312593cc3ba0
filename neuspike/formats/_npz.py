"""Reading ``.npz`` archives defensively: every malformed archive becomes a :class:`FormatError`.

``numpy.load`` trusts the archive: a member's header may declare a shape of a terabyte (numpy
allocates it before reading), a corrupt member surfaces ``zlib.error``, ``EOFError`` or
``BadZipFile`` only when the member is read, and a plain ``.npy`` file comes back as an array
instead of an archive. :class:`NpzArchive` reads the zip directory and each member's ``.npy``
header itself and checks, before allocating anything, that the declared shape and dtype match the
bytes the member holds (which a deflated member cannot exceed ~1032 times its compressed size).
"""

from __future__ import annotations

import math
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from neuspike.errors import FormatError

__all__ = ["NpzArchive"]

#: Deflate cannot expand data more than ~1032:1; a member declaring more is lying.
_MAX_DEFLATE_RATIO = 1100
#: Errors the zip and npy machinery raise on damaged bytes.
_DAMAGE = (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, struct.error, NotImplementedError,
           RuntimeError, KeyError, UnicodeDecodeError, SyntaxError, OverflowError, TypeError, IndexError)
_NPY_MAGIC = b"\x93NUMPY"


class NpzArchive:
    """The arrays of an ``.npz`` archive, read one member at a time with bounded memory.

    Parameters
    ----------
    path : Path
        An existing file.

    Raises
    ------
    FormatError
        If the file is not a zip archive (a plain ``.npy`` file is named as such) or its directory
        is damaged.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._size = self.path.stat().st_size
        try:
            with open(self.path, "rb") as fh:
                head = fh.read(len(_NPY_MAGIC))
        except OSError as exc:
            raise FormatError(f"{self.path}: cannot read the file ({exc})") from None
        if head == _NPY_MAGIC:
            raise FormatError(f"{self.path}: a single .npy array, not an .npz archive of named arrays")
        try:
            self._zip = zipfile.ZipFile(self.path)
            infos = self._zip.infolist()
        except _DAMAGE as exc:
            raise FormatError(f"{self.path}: not a readable .npz archive ({type(exc).__name__}: {exc})") from None
        self._members = {}
        for info in infos:
            if info.filename.endswith(".npy"):
                self._members.setdefault(info.filename[:-4], info)
        self.files = list(self._members)

    def __enter__(self) -> "NpzArchive":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._zip.close()

    def __contains__(self, key: str) -> bool:
        return key in self._members

    def __getitem__(self, key: str) -> np.ndarray:
        return self.array(key)

    def array(self, key: str) -> np.ndarray:
        """The array stored under ``key``, after checking its header against the member's size."""
        info = self._members.get(key)
        if info is None:
            raise FormatError(f"{self.path}: no array {key!r}; the archive holds {self.files}")
        where = f"{self.path}: array {key!r}"
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise FormatError(f"{where}: unsupported zip compression method {info.compress_type}")
        if info.compress_size > self._size:
            raise FormatError(f"{where}: the member claims {info.compress_size} compressed bytes, "
                              f"more than the file's {self._size}")
        limit = info.compress_size * (1 if info.compress_type == zipfile.ZIP_STORED else _MAX_DEFLATE_RATIO)
        if info.file_size > limit + 64:
            raise FormatError(f"{where}: the member claims {info.file_size} bytes from {info.compress_size} "
                              f"compressed bytes, more than its compression can hold")
        try:
            with self._zip.open(info) as fp:
                version = np.lib.format.read_magic(fp)
                if version == (1, 0):
                    shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
                elif version in ((2, 0), (3, 0)):
                    shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
                else:
                    raise ValueError(f"unknown .npy version {version}")
                header_bytes = fp.tell()
                if dtype.hasobject:
                    raise FormatError(f"{where}: holds Python objects (dtype {dtype}); refusing to unpickle")
                count = math.prod(int(n) for n in shape)
                nbytes = count * dtype.itemsize
                if nbytes != info.file_size - header_bytes:
                    raise FormatError(
                        f"{where}: its header declares shape {tuple(shape)} of {dtype} ({nbytes} bytes), "
                        f"but the member holds {info.file_size - header_bytes} bytes of data"
                    )
                buf = bytearray(nbytes)
                view = memoryview(buf)
                got = 0
                while got < nbytes:
                    n = fp.readinto(view[got:])
                    if not n:
                        break
                    got += n
                if got != nbytes:
                    raise FormatError(f"{where}: expected {nbytes} bytes of data, found {got}")
        except FormatError:
            raise
        except _DAMAGE as exc:
            raise FormatError(f"{where}: damaged member ({type(exc).__name__}: {exc})") from None
        flat = np.frombuffer(buf, dtype=dtype, count=count)
        return flat.reshape(shape, order="F" if fortran else "C")
