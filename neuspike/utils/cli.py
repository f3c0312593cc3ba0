"""Shared pieces of the command-line tools."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["UsageError", "ArgumentParser", "PRECISIONS", "WEIGHTS_ENV", "weights_dir_from_env"]

#: The precisions a learned method runs in (``"auto"`` resolved per device and module by
#: :mod:`neuspike.methods.precision`, which re-exports this): here, so that a command's parser offers
#: them without importing numpy or torch.
PRECISIONS = ("auto", "float32", "bfloat16")

#: Environment variable naming the folder of published weights (read by command-line entry points only).
WEIGHTS_ENV = "NEUSPIKE_WEIGHTS"


class UsageError(Exception):
    """A command-line usage error: the tool reports it in one line and exits with status 2."""


class ArgumentParser(argparse.ArgumentParser):
    """An ``argparse`` parser that raises :class:`UsageError` instead of exiting, so a tool's ``main``
    reports bad options the same way as bad input."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)


def weights_dir_from_env(cli_value: str | os.PathLike | None) -> Path | None:
    """The weights folder of a command line: its ``--weights`` value, else ``$NEUSPIKE_WEIGHTS``, else ``None``.

    Only ``main()`` functions call this; library code takes the folder as an argument.
    """
    if cli_value is not None:
        return Path(cli_value).resolve()
    env = os.environ.get(WEIGHTS_ENV)
    return Path(env).resolve() if env else None
