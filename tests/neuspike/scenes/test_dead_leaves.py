"""The dead-leaves scene: same spec same bytes, radiance range, independently moving layers."""

import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.scenes import SceneSpec, make_scene
from neuspike.scenes.dead_leaves import FOREGROUND_LAYERS, dead_leaves_layers


def spec(**kw):
    base = dict(kind="dead_leaves", size=(48, 32), velocity_px_s=(800.0, -300.0), seed=7)
    base.update(kw)
    return SceneSpec(**base)


def test_same_spec_same_bytes_and_seeds_differ():
    t = np.array([-0.002, 0.0, 0.003])
    a = make_scene(spec()).render(t)
    assert a.shape == (3, 32, 48) and a.dtype == np.float32
    assert np.array_equal(a, make_scene(spec()).render(t))
    assert not np.array_equal(a, make_scene(spec(seed=8)).render(t))


def test_radiance_follows_peak_and_dynamic_range():
    frame = make_scene(spec(peak=2.0)).render([0.0])[0]
    assert frame.min() >= 0.0 and frame.max() <= 2.0 + 1e-6 and frame.std() > 0.05
    hdr = make_scene(spec(dynamic_range=100.0)).render([0.0])[0]
    assert hdr.min() >= 0.01 - 1e-6 and hdr.max() <= 1.0 + 1e-6


def test_layers_move_with_their_own_velocities():
    layers = dead_leaves_layers(spec())
    assert len(layers) == FOREGROUND_LAYERS + 1
    assert layers[0][1] is None and layers[0][2] == (800.0, -300.0)
    velocities = {v for _, _, v in layers}
    assert len(velocities) == len(layers)  # every layer its own velocity
    for _, alpha, _ in layers[1:]:
        assert 0.0 <= alpha.min() and alpha.max() <= 1.0 and 0.0 < alpha.mean() < 1.0  # sparse, occluding
    # a still background: the foreground still moves, so frames differ
    still = make_scene(spec(velocity_px_s=(0.0, 0.0))).render([0.0, 0.01])
    assert not np.allclose(still[0], still[1])


def test_a_video_only_field_is_refused():
    with pytest.raises(InputError, match="video"):
        SceneSpec(kind="dead_leaves", fps=25.0)


def test_broad_leaves_have_wide_uniform_regions_and_leave_the_classic_picture_alone():
    """``leaf_min_radius`` paints tens of large leaves: far fewer edge pixels in the background than the
    classic picture's; unset, the spec's dict (the root of cell seeds and cache keys) and its bytes are
    those of a spec made before the field existed."""
    classic = spec(size=(160, 120))
    assert "leaf_min_radius" not in classic.as_dict()
    # rendered by the code before the field existed (commit 073dcc8): mean, std and four pixels
    frame = make_scene(classic).render([0.0])[0]
    np.testing.assert_allclose([frame.mean(), frame.std(), frame[0, 0], frame[60, 80], frame[119, 159], frame[30, 120]],
                               [0.546245, 0.189276, 0.629302, 0.623356, 0.574438, 0.645098], atol=1e-5)

    def edge_share(s):
        background = dead_leaves_layers(s)[0][0]
        gy, gx = np.gradient(background)
        return float((np.hypot(gx, gy) > 0.05).mean())

    for seed in (1, 2, 3):
        broad = spec(size=(160, 120), seed=seed, leaf_min_radius=0.1)
        assert broad.as_dict()["leaf_min_radius"] == 0.1
        assert edge_share(broad) < 0.5 * edge_share(spec(size=(160, 120), seed=seed))
    with pytest.raises(InputError, match="leaf_min_radius"):
        SceneSpec(kind="pan", leaf_min_radius=0.1)
    for bad in (0.0, 0.3, -0.1):
        with pytest.raises(InputError, match="leaf_min_radius"):
            spec(leaf_min_radius=bad)
