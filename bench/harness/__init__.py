"""The harness wing of ``bench``: what runs a benchmark and writes its results.

Sweep grids and their axes (:mod:`~bench.harness.grid`), cells and their recordings
(:mod:`~bench.harness.cells`), executors (:mod:`~bench.harness.executors`), the sweep runner
(:mod:`~bench.harness.runner`), the results schema (:mod:`~bench.harness.results`), provenance,
dataset manifests and runs (:mod:`~bench.harness.manifest`, :mod:`~bench.harness.datasets`), the
reconstruction images' layout (:mod:`~bench.harness.images`) and the timer (:mod:`~bench.harness.timer`).
Nothing here imports :mod:`bench.reporting`: the commands (``bench/*.py``) build a report after a run.
"""
