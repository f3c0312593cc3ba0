"""Test-suite settings shared by every test file.

Hypothesis runs derandomised (the same examples on every run, so a failure reproduces) and
without per-example deadlines (CI machines are shared and their timing is noisy).
"""

from hypothesis import settings

settings.register_profile("neuspike", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("neuspike")


import numpy as np
import pytest


@pytest.fixture
def one_torch_thread():
    """Small convolutions on one thread: on a shared 2-core machine a second OpenMP thread waiting
    for a busy core makes each step an order of magnitude slower."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed generator for tests that draw random data (modules may override with their own seed)."""
    return np.random.default_rng(1234)
