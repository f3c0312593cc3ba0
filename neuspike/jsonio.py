"""Canonical JSON and stable hashes: equal data give equal text and equal keys.

Used for cache keys, run identities and every JSON file the suite writes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from typing import Any

import numpy as np

__all__ = ["canonical_json", "json_default", "stable_hash"]


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
