"""Typed errors raised at the public boundary.

Every error names what was expected and what came. All derive from :class:`NeuSpikeError`
and from the built-in exception a caller would naturally catch (``ValueError``, ``OSError``).
"""

from __future__ import annotations


class NeuSpikeError(Exception):
    """Base class of every error this project raises on purpose."""


class InputError(NeuSpikeError, ValueError):
    """An argument or an array does not meet the documented contract."""


class FormatError(NeuSpikeError, ValueError):
    """A file's content is not a valid instance of its format (size, header, fields)."""


class SourceError(NeuSpikeError, OSError):
    """A source (image, video, recording) cannot be found or decoded."""


def one_line(exc: BaseException) -> str:
    """``Type: message`` of an exception on one line (its lines joined by `` | ``): how a command
    prints an error and how a result row records one."""
    text = f"{type(exc).__name__}: {exc}"
    return " | ".join(part.strip() for part in text.splitlines() if part.strip())
