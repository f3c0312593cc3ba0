"""Spike planes in NumPy ``.npz`` archives.

Two layouts are read:

* this project's own (:func:`write_spike_npz`): ``planes`` bool (T, H, W) plus ``plane_rate_hz``,
  ``start_s`` and, when known, ``gain``, ``threshold`` and ``dark_rate`` (0-d float64 arrays) and ``meta_json``;
* the Spike-Zoo / UHSR layout: ``spk`` uint8 (T, H, W) of 0 and 1, stored upright (row 0 at the
  top, no flip), no rate stored; other arrays (``label``, ...) are ignored.

Planes are never flipped: unlike Vidar ``.dat`` files, ``.npz`` archives in the field store
planes upright.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from neuspike.utils.atomic import write_with
from neuspike.utils.checks import check_positive
from neuspike.errors import FormatError, InputError, SourceError
from neuspike.formats._npz import NpzArchive
from neuspike.streams import VIDAR_PLANE_RATE_HZ, SpikeStream

__all__ = ["read_spike_npz", "write_spike_npz"]

#: Keys tried, in order, when ``key`` is not given.
_PLANE_KEYS = ("planes", "spk")


#: Longest ``meta_json`` read (characters) and deepest nesting accepted.
_MAX_META_CHARS = 1 << 24
_MAX_META_DEPTH = 64


def _scalar(archive: Any, key: str, path: Path) -> float | None:
    if key not in archive.files:
        return None
    a = np.asarray(archive[key])
    if a.shape != () or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise FormatError(f"{path}: expected {key!r} to be a single number, got shape {a.shape} dtype {a.dtype}")
    v = float(a)
    if not np.isfinite(v):
        raise FormatError(f"{path}: expected {key!r} to be a finite number, got {v!r}")
    return v


def _depth(value: Any) -> int:
    """Nesting depth of parsed JSON, without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, d = stack.pop()
        deepest = max(deepest, d)
        if isinstance(v, dict):
            stack.extend((x, d + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, d + 1) for x in v)
    return deepest


def _meta_from(a: np.ndarray, path: Path) -> dict[str, Any]:
    """The ``meta_json`` array (a 0-d string) as a JSON object of bounded size and depth."""
    if a.shape != () or a.dtype.kind not in "US":
        raise FormatError(f"{path}: expected 'meta_json' to be one string, got shape {a.shape} dtype {a.dtype}")
    text = a.item()
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    if len(text) > _MAX_META_CHARS:
        raise FormatError(f"{path}: 'meta_json' is {len(text)} characters long (at most {_MAX_META_CHARS})")
    try:
        meta = json.loads(text)
    except RecursionError:
        raise FormatError(f"{path}: 'meta_json' nests deeper than {_MAX_META_DEPTH} levels") from None
    except ValueError as err:
        raise FormatError(f"{path}: 'meta_json' is not a JSON object ({err})") from None
    if not isinstance(meta, dict):
        raise FormatError(f"{path}: 'meta_json' is not a JSON object, got {type(meta).__name__}")
    if _depth(meta) > _MAX_META_DEPTH:
        raise FormatError(f"{path}: 'meta_json' nests deeper than {_MAX_META_DEPTH} levels")
    return meta


def _planes_from(a: np.ndarray, path: Path, key: str) -> np.ndarray:
    if a.ndim != 3:
        raise FormatError(f"{path}: expected {key!r} of shape (T, H, W), got {a.shape}")
    if a.dtype == np.bool_:
        return np.ascontiguousarray(a)
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise FormatError(f"{path}: expected {key!r} to hold 0/1 numbers, got dtype {a.dtype}")
    if a.size:
        bad = (a != 0) & (a != 1)
        if bad.any():
            values = np.unique(a[bad])[:5].tolist()
            raise FormatError(
                f"{path}: expected {key!r} to hold only 0 and 1, found {int(np.count_nonzero(bad))} other "
                f"entries (e.g. {values})"
            )
    return np.ascontiguousarray(a != 0)


def read_spike_npz(
    path: str | os.PathLike,
    *,
    key: str | None = None,
    plane_rate_hz: float | None = None,
) -> SpikeStream:
    """Read spike planes from an ``.npz`` archive.

    Parameters
    ----------
    path : str or os.PathLike
    key : str, optional
        The array holding the planes; by default ``planes`` (this project's layout), else ``spk``
        (Spike-Zoo / UHSR).
    plane_rate_hz : float, optional
        The plane rate. By default the rate stored in the archive, else 20,000 (Vidar); a value
        that contradicts a stored rate raises.

    Returns
    -------
    SpikeStream
        Planes upright (no flip), with the stored start time, gain and threshold when present
        (``gain=None`` for real recordings). ``meta`` names the source file and key.

    Raises
    ------
    SourceError
        If the file is missing.
    FormatError
        If the file is not a readable ``.npz`` archive (a damaged member, a header declaring more
        data than the member holds, a plain ``.npy`` file), the key is absent, the planes are not
        (T, H, W) or hold values other than 0 and 1, or a stored number is out of range.
    InputError
        If ``plane_rate_hz`` contradicts the rate stored in the archive.
    """
    p = Path(path)
    if not p.is_file():
        raise SourceError(f"no such spike file: {p}")
    with NpzArchive(p) as archive:
        names = list(archive.files)
        if key is None:
            found = [k for k in _PLANE_KEYS if k in names]
            if not found:
                raise FormatError(f"{p}: no spike planes under {' or '.join(map(repr, _PLANE_KEYS))}; "
                                  f"the archive holds {names}; pass key=")
            key = found[0]
        elif key not in names:
            raise FormatError(f"{p}: no array {key!r}; the archive holds {names}")
        planes = _planes_from(archive[key], p, key)
        stored_rate = _scalar(archive, "plane_rate_hz", p)
        start_s = _scalar(archive, "start_s", p)
        gain = _scalar(archive, "gain", p)
        threshold = _scalar(archive, "threshold", p)
        dark_rate = _scalar(archive, "dark_rate", p)
        meta: dict[str, Any] = {}
        if "meta_json" in names:
            meta = _meta_from(archive["meta_json"], p)
    if plane_rate_hz is None:
        rate = stored_rate if stored_rate is not None else VIDAR_PLANE_RATE_HZ
    else:
        rate = check_positive("plane_rate_hz", plane_rate_hz)
        if stored_rate is not None and stored_rate != rate:
            raise InputError(f"plane_rate_hz: {p} stores {stored_rate} planes/s, but {rate} was given")
    meta.update({"source": str(p), "format": "npz", "key": key,
                 "plane_rate_hz_from": "file" if stored_rate is not None else
                 ("argument" if plane_rate_hz is not None else "default (Vidar)")})
    try:
        return SpikeStream(planes, plane_rate_hz=rate, start_s=start_s or 0.0, gain=gain, threshold=threshold,
                           dark_rate=dark_rate, meta=meta)
    except InputError as err:  # a stored rate, start, gain, threshold or dark rate out of range
        raise FormatError(f"{p}: {err}") from None


def _json_default(value: Any) -> Any:
    """NumPy scalars and arrays and paths as JSON; anything else is refused (``TypeError``), not repr'd."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def write_spike_npz(path: str | os.PathLike, stream: SpikeStream) -> Path:
    """Write a :class:`SpikeStream` as a compressed ``.npz`` archive, atomically.

    Stores ``planes`` (bool, upright), ``plane_rate_hz``, ``start_s``, ``gain``, ``threshold`` and
    ``dark_rate`` (each when not ``None``) and the stream's ``meta`` as ``meta_json``; :func:`read_spike_npz` reads
    it back to an equal stream. The file is written to a temporary file in the same folder and
    renamed into place, so a failure leaves no partial file.

    Raises
    ------
    InputError
        If ``stream`` is not a SpikeStream or its meta cannot be stored as JSON.
    """
    if not isinstance(stream, SpikeStream):
        raise InputError(f"stream: expected a SpikeStream, got {type(stream).__name__}")
    try:
        meta_json = json.dumps(stream.meta, default=_json_default)
    except (TypeError, ValueError) as err:
        raise InputError(f"stream.meta: cannot be stored as JSON ({err})") from None
    arrays: dict[str, np.ndarray] = {
        "planes": stream.planes,
        "plane_rate_hz": np.float64(stream.plane_rate_hz),
        "start_s": np.float64(stream.start_s),
        "meta_json": np.array(meta_json),
    }
    if stream.gain is not None:
        arrays["gain"] = np.float64(stream.gain)
    if stream.threshold is not None:
        arrays["threshold"] = np.float64(stream.threshold)
    if stream.dark_rate is not None:
        arrays["dark_rate"] = np.float64(stream.dark_rate)
    return write_with(path, lambda f: np.savez_compressed(f, **arrays), parents=False)
