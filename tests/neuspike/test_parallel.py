"""neuspike.utils.parallel: a child forked after a GNU OpenMP parallel region takes the reference paths."""

from __future__ import annotations

import multiprocessing as mp

import numpy as np
import pytest

from baselines import snm, tfstp
from neuspike.utils import parallel
from neuspike.scenes import SceneSpec, make_scene

PLANES = np.random.default_rng(0).random((48, 12, 17)) < 0.3
SCENE = SceneSpec(kind="zoom", image="coins", size=(33, 21))
TIMES = np.linspace(-0.01, 0.01, 5)


def _child(queue, expected):
    tf, sn, frames = expected
    queue.put((parallel.parallel_usable(), np.array_equal(tfstp.tfstp_rate(PLANES, 30), tf),
               float(np.abs(snm.snm_rate(PLANES, 24, plane_rate_hz=2e4) - sn).max()),
               np.array_equal(make_scene(SCENE).render(TIMES), frames)))


@pytest.mark.skipif("fork" not in mp.get_all_start_methods(), reason="no fork on this platform")
def test_a_child_forked_after_a_parallel_kernel_still_reconstructs_and_renders():
    # The kernels run here first (GNU OpenMP would terminate a forked child that starts a region).
    expected = (tfstp.tfstp_rate(PLANES, 30), snm.snm_rate(PLANES, 24, plane_rate_hz=2e4),
                make_scene(SCENE).render(TIMES))
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_child, args=(queue, expected))
    child.start()
    child.join(120)
    assert child.exitcode == 0
    usable, tf_equal, snm_diff, frames_equal = queue.get(timeout=5)
    assert tf_equal and frames_equal and snm_diff <= 1e-6  # the references: same bits, SNM within tolerance
    import numba

    assert usable == (numba.threading_layer() != "omp")


def test_usable_in_a_clean_process():
    assert parallel.parallel_usable()
