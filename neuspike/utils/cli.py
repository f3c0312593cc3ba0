"""Shared pieces of the command-line tools."""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

__all__ = ["UsageError", "ArgumentParser", "MethodOptions", "PRECISIONS", "READ_OUTS", "WEIGHTS_ENV",
           "weights_dir_from_env"]

#: The precisions a learned method runs in (``"auto"`` resolved per device and module by
#: :mod:`neuspike.methods.precision`, which re-exports this): here, so that a command's parser offers
#: them without importing numpy or torch.
PRECISIONS = ("auto", "float32", "bfloat16")

#: What a recurrent event network's frame shows in a video (``--read-out``; :mod:`neuspike.video`).
READ_OUTS = ("key", "window")

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


@dataclass(frozen=True)
class MethodOptions:
    """How every command builds its methods: the options declared once (:meth:`add_arguments`), read and
    checked once (:meth:`from_args`), and handed to :func:`neuspike.methods.create` as keywords
    (:meth:`create_kwargs`).

    ``weights_dir``: the folder of published weights (``--weights``, else ``$NEUSPIKE_WEIGHTS``; the
    suite's own trained weights ship with it); ``device``: the torch device of the learned methods;
    ``precision``: their arithmetic (``None``: each method's own, ``"auto"`` for the trained ones);
    ``compiled``: through ``torch.compile``; ``read_out``: what a recurrent event network's video frame
    shows (``None``: the key instant, the default).
    """

    weights_dir: Path | None = None
    device: str = "cpu"
    precision: str | None = None
    compiled: bool = False
    read_out: str | None = None

    #: The options a command may offer, as flags.
    FLAGS = ("weights", "device", "precision", "compile", "read_out", "plugin")

    @staticmethod
    def add_arguments(parser: Any, *, flags: Sequence[str] = ("weights", "device", "precision"),
                      device_note: str = "") -> None:
        """Declare ``flags`` (of :data:`FLAGS`) on ``parser`` (a parser or an argument group), with one
        wording in every command; ``device_note`` adds what the device means to this command."""
        unknown = sorted(set(flags) - set(MethodOptions.FLAGS))
        if unknown:
            raise ValueError(f"flags: unknown {unknown}; choose from {MethodOptions.FLAGS}")
        if "weights" in flags:
            parser.add_argument("--weights", metavar="DIR",
                                help=f"folder of published weights, e.g. FireNet's (default: ${WEIGHTS_ENV}); the "
                                "suite's own trained weights ship with it and need no flag")
        if "device" in flags:
            parser.add_argument("--device", default="cpu",
                                help="torch device of the learned methods (default: cpu; e.g. cuda); refused when "
                                "it is not here, or when no chosen method runs on a torch device" + device_note)
        if "precision" in flags:
            parser.add_argument("--precision", choices=PRECISIONS,
                                help="arithmetic of the learned methods (default: each method's own: auto, bfloat16 "
                                "only where a measured step is faster than float32 on this device; float32 for "
                                "numbers that match other machines)")
        if "compile" in flags:
            parser.add_argument("--compile", action="store_true",
                                help="run the learned methods through torch.compile (compiled once per input size, "
                                "5-20 s, outside the per-frame times; needs a C++ compiler)")
        if "read_out" in flags:
            parser.add_argument("--read-out", choices=READ_OUTS,
                                help="recurrent event networks (e2vid, firenet-sim, firenet): 'key' (default) steps "
                                "the events after the last full window as a partial one so a frame shows its own "
                                "instant; 'window' shows the last full window (at most one window earlier, said in "
                                "the label), one network step fewer per frame, at the price of frames that lag on "
                                "fast motion")
        if "plugin" in flags:
            parser.add_argument("--plugin", action="append", default=[], metavar="MODULE",
                                help="import MODULE (a module name or a .py path; in every worker of a parallel run) "
                                "to register extra methods (repeatable; also the modules in $NEUSPIKE_PLUGINS); this "
                                "runs its code, so name only files you trust")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "MethodOptions":
        """The options of parsed arguments, checked: a weights folder that is not one is refused naming where
        it came from (``--weights`` or ``$NEUSPIKE_WEIGHTS``); a blank device is refused. (Whether the
        device exists is for :meth:`check_device`, which imports torch only when a learned method needs it.)"""
        from neuspike.errors import InputError

        given = getattr(args, "weights", None)
        weights = weights_dir_from_env(given)
        if weights is not None and not weights.is_dir():
            origin = "--weights" if given is not None else f"${WEIGHTS_ENV}"
            raise InputError(f"{origin}: {str(weights)!r} is not a folder")
        device = getattr(args, "device", "cpu") or "cpu"
        if not isinstance(device, str) or not device.strip():
            raise InputError(f"--device: expected a torch device name such as 'cpu' or 'cuda', got {device!r}")
        precision = getattr(args, "precision", None)
        if precision is not None and precision not in PRECISIONS:
            raise InputError(f"--precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
        read_out = getattr(args, "read_out", None)
        if read_out is not None and read_out not in READ_OUTS:
            raise InputError(f"--read-out: expected one of {', '.join(READ_OUTS)}, got {read_out!r}")
        return cls(weights_dir=weights, device=device, precision=precision,
                   compiled=bool(getattr(args, "compile", False)), read_out=read_out)

    def create_kwargs(self) -> dict[str, Any]:
        """The keywords of :func:`neuspike.methods.create` and :func:`~neuspike.methods.create_many`."""
        return {"weights_dir": self.weights_dir, "device": self.device, "precision": self.precision,
                "compiled": self.compiled}
