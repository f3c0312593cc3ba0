"""Canonical JSON and stable hashes: equal data give equal text and equal keys.

Used for cache keys, run identities and every JSON file the suite writes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["canonical_json", "json_default", "portable_path", "stable_hash"]


def json_default(value: Any) -> Any:
    """JSON encoding of NumPy values, dataclasses, paths and sets (sorted)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        as_dict = getattr(value, "as_dict", None)
        return as_dict() if callable(as_dict) else dataclasses.asdict(value)
    if isinstance(value, (set, frozenset)):
        return sorted(value)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return repr(value)


def canonical_json(obj: Any) -> str:
    """Compact JSON with sorted keys: equal data give equal text."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=json_default)


def stable_hash(obj: Any, length: int = 20) -> str:
    """Hex SHA-256 of :func:`canonical_json` of ``obj``, cut to ``length`` characters."""
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()[:length]


def portable_path(path: str | os.PathLike) -> str:
    """``path`` as it can be written into a committed report: relative to the current folder where
    it lies inside it or beside it (``../shared/weights``), else ``.../`` and its last two parts
    (no absolute path of the machine that made the report)."""
    text = os.fspath(path)
    if not os.path.isabs(text):
        return text
    rel = os.path.relpath(text, Path.cwd())
    if not rel.startswith(os.pardir + os.sep + os.pardir) and rel != os.pardir + os.sep + os.pardir:
        return rel
    parts = Path(text).parts
    return os.path.join("...", *parts[-2:])
