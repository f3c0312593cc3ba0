"""Training learned methods on simulated data: ``python -m neuspike.train NAME``.

One system for every learned method (:class:`~neuspike.methods.learned.LearnedMethod`): the trainer asks
:func:`neuspike.methods.create` for the untrained method (``trained=False``), starts from a file through
its ``load_file`` (``init_from``), feeds its module what ``encode(sample)`` returns and does the rest.

* :mod:`neuspike.train.spec` — the frozen :class:`TrainSpec` with its data section
  (:class:`WindowData` or :class:`SequenceData`) and the learning-rate schedule;
* :mod:`neuspike.train.windows` — single windows: cells, the shard, augmentation, loss, validation;
* :mod:`neuspike.train.sequences` — sequences of event windows: cells, items with exact flow, the
  shard, batches, the temporal loss, validation;
* :mod:`neuspike.train.checkpoint` — the run folder: spec file, checkpoint (the earlier trainers'
  refused by name), log, exported weights and their card;
* :mod:`neuspike.train.loop` — the one loop: schedule, steps, validation, export, resume.

This package's ``__init__`` imports nothing heavy (the command's ``--help`` stays fast).
"""

from neuspike.train.spec import KIND_WEIGHTS, SequenceData, TrainSpec, WindowData, learning_rate, load_spec

__all__ = ["KIND_WEIGHTS", "SequenceData", "TrainSpec", "WindowData", "learning_rate", "load_spec", "train"]


def train(spec: TrainSpec, *, quiet: bool = False, **run):
    """Run (or resume) a training run (:func:`neuspike.train.loop.train`)."""
    from neuspike.train.loop import train as _train

    return _train(spec, quiet=quiet, **run)
