"""Voxel grids and spike bins against hand-computed examples and conservation laws."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from neuspike.errors import InputError
from neuspike.methods.representations import normalize_voxel_grid, spike_bins, voxel_grid
from neuspike.streams import EventStream


def stream(t, x, y, p, width=3, height=2) -> EventStream:
    return EventStream(np.asarray(t, float), np.asarray(x), np.asarray(y), np.asarray(p), width, height)


def random_stream(rng: np.random.Generator, n: int, width: int, height: int, t0: float, t1: float,
                  polarity: int | None = None) -> EventStream:
    t = np.sort(rng.uniform(t0, t1, n))
    p = rng.choice([-1, 1], n) if polarity is None else np.full(n, polarity)
    return EventStream(t, rng.integers(0, width, n), rng.integers(0, height, n), p, width, height)


# --- voxel grid ----------------------------------------------------------------------------------


def test_voxel_grid_hand_computed_example():
    # B = 5 over [0, 1] s: t* = 4 t.
    #   t = 0.0 at (x0, y0), ON  -> t* = 0.0: bin 0 gets +1
    #   t = 0.3 at (x1, y0), OFF -> t* = 1.2: bin 1 gets -0.8, bin 2 gets -0.2
    #   t = 0.5 at (x0, y0), ON  -> t* = 2.0: bin 2 gets +1
    #   t = 1.0 at (x2, y1), ON  -> t* = 4.0: bin 4 gets +1 (the window's end is inside it)
    events = stream([0.0, 0.3, 0.5, 1.0], [0, 1, 0, 2], [0, 0, 0, 1], [1, -1, 1, 1])
    grid = voxel_grid(events, bins=5, t0_s=0.0, t1_s=1.0, height=2, width=3, normalize=False)
    expected = np.zeros((5, 2, 3), np.float32)
    expected[0, 0, 0] = 1.0
    expected[1, 0, 1] = -0.8
    expected[2, 0, 1] = -0.2
    expected[2, 0, 0] = 1.0
    expected[4, 1, 2] = 1.0
    assert grid.dtype == np.float32 and grid.shape == (5, 2, 3)
    np.testing.assert_allclose(grid, expected, atol=1e-6)


def test_voxel_grid_with_a_shifted_span_and_one_bin():
    # The span need not start at 0: t* = 2 (t - 10) / 2 over [10, 12] s with B = 3.
    events = stream([10.5, 11.5], [2, 2], [1, 1], [1, -1])
    grid = voxel_grid(events, bins=3, t0_s=10.0, t1_s=12.0, height=2, width=3, normalize=False)
    np.testing.assert_allclose(grid[:, 1, 2], [0.5, 0.5 - 0.5, -0.5], atol=1e-6)
    # B = 1: every event adds its whole polarity.
    one = voxel_grid(events, bins=1, t0_s=10.0, t1_s=12.0, height=2, width=3, normalize=False)
    np.testing.assert_array_equal(one, np.zeros((1, 2, 3), np.float32))
    events = stream([10.5, 11.5, 11.6], [2, 2, 0], [1, 1, 0], [1, 1, -1])
    one = voxel_grid(events, bins=1, t0_s=10.0, t1_s=12.0, height=2, width=3, normalize=False)
    assert one[0, 1, 2] == 2.0 and one[0, 0, 0] == -1.0 and np.count_nonzero(one) == 2


@given(seed=st.integers(0, 2**32 - 1), bins=st.integers(1, 9), n=st.integers(0, 300))
def test_each_event_weighs_one_in_at_most_two_neighbouring_bins(seed, bins, n):
    rng = np.random.default_rng(seed)
    events = random_stream(rng, n, 5, 4, 0.25, 0.75, polarity=1)
    grid = voxel_grid(events, bins=bins, t0_s=0.0, t1_s=1.0, height=4, width=5, normalize=False)
    # All ON: no cancellation, so the total is the number of events (conservation of weight).
    assert grid.sum(dtype=np.float64) == pytest.approx(n, abs=1e-4)
    assert (grid >= 0).all()
    for i in range(min(n, 5)):
        one = EventStream(events.t_s[i:i + 1], events.x[i:i + 1], events.y[i:i + 1], events.p[i:i + 1], 5, 4)
        g = voxel_grid(one, bins=bins, t0_s=0.0, t1_s=1.0, height=4, width=5, normalize=False)
        assert np.abs(g).sum(dtype=np.float64) == pytest.approx(1.0, abs=1e-6)
        used = np.flatnonzero(g.reshape(bins, -1).any(axis=1))
        assert used.size <= 2 and (used.size < 2 or used[1] - used[0] == 1)
        t_star = (bins - 1) * events.t_s[i]
        assert all(abs(b - t_star) < 1 for b in used)
        assert g[:, events.y[i], events.x[i]].sum() == pytest.approx(1.0, abs=1e-6)


def test_mixed_polarities_sum_to_their_net_count():
    rng = np.random.default_rng(3)
    events = random_stream(rng, 1000, 7, 6, 0.0, 2.0)
    grid = voxel_grid(events, bins=5, t0_s=0.0, t1_s=2.0, height=6, width=7, normalize=False)
    assert grid.sum(dtype=np.float64) == pytest.approx(int(events.p.sum()), abs=1e-3)


def test_voxel_grid_rejects_bad_input():
    events = stream([0.5], [0], [0], [1])
    with pytest.raises(InputError, match="outside"):
        voxel_grid(events, bins=5, t0_s=0.6, t1_s=1.0, height=2, width=3, normalize=False)
    with pytest.raises(InputError, match="t1_s > t0_s"):
        voxel_grid(events, bins=5, t0_s=1.0, t1_s=1.0, height=2, width=3, normalize=False)
    with pytest.raises(InputError, match="sensor"):
        voxel_grid(events, bins=5, t0_s=0.0, t1_s=1.0, height=3, width=3, normalize=False)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(InputError):
            voxel_grid(events, bins=bad, t0_s=0.0, t1_s=1.0, height=2, width=3, normalize=False)
    with pytest.raises(InputError):
        voxel_grid(np.zeros((1, 4)), bins=5, t0_s=0.0, t1_s=1.0, height=2, width=3, normalize=False)


# --- normalisation -------------------------------------------------------------------------------


def test_normalisation_keeps_zeros_and_standardises_the_rest():
    rng = np.random.default_rng(0)
    events = random_stream(rng, 500, 16, 12, 0.0, 1.0)
    grid = voxel_grid(events, bins=5, t0_s=0.0, t1_s=1.0, height=12, width=16, normalize=False)
    nonzero = grid != 0
    assert 0 < nonzero.sum() < grid.size  # the example has both kinds of entries
    out = normalize_voxel_grid(grid)
    assert out.dtype == np.float32 and out.shape == grid.shape
    assert (out[~nonzero] == 0).all()
    values = out[nonzero].astype(np.float64)
    assert values.mean() == pytest.approx(0.0, abs=1e-6)
    assert values.std() == pytest.approx(1.0, abs=1e-5)
    # An affine map of the non-zero entries (keeping zeros) is undone by the normalisation.
    scaled = np.where(nonzero, 3.0 * grid + 0.7, 0.0)
    assert (scaled[nonzero] != 0).all()
    np.testing.assert_allclose(normalize_voxel_grid(scaled), out, atol=1e-5)
    # normalize=True is exactly this normalisation.
    direct = voxel_grid(events, bins=5, t0_s=0.0, t1_s=1.0, height=12, width=16, normalize=True)
    np.testing.assert_array_equal(direct, out)


@pytest.mark.parametrize(
    "t, x, y, p",
    [
        ([], [], [], []),  # no events
        ([0.25], [1], [0], [1]),  # one event on a bin centre: one non-zero entry
        ([0.3], [1], [0], [-1]),  # one event between bins: two entries of different size
        ([0.25, 0.5], [0, 2], [0, 1], [1, 1]),  # two equal entries: standard deviation 0
    ],
)
def test_degenerate_grids_give_no_nan_and_no_warning(t, x, y, p):
    events = stream(t, x, y, p)
    grid = voxel_grid(events, bins=5, t0_s=0.0, t1_s=1.0, height=2, width=3, normalize=True)
    assert np.isfinite(grid).all() and grid.dtype == np.float32
    raw = voxel_grid(events, bins=5, t0_s=0.0, t1_s=1.0, height=2, width=3, normalize=False)
    assert (grid[raw == 0] == 0).all()
    if np.count_nonzero(raw) == 2 and len(set(raw[raw != 0].tolist())) == 2:
        # two different values standardise to -1 and +1
        np.testing.assert_allclose(np.sort(grid[raw != 0]), [-1.0, 1.0], atol=1e-6)
    else:
        # nothing to standardise: no contrast, all zero
        assert not grid.any()


# --- spike bins ----------------------------------------------------------------------------------


def test_spike_bins_counts_each_group():
    rng = np.random.default_rng(5)
    planes = rng.random((12, 3, 4)) < 0.3
    counts = spike_bins(planes, 4)
    assert counts.shape == (4, 3, 4) and counts.dtype == np.float32
    for b in range(4):
        np.testing.assert_array_equal(counts[b], planes[3 * b:3 * b + 3].sum(axis=0))
    assert counts.sum() == planes.sum()
    np.testing.assert_array_equal(spike_bins(planes.astype(np.uint8), 1)[0], planes.sum(axis=0))


def test_spike_bins_rejects_uneven_groups():
    planes = np.zeros((10, 2, 2), bool)
    with pytest.raises(InputError, match="equal groups"):
        spike_bins(planes, 4)
    with pytest.raises(InputError, match="shape"):
        spike_bins(planes[0], 1)
    with pytest.raises(InputError):
        spike_bins(planes, 0)
