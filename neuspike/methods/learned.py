"""The base of every learned reconstruction method: module, device, precision, encoding, strict weights.

A learned method is a :class:`~neuspike.methods.Method` whose image comes from a torch module. The
base owns what all of them share, written once:

* **weights**: the constructor builds an *untrained* module from the parameters alone
  (:meth:`LearnedMethod.build_module`); a file is loaded into it afterwards by
  :meth:`LearnedMethod.load_file`, the one loader. The method never finds its own file: the registry
  entry carries the weights configuration (:class:`neuspike.methods.WeightsConfig`: the file's name
  and the sub-folders of a user's folder to look in), and :func:`neuspike.methods.create` resolves
  it (:func:`neuspike.methods.weights.resolve_weights`: the user's folder first, then the weights
  shipped in the package), builds the method, then loads the file (timm's split of builder and
  pretrained configuration). Training asks :func:`~neuspike.methods.create` for the untrained method
  (``trained=False``) and starts from earlier weights through the same :meth:`LearnedMethod.load_file`.
  Loading is strict (:func:`neuspike.methods.weights.load_state_strict`); a file whose sha256 differs
  from its card's is warned about (:func:`neuspike.methods.weights.check_card`). Our own weights are
  safetensors; published ``.pt`` files are read weights-only by the subclass that needs them (its
  :meth:`LearnedMethod.load_weights`).
* **device**: ``"cpu"`` by default; any torch device string the machine has (``"cuda"``,
  ``"cuda:1"``) when asked for. Nothing is ever placed on a GPU unasked.
* **precision**: ``"auto"`` is float32 where the device cannot compute bfloat16 natively (a CPU
  without AVX512-BF16 or AMX instructions, as torch reports them: emulated bfloat16 is always
  slower); where it can, one step of the module is timed in both and bfloat16 is chosen only when it
  is faster (:mod:`neuspike.methods.precision`; measured once per machine and module, remembered).
  The choice is ``params["precision"]``, so it appears in ``describe()``, in ``results.csv`` and in
  a sweep's identity. bfloat16 runs the module under autocast; recurrent states stay float32 where
  the module keeps them so.
* **encoding**: :meth:`LearnedMethod.encode` turns a sample into a list of *steps*, each a tuple of
  tensors (1, C, H, W) that is one call of the module. A feed-forward network has one step; a
  recurrent one has one per event window, its state carried from step to step and reset at the start
  of every reconstruction (so the result does not depend on call history).
* **compiling** (``compiled=True``, off by default): the module runs through ``torch.compile``
  with its weights frozen as constants (inductor's ``freezing``: convolution weights prepacked once,
  normalisation and activations fused), built at the first step and recompiled once per input size
  and for a recurrent module's first (stateless) step. It pays where many frames of one size follow
  (offered by ``bench.timing --compile``; not yet by the sweeps or videos): on a 2-core AMD EPYC Genoa at 400x250, NeuSpike-Net's forward pass took
  286 -> 199 ms in float32 and 174 -> 108 ms in bfloat16, for 5-20 s of compiling once. Images agree
  with the eager module's within float rounding (float32: 1e-6 here). It needs the C++ compiler torch's
  inductor calls; where compiling fails, the step raises :class:`InputError` naming the cause. Recorded
  as ``params["compiled"]`` only when on, so eager identities and results are unchanged.
* **read-out**: the last step's output (1, 1, H, W) becomes a float32 (H, W) image in [0, 1] by
  :meth:`LearnedMethod.to_image` (default: clamp), and its label goes to ``last_normalisation``.

Subclasses implement :meth:`build_module` and :meth:`encode`, and may override :meth:`load_weights`
and :meth:`to_image`. The same two give training (:mod:`neuspike.train`): the trainer creates the
untrained method and feeds its module what :meth:`encode` returns.
"""

from __future__ import annotations

import abc
import contextlib
import os
from pathlib import Path
from typing import Any, ClassVar, Iterator, Sequence

import numpy as np
import torch
from torch import nn

from neuspike.errors import InputError
from neuspike.methods import Method
from neuspike.sample import Sample
from neuspike.methods.precision import PRECISIONS
from neuspike.methods.weights import check_card, file_sha256, load_safetensors, load_state_strict

__all__ = ["PRECISIONS", "LearnedMethod", "native_bfloat16", "resolve_device", "resolve_precision", "synchronize"]

#: Label of the default read-out: the module's output clamped to [0, 1].
CLAMP = "clamp"


def native_bfloat16() -> bool:
    """Whether this CPU computes bfloat16 natively (AVX512-BF16 or AMX), as torch reports it."""
    cpu = getattr(torch, "cpu", None)
    for probe in ("_is_avx512_bf16_supported", "_is_amx_tile_supported"):
        check = getattr(cpu, probe, None)
        try:
            if check is not None and check():
                return True
        except Exception:  # a private probe that changed shape: assume no native support
            continue
    return False


def resolve_device(device: str | torch.device | None) -> torch.device:
    """``device`` as a torch device (``None`` -> CPU); a device this machine lacks raises :class:`InputError`."""
    try:
        dev = torch.device("cpu" if device is None else device)
    except (RuntimeError, TypeError) as exc:
        raise InputError(f"device: {device!r} is not a torch device ({exc})") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device: {device!r} was asked for but this machine has no CUDA device")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise InputError(f"device: {device!r} was asked for but this machine has "
                         f"{torch.cuda.device_count()} CUDA device(s), numbered from 0")
    if dev.type not in ("cpu", "cuda", "mps", "xpu"):
        raise InputError(f"device: {device!r} is not supported (cpu, cuda, mps or xpu)")
    backend = {"mps": getattr(torch.backends, "mps", None), "xpu": getattr(torch, "xpu", None)}.get(dev.type)
    if dev.type in ("mps", "xpu") and not (backend is not None and backend.is_available()):
        raise InputError(f"device: {device!r} was asked for but this machine has no {dev.type.upper()} device")
    return dev


def synchronize(device: torch.device) -> None:
    """Wait for the work queued on ``device`` (a CUDA device; others run synchronously): call before
    reading a clock that times it."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def resolve_precision(precision: str, device: torch.device) -> str:
    """``"auto"`` -> ``"bfloat16"`` where ``device`` computes it natively, else ``"float32"``."""
    if precision not in PRECISIONS:
        raise InputError(f"precision: expected one of {PRECISIONS}, got {precision!r}")
    if precision != "auto":
        return precision
    if device.type == "cpu":
        return "bfloat16" if native_bfloat16() else "float32"
    if device.type == "cuda":
        return "bfloat16" if torch.cuda.is_bf16_supported() else "float32"
    return "float32"


def _compile_failure(exc: BaseException) -> bool:
    """Whether ``exc`` is torch.compile failing (no C++ compiler, a backend error), not the step itself."""
    from torch._dynamo.exc import TorchDynamoException
    from torch._inductor.exc import CppCompileError

    return isinstance(exc, (TorchDynamoException, CppCompileError))


class LearnedMethod(Method):
    """Base of learned methods (module docstring).

    Parameters
    ----------
    name : str or None
        The registered name.
    device : str or torch.device
        Where the module runs (default ``"cpu"``).
    precision : ``"auto"``, ``"float32"`` or ``"bfloat16"``
        Arithmetic of the module (see :func:`resolve_precision`); the choice made is recorded in
        ``params["precision"]``.
    compiled : bool
        Run the module through ``torch.compile`` (module docstring); recorded as
        ``params["compiled"] = True`` when on.
    **params
        The subclass's own parameters (recorded in ``params``).

    The module is untrained until :meth:`load_file` loads a file into it (what
    :func:`neuspike.methods.create` does with the registry entry's weights).
    """

    #: Label of :meth:`to_image`'s read-out.
    output_label: ClassVar[str] = CLAMP

    def __init__(self, name: str | None = None, *, device: str | torch.device = "cpu", precision: str = "auto",
                 compiled: bool = False, **params: Any) -> None:
        if not isinstance(compiled, bool):
            raise InputError(f"compiled: expected True or False, got {compiled!r}")
        if compiled:  # recorded only when on: an eager method's identity is what it always was
            params["compiled"] = True
        dev = resolve_device(device)
        # "auto" resolved to bfloat16 only says the device can compute it: a measured step decides
        measure = precision == "auto" and resolve_precision(precision, dev) == "bfloat16"
        precision = "float32" if measure else resolve_precision(precision, dev)
        super().__init__(name, precision=precision, **params)
        #: What a measured "auto" precision rests on (None when it was not measured).
        self.precision_measurement: dict[str, Any] | None = None
        self.device = dev
        #: The file :meth:`load_file` loaded (``None`` while untrained), its sha256 and the layout read.
        self.weights_path: Path | None = None
        self.weights_sha256: str | None = None
        self.weights_layout: str | None = None
        self._state: Any = None
        self._compiled: Any = None  # the compiled module, built at the first step (compiled=True)
        self.module: nn.Module = self.build_module().to(dev).eval()  # every attribute above is set first
        if measure:  # a step's time does not depend on the weights' values: measured on the fresh module
            self._measure_precision()

    def load_file(self, path: str | os.PathLike, *, may_lack: tuple[str, ...] = ()) -> "LearnedMethod":
        """Load the weights file ``path`` into the module (strictly, by :meth:`load_weights`) and return the method.

        The one loader of learned weights: :func:`neuspike.methods.create` calls it with the file the
        registry entry resolves to, the trainer with a spec's ``init_from`` and a teacher's file. Records
        the file (``weights_path``, ``weights_sha256``, ``weights_layout`` and ``params["weights_file"]``,
        the file's name, part of a result's identity); a file whose sha256 differs from its card's is
        warned about. ``may_lack``: name prefixes of tensors the file may leave out
        (:func:`~neuspike.methods.weights.load_state_strict`; training only).

        Raises
        ------
        InputError
            When ``path`` is not a file.
        neuspike.errors.FormatError
            When the file does not fit the module (missing, unused or mis-shaped tensors, truncation).
        """
        path = Path(path)
        if not path.is_file():
            raise InputError(f"weights {path}: no such file")
        sha = file_sha256(path)
        check_card(path, sha)
        self.weights_layout = self.load_weights(self.module, path, may_lack=may_lack)
        self.weights_path, self.weights_sha256 = path, sha
        self.params["weights_file"] = path.name
        self._compiled = None  # a compiled module froze the previous weights as constants
        return self

    def _measure_precision(self) -> None:
        """Set ``params["precision"]`` by timing one step in float32 and in bfloat16
        (:func:`neuspike.methods.precision.choose_precision`); float32 when the step cannot be probed."""
        from neuspike.methods.precision import choose_precision, module_identity, probe_sample

        try:
            inputs = tuple(t.to(self.device) for t in self.encode(probe_sample())[0])
        except Exception as exc:  # a method that cannot encode the synthetic sample: keep float32
            self.precision_measurement = {"choice": "float32", "error": f"no probe step: {type(exc).__name__}"}
            return

        def step(precision: str) -> None:
            with torch.inference_mode(), contextlib.ExitStack() as stack:
                if precision == "bfloat16":
                    stack.enter_context(torch.autocast(self.device.type, dtype=torch.bfloat16))
                out = self.module(*inputs, None) if self.recurrent else self.module(*inputs)
                synchronize(self.device)
                return out

        choice, record = choose_precision(module_identity(type(self), self.params), str(self.device),
                                          torch.get_num_threads(), step)
        self.params["precision"] = choice
        self.precision_measurement = record

    # -- what a subclass provides ----------------------------------------------------------------

    @abc.abstractmethod
    def build_module(self) -> nn.Module:
        """A fresh module with this method's architecture (untrained)."""

    @abc.abstractmethod
    def encode(self, sample: Sample) -> Sequence[tuple[torch.Tensor, ...]]:
        """The module's inputs for ``sample``: a list of steps, each a tuple of (1, C, H, W) CPU tensors."""

    def load_weights(self, module: nn.Module, path: Path, *, may_lack: tuple[str, ...] = ()) -> str | None:
        """Load ``path`` into ``module`` strictly and return the layout read (default: a safetensors
        file of our own, ``"safetensors"``); called by :meth:`load_file`."""
        load_state_strict(module, load_safetensors(path), str(path), may_lack=may_lack)
        return "safetensors"

    def to_image(self, output: torch.Tensor, sample: Sample) -> np.ndarray:
        """The module's output (1, 1, H', W') as float32 (H, W) in [0, 1] (default: clamp, crop to the sample)."""
        image = output[0, 0, : sample.height, : sample.width].float().clamp(0.0, 1.0)
        return np.ascontiguousarray(image.cpu().numpy(), dtype=np.float32)

    # -- written once ----------------------------------------------------------------------------

    def parameter_count(self) -> int:
        return int(sum(p.numel() for p in self.module.parameters()))

    def reset(self) -> None:
        """Forget the recurrent state (start of a new sequence)."""
        self._state = None

    def describe(self) -> dict[str, Any]:
        info = super().describe()
        info.update(weights_file=self.weights_path.name if self.weights_path is not None else None,
                    weights_sha256=self.weights_sha256, device=str(self.device))
        return info

    @contextlib.contextmanager
    def _autocast(self) -> Iterator[None]:
        if self.params["precision"] == "bfloat16":
            with torch.autocast(self.device.type, dtype=torch.bfloat16):
                yield
        else:
            yield

    def _runner(self) -> nn.Module | Any:
        """What a step calls: the module, or (``compiled``) its compiled form, built once."""
        if not self.params.get("compiled", False):
            return self.module
        if self._compiled is None:
            # frozen weights: a subclass may have replaced self.module after the base's __init__
            self._compiled = torch.compile(self.module, dynamic=False, options={"freezing": True})
        return self._compiled

    def run_step(self, inputs: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """One call of the module on ``inputs`` (carrying the recurrent state); returns its output tensor."""
        inputs = tuple(t.to(self.device) for t in inputs)
        module = self._runner()
        try:
            with torch.inference_mode(), self._autocast():
                if self.recurrent:
                    out, self._state = module(*inputs, self._state)
                else:
                    out = module(*inputs)
        except Exception as exc:
            if module is self.module or not _compile_failure(exc):
                raise
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise InputError(f"method {self.name!r}: torch.compile failed on this machine ({type(exc).__name__}: "
                             f"{first[:300]}); run without compiling (compiled=False, no --compile)") from exc
        return out

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        self.reset()
        steps = self.encode(sample)
        if not steps:
            raise InputError(f"method {self.name!r}: the sample gave no input to the network")
        for inputs in steps:
            out = self.run_step(inputs)
        self.last_steps = len(steps)
        return self.to_image(out, sample), self.output_label
