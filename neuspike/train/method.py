"""The registered method a trainer trains (:func:`training_method`): shared by the training loop and
the processes that simulate a sequence shard, without either importing the other."""

from __future__ import annotations

import torch

from neuspike.errors import InputError
from neuspike.train.spec import TrainSpec

__all__ = ["training_method"]


def training_method(spec: TrainSpec, device: str | torch.device = "cpu"):
    """The registered method of ``spec`` built for training: :func:`neuspike.methods.create` untrained
    (a fresh module from ``spec.seed``, float32, no weights; a trainer starts from a file through the
    method's own :meth:`~neuspike.methods.learned.LearnedMethod.load_file`), its module in torch's default
    memory layout (inference may prefer channels-last; training runs in the default one)."""
    from neuspike.methods.learned import LearnedMethod
    from neuspike.methods import create, entry

    e = entry(spec.method)
    if not (isinstance(e.factory, type) and issubclass(e.factory, LearnedMethod)):
        raise InputError(f"method {spec.method!r} is not a learned method; it cannot be trained")
    want = "sequences" if e.factory.recurrent else "windows"
    if spec.kind != want:
        raise InputError(f"method {spec.method!r} trains on {want}, but the spec's data are {spec.kind}")
    torch.manual_seed(spec.seed)
    method = create(e.name, trained=False, device=str(device), precision="float32", **spec.params)
    method.module = method.module.to(memory_format=torch.contiguous_format)
    return method
