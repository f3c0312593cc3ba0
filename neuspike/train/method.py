"""The registered method a trainer trains (:func:`training_method`): shared by the training loop and
the processes that simulate a sequence shard, without either importing the other."""

from __future__ import annotations

import torch

from neuspike.errors import InputError
from neuspike.train.spec import TrainSpec

__all__ = ["training_method"]


def training_method(spec: TrainSpec, device: str | torch.device = "cpu"):
    """The registered method of ``spec`` built for training (fresh module from ``spec.seed``, no weights),
    its module on ``device`` (built on the CPU first, so the initial weights do not depend on the device)."""
    from neuspike.methods.learned import LearnedMethod
    from neuspike.methods import entry

    e = entry(spec.method)
    if not (isinstance(e.factory, type) and issubclass(e.factory, LearnedMethod)):
        raise InputError(f"method {spec.method!r} is not a learned method; it cannot be trained")
    want = "sequences" if e.factory.recurrent else "windows"
    if spec.kind != want:
        raise InputError(f"method {spec.method!r} trains on {want}, but the spec's data are {spec.kind}")
    torch.manual_seed(spec.seed)
    return e.factory.for_training(e.name, device=device, **{**dict(e.params), **spec.params})
