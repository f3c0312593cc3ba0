"""Random generators derived from a seed and a cell.

Every random draw in the suite comes from a generator passed in. Entry points derive one from the
user's seed and the identity of the work (the cell: scene, condition, and the part of the
simulation), so that the same seed gives the same bytes and different cells get independent
streams (NumPy's ``SeedSequence`` spawn keys).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import numpy as np

from neuspike.utils.checks import check_int


def _spawn_key(keys: tuple[Any, ...]) -> tuple[int, ...]:
    text = json.dumps(keys, sort_keys=True, default=repr, separators=(",", ":"))
    digest = hashlib.sha256(text.encode()).digest()
    return tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4))


def derive_rng(seed: int, *keys: Any) -> np.random.Generator:
    """A generator determined by ``seed`` and the JSON-serialisable ``keys`` (e.g. a cell).

    The same ``(seed, keys)`` always gives the same stream; different keys give statistically
    independent streams.
    """
    seed = check_int("seed", seed, minimum=0)
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=_spawn_key(keys)))
