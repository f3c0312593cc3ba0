"""Training learned methods on simulated data: ``python -m neuspike.train NAME``.

* :mod:`neuspike.train.spec` — the frozen :class:`TrainSpec` (saved as JSON beside the checkpoint);
* :mod:`neuspike.train.data` — cells from (seed, split, index), the simulated shard, augmentation;
* :mod:`neuspike.train.loop` — loss, schedule, validation, atomic checkpoints, resume, export.

The training protocol a method class offers: ``module_for(params)`` (an untrained module) and
``encode_sample(sample, params)`` (the module's input tensors, each (1, C, H, W)).
"""

from neuspike.train.spec import KIND_WEIGHTS, TrainSpec, load_spec

__all__ = ["KIND_WEIGHTS", "TrainSpec", "load_spec", "train"]


def train(spec: TrainSpec, *, quiet: bool = False):
    """Run (or resume) a training run (:func:`neuspike.train.loop.train`)."""
    from neuspike.train.loop import train as _train

    return _train(spec, quiet=quiet)
