"""The method interface and the registry every reconstruction method lives in.

A method is a small object with a ``name``, the set of ``inputs`` it needs (``{"spikes"}``,
``{"events"}`` or both), its ``params``, and ``reconstruct(sample) -> float32 (H, W)`` in [0, 1] in
the ground truth's units. Subclasses implement :meth:`Method._reconstruct`, which returns the image
and a short label of the normalisation it applied (e.g. ``"gain"`` when the stream's known gain was
divided out, ``"robust-p99"`` when it was not known); :meth:`Method.reconstruct` checks the inputs
and the output and records the label in ``last_normalisation``.

Variants are registry entries over one implementation: ``register("tfp-w8", TFP, params={"window": 8})``.
A learned method's entry carries its weights configuration (:class:`WeightsConfig`: the file name
and the sub-folders of a user's weights folder to look in; ``register(..., weights="x.safetensors")``
is short for ``weights=WeightsConfig("x.safetensors")``). :func:`create` resolves that file (the user's
``weights_dir`` first, then the weights shipped in the package:
:func:`neuspike.methods.weights.resolve_weights`), builds the method with the ``device`` (an untrained
module, for :class:`neuspike.methods.learned.LearnedMethod`), then hands it the file
(:meth:`Method.load_file`): a method never finds its own weights, and training asks for the untrained
method with ``create(name, trained=False)``. Nothing here reads the environment.

One registration contract for everything: a module, an entry point of the group ``neuspike.methods``
or a ``--plugin`` file provides ``register_methods(register)``, a callable that receives
:func:`register` and adds its methods with it. The suite's own baselines arrive the same way (so this
package never imports them), and so do the core's networks (:mod:`neuspike.nets`).

What a call reports besides the image is declared on :class:`Method`: ``last_normalisation`` (the
read-out's label) and ``last_steps`` (for recurrent methods, the network steps the call ran).
"""

from __future__ import annotations

import abc
import os
import threading
from dataclasses import dataclass, field
from importlib import metadata
from types import MappingProxyType
from typing import Any, Callable, Mapping

import numpy as np

from neuspike.errors import InputError, NeuSpikeError, one_line
from neuspike.sample import Sample

ENTRY_POINT_GROUP = "neuspike.methods"


class MethodUnavailable(NeuSpikeError, RuntimeError):
    """A method cannot run here (e.g. its weights were not given); the message says why."""


class Method(abc.ABC):
    """Base class of reconstruction methods.

    Class attributes
    ----------------
    inputs : frozenset of str
        The modalities the method needs.
    recurrent : bool
        ``True`` for methods with state across calls; :meth:`reset` clears it.
    """

    inputs: frozenset[str] = frozenset()
    recurrent: bool = False

    def __init__(self, name: str | None = None, **params: Any) -> None:
        self.name = name or type(self).__name__.lower()
        self.params: dict[str, Any] = dict(params)
        #: Label of the normalisation the last call applied (set by :meth:`reconstruct`).
        self.last_normalisation: str | None = None
        #: Network steps (event windows) the last call ran, for recurrent methods; ``None`` otherwise.
        self.last_steps: int | None = None

    def reset(self) -> None:
        """Clear recurrent state (start of a new sequence). Stateless methods do nothing."""

    def load_file(self, path: "str | os.PathLike") -> "Method":
        """Load the weights file ``path`` (found by :func:`create` from the registry entry) and return
        the method. Methods whose entry declares weights implement it
        (:meth:`neuspike.methods.learned.LearnedMethod.load_file` for torch modules); the others have none."""
        raise NeuSpikeError(f"method {self.name!r} ({type(self).__name__}) has no weights to load; a registry entry "
                            "that declares weights needs a method that implements load_file(path)")

    def parameter_count(self) -> int:
        """Number of learned parameters (0 for classical methods)."""
        return 0

    @abc.abstractmethod
    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        """Return ``(image, normalisation_label)``; ``image`` float32 (H, W) in [0, 1]."""

    def reconstruct(self, sample: Sample) -> np.ndarray:
        """Reconstruct the image at ``sample.key_time_s``.

        Returns
        -------
        ndarray, float32, shape (H, W), values in [0, 1].

        Raises
        ------
        InputError
            When the sample lacks an input the method needs.
        NeuSpikeError
            When the method produced an invalid image (wrong shape, non-finite, out of range):
            a defect of the method, reported rather than patched over.
        """
        missing = set(self.inputs) - set(sample.modalities)
        if missing:
            raise InputError(f"method {self.name!r} needs {sorted(self.inputs)}, the sample lacks {sorted(missing)}")
        image, label = self._reconstruct(sample)
        image = np.asarray(image)
        if image.shape != (sample.height, sample.width):
            raise NeuSpikeError(
                f"method {self.name!r} returned shape {image.shape}, expected {(sample.height, sample.width)}"
            )
        if image.dtype != np.float32:
            raise NeuSpikeError(f"method {self.name!r} returned dtype {image.dtype}, expected float32")
        if not np.isfinite(image).all():
            raise NeuSpikeError(f"method {self.name!r} returned non-finite values")
        if image.size and (image.min() < 0 or image.max() > 1):
            raise NeuSpikeError(
                f"method {self.name!r} returned values in [{image.min()}, {image.max()}], expected [0, 1]"
            )
        self.last_normalisation = label
        return image

    def reconstruct_next(self, sample: Sample, *, previous_s: float) -> np.ndarray:
        """Streaming (:mod:`neuspike.video`): the image at ``sample.key_time_s``, continuing this sequence.

        The first frame of a sequence goes through :meth:`reconstruct` (which warms up on the
        sample's history); each later frame comes here with ``previous_s``, the key instant of the
        previous frame. A recurrent method may override this to carry its state forward on the input
        after ``previous_s`` only, instead of warming up again; the default is :meth:`reconstruct`,
        which is exact for stateless methods.
        """
        return self.reconstruct(sample)

    def describe(self) -> dict[str, Any]:
        """What identifies this method's results: name, implementation, inputs, parameters, size."""
        return {
            "name": self.name,
            "implementation": f"{type(self).__module__}.{type(self).__qualname__}",
            "inputs": sorted(self.inputs),
            "params": dict(self.params),
            "recurrent": self.recurrent,
            "parameters": self.parameter_count(),
        }


@dataclass(frozen=True)
class WeightsConfig:
    """Where a learned method's weights come from (the registry entry's part; timm's ``pretrained_cfg``).

    ``file``: the file's name; ``subdirs``: sub-folders of the user's weights folder tried before the
    folder itself (e.g. ``("firenet",)``); the weights shipped in the package are tried last.
    """

    file: str
    subdirs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.file, str) or not self.file.strip():
            raise InputError(f"weights: expected a file name, got {self.file!r}")
        object.__setattr__(self, "subdirs", tuple(self.subdirs))


@dataclass(frozen=True)
class MethodEntry:
    """A registry entry: a factory (usually a Method subclass) and the parameters of this variant."""

    name: str
    factory: Callable[..., Method]
    params: Mapping[str, Any] = field(default_factory=dict)
    inputs: frozenset[str] = frozenset()
    description: str = ""
    #: A learned method's weights configuration (``None`` for classical methods).
    weights: WeightsConfig | None = None


_REGISTRY: dict[str, MethodEntry] = {}
_LOCK = threading.Lock()
_ENTRY_POINTS_LOADED = False


def register(
    name: str,
    factory: Callable[..., Method],
    *,
    params: Mapping[str, Any] | None = None,
    inputs: frozenset[str] | set[str] | None = None,
    description: str = "",
    weights: str | WeightsConfig | None = None,
) -> MethodEntry:
    """Add a method (or a variant of one) to the registry.

    ``weights``: a learned method's weights configuration, or only its file name; :func:`create`
    passes it to the factory, which resolves and loads it.

    Raises
    ------
    InputError
        If ``name`` is already registered or is not a non-empty string.
    """
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"method name must be a non-empty string, got {name!r}")
    ins = frozenset(inputs if inputs is not None else getattr(factory, "inputs", frozenset()))
    if not ins or not ins <= {"spikes", "events"}:
        raise InputError(f"method {name!r}: inputs must be a non-empty subset of {{'spikes', 'events'}}, got {sorted(ins)}")
    if isinstance(weights, str) and weights.strip():
        weights = WeightsConfig(weights)
    elif weights is not None and not isinstance(weights, WeightsConfig):
        raise InputError(f"method {name!r}: weights must be a file name or a WeightsConfig, got {weights!r}")
    entry = MethodEntry(name, factory, MappingProxyType(dict(params or {})), ins, description, weights)
    with _LOCK:
        if name in _REGISTRY:
            raise InputError(f"method {name!r} is already registered")
        _REGISTRY[name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove a method (for tests and interactive use)."""
    with _LOCK:
        if name not in _REGISTRY:
            raise InputError(f"unknown method {name!r}")
        del _REGISTRY[name]


def load_entry_points(force: bool = False) -> list[str]:
    """Call every ``neuspike.methods`` entry point once with :func:`register`; return the problems met."""
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED and not force:
        return []
    _ENTRY_POINTS_LOADED = True
    problems = []
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            ep.load()(register)
        except Exception as exc:  # a broken plug-in must not hide the others
            problems.append(f"entry point {ep.name!r} ({ep.value}): {one_line(exc)}")
    return problems


def available() -> list[str]:
    """Names of all registered methods, sorted."""
    load_entry_points()
    return sorted(_REGISTRY)


def entry(name: str) -> MethodEntry:
    """The registry entry of ``name``; unknown names raise :class:`InputError`."""
    load_entry_points()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise InputError(f"unknown method {name!r}; available: {', '.join(sorted(_REGISTRY)) or 'none'}") from None


def create(name: str, *, weights_dir: str | os.PathLike | None = None, device: str = "cpu", trained: bool = True,
           **overrides: Any) -> Method:
    """Instantiate a registered method, with optional parameter overrides.

    A method whose entry declares weights is built in three steps: its file is resolved from the entry
    (before anything is built, so a missing file costs nothing), the method is built with ``device``
    (an untrained module), then the file is loaded into it (:meth:`Method.load_file`).

    Parameters
    ----------
    name : str
        A registered name.
    weights_dir : path or None
        Folder of published weights the user named (learned methods only; their own shipped
        weights are found without it).
    device : str
        Torch device of a learned method (default ``"cpu"``); classical methods ignore it.
    trained : bool
        ``False``: the learned method untrained, no file resolved or loaded (what a trainer trains,
        and what it initialises from a file through the same :meth:`Method.load_file`).
    **overrides
        Parameters that replace the entry's.

    Raises
    ------
    neuspike.methods.weights.WeightsNotFound
        When the entry's weights file is found neither in ``weights_dir`` nor in the package
        (a :class:`MethodUnavailable`).
    """
    e = entry(name)
    params = {**e.params, **overrides}
    path = None
    if e.weights is not None:
        params["device"] = device
        if trained:
            from neuspike.methods.weights import resolve_weights

            path = resolve_weights(e.weights.file, weights_dir, subdirs=e.weights.subdirs)
    method = e.factory(name=name, **params)
    if not isinstance(method, Method):
        raise NeuSpikeError(f"factory of {name!r} returned {type(method).__name__}, not a Method")
    if path is not None:
        method.load_file(path)
    return method


@dataclass(frozen=True)
class Created:
    """What :func:`create_many` made of one name.

    ``method`` is the instance, or ``None`` when the method cannot run here (``unavailable``: the
    :class:`MethodUnavailable` raised, e.g. learned weights not given) or creating it failed
    (``error``: the exception, ``traceback``: its text).
    """

    name: str
    method: Method | None = None
    unavailable: MethodUnavailable | None = None
    error: BaseException | None = None
    traceback: str = ""


def uses_device(e: MethodEntry) -> bool:
    """Whether the method of ``e`` runs on a torch device (learned methods; the others ignore ``device``)."""
    return e.weights is not None


def reads_windows(e: MethodEntry) -> bool:
    """Whether the method of ``e`` streams fixed-count event windows and so takes ``read_out``."""
    return bool(getattr(e.factory, "READ_OUTS", ()))


def check_device(device: str, entries: "list[MethodEntry] | tuple[MethodEntry, ...]") -> None:
    """Refuse a ``device`` that none of ``entries`` can use, before any method is built.

    A device some learned method will use must exist here (:func:`neuspike.methods.learned.resolve_device`);
    a device other than ``"cpu"`` when no method runs on a torch device is refused too, since it would
    be silently ignored.

    Raises
    ------
    InputError
        Naming the device and why it cannot be used.
    """
    if not isinstance(device, str) or not device.strip():
        raise InputError(f"device: expected a torch device name such as 'cpu' or 'cuda', got {device!r}")
    if any(uses_device(e) for e in entries):
        from neuspike.methods.learned import resolve_device  # imports torch: only when a method needs it

        resolve_device(device)
    elif device != "cpu":
        names = ", ".join(e.name for e in entries)
        raise InputError(f"device {device!r}: none of the methods ({names}) runs on a torch device, they all run "
                         "on the CPU; leave the device out")


def create_many(names: "list[str] | tuple[str, ...]", *, weights_dir: str | os.PathLike | None = None,
                device: str = "cpu", precision: str | None = None, compiled: bool = False,
                read_out: str | None = None, skip_unavailable: bool = True,
                keep_errors: bool = False) -> dict[str, Created]:
    """Create each of ``names`` once, the way every front end does (commands, sweeps, timings).

    Every name is looked up and the device checked (:func:`check_device`) before anything is built,
    so an unknown name or an unusable device costs nothing.

    Parameters
    ----------
    names : sequence of str
        Registered names, without repeats.
    weights_dir, device :
        As for :func:`create`.
    precision : str or None
        The precision of every learned method (``"auto"``, ``"float32"`` or ``"bfloat16"``); ``None``
        keeps each entry's own. Methods that run on no torch device ignore it.
    compiled : bool
        Run every learned method's module through ``torch.compile`` (:class:`~neuspike.methods.learned.LearnedMethod`);
        the others ignore it.
    read_out : str or None
        What a streamed frame of the methods that read fixed-count event windows shows
        (``read_out`` of :class:`baselines.firenet.FireNet`: ``"key"`` or ``"window"``); ``None``
        keeps each one's own (``"key"``). The other methods ignore it; an :class:`InputError` when
        none of ``names`` takes it.
    skip_unavailable : bool
        ``True``: a method that cannot run here (:class:`MethodUnavailable`) is returned with
        ``unavailable`` set (a sweep's skipped row); ``False``: it raises :class:`MethodUnavailable`
        naming the method (a command the user asked for it by name).
    keep_errors : bool
        ``True``: any other exception raised while creating is returned in ``error`` (a row with an
        error); ``False``: it propagates.

    Returns
    -------
    dict
        ``{name: Created}`` in the order of ``names``.

    Raises
    ------
    InputError
        An unknown or repeated name, or an unusable device.
    """
    names = list(names)
    if len(set(names)) != len(names):
        raise InputError(f"methods repeat a name: {names}")
    entries = [entry(name) for name in names]  # unknown names raise, listing the known ones
    check_device(device, entries)
    if precision is not None:
        from neuspike.methods.precision import PRECISIONS

        if precision not in PRECISIONS:
            raise InputError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if read_out is not None and not any(reads_windows(e) for e in entries):
        raise InputError(f"read_out {read_out!r}: none of {', '.join(names)} reads event windows (it applies to "
                         f"the recurrent event networks, e.g. e2vid, firenet-sim, firenet)")
    out: dict[str, Created] = {}
    for name, e in zip(names, entries):
        extra = {"precision": precision} if precision is not None and uses_device(e) else {}
        if compiled and uses_device(e):
            extra["compiled"] = True
        if read_out is not None and reads_windows(e):
            extra["read_out"] = read_out
        try:
            out[name] = Created(name, create(name, weights_dir=weights_dir, device=device, **extra))
        except MethodUnavailable as exc:
            if not skip_unavailable:
                raise MethodUnavailable(f"method {name!r} is unavailable: {exc}") from None
            out[name] = Created(name, unavailable=exc)
        except Exception as exc:
            if not keep_errors:
                raise
            import traceback

            out[name] = Created(name, error=exc, traceback=traceback.format_exc())
    return out
