"""Small named input checks for public functions.

Each raises :class:`neuspike.errors.InputError` with the expected and the actual value.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.errors import InputError


def check_ndim(name: str, array: np.ndarray, ndim: int) -> None:
    """Raise unless ``array`` has ``ndim`` dimensions."""
    if np.ndim(array) != ndim:
        raise InputError(f"{name}: expected a {ndim}-D array, got shape {np.shape(array)}")



def _float(name: str, value: Any, what: str) -> float:
    """``value`` as a float, or :class:`InputError` saying ``expected {what}`` (``true`` is not a number)."""
    if isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name}: expected {what}, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected {what}, got {value!r}") from None


def check_finite(name: str, value: Any) -> float:
    """Return ``value`` as a float, raising unless it is a finite number (``bool`` is refused)."""
    if isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name}: expected a number, got {value!r}")
    v = _float(name, value, "a number")
    if not np.isfinite(v):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    return v


def check_positive(name: str, value: Any) -> float:
    """Return ``value`` as a float, raising unless it is finite and > 0."""
    v = _float(name, value, "a positive number")
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name}: expected a positive finite number, got {value!r}")
    return v


def check_nonnegative(name: str, value: Any) -> float:
    """Return ``value`` as a float, raising unless it is finite and >= 0."""
    v = _float(name, value, "a number >= 0")
    if not np.isfinite(v) or v < 0:
        raise InputError(f"{name}: expected a finite number >= 0, got {value!r}")
    return v


def check_int(name: str, value: Any, *, minimum: int | None = None, what: str = "a whole number") -> int:
    """Return ``value`` as an int, raising unless it is an integer (Python's or NumPy's; ``bool`` is
    refused) and, where ``minimum`` is given, at least ``minimum``. ``what`` names the expected value
    in the message (``"expected {what} >= {minimum}, got ..."``)."""
    expected = what if minimum is None else f"{what} >= {minimum}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{name}: expected {expected}, got {value!r}")
    if minimum is not None and value < minimum:
        raise InputError(f"{name}: expected {expected}, got {value!r}")
    return int(value)


def check_positive_int(name: str, value: Any) -> int:
    """Return ``value`` as an int, raising unless it is a whole number >= 1."""
    return check_int(name, value, minimum=1)


def check_size(name: str, width: Any, height: Any) -> tuple[int, int]:
    """Return ``(width, height)`` as ints, raising unless both are whole numbers >= 1."""
    return check_positive_int(f"{name} width", width), check_positive_int(f"{name} height", height)


def check_spike_window(planes: Any, key_plane: Any) -> tuple[np.ndarray, int]:
    """Validate a spike window and a key plane; return them as ``(bool array, int)``.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W), T >= 1
    key_plane : int in [0, T)

    Raises
    ------
    InputError
        On a wrong type, dtype, shape or an out-of-range key plane.
    """
    if not isinstance(planes, np.ndarray):
        raise InputError(f"planes: expected a numpy array of bool (T, H, W), got {type(planes).__name__}")
    if planes.ndim != 3:
        raise InputError(f"planes: expected shape (T, H, W), got {planes.shape}")
    if planes.dtype != np.bool_:
        raise InputError(f"planes: expected dtype bool, got {planes.dtype}")
    if planes.shape[0] < 1:
        raise InputError(f"planes: expected at least one plane, got shape {planes.shape}")
    key_plane = check_int("key_plane", key_plane, what="an integer plane index")
    if not 0 <= key_plane < planes.shape[0]:
        raise InputError(f"key_plane: expected an index in [0, {planes.shape[0]}), got {key_plane}")
    return planes, int(key_plane)


def parse_size(text: str) -> tuple[int, int]:
    """``"400x250"`` -> ``(400, 250)`` (width, height), both whole numbers >= 1.

    Raises
    ------
    InputError
        For anything else, naming what was expected.
    """
    parts = str(text).strip().lower().replace(" ", "").split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise InputError(f"size: expected WxH such as 400x250, got {text!r}")
    w, h = int(parts[0]), int(parts[1])
    if w < 1 or h < 1:
        raise InputError(f"size: width and height must be at least 1, got {text!r}")
    return w, h
