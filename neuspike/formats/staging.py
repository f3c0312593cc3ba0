"""Output folders that change in one step: a recording folder is entirely old or entirely new.

Each file of a recording is written atomically, but a folder of several files is not: a run killed
after replacing ``spikes.dat`` and before ``meta.json`` would leave a folder that looks complete
and mixes two runs. :func:`staged_folder` writes a whole folder under a temporary name beside the
target (``.<name>.<id>.staging``) and swaps it in when complete: with ``renameat2(RENAME_EXCHANGE)``
where the system has it (Linux, one atomic step), otherwise by two renames (a moment where the
folder is absent, never mixed). Entries of the old folder that the run does not write (a user's own
files) are carried over into the new one; temporaries of the run's own entries (``.<entry>.<id>.tmp``,
left by a killed run) never are. A killed run's staging folders are removed by the next
run into the same target, after giving back any such entries. One run at a time per target: a
second run started meanwhile removes the first one's staging folder as stale.

:func:`check_writable_folder` tells, before any work, whether an output folder can be written.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from neuspike.errors import InputError

__all__ = ["check_writable_folder", "remove_stale_temporaries", "staged_folder"]

_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def check_writable_folder(folder: str | os.PathLike, *, what: str = "--out", create: bool = True) -> Path:
    """Create ``folder`` if needed and check that a file can be written in it.

    With ``create=False`` nothing is created: the folder, or where it does not exist yet its
    nearest existing parent, must take a file (a failed command leaves no empty folder behind).

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    InputError
        One line naming the folder and the reason (not a folder, no permission, read-only, ...).
    """
    out = Path(folder)
    try:
        if out.exists() and not out.is_dir():
            raise InputError(f"{what} {out}: exists and is not a folder")
        if create:
            out.mkdir(parents=True, exist_ok=True)
        probe_dir = out
        while not probe_dir.exists():
            probe_dir = probe_dir.parent
        if not probe_dir.is_dir():
            raise InputError(f"{what} {out}: {probe_dir} is not a folder")
        fd, probe = tempfile.mkstemp(dir=probe_dir, prefix=".write-check.", suffix=".tmp")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"{what} {out}: cannot write there ({exc.strerror or exc})") from None
    return out


def remove_stale_temporaries(folder: str | os.PathLike, pattern: str = ".*.tmp") -> int:
    """Remove hidden temporary files (``.<name>.<random>.tmp``) a killed run left in ``folder``.

    Only call this where no other process writes at the same time (one run per output folder).
    Returns the number of files removed.
    """
    removed = 0
    for path in Path(folder).glob(pattern):
        if path.is_file():
            try:
                path.unlink()
                removed += 1
            except FileNotFoundError:
                pass
    return removed


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two existing paths; False when the system cannot."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: no exchange on this file system
        return False
    raise OSError(err, os.strerror(err), str(b))


def _is_ours(name: str, ours: frozenset[str]) -> bool:
    """An entry the run writes, or a temporary that some run of the suite left when it was killed,
    whatever it was writing: ``.<entry>.<random>.tmp`` (atomic writes) and the writers' partial files
    and folders ``.<stem>.partial<suffix>`` and ``.<entry>.partial`` (:mod:`neuspike.video.writers`).
    A temporary is never a user's file, so it is never carried into the new folder."""
    return name in ours or (name.startswith(".") and (".partial" in name or name.endswith(".tmp")))


def _carry(src: Path, dst: Path, ours: frozenset[str]) -> None:
    """Move the entries of ``src`` that a run does not write (``ours``) into ``dst``; never a temporary of ours."""
    for entry in list(src.iterdir()):
        if not _is_ours(entry.name, ours) and not (dst / entry.name).exists():
            os.replace(entry, dst / entry.name)


def _clean_stale(out: Path, ours: frozenset[str]) -> None:
    for stale in out.parent.glob(f".{out.name}.*.staging"):
        if not stale.is_dir():
            continue
        if out.is_dir():
            _carry(stale, out, ours)
        shutil.rmtree(stale, ignore_errors=True)


@contextmanager
def staged_folder(out: str | os.PathLike, *, ours: Iterable[str]) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``out``; when the block succeeds it becomes ``out``.

    Parameters
    ----------
    out : path
        The folder to create or replace.
    ours : iterable of str
        Names of the entries the run writes. Other entries of an existing ``out`` are kept (moved
        into the new folder); ours are replaced as a whole, so none of the old run's remain.

    On an exception inside the block the temporary folder is removed and ``out`` is untouched.
    """
    target = Path(out)
    if target.is_symlink():  # replace the folder it points to, not the link
        target = target.resolve()
    names = frozenset(ours)
    check_writable_folder(target.parent, what="output folder's parent")
    if target.exists() and not target.is_dir():
        raise InputError(f"{target}: exists and is not a folder")
    _clean_stale(target, names)
    staging = target.parent / f".{target.name}.{uuid.uuid4().hex[:12]}.staging"
    staging.mkdir()
    try:
        yield staging
        if target.is_dir():
            _carry(target, staging, names)
            if _exchange(staging, target):
                shutil.rmtree(staging, ignore_errors=True)  # now the old folder
                return
            old = target.parent / f".{target.name}.{uuid.uuid4().hex[:12]}.staging"
            os.replace(target, old)
            os.replace(staging, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(staging, target)
    except BaseException:
        if staging.is_dir() and target.is_dir():
            _carry(staging, target, names)  # give back the carried entries before discarding
        shutil.rmtree(staging, ignore_errors=True)
        raise
