"""Where a learned method's weights come from, and how they are read and written.

Two kinds of weights exist:

* **Our own**, trained here with ``python -m neuspike.train``: they ship inside the package, in
  :data:`PACKAGE_WEIGHTS` (``neuspike/trained/``), as ``<name>.safetensors`` beside a small JSON card
  ``<name>.json`` (training spec, steps, data, validation metrics, sha256 of the tensors file). They
  are found without any flag.
* **Published** ones (FireNet's ``.pt`` files) come from a folder the user names. Library code takes
  that folder as an explicit ``weights_dir`` argument; only command-line entry points read the
  ``NEUSPIKE_WEIGHTS`` environment variable (:data:`WEIGHTS_ENV`), through :func:`weights_dir_from_env`.

:func:`resolve_weights` looks a file up in the given folder (and its named sub-folders), then in the
package's folder, and raises one :class:`WeightsNotFound` naming every path it tried.

Loading is strict: every tensor in the file is used, none of the module's is missing, all shapes
agree; anything else, a truncated file included, is a :class:`~neuspike.errors.FormatError`.
Published ``.pt`` files are opened with ``torch.load(..., weights_only=True)`` only, so a pickled
payload is refused rather than executed.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import warnings
from pathlib import Path
from typing import Any, Mapping, Sequence

import torch
from torch import nn

from neuspike.utils import atomic
from neuspike.utils.cli import WEIGHTS_ENV, weights_dir_from_env  # noqa: F401  (the command line's; re-exported)
from neuspike.errors import FormatError, one_line
from neuspike.methods import MethodUnavailable

__all__ = [
    "PACKAGE_WEIGHTS",
    "WeightsMismatch",
    "check_card",
    "WEIGHTS_ENV",
    "WeightsNotFound",
    "file_sha256",
    "load_safetensors",
    "load_state_strict",
    "load_torch_state",
    "read_card",
    "resolve_weights",
    "save_safetensors",
    "tensor_names",
    "weights_dir_from_env",
]

#: Folder of the weights trained here, shipped with the package.
PACKAGE_WEIGHTS = Path(__file__).resolve().parents[1] / "trained"


class WeightsNotFound(MethodUnavailable):
    """A weights file is in none of the places looked in; the message names every path tried."""

    def __init__(self, file_name: str, tried: Sequence[Path], hint: str = "") -> None:
        self.file_name = file_name
        self.tried = tuple(tried)
        where = ", ".join(str(p) for p in self.tried) or "nowhere (no folder given)"
        super().__init__(f"weights {file_name} not found; looked in: {where}" + (f". {hint}" if hint else ""))


class WeightsMismatch(UserWarning):
    """A weights file whose sha256 is not the one its JSON card records (changed after export)."""


def check_card(path: str | os.PathLike, sha256: str) -> None:
    """Warn (:class:`WeightsMismatch`) when the card beside ``path`` records another sha256 than ``sha256``.

    A file without a card (published ``.pt`` weights) or a card without ``sha256`` passes.
    """
    card = read_card(path)
    recorded = (card or {}).get("sha256")
    if recorded is not None and recorded != sha256:
        warnings.warn(f"{path}: sha256 {sha256[:12]}... differs from its card's {str(recorded)[:12]}...; "
                      "the file changed after it was exported (its card no longer describes it)",
                      WeightsMismatch, stacklevel=3)


def resolve_weights(file_name: str, weights_dir: str | os.PathLike | None, *,
                    subdirs: Sequence[str] = ()) -> Path:
    """Locate ``file_name``: in ``weights_dir/<sub>/`` for each of ``subdirs``, in ``weights_dir``, then in the package.

    Parameters
    ----------
    file_name : str
        The file's name (no folders).
    weights_dir : path or None
        The folder the user named (``None``: only the package's own weights are looked at).
    subdirs : sequence of str
        Sub-folders of ``weights_dir`` tried first (e.g. ``("firenet",)``).

    Returns
    -------
    Path of the first existing candidate.

    Raises
    ------
    WeightsNotFound
        Naming every path tried.
    """
    if not isinstance(file_name, str) or not file_name or Path(file_name).name != file_name:
        raise FormatError(f"weights file name must be a plain file name, got {file_name!r}")
    candidates: list[Path] = []
    if weights_dir is not None:
        root = Path(weights_dir)
        candidates += [root / sub / file_name for sub in subdirs] + [root / file_name]
    candidates.append(PACKAGE_WEIGHTS / file_name)
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    hint = "" if weights_dir is not None else f"pass a weights folder (CLI --weights DIR or ${WEIGHTS_ENV})"
    raise WeightsNotFound(file_name, candidates, hint)


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def load_state_strict(module: nn.Module, state: Mapping[str, torch.Tensor], source: str, *,
                      may_lack: tuple[str, ...] = ()) -> nn.Module:
    """Load ``state`` into ``module``: same names, same shapes, nothing left over; cast to the module's dtypes.

    ``may_lack``: name prefixes of the module's tensors that ``state`` may leave out (they keep the
    module's own values): parts that compute the identity as constructed, added to a design after
    the weights were trained (training's ``init_from`` only).

    Raises
    ------
    FormatError
        Naming the missing, unused or mis-shaped tensors and ``source``.
    """
    own = module.state_dict()
    missing = sorted(k for k in set(own) - set(state) if not k.startswith(may_lack))
    unused = sorted(set(state) - set(own))
    if missing or unused:
        raise FormatError(f"{source}: missing tensors {missing[:8]}{'...' if len(missing) > 8 else ''}, "
                          f"unused tensors {unused[:8]}{'...' if len(unused) > 8 else ''}")
    wrong = [f"{k}: file {tuple(state[k].shape)}, network {tuple(own[k].shape)}"
             for k in state if tuple(state[k].shape) != tuple(own[k].shape)]
    if wrong:
        raise FormatError(f"{source}: shapes differ: {wrong[:8]}")
    module.load_state_dict({**own, **{k: v.to(own[k].dtype) for k, v in state.items()}}, strict=True)
    return module


def load_safetensors(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Every tensor of a ``.safetensors`` file, on the CPU.

    Raises
    ------
    FormatError
        When the file is truncated or not a safetensors file.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    try:
        return load_file(str(path), device="cpu")
    except (SafetensorError, OSError, ValueError, RuntimeError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise FormatError(f"{path}: not a readable safetensors file ({type(exc).__name__}: {exc})") from exc


def load_torch_state(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """The state dict of a published ``.pt`` checkpoint (``{"state_dict": ...}`` or bare), weights only.

    Raises
    ------
    FormatError
        When the file cannot be read weights-only or holds something other than tensors.
    """
    try:
        checkpoint = torch.load(Path(path), map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as exc:
        # torch's own message runs to many lines and advises loading with weights_only=False, which would
        # run whatever code the file carries: keep only its first line and never pass that advice on
        first = next((line.strip() for line in str(exc).splitlines() if line.strip()), "")
        if "weights_only" in first or "Weights only load failed" in first:
            detail = re.search(r"WeightsUnpickler error:\s*(Unsupported global: GLOBAL \S+|[^.\n]*)", str(exc))
            first = "not tensors only" + (f": {detail.group(1).strip()}" if detail and detail.group(1).strip() else "")
        raise FormatError(f"{path}: cannot be read as a weights-only torch file ({type(exc).__name__}: "
                          f"{first}); only tensors are loaded") from exc
    state = checkpoint.get("state_dict", checkpoint) if isinstance(checkpoint, dict) else None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise FormatError(f"{path}: expected a dictionary of tensors (optionally under 'state_dict')")
    return state


def tensor_names(path: str | os.PathLike) -> set[str]:
    """The names of the tensors in a ``.safetensors`` file (its header only, no tensor is read).

    Raises
    ------
    FormatError
        When the file is not a readable safetensors file.
    """
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="pt") as f:
            return set(f.keys())
    except (SafetensorError, OSError, ValueError) as exc:
        raise FormatError(f"{path}: not a readable safetensors file ({type(exc).__name__}: {exc})") from exc


def save_safetensors(module_or_state: nn.Module | Mapping[str, torch.Tensor], path: str | os.PathLike, *,
                     card: Mapping[str, Any] | None = None, dtype: torch.dtype | None = torch.bfloat16) -> Path:
    """Write the tensors (cast to ``dtype`` when floating; ``None`` keeps them) and, with ``card``, its JSON card.

    Both files are written atomically; the card gains ``sha256`` (of the tensors file), ``dtype`` and
    ``parameters``. Returns the tensors file's path.
    """
    from safetensors.torch import save

    state = module_or_state.state_dict() if isinstance(module_or_state, nn.Module) else dict(module_or_state)
    tensors = {}
    for k, v in state.items():
        v = v.detach().cpu()
        if dtype is not None and v.is_floating_point():
            v = v.to(dtype)
        tensors[k] = v.contiguous()
    data = save(tensors)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_bytes(path, data)
    if card is not None:
        full = dict(card)
        full["sha256"] = hashlib.sha256(data).hexdigest()
        full["dtype"] = str(dtype).removeprefix("torch.") if dtype is not None else "as trained"
        full["parameters"] = int(sum(v.numel() for v in tensors.values()))
        atomic.write_text(path.with_suffix(".json"), json.dumps(full, indent=2, sort_keys=True) + "\n")
    return path


def read_card(weights_path: str | os.PathLike) -> dict[str, Any] | None:
    """The JSON card beside a weights file (``None`` when there is none)."""
    card = Path(weights_path).with_suffix(".json")
    if not card.is_file():
        return None
    try:
        data = json.loads(card.read_text())
    except (OSError, ValueError) as exc:
        raise FormatError(f"{card}: not a readable JSON card ({one_line(exc)})") from None
    if not isinstance(data, dict):
        raise FormatError(f"{card}: a weights card is a JSON object, got a {type(data).__name__}")
    return data
