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


@pytest.fixture(autouse=True, scope="session")
def _no_cache_in_the_users_home(tmp_path_factory):
    """Measured precisions are remembered in ``$NEUSPIKE_CACHE``: never in the home folder of whoever
    runs the tests (a machine with native bfloat16 measures its networks when they are created)."""
    import os

    previous = os.environ.get("NEUSPIKE_CACHE")
    os.environ["NEUSPIKE_CACHE"] = str(tmp_path_factory.mktemp("neuspike-cache"))
    yield
    if previous is None:
        os.environ.pop("NEUSPIKE_CACHE", None)
    else:
        os.environ["NEUSPIKE_CACHE"] = previous
