"""Single-window training: the spec's refusals, deterministic cells and batches, the loss falls, resume
reproduces a straight run, a later stage starts from the first."""

import json

import numpy as np
import pytest
import torch

from neuspike.errors import FormatError, InputError
from neuspike.train import TrainSpec, WindowData, learning_rate, load_spec
from neuspike.train.loop import Trainer
from neuspike.train.mixture import LEGACY_DATA_FIELDS, legacy_mixture
from neuspike.train.terms import LEGACY_FIELDS, legacy_losses
from neuspike.train.windows import augment, draw_cell, load_sample, save_sample, simulate_cell

DATA_FIELDS = set(WindowData.__dataclass_fields__)


def window_data(**kw) -> WindowData:
    """A data section from its fields and the earlier loss and data fields' names (read into the loss and
    data terms, as a spec file of those fields is)."""
    rest, losses = legacy_losses(kw, kw.pop("losses", None))
    rest, mixture = legacy_mixture(rest, rest.pop("mixture", None))
    return WindowData(**rest, losses=losses, mixture=mixture)


def tiny_spec(tmp_path, **kw) -> TrainSpec:
    base = dict(out_dir=str(tmp_path / "run"), shard_dir=str(tmp_path / "shard"), steps=4, batch=2, crop=16,
                view=16, train_items=3, val_items=2, val_every=2, checkpoint_every=2, warmup=2, workers=1,
                precision="float32", threads=1)
    base.update(kw)
    data = window_data(**{k: base.pop(k) for k in list(base) if k in DATA_FIELDS or k in LEGACY_FIELDS
                             or k in LEGACY_DATA_FIELDS["windows"]})
    return TrainSpec(data=data, **base)


def test_the_spec_refuses_test_photographs_and_round_trips(tmp_path):
    with pytest.raises(InputError, match="test photographs"):
        WindowData(photos=("camera", "cat"))
    with pytest.raises(InputError, match="crop"):
        TrainSpec(crop=200, data=WindowData(view=128))
    spec = tiny_spec(tmp_path)
    (tmp_path / "spec.json").write_text(json.dumps(spec.as_dict()))
    assert load_spec(tmp_path / "spec.json") == spec


def test_same_seed_same_cells_and_windows(tmp_path):
    spec = tiny_spec(tmp_path)
    a = draw_cell(spec, "train", 5, tmp_path)
    assert a[1:] == draw_cell(spec, "train", 5, tmp_path)[1:] and a[0] == draw_cell(spec, "train", 5, tmp_path)[0]
    kinds = {draw_cell(spec, "train", i, tmp_path)[3]["kind"] for i in range(40)}
    assert {"pan", "zoom", "fan", "dead_leaves"} <= kinds
    lights = [draw_cell(spec, "train", i, tmp_path)[1].light for i in range(40)]
    assert min(lights) >= spec.data.light_range[0] and max(lights) <= spec.data.light_range[1]
    other = tiny_spec(tmp_path, seed=1)
    assert [draw_cell(other, "train", i, tmp_path)[3] for i in range(5)] != \
        [draw_cell(spec, "train", i, tmp_path)[3] for i in range(5)]
    s1, s2 = simulate_cell(spec, "train", 3, tmp_path), simulate_cell(spec, "train", 3, tmp_path)
    assert np.array_equal(s1.spikes.planes, s2.spikes.planes) and np.array_equal(s1.events.t_s, s2.events.t_s)


def test_pan_speeds_are_drawn_in_the_speed_range_and_old_shard_keys_stay(tmp_path):
    from neuspike.train.spec import DEFAULT_SPEED_RANGE

    spec = tiny_spec(tmp_path, view=40, speed_range=(5000.0, 20000.0))
    scale = 40 / 400  # speeds are given at a view 400 pixels wide
    speeds = [float(np.hypot(*scene.velocity_px_s)) / scale
              for scene, *_ in (draw_cell(spec, "train", i, tmp_path) for i in range(60))
              if scene.kind in ("pan", "dead_leaves")]
    assert len(speeds) > 5 and min(speeds) >= 5000.0 - 1e-6 and max(speeds) <= 20000.0 + 1e-6
    assert WindowData().speed_range == DEFAULT_SPEED_RANGE and "speed_range" not in WindowData().key(0)
    assert WindowData(speed_range=(100, 20000)).key(0)["speed_range"] == [100.0, 20000.0]
    with pytest.raises(InputError, match="speed_range"):
        WindowData(speed_range=(0, 100))


def test_scale_range_draws_the_region_at_the_sweeps_scale_and_moves_it_as_a_sweep_would(tmp_path, monkeypatch):
    """On a horizontal ramp photograph (800x500: it fills the 400x250 sensor at half size), a view at r = 1 spans
    80 photograph pixels in 40 (slope 2/800 per pixel), at r = 0.5 twice that; speeds are the drawn px/s times r.
    Without the field the original draw (and the old shard keys) stay."""
    from neuspike.train import windows

    ramp = np.tile(np.arange(800, dtype=np.float32) / 800, (500, 1))
    monkeypatch.setattr(windows, "read_photo", lambda name: ramp)
    for r in (1.0, 0.5):
        spec = tiny_spec(tmp_path / str(r), view=40, speed_range=(5000.0, 20000.0), scale_range=(r, r))
        cells = [draw_cell(spec, "train", i, tmp_path / str(r)) for i in range(40)]
        speeds = [float(np.hypot(*scene.velocity_px_s)) / r for scene, *_ in cells
                  if scene.kind in ("pan", "dead_leaves")]
        assert len(speeds) > 5 and min(speeds) >= 5000.0 - 1e-6 and max(speeds) <= 20000.0 + 1e-6
        for scene, *_ in cells:
            if scene.kind != "dead_leaves":
                slope = np.diff(np.load(scene.image)[:, 4:-4], axis=1)
                assert np.allclose(slope, (2 / r) / 800, atol=1e-5)
    assert WindowData(scale_range=(0.5, 2)).key(0)["scale_range"] == [0.5, 2.0]
    assert "scale_range" not in WindowData().key(0)
    for bad in ((0, 1), (2, 1), "x"):
        with pytest.raises(InputError, match="scale_range"):
            WindowData(scale_range=bad)


def test_sweep_cells_sit_on_the_sweeps_points_and_leave_earlier_draws_alone(tmp_path):
    """With sweep_fraction p, about p of the cells take one of the 12 sweep points (light, S, noise) and pan at
    the sweeps' 1000 px/s; the rest draw from the mixture's ranges. p = 0 keeps an earlier spec's key and
    cell descriptions."""
    from bench.harness import grid
    from neuspike.train.spec import SWEEP_POINTS, SWEEP_SPEED_PX_S

    # the points of the sweeps' own presets (bench.harness.grid): the light sweep, the motion sweep, the noise test
    presets = {(l, grid.PAPER_FIXED_MOTION, "none") for l in grid.PAPER_LIGHTS} | \
        {(grid.PAPER_FIXED_LIGHT, m, "none") for m in grid.PAPER_MOTIONS} | \
        {(grid.PAPER_FIXED_LIGHT, grid.PAPER_FIXED_MOTION, n) for n in grid.PAPER_NOISE_LEVELS}
    assert len(SWEEP_POINTS) == 12 and set(SWEEP_POINTS) == presets
    assert SWEEP_SPEED_PX_S == grid.PAN_SPEED_PX_S_AT_400
    spec = tiny_spec(tmp_path, view=40, speed_range=(5000.0, 20000.0), sweep_fraction=0.5)
    cells = [draw_cell(spec, "train", i, tmp_path) for i in range(200)]
    at = [c for c in cells if c[3]["at_sweep"]]
    assert 70 <= len(at) <= 130  # binomial(200, 0.5): 5 sigma either side
    for scene, cond, _, info in cells:
        if info["at_sweep"]:
            assert (cond.light, cond.motion, cond.noise) in presets
            if scene.kind in ("pan", "dead_leaves"):  # the sweeps' speed at a view 40 pixels wide
                assert np.hypot(*scene.velocity_px_s) == pytest.approx(1000.0 * 40 / 400)
        elif scene.kind in ("pan", "dead_leaves"):
            assert np.hypot(*scene.velocity_px_s) >= 5000.0 * 40 / 400 - 1e-6
    assert len({(c[1].light, c[1].motion, c[1].noise) for c in at}) >= 10
    assert WindowData(mixture={"sweep": 0.25}).key(0)["sweep_fraction"] == 0.25
    assert "sweep_fraction" not in WindowData().key(0)
    old = tiny_spec(tmp_path)
    assert "at_sweep" not in draw_cell(old, "train", 0, tmp_path)[3]
    everyone = tiny_spec(tmp_path, sweep_fraction=1.0)
    assert all(draw_cell(everyone, "train", i, tmp_path)[3]["at_sweep"] for i in range(20))
    for bad in (-0.1, 1.5, True, "half"):
        with pytest.raises(InputError, match="mixture.sweep.fraction"):
            WindowData(mixture={"sweep": bad})


def test_sweep_scenes_give_the_sweep_cells_the_sweeps_own_scenes_and_leave_the_rest_alone(tmp_path):
    """sweep_scenes: the sweep cells take the four kinds of bench.harness.grid alike, the zoom and fan with the
    scenes bench.harness.grid builds (compared field by field with its own SceneSpec), at one of the sweeps'
    points; the other cells are those of the same spec without it."""
    from dataclasses import fields

    from bench.harness import grid
    from neuspike.train.spec import SWEEP_POINTS
    from neuspike.train.windows import SWEEP_SCENE_KINDS

    assert SWEEP_SCENE_KINDS == grid.SCENE_KINDS
    base = tiny_spec(tmp_path, view=40, sweep_fraction=0.5)
    spec = tiny_spec(tmp_path, view=40, sweep_fraction=0.5, sweep_scenes=True)
    kinds = []
    for i in range(120):
        before, after = draw_cell(base, "train", i, tmp_path), draw_cell(spec, "train", i, tmp_path)
        assert after[3]["sweep_scene"] == after[3]["at_sweep"] == before[3]["at_sweep"]
        if not after[3]["at_sweep"]:
            assert after[:3] == before[:3]  # scene, condition, simulation seed
            continue
        assert (after[1].light, after[1].motion, after[1].noise) in SWEEP_POINTS
        scene = after[0]
        kinds.append(scene.kind)
        if scene.kind in ("zoom", "fan"):  # the sweeps' own scene at this view and image
            ours = grid.scene_entry(f"{scene.kind}:{scene.image}", scene.size).spec
            for f in fields(scene):
                if f.name not in ("image",):
                    assert getattr(scene, f.name) == getattr(ours, f.name), (scene.kind, f.name)
        elif scene.kind == "pan":
            assert np.hypot(*scene.velocity_px_s) == pytest.approx(1000.0 * 40 / 400)
    assert set(kinds) == set(SWEEP_SCENE_KINDS) and "dead_leaves" not in kinds
    assert all(10 <= kinds.count(k) <= 22 for k in SWEEP_SCENE_KINDS)  # about 60 / 4 each
    assert WindowData(mixture={"sweep": {"fraction": 0.5, "scenes": True}}).key(0)["sweep_scenes"] is True
    assert "sweep_scenes" not in WindowData(mixture={"sweep": 0.5}).key(0)
    assert "sweep_scene" not in draw_cell(base, "train", 0, tmp_path)[3]
    with pytest.raises(InputError, match=r"mixture.sweep.scenes.*mixture.sweep.fraction > 0"):
        WindowData(mixture={"sweep": {"scenes": True}})
    with pytest.raises(InputError, match="mixture.sweep.scenes"):
        WindowData(mixture={"sweep": {"fraction": 0.5, "scenes": "yes"}})


def test_the_smooth_term_blurs_a_share_of_the_photographs_outside_a_sharp_ellipse(tmp_path):
    """mixture.smooth p: about p of the photograph cells take their region blurred outside an ellipse, every other
    draw (kind, scene, condition, simulation seed) that of the same spec without it. The saved picture keeps the
    photograph at the ellipse's centre and is smoother than it far outside (its gradient energy there falls),
    its mean level kept; the same seed saves the same picture; the shard key names the term only when set; bad
    widths are refused by name."""
    import dataclasses
    from pathlib import Path

    base = tiny_spec(tmp_path / "base", view=64)
    spec = tiny_spec(tmp_path / "smooth", view=64, mixture={"smooth": {"fraction": 0.5, "sigma": [16, 32]}})
    smooth = pictures = 0
    for i in range(60):
        before, after = draw_cell(base, "train", i, tmp_path / "a"), draw_cell(spec, "train", i, tmp_path / "b")
        assert after[1:3] == before[1:3]
        assert dataclasses.replace(after[0], image=before[0].image) == before[0]
        if before[0].kind == "dead_leaves":
            assert after[3]["smooth"] is False
            continue
        pictures += 1
        if not after[3]["smooth"]:
            np.testing.assert_array_equal(np.load(after[0].image), np.load(before[0].image))
            continue
        smooth += 1
        photo, picture = np.load(before[0].image), np.load(after[0].image)
        assert Path(after[0].image).name.endswith(f"-smooth-{i:06d}.npy") and picture.dtype == np.float32
        assert abs(float(picture.mean()) - float(photo.mean())) < 0.02
        again = draw_cell(spec, "train", i, tmp_path / "c")[0]
        np.testing.assert_array_equal(np.load(again.image), picture)

        def roughness(x):
            return float(np.abs(np.diff(x, axis=0)).mean() + np.abs(np.diff(x, axis=1)).mean())

        gap = np.abs(picture - photo)
        corners = np.concatenate([gap[:6, :6].ravel(), gap[:6, -6:].ravel(), gap[-6:, :6].ravel(), gap[-6:, -6:].ravel()])
        if roughness(photo) > 0.01:
            assert roughness(picture) < roughness(photo)
        assert float(gap.min()) < 1e-3 or float(corners.max()) == 0.0  # sharp somewhere: the ellipse
    assert pictures > 20 and 0.2 < smooth / pictures < 0.8
    assert spec.data.key(0)["smooth"] == [0.5, [16.0, 32.0]] and "smooth" not in base.data.key(0)
    for bad in ([0, 4], [8, 4], [4], "wide", [4, float("inf")]):
        with pytest.raises(InputError, match="mixture.smooth.sigma"):
            WindowData(mixture={"smooth": {"fraction": 0.5, "sigma": bad}})


def test_broad_fraction_swaps_only_the_picture_for_a_broad_leaves_one(tmp_path):
    """broad_fraction p: about p of the picture cells take a broad-leaves picture (the saved file is the
    first frame of the still dead-leaves scene named by its seed, rendered again here), with every other
    draw (kind, scene parameters, condition, simulation seed) that of the same spec without it; dead-leaves
    cells are untouched. The shard key names the fraction only when it is set; bad fractions are refused."""
    import dataclasses
    from pathlib import Path

    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.train.__main__ import build_parser, spec_from_args
    from neuspike.utils.rng import derive_rng

    base, spec = tiny_spec(tmp_path, view=40), tiny_spec(tmp_path, view=40, broad_fraction=0.5)
    broad = pictures = 0
    for i in range(80):
        before, after = draw_cell(base, "train", i, tmp_path), draw_cell(spec, "train", i, tmp_path)
        assert after[1:3] == before[1:3]  # condition, simulation seed
        assert dataclasses.replace(after[0], image=before[0].image) == before[0]
        if before[0].kind == "dead_leaves":
            assert after[0] == before[0] and after[3]["broad"] is False
            continue
        pictures += 1
        if after[0].image == before[0].image:
            assert after[3]["broad"] is False
            continue
        broad += 1
        assert after[3]["broad"] is True
        rng = derive_rng(spec.seed, "broad-picture", "train", i)  # the picture's own stream: draw, radius, seed
        assert rng.random() < 0.5
        radius, seed = rng.uniform(0.05, 0.15), int(rng.integers(2**31))
        assert Path(after[0].image).name == f"train-{i:06d}-broad-{seed}.npy"
        scene = make_scene(SceneSpec("dead_leaves", size=(40, 40), velocity_px_s=(0.0, 0.0), seed=seed,
                                     leaf_min_radius=radius))
        saved = np.load(after[0].image)
        assert saved.dtype == np.float32 and saved.std() > 0.01
        np.testing.assert_array_equal(saved, np.clip(scene.render(np.array([0.0]))[0], 0, 1).astype(np.float32))
    assert pictures > 30 and abs(broad / pictures - 0.5) < 4 * (0.25 / pictures) ** 0.5
    assert "broad" not in draw_cell(base, "train", 0, tmp_path)[3]
    assert spec.data.key(0)["broad_fraction"] == 0.5 and "broad_fraction" not in base.data.key(0)
    for bad in (-0.1, 1.5, True, "half"):
        with pytest.raises(InputError, match="mixture.broad.fraction"):
            WindowData(mixture={"broad": bad})
    args = build_parser().parse_args(["neuspike-net", "--set", "data.mixture.broad=0.3", "--out", str(tmp_path / "r")])
    assert spec_from_args(args).data.mixture == {"broad": {"fraction": 0.3}}


def test_fast_pans_pan_a_share_of_the_other_cells_at_multiples_of_the_sweeps_speed(tmp_path):
    """mixture.fast_pans p: about p of the cells not at a sweep point are pans of a training photograph at one
    of the given multiples of 1000 px/s (scaled with the region as every speed is), at S = motion, one of the
    sweeps' light scales and no noise; every other cell is the one drawn without the term, and a spec
    without it keeps its key."""
    from bench.harness import grid
    from neuspike.train.windows import FAST_PAN_LIGHTS

    assert set(FAST_PAN_LIGHTS) == set(grid.PAPER_LIGHTS)
    common = dict(view=40, scale_range=(0.5, 1.5), sweep_fraction=0.3)
    base = tiny_spec(tmp_path, **common)
    spec = tiny_spec(tmp_path, **common, losses=None,
                     mixture={"sweep": {"fraction": 0.3}, "fast_pans": {"fraction": 0.5, "speeds": [4, 16]}})
    fast, others, multiples = 0, 0, set()
    for i in range(160):
        before, after = draw_cell(base, "train", i, tmp_path), draw_cell(spec, "train", i, tmp_path)
        if before[3]["at_sweep"]:
            assert after[:3] == before[:3] and after[3]["fast_pan"] is False
            continue
        others += 1
        if not after[3]["fast_pan"]:
            assert after[:3] == before[:3]
            continue
        fast += 1
        scene, cond = after[0], after[1]
        assert scene.kind == "pan" and cond.motion == 256 and cond.noise == "none" and cond.light in FAST_PAN_LIGHTS
        # 1000 px/s times the multiple times the region's scale (0.5-1.5: the two multiples' ranges do not overlap)
        speed = np.hypot(*scene.velocity_px_s)
        assert 0.5 - 1e-9 <= speed / 4000.0 <= 1.5 + 1e-9 or 0.5 - 1e-9 <= speed / 16000.0 <= 1.5 + 1e-9
        multiples.add(4 if speed < 7000.0 else 16)
    assert others > 80 and abs(fast / others - 0.5) < 4 * (0.25 / others) ** 0.5 and multiples == {4, 16}
    assert spec.data.key(0)["fast_pans"] == [0.5, [4.0, 16.0], 256] and "fast_pans" not in base.data.key(0)
    for bad in ({"fraction": 0.5, "speeds": []}, {"fraction": 0.5, "speeds": [0]}, {"fraction": 0.5, "motion": 0},
                {"speeds": [2]}):
        with pytest.raises(InputError, match="mixture.fast_pans"):
            WindowData(mixture={"fast_pans": bad})


def test_sweep_scene_weights_set_the_shares_of_the_sweep_scenes(tmp_path):
    """sweep_scene_weights: the sweep cells' kinds in the given shares (all fans with (0, 0, 1, 0); about
    4 / 7 fans with (1, 1, 4, 1)), each at one of the sweeps' points; the other cells unchanged."""
    from neuspike.train.__main__ import build_parser, spec_from_args
    from neuspike.train.spec import SWEEP_POINTS

    equal = tiny_spec(tmp_path, view=40, sweep_fraction=0.5, sweep_scenes=True)
    fans = tiny_spec(tmp_path, view=40, sweep_fraction=0.5, sweep_scenes=True, sweep_scene_weights=[0, 0, 1, 0])
    heavy = tiny_spec(tmp_path, view=40, sweep_fraction=0.5, sweep_scenes=True, sweep_scene_weights=(1, 1, 4, 1))
    assert heavy.data.mixture["sweep"]["scene_weights"] == (1.0, 1.0, 4.0, 1.0)
    counts = {"fan": 0, "other": 0}
    for i in range(200):
        before, only, most = (draw_cell(s, "train", i, tmp_path) for s in (equal, fans, heavy))
        assert before[3]["at_sweep"] == only[3]["at_sweep"] == most[3]["at_sweep"]
        if not before[3]["at_sweep"]:
            assert only[:3] == before[:3] == most[:3]
            continue
        assert only[0].kind == "fan"
        assert (only[1].light, only[1].motion, only[1].noise) in SWEEP_POINTS
        counts["fan" if most[0].kind == "fan" else "other"] += 1
    n = counts["fan"] + counts["other"]
    assert n > 60 and abs(counts["fan"] / n - 4 / 7) < 4 * (4 / 7 * 3 / 7 / n) ** 0.5
    assert heavy.data.key(0)["sweep_scene_weights"] == [1.0, 1.0, 4.0, 1.0]
    assert "sweep_scene_weights" not in equal.data.key(0)
    for bad in ((1, 1, 1), (0, 0, 0, 0), (1, -1, 1, 1), (1, 1, float("nan"), 1), "1,1,4,1", (True, 1, 1, 1)):
        with pytest.raises(InputError, match="mixture.sweep.scene_weights"):
            WindowData(mixture={"sweep": {"fraction": 0.5, "scenes": True, "scene_weights": bad}})
    with pytest.raises(InputError, match="mixture.sweep.scene_weights.*mixture.sweep.scenes"):
        WindowData(mixture={"sweep": {"fraction": 0.5, "scene_weights": (1, 1, 4, 1)}})
    args = build_parser().parse_args(["neuspike-net", "--set",
                                      'data.mixture.sweep={"fraction": 0.5, "scenes": true, "scene_weights": [1,1,4,1]}',
                                      "--out", str(tmp_path / "r")])
    assert spec_from_args(args).data.mixture["sweep"]["scene_weights"] == (1.0, 1.0, 4.0, 1.0)
    for retired in ("--sweep-fraction", "--broad-fraction"):  # the earlier flags are gone, not silently ignored
        with pytest.raises(SystemExit):
            build_parser().parse_args(["neuspike-net", retired, "0.5"])


def test_saved_windows_load_back_identically(tmp_path):
    spec = tiny_spec(tmp_path)
    s = simulate_cell(spec, "val", 0, tmp_path)
    save_sample(tmp_path / "w.npz", s)
    back = load_sample(tmp_path / "w.npz")
    assert np.array_equal(back.spikes.planes, s.spikes.planes)
    w = s.window_events()
    assert np.array_equal(back.events.t_s, w.t_s) and np.array_equal(back.events.p, w.p)
    assert np.array_equal(back.ground_truth, s.ground_truth) and back.spikes.gain == s.spikes.gain


def test_augment_applies_one_transform_to_every_tensor():
    x = torch.arange(2 * 8 * 8, dtype=torch.float32).reshape(2, 8, 8)
    y = x[:1].clone()
    a = augment([x, y], np.random.default_rng(3), 6)
    b = augment([x, y], np.random.default_rng(3), 6)
    assert torch.equal(a[0], b[0]) and torch.equal(a[0][:1], a[1])
    assert a[0].shape == (2, 6, 6)


def test_learning_rate_warms_up_then_decays_to_the_floor(tmp_path):
    spec = tiny_spec(tmp_path, steps=100, warmup=10, lr=1e-3, lr_min=1e-5)
    assert learning_rate(spec, 0) == pytest.approx(1e-4)
    assert learning_rate(spec, 9) == pytest.approx(1e-3)
    assert learning_rate(spec, 100) == pytest.approx(1e-5)


def test_the_loss_falls_on_a_fixed_batch(tmp_path, one_torch_thread):
    trainer = Trainer(tiny_spec(tmp_path, lr=2e-3, warmup=1, steps=1000), quiet=True)
    g = torch.Generator().manual_seed(0)
    # the shipped design's spike input: the 32 channels and the key estimates after them
    spikes = torch.rand(2, 32 + trainer.module.key_channels, 16, 16, generator=g)
    events = torch.randn(2, 32, 16, 16, generator=g)
    # not the mean of the spike channels, which the support head gives before any step
    target = 0.5 * spikes[:, :1] + 0.5 * torch.sigmoid(events[:, :1])
    quantum = torch.full((2, 1, 16, 16), 0.5)  # the shipped head counts its correction in spikes
    trainer.task.batch = lambda step: ([spikes, events, quantum], target)  # one fixed batch
    trainer.task.step_variant = lambda step: "fusion"
    losses = [trainer.train_step()["loss"] for _ in range(15)]
    assert np.mean(losses[-5:]) < 0.7 * np.mean(losses[:3])


def test_a_resumed_run_equals_a_straight_run(tmp_path, one_torch_thread):
    shard = str(tmp_path / "shard")  # one shard: its photo crops are named by path in the scene specs
    straight = Trainer(tiny_spec(tmp_path / "a", shard_dir=shard), quiet=True)
    straight.run()
    Trainer(tiny_spec(tmp_path / "b", shard_dir=shard), quiet=True).run(until=2)  # killed after step 2
    with pytest.raises(InputError, match="another spec"):
        Trainer(tiny_spec(tmp_path / "b", shard_dir=shard, lr=1e-3), quiet=True).run()
    resumed = Trainer(tiny_spec(tmp_path / "b", shard_dir=shard), quiet=True)
    assert resumed.run()["resumed"]
    for (k, v), w in zip(straight.module.state_dict().items(), resumed.module.state_dict().values()):
        assert torch.equal(v, w), k
    log = (tmp_path / "b" / "run" / "train_log.csv").read_text().splitlines()
    steps = [int(r.split(",")[0]) for r in log[1:] if ",train," in r]
    assert steps == [1, 2, 3, 4]
    straight_log = (tmp_path / "a" / "run" / "train_log.csv").read_text().splitlines()
    # the same rows (step, kind, variant, loss) as the straight run: none repeated, none lost
    assert [r.split(",")[:4] for r in log] == [r.split(",")[:4] for r in straight_log]
    assert (tmp_path / "a" / "run" / "neuspike-net.safetensors").exists()
    assert (tmp_path / "a" / "run" / "neuspike-net-spike.safetensors").exists()


def test_a_second_stage_starts_from_the_first_and_exports_only_improvements(tmp_path, one_torch_thread):
    shard = str(tmp_path / "shard")
    first = Trainer(tiny_spec(tmp_path / "a", shard_dir=shard), quiet=True)
    first.run()
    weights = tmp_path / "a" / "run" / "neuspike-net.safetensors"
    with pytest.raises(InputError, match="safetensors"):
        tiny_spec(tmp_path / "b", shard_dir=shard, init_from=str(tmp_path / "w.pt"))
    with pytest.raises(InputError, match="init_from .*no such file"):  # named, before the run folder exists
        Trainer(tiny_spec(tmp_path / "c", shard_dir=shard, init_from=str(tmp_path / "gone.safetensors")), quiet=True)
    assert not (tmp_path / "c").exists()
    second = Trainer(tiny_spec(tmp_path / "b", shard_dir=shard, steps=2, init_from=str(weights)), quiet=True)
    from neuspike.methods.weights import load_safetensors

    saved = load_safetensors(weights)
    for k, v in second.module.state_dict().items():  # the exported (bfloat16) weights, cast back
        assert torch.equal(v, saved[k].to(v.dtype)), k
    second.run()
    import csv

    rows = list(csv.DictReader(open(tmp_path / "b" / "run" / "train_log.csv")))
    baseline = {r["variant"]: float(r["val_psnr"]) for r in rows if r["step"] == "0" and r["kind"] == "val"}
    assert set(baseline) == {"fusion", "spike"}  # fusion and spike-only scored before the first step
    assert set(second.best) == {"fusion", "spike"}
    assert all(second.best[v]["val_psnr"] >= baseline[v] for v in baseline)


def test_a_stage_that_adds_the_motion_gate_starts_as_the_weights_and_trains_the_gate_faster(tmp_path, one_torch_thread):
    """Weights without the gate start a gated run unchanged; the gate's parameters (and only they) learn at
    new_parts_lr_scale times the rate; the spike-only export leaves the gate out."""
    from neuspike.methods.weights import load_safetensors

    shard = str(tmp_path / "shard")
    Trainer(tiny_spec(tmp_path / "a", shard_dir=shard, steps=1, params={"motion_gate": "none"}), quiet=True).run()
    weights = tmp_path / "a" / "run" / "neuspike-net.safetensors"
    with pytest.raises(InputError, match="new_parts_lr_scale"):
        tiny_spec(tmp_path / "b", shard_dir=shard, new_parts_lr_scale=0.0)
    spec = tiny_spec(tmp_path / "b", shard_dir=shard, steps=4, init_from=str(weights), new_parts_lr_scale=10.0,
                     params={"motion_gate": "stats"})
    second = Trainer(spec, quiet=True)
    saved = load_safetensors(weights)
    gate = {k for k in second.module.state_dict() if k.startswith("motion_gate.")}
    assert gate and set(second.module.state_dict()) - set(saved) == gate
    for k in saved:
        assert torch.equal(second.module.state_dict()[k], saved[k].to(torch.float32)), k
    second.run()
    rest, new = second.optim.param_groups
    assert {id(p) for p in new["params"]} == {id(p) for n, p in second.module.named_parameters() if n in gate}
    assert new["lr"] == pytest.approx(10.0 * rest["lr"]) and rest["lr"] == pytest.approx(learning_rate(spec, 3))
    name, state, params = second.task.exported("spike", "neuspike-net")
    assert name == "neuspike-net-spike" and params["motion_gate"] == "none" and params["spike_only"] is True
    assert not any(k.startswith("motion_gate.") for k in state)


def test_auto_precision_takes_bfloat16_only_when_a_measured_step_is_faster_and_a_resume_keeps_it(
        tmp_path, one_torch_thread, monkeypatch):
    import json

    spec = tiny_spec(tmp_path, precision="auto", steps=2)
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    before = {k: v.clone() for k, v in trainer.module.state_dict().items()}
    assert trainer._step_ms("bfloat16", repeats=1) > 0 and trainer._step_ms("float32", repeats=1) > 0
    for k, v in trainer.module.state_dict().items():  # timing a step changes no weight
        assert torch.equal(v, before[k]), k
    for bf16_ms, want in ((95.0, "float32"), (80.0, "bfloat16")):
        (tmp_path / "run" / "precision.json").unlink(missing_ok=True)
        trainer.precision = "bfloat16"  # what "auto" resolves to on a CPU with native bfloat16
        monkeypatch.setattr(trainer, "_step_ms", lambda p, repeats=3, b=bf16_ms: {"float32": 100.0, "bfloat16": b}[p])
        record = trainer.choose_precision()
        assert record["measured"] and record["choice"] == want == trainer.precision == trainer.task.precision
    resumed = Trainer(spec, quiet=True)  # the folder's record wins over a new measurement
    assert resumed.choose_precision()["choice"] == "bfloat16" == resumed.precision
    assert json.loads((tmp_path / "run" / "precision.json").read_text())["ms_per_step"]["bfloat16"] == 80.0
    plain = Trainer(tiny_spec(tmp_path / "f32", precision="float32"), quiet=True).choose_precision()
    assert plain == {"choice": "float32", "requested": "float32", "measured": False}
    # a damaged record is one line naming the file, not a traceback
    for text in ("garbage{", "[1, 2]", '{"choice": "float16"}'):
        (tmp_path / "run" / "precision.json").write_text(text)
        with pytest.raises(FormatError, match="precision.json"):
            Trainer(spec, quiet=True).choose_precision()


def test_the_offset_term_adds_its_weight_times_the_error_of_each_crops_level():
    """A constant shift c of a crop costs offset_weight * |c| more than without the term; a crop whose
    level is right costs nothing more; the weight is checked and old specs mean 0."""
    from neuspike.methods import create
    from neuspike.train.windows import WindowTask

    method = create("neuspike-net-spike", precision="float32")
    gen = torch.Generator().manual_seed(0)
    target = torch.rand(2, 1, 24, 24, generator=gen) * 0.5 + 0.25
    shifted = target + torch.tensor([0.05, -0.02]).view(2, 1, 1, 1)
    tasks = {w: WindowTask(TrainSpec(data=window_data(offset_weight=w)), method) for w in (0.0, 3.0)}
    base, _ = tasks[0.0].loss(shifted, target)
    with_term, _ = tasks[3.0].loss(shifted, target)
    assert float(with_term - base) == pytest.approx(3.0 * (0.05 + 0.02) / 2, rel=1e-5)
    texture = target + 0.1 * (torch.rand(2, 1, 24, 24, generator=gen) - 0.5)
    texture = texture - texture.mean(dim=(-2, -1), keepdim=True) + target.mean(dim=(-2, -1), keepdim=True)
    extra = tasks[3.0].loss(texture, target)[0] - tasks[0.0].loss(texture, target)[0]
    assert float(extra) == pytest.approx(0.0, abs=1e-6)
    _check_loss_weight_field("offset")
    assert "offset" not in WindowData().losses


def _check_loss_weight_field(term: str) -> None:
    """A loss term's weight: bad values refused by name, the shard key unchanged by it, a spec file
    without the term has none, and the earlier field (``<term>_weight``) reads into the term."""
    from neuspike.train.spec import spec_from_dict

    for bad in (-0.1, float("nan"), float("inf"), "1", True):
        with pytest.raises(InputError, match=f"losses.{term}.weight"):
            WindowData(losses={term: bad})
    assert WindowData(losses={term: 0.5}).key(0) == WindowData().key(0)
    earlier = TrainSpec(data=WindowData()).as_dict()
    assert term not in spec_from_dict(earlier).data.losses
    earlier["data"].pop("losses")
    earlier["data"][f"{term}_weight"] = 0.5  # a spec file of the earlier field
    read = spec_from_dict(earlier).data.losses
    assert read[term]["weight"] == 0.5 and {k: v for k, v in read.items() if k != term} == WindowData().losses


def test_the_support_term_scores_the_convex_part_and_leaves_the_shard_key(tmp_path, one_torch_thread):
    """support_weight w adds w * L1(convex part, truth) to the loss (computed by hand here), logs it,
    keeps the shard key and old specs (0), is refused for a tanh head and for bad weights; a run with
    it trains and its log keeps the column."""
    from neuspike.methods import create
    from neuspike.train.windows import WindowTask

    method = create("neuspike-net", precision="float32")
    gen = torch.Generator().manual_seed(1)
    target = torch.rand(2, 1, 24, 24, generator=gen)
    image = target + 0.05 * torch.randn(2, 1, 24, 24, generator=gen)
    convex = target + 0.2 * torch.randn(2, 1, 24, 24, generator=gen)
    tasks = {w: WindowTask(TrainSpec(data=window_data(support_weight=w)), method) for w in (0.0, 0.5)}
    base, _ = tasks[0.0].loss(image, target)
    with_term, parts = tasks[0.5].loss((image, convex), target)
    by_hand = float((convex - target).abs().mean())
    assert parts["support_l1"] == pytest.approx(by_hand, rel=1e-6)
    assert float(with_term - base) == pytest.approx(0.5 * by_hand, rel=1e-5)
    with pytest.raises(InputError, match="convex part"):
        tasks[0.5].loss(image, target)
    _check_loss_weight_field("support")
    from neuspike.nets import DEFAULT_DESIGN, NeuSpikeNetMethod

    tanh = NeuSpikeNetMethod("neuspike-net", precision="float32", **{**DEFAULT_DESIGN, "spike_only": False, "head": "tanh"})
    with pytest.raises(InputError, match="losses.support"):
        WindowTask(TrainSpec(data=window_data(support_weight=0.5)), tanh)

    trainer = Trainer(tiny_spec(tmp_path, support_weight=0.5, steps=2, val_every=2), quiet=True)
    trainer.run()
    log = (tmp_path / "run" / "train_log.csv").read_text().splitlines()
    assert "support_l1" in log[0].split(",")
    rows = [r for r in log[1:] if ",train," in r]
    assert rows and all(r.split(",")[log[0].split(",").index("support_l1")] != "" for r in rows)


def test_the_edge_ssim_term_scores_the_ssim_loss_on_the_truths_edges_only():
    """edge_ssim_weight w adds w * mean((1 - SSIM map) / 2) over the top 10 % of the truth's gradient
    (the fast-motion report's edge mask, pixel for pixel); with every pixel an edge it would be the
    whole-image SSIM loss; a perfect image costs nothing; the weight is checked, old specs mean 0, and
    the shard key is unchanged."""
    import kornia

    from neuspike.methods import create
    from neuspike.train.terms import edge_mask
    from neuspike.train.windows import WindowTask
    from bench.fast_motion import edge_mask as report_edges

    method = create("neuspike-net-spike", precision="float32")
    gen = torch.Generator().manual_seed(2)
    target = torch.rand(2, 1, 32, 32, generator=gen)
    pred = (target + 0.1 * torch.randn(2, 1, 32, 32, generator=gen)).clamp(0, 1)
    mask = edge_mask(target)
    for i in range(2):
        assert np.array_equal(mask[i, 0].numpy(), report_edges(target[i, 0].numpy()))
    assert int(mask.sum()) == 2 * round(0.1 * 32 * 32)
    tasks = {w: WindowTask(TrainSpec(data=window_data(edge_ssim_weight=w)), method) for w in (0.0, 2.0)}
    base, _ = tasks[0.0].loss(pred, target)
    with_term, parts = tasks[2.0].loss(pred, target)
    ssim_map = kornia.metrics.ssim(pred, target, window_size=11, max_val=1.0)
    by_hand = float(((1 - ssim_map) / 2)[mask].mean())
    assert parts["edge_ssim_loss"] == pytest.approx(by_hand, rel=1e-5)
    assert float(with_term - base) == pytest.approx(2.0 * by_hand, rel=1e-5)
    # with every pixel an edge the term is the whole-image SSIM loss the trainer already has
    every = ((1 - ssim_map) / 2).mean()
    assert float(every) == pytest.approx(float(kornia.losses.SSIMLoss(window_size=11, max_val=1.0)(pred, target)),
                                         rel=1e-5)
    assert float(tasks[2.0].loss(target.clone(), target)[1]["edge_ssim_loss"]) == pytest.approx(0.0, abs=1e-6)
    _check_loss_weight_field("edge_ssim")


def test_the_crop_losses_average_to_the_main_loss():
    """Each crop's own L1 + SSIM loss (the spike floor's measure) averages over the batch to the loss."""
    from neuspike.methods import create
    from neuspike.train.windows import WindowTask

    task = WindowTask(TrainSpec(data=window_data(ssim_weight=0.7)), create("neuspike-net", precision="float32"))
    gen = torch.Generator().manual_seed(3)
    target = torch.rand(3, 1, 24, 24, generator=gen)
    pred = (target + 0.2 * torch.randn(3, 1, 24, 24, generator=gen)).clamp(0, 1)
    per_crop = task.crop_losses(pred, target)
    assert per_crop.shape == (3,)
    assert float(per_crop.mean()) == pytest.approx(float(task.loss(pred, target)[0]), rel=1e-5)
    assert float(task.crop_losses(target, target).abs().max()) == pytest.approx(0.0, abs=1e-6)


def test_the_spike_floor_adds_the_fusions_excess_over_its_spike_only_self_and_vanishes_with_a_shut_gate(
        tmp_path, one_torch_thread):
    """spike_floor_weight w adds w * mean(relu(l_fusion - l_spike)) on a fusion step (the two forwards
    computed by hand here) and nothing on a spike-only step; with the motion gate shut (g = 0) the fusion
    is its spike-only self (F(t, 0) = t), so the term is 0. Spike-only networks refuse it by name."""
    from neuspike.methods import create
    from neuspike.train.windows import WindowTask

    with pytest.raises(InputError, match="losses.spike_floor.*fusion networks only"):
        WindowTask(TrainSpec(data=window_data(spike_floor_weight=1.0)), create("neuspike-net-spike"))
    _check_loss_weight_field("spike_floor")
    spec = tiny_spec(tmp_path, spike_floor_weight=2.0, params={"motion_gate": "stats"})
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    plain = WindowTask(tiny_spec(tmp_path, params={"motion_gate": "stats"}), trainer.method)
    plain.train_paths = trainer.task.train_paths
    task = trainer.task
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():  # a fresh network's image does not depend on its features: move every weight
        for p in trainer.module.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=gen))
        # the moved fusion is worse than its spike-only self on some crops, not on all (it depends on the
        # network's initial draw): the first fusion step of the first 40 steps with an excess is the one tested
        for step in [k for k in range(40) if task.step_variant(k) == "fusion"]:
            inputs, target = task.batch(step)
            excess = (task.crop_losses(task.forward(inputs, "fusion"), target)
                      - task.crop_losses(task.forward(inputs, "spike"), target)).clamp_min(0).mean()
            if float(excess) > 0:
                break
        loss, parts = task.step_loss(step, trainer.autocast)
        base, _ = plain.step_loss(step, trainer.autocast)
    assert float(excess) > 0  # (the term is tested where it is not 0)
    assert parts["spike_floor"] == pytest.approx(float(excess), rel=1e-5, abs=1e-7)
    # (the losses are near 2 after the move: float32 rounds their difference to a few 1e-7)
    assert float(loss - base) == pytest.approx(2.0 * float(excess), rel=1e-4, abs=1e-6)
    spike_step = next(k for k in range(100) if task.step_variant(k) == "spike")
    with torch.no_grad():
        assert "spike_floor" not in task.step_loss(spike_step, trainer.autocast)[1]
        gate = trainer.module.motion_gate.mlp[2]
        gate.bias.fill_(-60.0)  # 2 sigmoid(-60): the motion features scaled by ~1e-26
        shut, shut_parts = task.step_loss(step, trainer.autocast)
        assert torch.allclose(task.forward(inputs, "fusion"), task.forward(inputs, "spike"), atol=1e-6)
    assert shut_parts["spike_floor"] == pytest.approx(0.0, abs=1e-6)


def _moved_beside_plain(spec: TrainSpec, plain_spec: TrainSpec):
    """A prepared trainer for ``spec`` with every weight moved (a fresh network's image does not depend on its
    features), and a task of ``plain_spec`` (the same data, without the term under test) on the same windows and
    the same module: the difference of their step losses is the term."""
    from neuspike.train.windows import WindowTask

    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    plain = WindowTask(plain_spec, trainer.method)
    plain.train_paths = trainer.task.train_paths
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in trainer.module.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=gen))
    return trainer, trainer.task, plain


def _floor_step(trainer, task, plain, step: int):
    """``step``'s loss less the plain task's (the term under test), the step's logged parts, and each crop's
    excess relu(l_fusion - l_spike), the two forwards computed here."""
    with torch.no_grad():
        loss, parts = task.step_loss(step, trainer.autocast)
        base, _ = plain.step_loss(step, trainer.autocast)
        inputs, target = task.batch(step)
        excess = (task.crop_losses(task.forward(inputs, "fusion"), target)
                  - task.crop_losses(task.forward(inputs, "spike"), target)).clamp_min(0)
    return loss - base, parts, excess


def test_the_spike_floor_by_noise_level_weighs_each_crop_by_its_windows_level(tmp_path, one_torch_thread):
    """spike_floor_noise_weights gives the crops of the named noise levels their own floor weight (the
    others keep spike_floor_weight): the term is mean_i(w_i * relu(l_fusion,i - l_spike,i)), each crop's
    level read from its window as the simulator recorded it. Bad levels and weights are refused by name,
    the spec round-trips through JSON and the shard key does not change."""
    from neuspike.methods import create
    from neuspike.train.spec import spec_from_dict
    from neuspike.train.windows import WindowTask

    for bad in ({"loud": 1.0}, {"high": -1.0}, {"high": float("nan")}, {}, [("high", 1.0)]):
        with pytest.raises(InputError, match="losses.spike_floor.noise_weights"):
            window_data(spike_floor_noise_weights=bad)
    with pytest.raises(InputError, match="losses.spike_floor.*fusion networks only"):
        WindowTask(TrainSpec(data=window_data(spike_floor_noise_weights={"high": 1.0})), create("neuspike-net-spike"))
    assert window_data(spike_floor_noise_weights={"high": 3}).key(0) == WindowData().key(0)
    spec = tiny_spec(tmp_path, batch=4, train_items=6, noise_levels=("none", "high"), spike_floor_weight=0.5,
                     spike_floor_noise_weights={"high": 4.0}, params={"motion_gate": "stats"})
    assert spec_from_dict(json.loads(json.dumps(spec.as_dict()))) == spec
    trainer, task, plain = _moved_beside_plain(spec, tiny_spec(tmp_path, batch=4, train_items=6,
                                                               noise_levels=("none", "high"),
                                                               params={"motion_gate": "stats"}))
    seen, positive = set(), set()
    for step in [k for k in range(40) if task.step_variant(k) == "fusion"][:8]:  # (enough crops of each level)
        levels = [load_sample(task.train_paths[i]).meta["cell"]["noise"] for i in task.batch_indices(step)]
        assert task.noise_levels(step) == levels
        seen.update(levels)
        weights = torch.tensor([4.0 if level == "high" else 0.5 for level in levels])
        term, parts, excess = _floor_step(trainer, task, plain, step)
        # (the two losses are near 2 here: float32 rounds their difference to a few 1e-7)
        assert float(term) == pytest.approx(float((weights * excess).mean()), rel=1e-4, abs=1e-6)
        assert parts["spike_floor"] == pytest.approx(float(excess.mean()), rel=1e-5, abs=1e-7)
        positive.update(level for level, e in zip(levels, excess.tolist()) if e > 0)
    assert seen == positive == {"none", "high"}  # both weights were used, on crops with an excess


def test_the_spike_floor_emphasis_multiplies_the_weight_of_crops_whose_cell_lies_in_its_ranges(
        tmp_path, one_torch_thread):
    """losses.spike_floor.emphasis: each crop's floor weight (its noise level's, else the term's) times the
    factor of every entry whose light and motion ranges hold the window's cell, read from the shard as the
    simulator recorded it: mean_i(w_i * f_i * relu(l_fusion,i - l_spike,i)). Bad entries refused by name."""
    from neuspike.train.spec import spec_from_dict

    def floor(**params):
        return window_data(losses={"l1": 1, "ssim": 1, "spike_floor": {"weight": 0.5, **params}})

    for bad in ([], {"light": [0, 1], "factor": 2}, [{"light": [0, 1]}], [{"factor": 2}],
                [{"light": [1, 0], "factor": 2}], [{"light": 0.5, "factor": 2}], [{"light": [0, 1], "factor": 0}],
                [{"speed": [0, 1], "factor": 2}]):
        with pytest.raises(InputError, match=r"losses.spike_floor.emphasis"):
            floor(emphasis=bad)
    lights = (0.05, 0.4)
    emphasis = [{"light": [0.2, 1.0], "factor": 3.0}, {"motion": [0, 32], "light": [0.0, 1.0], "factor": 5.0}]
    losses = {"l1": 1, "ssim": 1, "spike_floor": {"weight": 0.5, "noise_weights": {"high": 4.0},
                                                  "emphasis": emphasis}}
    common = dict(batch=4, train_items=8, noise_levels=("none", "high"), light_range=lights, motions=(16, 128),
                  params={"motion_gate": "stats"})
    spec = tiny_spec(tmp_path, losses=losses, **common)
    assert spec_from_dict(json.loads(json.dumps(spec.as_dict()))) == spec
    assert spec.data.key(0) == tiny_spec(tmp_path, **common).data.key(0)  # (the same windows)
    trainer, task, plain = _moved_beside_plain(spec, tiny_spec(tmp_path, **common))
    factors_seen = set()
    for step in [k for k in range(40) if task.step_variant(k) == "fusion"][:8]:
        cells = [load_sample(task.train_paths[i]).meta["cell"] for i in task.batch_indices(step)]
        assert task.cells(step) == cells
        w = []
        for cell in cells:
            f = (3.0 if cell["light"] >= 0.2 else 1.0) * (5.0 if cell["motion"] <= 32 else 1.0)
            factors_seen.add(f)
            w.append((4.0 if cell["noise"] == "high" else 0.5) * f)
        term, _, excess = _floor_step(trainer, task, plain, step)
        assert float(term) == pytest.approx(float((torch.tensor(w) * excess).mean()), rel=1e-4, abs=1e-6)
    assert len(factors_seen) >= 3  # (the windows' draws reach several products of the two entries)


def test_a_window_whose_cell_lacks_its_light_motion_or_noise_is_refused_by_name(tmp_path):
    import numpy as np

    spec = tiny_spec(tmp_path, batch=2, train_items=2)
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    task = trainer.task
    for path in task.train_paths:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        cell = json.loads(str(arrays["cell"]))
        del cell["motion"]
        arrays["cell"] = json.dumps(cell)
        with open(path, "wb") as f:
            np.savez(f, **arrays)
    with pytest.raises(FormatError, match="the window's cell records no motion"):
        task.cells(0)


def test_the_ssim_term_by_noise_level_weighs_each_crop_by_its_windows_level(tmp_path, one_torch_thread):
    """losses.ssim.noise_weights: the term is mean_i(w_i * s_i), s_i a crop's SSIM loss (1 - SSIM) / 2 from
    kornia's SSIM map and w_i its noise level's weight (the others: the term's weight); without it the term
    is as before. Bad levels are refused by name."""
    import kornia

    with pytest.raises(InputError, match="losses.ssim.noise_weights"):
        window_data(losses={"l1": 1, "ssim": {"noise_weights": {"loud": 2.0}}})
    common = dict(batch=4, train_items=6, noise_levels=("none", "high"))
    spec = tiny_spec(tmp_path, losses={"ssim": {"weight": 0.5, "noise_weights": {"high": 3.0}}}, **common)
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    task = trainer.task
    seen = set()
    for step in range(6):
        levels = task.noise_levels(step)
        seen.update(levels)
        with torch.no_grad():
            loss, parts = task.step_loss(step, trainer.autocast)
            inputs, target = task.batch(step)
            image = task.forward(inputs, task.step_variant(step)).float()
            s = ((1 - kornia.metrics.ssim(image, target, window_size=11, max_val=1.0)) / 2).mean(dim=(1, 2, 3))
        w = torch.tensor([3.0 if level == "high" else 0.5 for level in levels])
        assert float(loss) == pytest.approx(float((w * s).mean()), rel=1e-5)
        assert parts["ssim_loss"] == pytest.approx(float(s.mean()), rel=1e-5)
    assert seen == {"none", "high"}


def test_the_spike_floor_on_ssim_alone_compares_each_crops_structure_only(tmp_path, one_torch_thread):
    """spike_floor_terms='ssim': the floor is w * mean_i(relu(s_fusion,i - s_spike,i)), s a crop's SSIM loss
    (1 - SSIM) / 2 alone, computed here straight from kornia's SSIM map; the L1 part of the loss is left out
    of it. Bad values and spike-only networks are refused by name; the spec round-trips and the shard key
    does not change."""
    import kornia

    from neuspike.methods import create
    from neuspike.train.spec import spec_from_dict
    from neuspike.train.windows import WindowTask

    with pytest.raises(InputError, match="losses.spike_floor.terms"):
        window_data(spike_floor_terms="l1")
    with pytest.raises(InputError, match="losses.spike_floor.*fusion networks only"):
        WindowTask(TrainSpec(data=window_data(spike_floor_terms="ssim")), create("neuspike-net-spike"))
    assert window_data(spike_floor_terms="ssim").key(0) == WindowData().key(0)
    small = dict(batch=4, train_items=6, params={"motion_gate": "stats"})
    spec = tiny_spec(tmp_path, spike_floor_weight=3.0, spike_floor_terms="ssim", **small)
    assert spec_from_dict(json.loads(json.dumps(spec.as_dict()))) == spec
    trainer, task, plain = _moved_beside_plain(spec, tiny_spec(tmp_path, **small))
    checked = 0
    # the fusion's SSIM is worse than its spike-only self's on some crops of a moved network, not on all:
    # every fusion step is checked, and at least one of them with a positive term
    for step in [k for k in range(40) if task.step_variant(k) == "fusion"][:6]:
        with torch.no_grad():
            loss, parts = task.step_loss(step, trainer.autocast)
            base, _ = plain.step_loss(step, trainer.autocast)
            inputs, target = task.batch(step)

            def structure(image):
                ssim_map = kornia.metrics.ssim(image.float(), target, window_size=spec.data.losses["ssim"]["window"],
                                               max_val=1.0)
                return ((1.0 - ssim_map) / 2).mean(dim=(1, 2, 3))

            fusion, spike = task.forward(inputs, "fusion"), task.forward(inputs, "spike")
            excess = (structure(fusion) - structure(spike)).clamp_min(0)
            both = (task.crop_losses(fusion, target) - task.crop_losses(spike, target)).clamp_min(0)
        assert parts["spike_floor"] == pytest.approx(float(excess.mean()), rel=1e-5, abs=1e-7)
        # (the two losses are near 2 here: float32 rounds their difference to a few 1e-7)
        assert float(loss - base) == pytest.approx(3.0 * float(excess.mean()), rel=1e-4, abs=1e-6)
        if float(excess.mean()) > 0:
            checked += 1
            assert not torch.allclose(excess, both)  # the L1 part is not in it
    assert checked > 0  # (the term is tested where it is not 0)


def test_gate_targets_add_the_mean_squared_miss_of_the_named_gains(tmp_path, one_torch_thread):
    """gate_targets: each fusion step adds w * the mean of (g - target)^2 over the (crop, motion level)
    pairs whose crop's noise level names a target, g the motion gate's gains for that crop (recomputed
    here from the gate itself on the step's inputs); spike-only steps add nothing. Networks without a
    gate, bad targets and a missing weight are refused by name; the spec round-trips (also from the
    flag) and the shard key does not change."""
    from neuspike.methods import create
    from neuspike.train.method import training_method
    from neuspike.train.spec import spec_from_dict
    from neuspike.train.windows import WindowTask

    targets = {"none": {"3": 0.5}, "small": {"2": 0.25}, "medium": {"1": 0.2, "0": 1.5}, "high": {"1": 0.0}}
    with pytest.raises(InputError, match="weight > 0"):
        window_data(gate_targets=targets)
    with pytest.raises(InputError, match="unknown motion levels"):
        window_data(gate_targets={"high": {"4": 0.0}}, gate_target_weight=1.0)
    with pytest.raises(InputError, match=r"gain in \[0, 2\)"):
        window_data(gate_targets={"high": {"1": 2.0}}, gate_target_weight=1.0)
    on = dict(gate_targets=targets, gate_target_weight=2.5)
    assert window_data(**on).key(0) == WindowData().key(0)
    no_gate = TrainSpec(data=window_data(**on), params={"motion_gate": "none"})
    for network in (create("neuspike-net-spike"), training_method(no_gate)):
        with pytest.raises(InputError, match="no motion (gate|path)"):
            WindowTask(no_gate, network)
    small = dict(batch=4, train_items=8, noise_levels=("none", "small", "medium", "high"),
                 params={"motion_gate": "stats"})
    spec = tiny_spec(tmp_path, **on, **small)
    assert spec_from_dict(json.loads(json.dumps(spec.as_dict()))) == spec
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    task, module = trainer.task, trainer.module
    plain = WindowTask(tiny_spec(tmp_path, **small), trainer.method)
    plain.train_paths = task.train_paths
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():  # a fresh gate gives 1 everywhere: move its weights so the gains differ per crop
        for p in module.motion_gate.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=gen))
    order = {"3": 0, "2": 1, "1": 2, "0": 3}  # the gate lists x_m^3 first
    steps = list(range(12))
    assert {task.step_variant(k) for k in steps} == {"fusion", "spike"}
    seen = set()
    for step in steps:
        with torch.no_grad():
            loss, parts = task.step_loss(step, trainer.autocast)
            base, _ = plain.step_loss(step, trainer.autocast)
            inputs, _ = task.batch(step)
            gains = module.motion_gate(module._split(inputs[0])[0], inputs[1])
        if task.step_variant(step) == "spike":
            assert "gate_target" not in parts and float(loss) == float(base)
            continue
        misses = [(float(gains[i, order[k]]) - t) ** 2
                  for i, level in enumerate(task.noise_levels(step)) for k, t in targets[level].items()]
        seen.update(task.noise_levels(step))
        assert parts["gate_target"] == pytest.approx(sum(misses) / len(misses), rel=1e-5)
        assert float(loss - base) == pytest.approx(2.5 * sum(misses) / len(misses), rel=1e-4, abs=1e-6)
    assert len(seen) >= 2  # (crops of several levels, so the per-crop mapping is exercised)


def test_gate_targets_supervise_the_noise_gate_where_the_network_has_one(tmp_path, one_torch_thread):
    """With motion_gate 'stats-noise' the term is the miss of the noise gate's gains (not the stats gate's):
    recomputed here from the noise gate on the step's inputs, with both gates moved so they differ."""
    targets = {"none": {"1": 1.0}, "small": {"1": 1.0}, "medium": {"1": 0.5}, "high": {"1": 0.0}}
    spec = tiny_spec(tmp_path, gate_targets=targets, gate_target_weight=1.0, batch=4, train_items=8,
                     noise_levels=("none", "small", "medium", "high"), params={"motion_gate": "stats-noise"})
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    task, module = trainer.task, trainer.module
    gen = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in [*module.motion_gate.parameters(), *module.noise_gate.parameters()]:
            p.add_(0.3 * torch.randn(p.shape, generator=gen))
    step = next(k for k in range(20) if task.step_variant(k) == "fusion")
    with torch.no_grad():
        _, parts = task.step_loss(step, trainer.autocast)
        inputs, _ = task.batch(step)
        spikes = module._split(inputs[0])[0]
        noise, stats = module.noise_gate(spikes, inputs[1]), module.motion_gate(spikes, inputs[1])
    want = [targets[level]["1"] for level in task.noise_levels(step)]
    miss = float((noise[:, 2] - torch.tensor(want)).square().mean())
    assert parts["gate_target"] == pytest.approx(miss, rel=1e-5)
    assert parts["gate_target"] != pytest.approx(float((stats[:, 2] - torch.tensor(want)).square().mean()), rel=1e-3)


def test_gate_forcing_trains_the_rest_on_the_targets_and_the_gate_on_its_miss(tmp_path, one_torch_thread):
    """gate_forcing: the step's image comes from a forward whose supervised gains are the targets (x_m^1
    here; the other levels the gate's own), rebuilt here by patching the noise gate; the term is still the
    miss of the gate's own gains, and the gate gets gradient from that term alone on the forced gains.
    Forcing without targets is refused."""
    with pytest.raises(InputError, match="losses.gate_target: give its targets"):
        window_data(gate_forcing=True)
    targets = {"none": {"1": 1.0}, "small": {"1": 1.0}, "medium": {"1": 0.5}, "high": {"1": 0.0}}
    common = dict(batch=4, train_items=8, noise_levels=("none", "small", "medium", "high"),
                  params={"motion_gate": "stats-noise"})
    spec = tiny_spec(tmp_path, gate_targets=targets, gate_target_weight=1.0, gate_forcing=True, **common)
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(trainer._bar)
    task, module = trainer.task, trainer.module
    gen = torch.Generator().manual_seed(2)
    with torch.no_grad():
        for p in module.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=gen))
    step = next(k for k in range(20) if task.step_variant(k) == "fusion")
    levels = task.noise_levels(step)
    want = torch.tensor([targets[level]["1"] for level in levels])
    loss, parts = task.step_loss(step, trainer.autocast)
    inputs, target = task.batch(step)
    with torch.no_grad():
        own = module.noise_gate(module._split(inputs[0])[0], inputs[1])
        forced = own.clone()
        forced[:, 2] = want
        handle = module.noise_gate.register_forward_hook(lambda _m, _i, _out: forced)
        try:
            image = task.forward(inputs, "fusion")
        finally:
            handle.remove()
        main, _ = task.loss(image, target)
        free, _ = task.loss(task.forward(inputs, "fusion"), target)
    miss = float((own[:, 2] - want).square().mean())
    assert parts["gate_target"] == pytest.approx(miss, rel=1e-5)
    assert float(loss.detach()) == pytest.approx(float(main) + miss, rel=1e-5)
    assert abs(float(main) - float(free)) > 1e-6  # (forcing changed the image)
    module.zero_grad()
    loss.backward()
    last = module.noise_gate.mlp[2]
    # the x_m^1 row of the gate's last layer learns from the miss alone: 2 (g - t) g (1 - g / 2) over the batch
    g = own[:, 2]
    hidden = torch.relu(module.noise_gate.mlp[0](
        type(module.noise_gate).statistics(module._split(inputs[0])[0], inputs[1]))).detach()
    expected = ((2 * (g - want) * g * (1 - g / 2) / len(g))[:, None] * hidden).sum(0)
    assert torch.allclose(last.weight.grad[2], expected, rtol=1e-4, atol=1e-7)


def test_training_the_motion_path_only_holds_the_rest_bit_for_bit(tmp_path, one_torch_thread):
    """train_parts='motion' trains only the motion path: every other parameter (so the spike-only variant)
    ends as init_from gave it, the motion parameters move; it needs init_from and a fusion network."""
    from neuspike.methods.weights import load_safetensors
    from neuspike.train.windows import MOTION_PREFIXES

    with pytest.raises(InputError, match="train_parts"):
        WindowData(train_parts="decoders")
    with pytest.raises(InputError, match="train_parts 'motion'.*init_from"):
        tiny_spec(tmp_path, train_parts="motion")
    shard = str(tmp_path / "shard")
    Trainer(tiny_spec(tmp_path / "a", shard_dir=shard, steps=1, params={"motion_gate": "stats"}), quiet=True).run()
    weights = tmp_path / "a" / "run" / "neuspike-net.safetensors"
    saved = load_safetensors(weights)
    spec = tiny_spec(tmp_path / "b", shard_dir=shard, steps=3, init_from=str(weights), train_parts="motion",
                     spike_floor_weight=1.0, params={"motion_gate": "stats"}, lr=1e-3)
    second = Trainer(spec, quiet=True)
    assert {second.task.step_variant(k) for k in range(20)} == {"fusion"}  # a spike-only step would train nothing
    second.run()
    moved = 0
    for k, v in second.module.state_dict().items():
        if k.startswith(MOTION_PREFIXES):
            moved += not torch.equal(v, saved[k].to(v.dtype))
        else:
            assert torch.equal(v, saved[k].to(v.dtype)), k
    assert moved > 0
    name, state, _ = second.task.exported("spike", "neuspike-net")
    assert all(torch.equal(v, saved[k].to(v.dtype)) for k, v in state.items())


def test_part_lr_scales_give_a_named_part_its_own_multiple_of_the_rate(tmp_path, one_torch_thread):
    """part_lr_scales {prefix: k}: those parameters (and only they) learn at k times the schedule's rate;
    a multiple of 0 holds that part bit for bit (no gradient, no group); a prefix that names nothing, or a
    bad multiple, is refused by name; earlier specs mean none."""
    from neuspike.train.spec import spec_from_dict

    for bad in (-1.0, float("nan"), True, "2"):
        with pytest.raises(InputError, match="part_lr_scales"):
            tiny_spec(tmp_path, part_lr_scales={"motion_gate.": bad})
    with pytest.raises(InputError, match="part_lr_scales"):
        tiny_spec(tmp_path, part_lr_scales={"": 2.0})
    earlier = tiny_spec(tmp_path).as_dict()
    del earlier["part_lr_scales"]
    assert spec_from_dict(earlier).part_lr_scales == {}
    with pytest.raises(InputError, match="'nothing.' names no parameter"):
        Trainer(tiny_spec(tmp_path / "x", part_lr_scales={"nothing.": 2.0}), quiet=True)
    spec = tiny_spec(tmp_path / "a", steps=3, params={"motion_gate": "stats"}, part_lr_scales={"motion_gate.": 10.0})
    trainer = Trainer(spec, quiet=True)
    trainer.run()
    rest, gate = trainer.optim.param_groups
    named = dict(trainer.module.named_parameters())
    assert {id(p) for p in gate["params"]} == {id(p) for n, p in named.items() if n.startswith("motion_gate.")}
    assert len(rest["params"]) + len(gate["params"]) == len(named)
    assert gate["lr"] == pytest.approx(10.0 * rest["lr"]) and rest["lr"] == pytest.approx(learning_rate(spec, 2))
    again = Trainer(spec, quiet=True)
    assert again.run()["resumed"]  # the optimiser's groups load back from the checkpoint
    for a, b in zip(trainer.optim.param_groups, again.optim.param_groups):
        assert a["lr_scale"] == b["lr_scale"] and len(a["params"]) == len(b["params"])
    held = tiny_spec(tmp_path / "b", steps=3, params={"motion_gate": "stats"}, part_lr_scales={"motion_gate.": 0.0},
                     lr=1e-2)
    trainer = Trainer(held, quiet=True)
    before = {k: v.clone() for k, v in trainer.module.state_dict().items()}
    trainer.run()
    assert len(trainer.optim.param_groups) == 1
    after = trainer.module.state_dict()
    for k, v in after.items():
        if k.startswith("motion_gate."):
            assert torch.equal(v, before[k]), k
    assert any(not torch.equal(v, before[k]) for k, v in after.items() if k.startswith("motion."))


def test_full_frame_validation_windows_keep_the_training_crops_and_the_old_shard_keys(tmp_path):
    """``val_view`` makes only the validation windows WxH (the sweeps' frame); the training windows,
    their draws and the key of a shard without it are what they were; a run validates on them."""
    from dataclasses import replace

    from neuspike.train.__main__ import build_parser, spec_from_args
    from neuspike.train.loop import train
    from neuspike.train.windows import draw_cell

    square = WindowData(shard_dir=str(tmp_path / "square"), view=16, train_items=3, val_items=2, workers=1)
    wide = replace(square, shard_dir=str(tmp_path / "wide"), val_view=(40, 24))
    assert wide.key(0) == {**square.key(0), "val_view": [40, 24]} and "val_view" not in square.key(0)
    a, b = TrainSpec(data=square, crop=16), TrainSpec(data=wide, crop=16)
    for i in range(3):  # the training cells are drawn as before, the validation cells at the new size
        sa, *rest_a = draw_cell(a, "train", i, tmp_path / "src-a")
        sb, *rest_b = draw_cell(b, "train", i, tmp_path / "src-b")
        assert rest_a == rest_b
        if rest_a[2]["kind"] != "dead_leaves":  # the same region of the same photograph, saved in each run's folder
            assert np.array_equal(np.load(sa.image), np.load(sb.image))
            sb = replace(sb, image=sa.image)
        assert sa == sb
        assert draw_cell(b, "val", i, tmp_path / "src-b")[0].size == (40, 24)
        assert draw_cell(a, "val", i, tmp_path / "src-a")[0].size == (16, 16)
    spec = TrainSpec(data=wide, out_dir=str(tmp_path / "run"), steps=2, batch=2, crop=16, val_every=2,
                     checkpoint_every=2, warmup=1, precision="float32", threads=1)
    result = train(spec, quiet=True)
    assert result["step"] == 2 and result["best"]["fusion"]["val_psnr"] > 0
    trainer = Trainer(spec, quiet=True)
    trainer.task.prepare(lambda **kw: type("Bar", (), {"update": lambda *a: None, "close": lambda *a: None})())
    trainer.task.load_validation()
    assert tuple(trainer.task.val_batch[1].shape) == (2, 1, 24, 40)
    assert load_spec(tmp_path / "run" / "spec.json").data.val_view == (40, 24)
    args = build_parser().parse_args(["neuspike-net", "--val-view", "400x250", "--set", "data.losses.offset=2"])
    parsed = spec_from_args(args)
    assert parsed.data.val_view == (400, 250) and parsed.data.losses["offset"] == {"weight": 2.0}
    with pytest.raises(InputError, match="--val-view: not for 'e2vid'"):
        spec_from_args(build_parser().parse_args(["e2vid", "--val-view", "400x250"]))
    for bad in ((8, 250), "400x250", (400,)):
        with pytest.raises(InputError, match="val_view"):
            replace(square, val_view=bad)


def test_crop_trim_cuts_each_batch_to_one_drawn_size_off_the_same_crops(tmp_path):
    """``crop_trim`` keeps the shard (its key), the windows and the crops; each step's batch is cut at
    the bottom and right to one size drawn in crop - N .. crop; 0 leaves the batches as they were."""
    from dataclasses import replace

    from neuspike.train.__main__ import build_parser, spec_from_args

    spec = tiny_spec(tmp_path, crop=16, batch=2)
    trimmed = replace(spec, data=replace(spec.data, crop_trim=7))
    assert trimmed.data.key(0) == spec.data.key(0)
    bar = lambda **kw: type("Bar", (), {"update": lambda *a: None, "close": lambda *a: None})()  # noqa: E731
    tasks = []
    for s in (spec, trimmed):
        trainer = Trainer(s, quiet=True)
        trainer.task.prepare(bar)
        tasks.append(trainer.task)
    sizes = set()
    for step in range(12):
        (x0, t0), (x1, t1) = tasks[0].batch(step), tasks[1].batch(step)
        h, w = t1.shape[-2:]
        assert 9 <= h <= 16 and 9 <= w <= 16
        sizes.add((h, w))
        assert torch.equal(t1, t0[..., :h, :w])
        for a, b in zip(x0, x1):
            assert torch.equal(b, a[..., :h, :w] if a.shape[-1] > 1 else a)
        assert torch.equal(tasks[1].batch(step)[1], t1)  # the same step draws the same size
    assert len(sizes) > 3
    assert tuple(tasks[0].batch(0)[1].shape[-2:]) == (16, 16)
    for bad in (-1, 8, 2.5, True):
        with pytest.raises(InputError, match="crop_trim"):
            replace(spec.data, crop_trim=bad)
    assert spec_from_args(build_parser().parse_args(["neuspike-net", "--crop-trim", "6"])).data.crop_trim == 6
    with pytest.raises(InputError, match="crop-trim"):
        spec_from_args(build_parser().parse_args(["e2vid", "--crop-trim", "6"]))


def test_the_run_says_where_it_exports_and_that_export_replaces_the_shipped_weights(tmp_path, capsys):
    from neuspike.methods.weights import PACKAGE_WEIGHTS

    trainer = Trainer(tiny_spec(tmp_path, export_dir=str(tmp_path / "out")), quiet=True)
    line = trainer._export_line()
    assert str(tmp_path / "run") in line and str(tmp_path / "out") in line and "replaced" not in line
    package = Trainer(tiny_spec(tmp_path, export=True), quiet=True)._export_line()
    assert f"{PACKAGE_WEIGHTS} (the package's shipped weights: replaced)" in package
    trainer.run(until=0)  # quiet, and not into the package: nothing said
    assert "best weights are exported to" not in capsys.readouterr().out
    Trainer(tiny_spec(tmp_path, export_dir=str(tmp_path / "out")), quiet=False).run(until=0)
    assert line in capsys.readouterr().out


def test_the_light_noise_sweep_grid_draws_the_reports_points_and_leaves_old_keys(tmp_path):
    """sweep_grid "light-noise": the sweep cells sit on the 24 points where the light x noise report
    crosses light and noise (every light at every level, S = 128); the default keeps the 12 and the key."""
    from neuspike.train.spec import LIGHT_NOISE_POINTS, SWEEP_POINTS

    assert len(LIGHT_NOISE_POINTS) == 24 and set(SWEEP_POINTS) < set(LIGHT_NOISE_POINTS)
    assert {(l, n) for l, _, n in LIGHT_NOISE_POINTS} == {(l, n) for l in {p[0] for p in SWEEP_POINTS}
                                                          for n in ("none", "small", "medium", "high")}
    old = tiny_spec(tmp_path, sweep_fraction=1.0)
    new = tiny_spec(tmp_path, sweep_fraction=1.0, sweep_grid="light-noise")
    assert "sweep_grid" not in old.data.key(0) and new.data.key(0)["sweep_grid"] == "light-noise"
    drawn = set()
    for i in range(200):
        c = draw_cell(new, "train", i, tmp_path)[1]
        drawn.add((c.light, c.motion, c.noise))
    assert drawn <= set(LIGHT_NOISE_POINTS) and len(drawn - set(SWEEP_POINTS)) > 5
    with pytest.raises(InputError, match="mixture.sweep.grid: expected one of"):
        tiny_spec(tmp_path, sweep_fraction=1.0, sweep_grid="everything")
    with pytest.raises(InputError, match=r"mixture.sweep.grid: .*give mixture.sweep.fraction > 0"):
        tiny_spec(tmp_path, sweep_grid="light-noise")


@pytest.mark.parametrize("dark_rate", [None, 0.0, 1 / 180])
def test_a_saved_window_round_trips_with_its_dark_rate(tmp_path, dark_rate):
    """The shard keeps everything a method reads, the sensor's dark rate included (the counted level
    subtracts it; without it a method would estimate it from the window)."""
    from neuspike.sample import Sample
    from neuspike.streams import EventStream, SpikeStream

    rng = np.random.default_rng(0)
    planes = rng.random((16, 6, 9)) < 0.2
    spikes = SpikeStream(planes=planes, plane_rate_hz=20_000.0, start_s=0.0, gain=0.25, threshold=1.0,
                         dark_rate=dark_rate)
    events = EventStream(t_s=np.array([1e-4, 2e-4]), x=np.array([1, 2]), y=np.array([0, 5]),
                         p=np.array([1, -1], np.int8), width=9, height=6)
    sample = Sample(height=6, width=9, key_time_s=4e-4, window_start_s=0.0, window_end_s=8e-4, spikes=spikes,
                    events=events, event_threshold=0.2, ground_truth=rng.random((6, 9)).astype(np.float32))
    save_sample(tmp_path / "w.npz", sample)
    back = load_sample(tmp_path / "w.npz")
    assert back.spikes.dark_rate == dark_rate
    assert np.array_equal(back.spikes.planes, planes) and back.spikes.gain == 0.25
    assert np.array_equal(back.events.t_s, events.t_s) and np.array_equal(back.ground_truth, sample.ground_truth)
