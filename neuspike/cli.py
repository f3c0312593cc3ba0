"""Shared pieces of the command-line tools."""

from __future__ import annotations

import argparse

__all__ = ["UsageError", "ArgumentParser"]


class UsageError(Exception):
    """A command-line usage error: the tool reports it in one line and exits with status 2."""


class ArgumentParser(argparse.ArgumentParser):
    """An ``argparse`` parser that raises :class:`UsageError` instead of exiting, so a tool's ``main``
    reports bad options the same way as bad input."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)
