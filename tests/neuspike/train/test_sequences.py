"""Sequence training: exact flow against rendering, window/target alignment with the method's own
encoding, batches and flips, determinism, the loss falling on a fixed batch, and resume."""

from __future__ import annotations

from neuspike.train.checkpoint import read_checkpoint_file

import dataclasses

import numpy as np
import pytest
import torch

from neuspike.conditions import Condition
from neuspike.errors import InputError
from neuspike.scenes import SceneSpec, make_scene
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig
from neuspike.scenes.motion import backward_flow, scene_time_s
from neuspike.train.loop import train
from neuspike.train.sequences import Cell, draw_cell, make_batch, run_sequence, sequence_loss, simulate_item, warp
from neuspike.train.spec import SequenceData, TrainSpec, learning_rate
from neuspike.utils.rng import derive_rng

DataSpec = SequenceData
DEFAULT_SEQUENCE_LOSSES = dict(SequenceData().losses)


def training_method(name: str):
    """The registered method around a fresh module (what the trainer encodes with)."""
    from neuspike.methods import create

    method = create(name, trained=False, precision="float32")
    method.module = method.module.to(memory_format=torch.contiguous_format)
    return method


def scene_time(sensor_t_s, condition, sensor):
    return scene_time_s(sensor_t_s, motion=condition.motion, planes=sensor.planes,
                        plane_rate_hz=sensor.plane_rate_hz, upsampled_rate_hz=sensor.upsampled_rate_hz)

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _interior(a: np.ndarray, margin: int) -> np.ndarray:
    return a[..., margin:-margin, margin:-margin]


def test_backward_flow_of_a_pan_is_exact_for_whole_pixel_steps():
    """A pan moving (3, -2) pixels: warping the earlier frame gives the later one exactly (no resampling)."""
    t0, t1 = -0.0011, 0.0004
    spec = SceneSpec("pan", image="brick", size=(64, 48), velocity_px_s=(3 / 0.0015, -2 / 0.0015))
    f0, f1 = make_scene(spec).render(np.array([t0, t1]))
    flow = backward_flow(spec, t0, t1)
    np.testing.assert_allclose(flow[:, 5, 7], [-3.0, 2.0], atol=1e-5)
    warped, _ = warp(torch.from_numpy(f0)[None, None], torch.from_numpy(flow)[None])
    np.testing.assert_allclose(_interior(warped[0, 0].numpy(), 4), _interior(f1, 4), atol=1e-4)


@pytest.mark.parametrize("spec", [
    SceneSpec("pan", image="astronaut", size=(64, 48), velocity_px_s=(3100.0, -1200.0)),
    SceneSpec("zoom", image="astronaut", size=(64, 48), zoom_rate_hz=-60.0, focus=(20.0, 30.0)),
    SceneSpec("zoom", image="astronaut", size=(160, 100), zoom_rate_hz=-30.0, focus=(40.0, 70.0),
              crop=(70, 20, 48, 48)),  # a crop away from the focus: the flow is the view's there
])
def test_backward_flow_maps_the_later_frame_onto_the_earlier(spec):
    """warp(render(t0), flow) equals render(t1) up to bilinear resampling error, far below the frames' change."""
    scene = make_scene(spec)
    t0, t1 = -0.0011, 0.0004
    f0, f1 = scene.render(np.array([t0, t1]))
    flow = torch.from_numpy(backward_flow(spec, t0, t1))[None]
    warped, valid = warp(torch.from_numpy(f0)[None, None], flow)
    warped = warped[0, 0].numpy()
    assert valid.mean() > 0.8
    err = np.abs(_interior(warped - f1, 8)).mean()
    change = np.abs(_interior(f0 - f1, 8)).mean()
    assert err < 0.25 * change, (err, change)


def test_scene_time_maps_frames_and_the_key_instant():
    cond, sensor = Condition(motion=64), SensorConfig()
    hold = sensor.planes // cond.motion
    k = np.array([0, 5, 63])
    frame_sensor_t = (k + 0.5) * hold / sensor.plane_rate_hz
    np.testing.assert_allclose(scene_time(frame_sensor_t, cond, sensor),
                               (k - 31.5) / sensor.upsampled_rate_hz, rtol=0, atol=1e-15)
    key = sensor.planes / (2 * sensor.plane_rate_hz)
    assert abs(scene_time(np.array([key]), cond, sensor)[0]) < 1e-15


@pytest.fixture(scope="module")
def tiny():
    """A small pan cell and its item (simulated once for the module)."""
    torch.set_num_threads(1)
    data = DataSpec(size=40, windows=4, length=4, displacement_px=6.0)
    cell = Cell(SceneSpec("pan", image="brick", size=(40, 40), velocity_px_s=(2500.0, 900.0)),
                Condition(light=0.25, motion=128, noise="none"), SensorConfig(event_threshold=0.2), 7)
    method = training_method("firenet-sim")
    return data, cell, method, simulate_item(method, cell, data)


def test_item_is_the_methods_own_encoding_with_targets_at_window_ends(tiny):
    data, cell, method, item = tiny
    assert item is not None
    assert item.voxels.shape == (4, 5, 40, 40) and item.targets.shape == (4, 40, 40)
    # the last target is the sample's own ground truth (the key instant)
    sample = simulate_sample(cell.scene, cell.condition, sensor=cell.sensor, seed=cell.seed,
                             modalities={"events"}, history_s=item_history(item, cell, data))
    np.testing.assert_allclose(item.targets[-1].astype(np.float32), sample.ground_truth, atol=1e-3)
    steps = method.encode(sample)[-4:]
    np.testing.assert_allclose(item.voxels.astype(np.float32), np.stack([s[0][0].numpy() for s in steps]),
                               atol=1e-2, rtol=1e-2)
    # consecutive targets are related by the stored flow (pan: a translation)
    warped, valid = warp(torch.from_numpy(item.targets[:-1].astype(np.float32))[:, None],
                         torch.from_numpy(item.flow[1:].astype(np.float32)))
    err = np.abs(_interior(warped[:, 0].numpy() - item.targets[1:].astype(np.float32), 6)).mean()
    change = np.abs(_interior(item.targets[:-1].astype(np.float32) - item.targets[1:], 6)).mean()
    assert err < 0.4 * change, (err, change)  # bilinear resampling of a fine texture; a wrong flow gives > change


def item_history(item, cell, data):
    from neuspike.train.sequences import _history_s

    return _history_s(cell, data.displacement_px)  # the tiny cell fits on the first try (checked below)


def test_same_seed_same_bytes(tiny):
    data, cell, method, item = tiny
    again = simulate_item(method, cell, data)
    assert item.meta["events"] == again.meta["events"]
    for a, b in ((item.voxels, again.voxels), (item.targets, again.targets), (item.flow, again.flow)):
        assert a.tobytes() == b.tobytes()


def test_test_photographs_are_refused():
    with pytest.raises(InputError, match="test photographs"):
        DataSpec(photos=("camera", "brick"))


def test_flips_keep_the_flow_consistent(tiny):
    """After any crop and flip, warping target k-1 with flow k still gives target k."""
    _, _, _, item = tiny
    shard = {"voxels": item.voxels[None], "targets": item.targets[None, :, None], "flow": item.flow[None]}
    rng = np.random.default_rng(3)
    for _ in range(6):
        b = make_batch(shard, rng, batch=1, crop=32, length=3)
        assert b["voxels"].shape == (3, 1, 5, 32, 32)
        warped, _ = warp(b["targets"][:-1, 0], b["flow"][1:, 0])
        err = (warped - b["targets"][1:, 0]).abs()[..., 5:-5, 5:-5].mean()
        change = (b["targets"][:-1, 0] - b["targets"][1:, 0]).abs()[..., 5:-5, 5:-5].mean()
        wrong, _ = warp(b["targets"][:-1, 0], -b["flow"][1:, 0])
        err_wrong = (wrong - b["targets"][1:, 0]).abs()[..., 5:-5, 5:-5].mean()
        assert err < 0.45 * change and err < 0.5 * err_wrong, (err, change, err_wrong)


def test_loss_falls_on_a_fixed_batch(tiny):
    """A few Adam steps on one batch reduce the sequence loss (FireNet-size module, float32)."""
    _, _, method, item = tiny
    torch.manual_seed(0)
    module = training_method("firenet-sim").module.train()
    data = DataSpec(size=40, windows=4, length=4, warmup_windows=1)
    shard = {"voxels": item.voxels[None], "targets": item.targets[None, :, None], "flow": item.flow[None]}
    batch = make_batch(shard, np.random.default_rng(0), batch=1, crop=24, length=4)
    opt = torch.optim.Adam(module.parameters(), lr=1e-2)
    losses = []
    for _ in range(10):
        loss, parts = sequence_loss(run_sequence(module, batch["voxels"], precision="float32"), batch, data)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.8 * losses[0], losses


def _tiny_run(steps: int, val_every: int, tmp_path, run: str = "run", **kw) -> TrainSpec:
    """A FireNet run on two 32x32 sequences of 3 windows: seconds on the CPU."""
    data = DataSpec(size=32, windows=3, kinds=("pan",), noise_levels=("none",), displacement_px=6.0,
                    train_items=2, val_items=1, length=3, warmup_windows=1, shard_root=str(tmp_path / "shards"))
    return TrainSpec(method="firenet-sim", data=data, out_dir=str(tmp_path / run), crop=24, batch=2,
                     optimizer="adam", weight_decay=0.0, lr=2e-4, lr_min=None, warmup=1, steps=steps,
                     val_every=val_every, checkpoint_every=1, precision="float32", threads=None, **kw)


def test_resume_gives_the_same_weights_as_one_run(tmp_path):
    """Two steps, stop, two more (resumed from the checkpoint) == four steps in one go: same data order, same bytes."""
    spec = _tiny_run(4, 2, tmp_path, "one", export_dir=str(tmp_path / "w1"))
    one = train(spec, quiet=True)
    two_spec = dataclasses.replace(spec, out_dir=str(tmp_path / "two"), export_dir=None)
    train(two_spec, quiet=True, until=2)  # killed after step 2
    two = train(two_spec, quiet=True)
    assert one["step"] == two["step"] == 4 and two["resumed"]
    a = read_checkpoint_file(tmp_path / "one" / "checkpoint.pt")["module"]
    b = read_checkpoint_file(tmp_path / "two" / "checkpoint.pt")["module"]
    for k in a:
        assert torch.equal(a[k], b[k]), k
    assert (tmp_path / "w1" / "firenet-sim.safetensors").is_file()
    assert (tmp_path / "one" / "firenet-sim.safetensors").is_file()
    log = (tmp_path / "one" / "train_log.csv").read_text().splitlines()
    assert log[0].startswith("step,kind") and [r.split(",")[:2] for r in log[1:]] == \
        [["1", "train"], ["2", "train"], ["2", "val"], ["3", "train"], ["4", "train"], ["4", "val"]]
    log2 = (tmp_path / "two" / "train_log.csv").read_text().splitlines()
    assert [r.split(",")[:4] for r in log2] == [r.split(",")[:4] for r in log]
    with pytest.raises(InputError, match="another spec"):
        train(dataclasses.replace(spec, steps=2), quiet=True)


def test_init_from_starts_at_the_given_weights_and_sets_the_bar(tmp_path):
    """A run continued from exported weights (no checkpoint) starts exactly there; its start's validation is the bar."""
    from neuspike.methods.weights import load_safetensors

    spec = _tiny_run(2, 1, tmp_path, "a", export_dir=str(tmp_path / "w"))
    first = train(spec, quiet=True)
    weights = tmp_path / "w" / "firenet-sim.safetensors"
    start = load_safetensors(str(weights))
    later = dataclasses.replace(spec, out_dir=str(tmp_path / "b"), steps=1, val_every=5, init_from=str(weights),
                                export_dir=str(tmp_path / "w2"))
    result = train(later, quiet=True, until=0)
    state = read_checkpoint_file(tmp_path / "b" / "checkpoint.pt")["module"]
    assert set(state) == set(start)
    for k in start:
        assert torch.equal(state[k], start[k].to(state[k].dtype)), k
    assert result["best"]["main"]["step"] == 0
    assert result["best"]["main"]["val_ssim"] == pytest.approx(first["best"]["main"]["val_ssim"], abs=1e-6)
    assert not (tmp_path / "w2").exists()  # nothing better than the start: nothing exported
    with pytest.raises(InputError, match="safetensors"):
        dataclasses.replace(spec, init_from="weights.pt")


def test_learning_rate_warms_up_then_holds_or_follows_a_cosine():
    """Constant after the warm-up without lr_min; with it, the cosine's closed form: peak, half-way mean, floor."""
    flat = TrainSpec(method="e2vid", data=SequenceData(), crop=48, lr=2e-4, warmup=50, lr_min=None, steps=1050)
    assert learning_rate(flat, 0) == pytest.approx(2e-4 / 50)
    assert learning_rate(flat, 49) == pytest.approx(2e-4)
    assert learning_rate(flat, 1049) == pytest.approx(2e-4)
    cos = dataclasses.replace(flat, lr_min=1e-5)
    assert learning_rate(cos, 49) == learning_rate(flat, 49)  # same warm-up
    assert learning_rate(cos, 50) == pytest.approx(2e-4)
    assert learning_rate(cos, 550) == pytest.approx((2e-4 + 1e-5) / 2)  # half-way down the cosine
    assert learning_rate(cos, 1050) == pytest.approx(1e-5)
    rates = [learning_rate(cos, k) for k in range(50, 1051)]
    assert all(a >= b for a, b in zip(rates, rates[1:]))
    with pytest.raises(InputError, match="lr_min"):
        dataclasses.replace(flat, lr_min=3e-4)


def test_backward_flow_of_a_crop_is_the_crop_of_the_views_flow():
    full = SceneSpec("zoom", image="astronaut", size=(160, 100), zoom_rate_hz=25.0, focus=(40.0, 70.0))
    cropped = dataclasses.replace(full, crop=(70, 20, 48, 32))
    np.testing.assert_array_equal(backward_flow(cropped, -0.001, 0.0005),
                                  backward_flow(full, -0.001, 0.0005)[:, 20:52, 70:118])


def test_a_view_spec_cuts_items_from_the_larger_view_and_leaves_old_shard_keys_alone():
    """Without ``view`` the key and every draw are those of a spec made before the field existed;
    with it, cells are crops of the view at drawn positions, and the item's targets are those crops."""
    plain = DataSpec()
    assert plain.key() == "f40df6737f28"  # the shard key the first e2vid stages trained on
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    view = DataSpec(size=40, windows=3, length=3, view=(160, 100), kinds=("pan",), noise_levels=("none",))
    assert view.key() != dataclasses.replace(view, view=None).key()
    cell = draw_cell(view, rng_a)
    assert cell.scene.size == (160, 100) and cell.scene.crop[2:] == (40, 40)
    x0, y0 = cell.scene.crop[:2]
    assert 0 <= x0 <= 120 and 0 <= y0 <= 60
    assert draw_cell(dataclasses.replace(view, view=None), rng_b).scene.crop is None
    item = simulate_item(training_method("firenet-sim"), cell, view)
    assert item is not None and item.voxels.shape[-2:] == (40, 40)
    times = np.array([0.0])  # the key instant: the last target is the crop of the full view's frame
    whole = make_scene(dataclasses.replace(cell.scene, crop=None)).render(times)[0]
    np.testing.assert_allclose(item.targets[-1].astype(np.float32),
                               np.clip(whole[y0:y0 + 40, x0:x0 + 40], 0, 1), atol=1e-3)
    with pytest.raises(InputError, match="view"):
        DataSpec(size=128, view=(400, 100))


def test_dead_leaves_items_flow_with_the_background_and_the_mask_takes_the_foreground():
    """A dead-leaves cell: its flow is the background layer's translation, so warping the background
    layer alone reproduces its later frame (the foreground shapes are left to the loss's occlusion
    mask); the item simulates, also beside a view; an unknown kind is refused."""
    from neuspike.scenes.dead_leaves import DeadLeavesScene

    data = DataSpec(size=48, windows=3, length=3, kinds=("dead_leaves",), noise_levels=("none",))
    cell = draw_cell(data, np.random.default_rng(7))
    assert cell.scene.kind == "dead_leaves"
    t0, t1 = -0.0012, 0.0003
    flow = backward_flow(cell.scene, t0, t1)
    np.testing.assert_allclose(flow[:, 10, 10], -np.asarray(cell.scene.velocity_px_s) * (t1 - t0), rtol=1e-5)
    scene = DeadLeavesScene(cell.scene)
    import copy

    background = copy.copy(scene)  # the same layers; keep only the opaque background
    background._layers = scene._layers[:1]
    b0, b1 = background._render(np.array([t0, t1]))
    warped, _ = warp(torch.from_numpy(b0)[None, None], torch.from_numpy(flow)[None])
    err = np.abs(_interior(warped[0, 0].numpy() - b1, 8)).mean()
    assert err < 0.25 * np.abs(_interior(b0 - b1, 8)).mean()
    item = simulate_item(training_method("firenet-sim"), cell, data)
    assert item is not None and item.meta["scene"] == "dead_leaves" and item.meta["photo"] is None
    # beside a view (which photographs are cut from), dead-leaves cells are drawn at the item size
    viewed = DataSpec(size=48, windows=3, length=3, kinds=("dead_leaves",), noise_levels=("none",), view=(160, 100))
    leaves = draw_cell(viewed, np.random.default_rng(7))
    assert leaves.scene.kind == "dead_leaves" and leaves.scene.size == (48, 48) and leaves.scene.crop is None
    leaves_item = simulate_item(training_method("firenet-sim"), leaves, viewed)
    assert leaves_item is not None and leaves_item.targets.shape[-2:] == (48, 48)
    assert leaves_item.flow.shape[-2:] == (48, 48)
    with pytest.raises(InputError, match="kinds"):
        DataSpec(kinds=("pan", "video"))


def test_listed_twice_is_drawn_twice_as_often_and_the_default_draws_are_unchanged():
    """Kinds and noise levels are drawn uniformly over their tuples (a repeat weights a level); the
    default spec, which lists neither twice nor dead_leaves, keeps its key and its draws."""
    assert DataSpec().kinds == ("pan", "zoom", "fan") and DataSpec().key() == "f40df6737f28"
    weighted = DataSpec(size=32, noise_levels=("none", "none", "high"), kinds=("pan",))
    rng = np.random.default_rng(11)
    noise = [draw_cell(weighted, rng).condition.noise for _ in range(1500)]
    share = noise.count("none") / len(noise)
    assert abs(share - 2 / 3) < 4 * np.sqrt(2 / 9 / len(noise)), share  # four binomial standard deviations
    with pytest.raises(InputError, match="noise_levels"):
        DataSpec(noise_levels=())


def test_command_line_kinds_noise_levels_and_snapshots(tmp_path):
    """--kinds / --noise-levels reach the data spec; --snapshot-every keeps every N-th step's weights with a card."""
    import json

    from neuspike.train.__main__ import build_parser, spec_from_args

    args = build_parser().parse_args(["firenet-sim", "--kinds", "pan,dead_leaves", "--noise-levels", "none,none,high"])
    spec = spec_from_args(args)
    assert spec.data.kinds == ("pan", "dead_leaves") and spec.data.noise_levels == ("none", "none", "high")
    run = _tiny_run(4, 4, tmp_path)
    train(run, quiet=True, snapshot_every=2)
    snaps = sorted(p.name for p in (tmp_path / "run" / "snapshots").iterdir())
    assert snaps == ["step-00002", "step-00004"]
    card = json.loads((tmp_path / "run" / "snapshots" / "step-00004" / "firenet-sim.json").read_text())
    assert card["training"]["step"] == 4 and "val_ssim" in card["validation"]
    last = read_checkpoint_file(tmp_path / "run" / "checkpoint.pt")["module"]
    from neuspike.methods.weights import load_safetensors

    kept = load_safetensors(str(tmp_path / "run" / "snapshots" / "step-00004" / "firenet-sim.safetensors"))
    for k in last:
        assert torch.equal(kept[k].to(last[k].dtype), last[k]), k
    with pytest.raises(InputError, match="snapshot_every"):
        train(run, quiet=True, snapshot_every=0)


def test_hdr_fraction_sets_the_share_of_high_dynamic_range_items():
    """0 gives only linear scenes (the sweeps' radiance model), 1 only HDR ones; the default 0.5 keeps the old key."""
    rng = np.random.default_rng(3)
    linear = DataSpec(size=32, kinds=("pan",), hdr_fraction=0.0)
    assert all(draw_cell(linear, rng).scene.dynamic_range is None for _ in range(200))
    hdr = dataclasses.replace(linear, hdr_fraction=1.0)
    assert all(10 <= draw_cell(hdr, rng).scene.dynamic_range <= 1000 for _ in range(200))
    assert DataSpec(hdr_fraction=0.5).key() == DataSpec().key() == "f40df6737f28" != DataSpec(hdr_fraction=0.0).key()
    with pytest.raises(InputError, match="hdr_fraction"):
        DataSpec(hdr_fraction=1.5)


def test_a_shard_built_by_several_processes_holds_the_items_of_one(tmp_path):
    """Item i draws from its own generator, so two worker processes write the items one process
    writes (arrays and metadata; the zip's time stamps may differ); the count is no part of the run."""
    from neuspike.train.__main__ import build_parser, spec_from_args
    from neuspike.train.sequences import build_shard, load_shard

    spec = _tiny_run(1, 1, tmp_path)
    data = dataclasses.replace(spec.data, train_items=3)
    method = training_method("firenet-sim")
    one = build_shard(method, data, seed=0, split="train", count=3, folder=tmp_path / "one")
    two = build_shard(method, dataclasses.replace(data, workers=2), seed=0, split="train", count=3,
                      folder=tmp_path / "two", workers=2, spec=dataclasses.replace(spec, data=data))
    assert [p.name for p in one] == [p.name for p in two] == ["train-00000.npz", "train-00001.npz", "train-00002.npz"]
    a, b = load_shard(one), load_shard(two)
    for k in a:
        assert a[k].tobytes() == b[k].tobytes(), k
    for p, q in zip(one, two):
        assert str(np.load(p)["meta"]) == str(np.load(q)["meta"])
    assert dataclasses.replace(spec, data=dataclasses.replace(spec.data, workers=4)).identity() == spec.identity()
    assert spec_from_args(build_parser().parse_args(["e2vid", "--workers", "3"])).data.workers == 3
    with pytest.raises(InputError, match="workers"):
        dataclasses.replace(data, workers=0)


def test_a_stacked_shard_is_memory_mapped_and_equal_to_the_items(tmp_path):
    """The stacked shard (written once beside the items, then memory-mapped read-only) holds exactly
    the items' arrays; a second load reopens it without rewriting, no temporary is left, and a stack
    whose items changed, or without its record of them, is built again."""
    from neuspike.train.sequences import build_shard, load_shard

    spec = _tiny_run(1, 1, tmp_path)
    data = dataclasses.replace(spec.data, train_items=3)
    paths = build_shard(training_method("firenet-sim"), data, seed=0, split="train", count=3, folder=tmp_path / "s")
    held = load_shard(paths)
    mapped = load_shard(paths, stack_dir=tmp_path / "s")
    for k in held:
        assert isinstance(mapped[k], np.memmap) and not mapped[k].flags.writeable, k
        assert mapped[k].shape == held[k].shape and np.array_equal(mapped[k], held[k]), k
    stacked = sorted((tmp_path / "s").glob("*.npy"))
    assert [f.name for f in stacked] == ["train-00000-3.flow.npy", "train-00000-3.targets.npy", "train-00000-3.voxels.npy"]
    assert (tmp_path / "s" / "train-00000-3.items.json").is_file()
    stamps = [f.stat().st_mtime_ns for f in stacked]
    again = load_shard(paths, stack_dir=tmp_path / "s")
    assert [f.stat().st_mtime_ns for f in stacked] == stamps and np.array_equal(again["flow"], held["flow"])
    assert not list((tmp_path / "s").glob(".*.tmp"))
    # an item built again (here: rewritten with other bytes) makes the stack stale: it is rebuilt
    with np.load(paths[1]) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["flow"] = arrays["flow"] + np.float16(1)
    np.savez(paths[1], **arrays)
    rebuilt = load_shard(paths, stack_dir=tmp_path / "s")
    assert np.array_equal(rebuilt["flow"][1], arrays["flow"]) and np.array_equal(rebuilt["flow"][0], held["flow"][0])
    # a stack without its record of items (an interrupted build) is rebuilt too
    (tmp_path / "s" / "train-00000-3.items.json").unlink()
    assert np.array_equal(load_shard(paths, stack_dir=tmp_path / "s")["flow"], rebuilt["flow"])


def test_view_fraction_cuts_that_share_of_items_from_the_view_and_fits_the_rest():
    """With ``view_fraction`` f, about f of the items are crops of the view and the others are the whole
    photograph fitted to the item; at its default (1) the key and the draws are a view spec's own."""
    view = DataSpec(size=40, windows=3, length=3, view=(160, 100), kinds=("pan",), noise_levels=("none",))
    assert dataclasses.replace(view, view_fraction=1).key() == view.key()
    rng_a, rng_b = np.random.default_rng(7), np.random.default_rng(7)
    for _ in range(5):  # the default draws exactly as before the field existed
        assert draw_cell(view, rng_a) == draw_cell(dataclasses.replace(view, view_fraction=1.0), rng_b)
    mixed = dataclasses.replace(view, view_fraction=0.25)
    assert mixed.key() not in (view.key(), dataclasses.replace(view, view=None).key())
    rng = np.random.default_rng(0)
    cells = [draw_cell(mixed, rng) for _ in range(400)]
    cut = [c for c in cells if c.scene.crop is not None]
    assert all(c.scene.size == (160, 100) and c.scene.crop[2:] == (40, 40) for c in cut)
    assert all(c.scene.size == (40, 40) for c in cells if c.scene.crop is None)
    assert abs(len(cut) / len(cells) - 0.25) < 0.07  # binomial sd 0.022
    assert all(draw_cell(dataclasses.replace(view, view_fraction=0.0), rng).scene.crop is None for _ in range(20))
    with pytest.raises(InputError, match="view_fraction"):
        DataSpec(size=40, view_fraction=0.5)  # no view to cut from
    with pytest.raises(InputError, match="view_fraction"):
        dataclasses.replace(view, view_fraction=1.5)


def test_history_term_adds_the_gap_between_a_full_and_a_restarted_pass(tiny):
    """``history`` w adds w * mean |o_last - o'_last|, o' from a second pass over the last
    length - length // 2 windows started from zeros (computed here by hand); 0 leaves the loss alone;
    a negative weight is refused."""
    from neuspike.train.sequences import SequenceTask

    _, _, method, item = tiny
    torch.manual_seed(0)
    trained = training_method("firenet-sim")
    shard = {"voxels": item.voxels[None], "targets": item.targets[None, :, None], "flow": item.flow[None]}
    losses = {}
    for w in (0.0, 2.0):
        data = DataSpec(size=40, windows=4, length=4, warmup_windows=1, losses={**DEFAULT_SEQUENCE_LOSSES, "history": w})
        spec = TrainSpec(method="firenet-sim", data=data, out_dir="unused", crop=24, batch=1, steps=1,
                         precision="float32", threads=None)
        task = SequenceTask(spec, trained)
        task.train_shard = shard
        losses[w] = float(task.step_loss(0, lambda: None)[0].detach())
    batch = make_batch(shard, derive_rng(0, "batch", 0),
                       batch=1, crop=24, length=4)
    with torch.no_grad():
        full = run_sequence(trained.module, batch["voxels"], precision="float32")
        short = run_sequence(trained.module, batch["voxels"][2:], precision="float32")
    gap = float((full[-1] - short[-1]).abs().mean())
    assert gap > 1e-4  # a fresh FireNet's image depends on its history
    assert losses[2.0] - losses[0.0] == pytest.approx(2.0 * gap, rel=1e-4, abs=1e-6)
    with pytest.raises(InputError, match="history"):
        DataSpec(losses={"history": -1.0})


def test_empty_term_adds_the_spread_of_the_image_without_events(tiny):
    """``empty`` w adds w * mean |b - mean(b)|, b the image of one all-zero window of the crop's size from
    a zero state (computed here by hand); steps on the trainer's loss with the term weighted heavily
    flatten the blank image (its gradient reaches the module); a negative weight is refused."""
    from neuspike.train.sequences import SequenceTask

    _, _, method, item = tiny
    torch.manual_seed(0)
    trained = training_method("firenet-sim")
    shard = {"voxels": item.voxels[None], "targets": item.targets[None, :, None], "flow": item.flow[None]}

    def task_for(w, net):
        data = DataSpec(size=40, windows=4, length=4, warmup_windows=1, losses={**DEFAULT_SEQUENCE_LOSSES, "empty": w})
        spec = TrainSpec(method="firenet-sim", data=data, out_dir="unused", crop=24, batch=1, steps=1,
                         precision="float32", threads=None)
        task = SequenceTask(spec, net)
        task.train_shard = shard
        return task

    losses = {w: task_for(w, trained).step_loss(0, lambda: None) for w in (0.0, 3.0)}
    with torch.no_grad():
        blank = run_sequence(trained.module, torch.zeros(1, 1, 5, 24, 24), precision="float32")[0]
    spread = float((blank - blank.mean()).abs().mean())
    assert spread > 1e-5  # zero padding leaves a fresh FireNet's blank image uneven near its borders
    assert float(losses[3.0][0].detach() - losses[0.0][0].detach()) == pytest.approx(3.0 * spread, rel=1e-4, abs=1e-7)
    assert losses[3.0][1]["empty_spread"] == pytest.approx(spread, rel=1e-4)
    assert "empty_spread" not in losses[0.0][1]

    def spread_after_steps(w):
        torch.manual_seed(0)
        fresh = training_method("firenet-sim")
        task = task_for(w, fresh)
        opt = torch.optim.Adam(fresh.module.parameters(), lr=1e-3)
        for step in range(5):
            opt.zero_grad()
            task.step_loss(step, lambda: None)[0].backward()
            opt.step()
        with torch.no_grad():
            image = run_sequence(fresh.module, torch.zeros(1, 1, 5, 24, 24), precision="float32")[0]
        return float((image - image.mean()).abs().mean())

    assert spread_after_steps(1000.0) < 0.5 * spread_after_steps(0.0)
    with pytest.raises(InputError, match="empty"):
        DataSpec(losses={"empty": -1.0})


def test_partial_window_spreads_its_last_bins_over_the_window():
    """All bins kept: the grid itself; one bin kept: that bin's events in every bin; two of five kept:
    the bins interpolate linearly from the fourth to the fifth; the result is normalised (mean 0, std 1
    over its non-zero entries) and an impossible count is refused."""
    from neuspike.methods.representations import normalize_voxel_grid
    from neuspike.train.sequences import partial_window

    rng = np.random.default_rng(3)
    raw = rng.normal(size=(5, 6, 7)) * (rng.random((5, 6, 7)) < 0.4)
    grid = normalize_voxel_grid(raw)
    np.testing.assert_allclose(partial_window(grid, 5), grid, atol=1e-5)
    one = partial_window(grid, 1)
    for b in range(5):
        np.testing.assert_allclose(one[b], normalize_voxel_grid(np.repeat(grid[4:], 5, axis=0))[b], atol=1e-5)
    two = partial_window(grid, 2)
    expected = normalize_voxel_grid(np.stack([grid[3] + (grid[4] - grid[3]) * t / 4 for t in range(5)]))
    np.testing.assert_allclose(two, expected, atol=1e-5)
    values = two[two != 0]
    assert abs(values.mean()) < 1e-5 and abs(values.std() - 1) < 1e-4
    with pytest.raises(InputError, match="kept"):
        partial_window(grid, 0)


def test_partial_first_cuts_the_first_window_of_that_share_of_runs_and_leaves_the_rest(tiny):
    """At 0 the batches are exactly the ones drawn before the option existed; at 1 every run's first
    window is a cut-short grid and every other window, target and flow is unchanged."""
    _, _, _, item = tiny
    shard = {"voxels": item.voxels[None].repeat(3, 0), "targets": item.targets[None, :, None].repeat(3, 0),
             "flow": item.flow[None].repeat(3, 0)}
    plain = make_batch(shard, np.random.default_rng(5), batch=3, crop=24, length=3)
    same = make_batch(shard, np.random.default_rng(5), batch=3, crop=24, length=3, partial_first=0.0)
    cut = make_batch(shard, np.random.default_rng(5), batch=3, crop=24, length=3, partial_first=1.0)
    for key in plain:
        assert torch.equal(plain[key], same[key])
    assert torch.equal(cut["voxels"][1:], plain["voxels"][1:])
    assert torch.equal(cut["targets"], plain["targets"]) and torch.equal(cut["flow"], plain["flow"])
    assert not torch.equal(cut["voxels"][0], plain["voxels"][0])
    with pytest.raises(InputError, match="mixture.partial_first.fraction"):
        DataSpec(mixture={"partial_first": 1.5})
    with pytest.raises(InputError, match="unknown terms.*'sweep'.*the registered ones: partial_first"):
        DataSpec(mixture={"sweep": 0.5})
    # the earlier field reads into the term, and the shard key does not change
    from neuspike.train.spec import spec_from_dict

    earlier = TrainSpec(method="e2vid", data=DataSpec()).as_dict()
    earlier["data"].pop("mixture")
    earlier["data"]["partial_first"] = 0.25
    read = spec_from_dict(earlier).data
    assert read.mixture == {"partial_first": {"fraction": 0.25}} and read.key() == DataSpec().key()


def test_runs_with_different_seeds_never_share_a_shard():
    """Item i is drawn from ``derive_rng(seed, ...)``, so a run with another seed must not reuse (and
    silently train on) the items a seed-0 run left in the shard root; seed 0 keeps the old folder names."""
    from neuspike.train.sequences import SequenceTask

    data = DataSpec(size=40, windows=4, length=4)
    dirs = {}
    for seed in (0, 1, 2):
        spec = TrainSpec(method="firenet-sim", data=data, out_dir="unused", crop=24, batch=1, steps=1,
                         precision="float32", threads=None, seed=seed)
        dirs[seed] = SequenceTask(spec, training_method("firenet-sim")).shard_dir
    assert dirs[0].name == data.key() == data.key(0)  # the shards every earlier stage trained on
    assert len(set(dirs.values())) == 3
    cells = [draw_cell(data, derive_rng(seed, "sequences", "train", 0)) for seed in (0, 1)]
    assert cells[0] != cells[1]  # what the seed changes: the items themselves


def test_broad_leaves_items_are_dead_leaves_with_a_drawn_smallest_leaf():
    """``broad_leaves`` draws a dead-leaves scene whose smallest leaf is 5-15 % of the item's side;
    ``dead_leaves`` items leave the field unset (their draws are those before the kind existed)."""
    rng = np.random.default_rng(3)
    broad = [draw_cell(DataSpec(size=32, kinds=("broad_leaves",)), rng).scene for _ in range(20)]
    assert all(s.kind == "dead_leaves" and 0.05 <= s.leaf_min_radius <= 0.15 for s in broad)
    assert len({s.leaf_min_radius for s in broad}) == 20
    classic = draw_cell(DataSpec(size=32, kinds=("dead_leaves",)), rng).scene
    assert classic.kind == "dead_leaves" and classic.leaf_min_radius is None


def test_a_randomised_sensor_draws_the_event_camera_per_sequence_and_leaves_nominal_specs_alone():
    """``sensor="randomised"``: a threshold mismatch always, the other DAVIS stages half the time each,
    in their ranges, the same for the same seed; ``"nominal"`` declares nothing and keeps every draw
    and the shard key of the specs before the field."""
    nominal, randomised = DataSpec(size=32), DataSpec(size=32, sensor="randomised", threshold_range=(0.2, 1.5))
    assert nominal.key() == DataSpec(size=32, sensor="nominal").key() != randomised.key()
    assert DataSpec().key() == "f40df6737f28"
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    plain = [draw_cell(nominal, a) for _ in range(50)]
    assert all(c.condition.effects == () for c in plain)
    cells = [draw_cell(randomised, b) for _ in range(400)]
    again = [draw_cell(randomised, np.random.default_rng(5)) for _ in range(1)]
    assert again[0] == cells[0]
    names = [{e.name: dict(e.params) for e in c.condition.effects} for c in cells]
    assert all(0.01 <= n["threshold_mismatch"]["sigma"] <= 0.1 for n in names)
    for name, key, lo, hi in (("refractory", "period_s", 1e-4, 1e-3), ("leak", "rate_hz", 0.01, 1.0),
                              ("bandwidth", "cutoff_hz", 10.0, 300.0)):
        present = [n[name][key] for n in names if name in n]
        assert 0.35 < len(present) / len(names) < 0.65 and all(lo <= v <= hi for v in present), name
    # shot noise only where the noise level declares none (a level's own shot noise is not replaced)
    assert all("shot_noise" not in n or c.condition.noise == "none" for n, c in zip(names, cells))
    thresholds = [c.sensor.event_threshold for c in cells]
    assert min(thresholds) >= 0.2 and max(thresholds) <= 1.5 and max(thresholds) > 1.0
    with pytest.raises(InputError, match="sensor"):
        DataSpec(sensor="wild")


def test_a_mixed_sensor_is_nominal_for_half_the_sequences_and_randomised_for_the_rest():
    """``sensor="mixed"``: about half the sequences declare no stage; the others carry a threshold
    mismatch (which every randomised camera has), with the randomised ranges; the same seed, the same cells."""
    mixed = DataSpec(size=32, sensor="mixed", threshold_range=(0.1, 1.5))
    rng = np.random.default_rng(9)
    cells = [draw_cell(mixed, rng) for _ in range(400)]
    assert draw_cell(mixed, np.random.default_rng(9)) == cells[0]
    plain = [c for c in cells if c.condition.effects == ()]
    assert 0.4 < len(plain) / len(cells) < 0.6
    drawn = [{e.name: dict(e.params) for e in c.condition.effects} for c in cells if c.condition.effects]
    assert all(0.01 <= n["threshold_mismatch"]["sigma"] <= 0.1 for n in drawn)
    assert mixed.key() != DataSpec(size=32, sensor="randomised", threshold_range=(0.1, 1.5)).key()
