"""Choosing a simulator backend, and the NumPy fallback where numba cannot be imported."""

from __future__ import annotations

import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.utils import parallel as backends
from neuspike.sensors.event_camera import EventCamera
from neuspike.sensors.spike_camera import SpikeCamera, integrate_and_fire


def test_without_numba_auto_falls_back_to_numpy_and_numba_is_refused(monkeypatch):
    monkeypatch.setattr(backends, "NUMBA_AVAILABLE", False)
    assert backends.resolve_backend("auto") == "numpy"
    assert SpikeCamera(8, 2, light=1.0, rng=None).backend == "numpy"
    assert EventCamera(8, 2, light=1.0).backend == "numpy"
    with pytest.raises(InputError, match="numba cannot be imported"):
        SpikeCamera(8, 2, light=1.0, rng=None, backend="numba")
    with pytest.raises(InputError, match="numba cannot be imported"):
        EventCamera(8, 2, light=1.0, backend="numba")
    planes, _ = integrate_and_fire(np.full((3, 2, 8), 0.5, np.float32), hold_planes=2, light=1.0, threshold=1.0)
    assert planes.sum() == 2 * 8 * 3  # every other plane fires at half the threshold per plane


def test_unknown_backends_are_refused_with_the_choices():
    with pytest.raises(InputError, match=r"\('auto', 'numba', 'numpy'\)"):
        EventCamera(8, 2, light=1.0, backend="cuda")


def test_one_resolver_for_every_compiled_stage(monkeypatch):
    # SNM's reference is torch; the choices in the message follow the caller's reference.
    assert backends.resolve_backend("torch", compiled=True, reference="torch") == "torch"
    with pytest.raises(InputError, match=r"\('auto', 'numba', 'torch'\)"):
        backends.resolve_backend("numpy", compiled=True, reference="torch")
    with pytest.raises(InputError, match="numba cannot be imported"):
        backends.resolve_backend("numba", compiled=False)
    assert backends.resolve_backend("auto", compiled=False) == "numpy"
    # a child forked after an OpenMP parallel region takes the reference, even when numba was asked for
    monkeypatch.setattr(backends, "_forked_after_parallel", True)
    assert backends.resolve_backend("numba", compiled=True) == "numpy"
    assert backends.resolve_backend("auto", compiled=True, reference="torch") == "torch"
