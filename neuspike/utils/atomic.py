"""Writing files so that nothing is ever half-written.

Every writer in the suite writes into a temporary file in the destination's folder and then
renames it over the destination (``os.replace`` is atomic on one file system). :func:`publish`
does that rename and first gives the file the permissions an ordinary ``open`` would have
(``0o666`` less the process umask): ``tempfile.mkstemp`` creates files readable only by their
owner, which would leak into every output.
"""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

from neuspike.utils.jsonio import json_default


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_umask()


def temp_beside(path: str | os.PathLike) -> tuple[int, str]:
    """``(fd, name)`` of a new temporary file in ``path``'s folder (hidden, ``.tmp`` suffix)."""
    p = Path(path)
    return tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")


def publish(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """Give ``tmp`` ordinary file permissions and rename it over ``path`` atomically."""
    os.chmod(tmp, _FILE_MODE)
    os.replace(tmp, path)


@contextmanager
def replacing(path: str | os.PathLike) -> Iterator[str]:
    """Yield the name of a temporary file beside ``path``; write it inside the ``with`` block.

    On success the file replaces ``path`` in one step (with ordinary permissions); on any error
    it is removed and ``path`` is untouched.
    """
    fd, tmp = temp_beside(path)
    os.close(fd)
    try:
        yield tmp
        publish(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_with(path: str | os.PathLike, write: Callable[[Any], Any], *, parents: bool = True) -> Path:
    """Write a file atomically and durably: ``write(fileobj)`` fills a temporary file beside ``path``
    (its parent folders created first unless ``parents`` is False), which is flushed to disk and
    then replaces ``path`` in one step. A crash leaves either the old file or the new one."""
    path = Path(path)
    if parents:
        path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp, open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    return path


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; on any error the destination is untouched."""
    return write_with(path, lambda f: f.write(data))


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    """Write indented, key-sorted JSON atomically (NumPy values, dataclasses, sets and paths encoded)."""
    return write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=json_default) + "\n")
