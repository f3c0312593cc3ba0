"""The simulation: from a scene and a condition to spike and event recordings, their files and their cache.

Modules (import from them directly; this package imports nothing, so the command answers ``--help``
without loading the simulator):

:mod:`~neuspike.simulation.recording`  what a simulation gives (:class:`SensorConfig`, :class:`Recording`)
:mod:`~neuspike.simulation.cameras`    the cameras of a condition and the metadata every recording carries
:mod:`~neuspike.simulation.window`     one Algorithm-1 window (:func:`simulate_window`, :func:`static_region`)
:mod:`~neuspike.simulation.sequence`   continuous simulation, chunk by chunk (:func:`simulate_sequence`)
:mod:`~neuspike.simulation.cache`      the on-disk cache of windows, one file per modality
:mod:`~neuspike.simulation.cell`       the one way from a (scene, condition, seed) cell to a recording
:mod:`~neuspike.simulation.writing`    recording folders (``spikes.dat``, ``events.h5``, ground truth, ``meta.json``)
:mod:`~neuspike.simulation.command`    ``python -m neuspike.simulate``
"""
