"""The fast-motion test: pan speed factors in scene names, the summary against results.csv, the support file."""

import numpy as np
import pandas as pd
import pytest

from bench import fast_motion
from bench.harness.grid import PAN_SPEED_PX_S_AT_400, scene_entry
from neuspike.errors import InputError


def test_a_speed_factor_multiplies_the_pan_speed_and_names_the_scene():
    base, fast = scene_entry("pan:camera", (200, 100)), scene_entry("pan@8x:camera", (200, 100))
    assert np.hypot(*base.spec.velocity_px_s) == pytest.approx(PAN_SPEED_PX_S_AT_400 * 200 / 400)
    assert np.hypot(*fast.spec.velocity_px_s) == pytest.approx(8 * np.hypot(*base.spec.velocity_px_s))
    assert fast.name == "pan@8x:camera" and scene_entry("pan@1x:camera", (200, 100)).name == "pan:camera"
    assert fast_motion.speed_of(fast.name) == 8.0 and fast_motion.speed_of("pan:camera") == 1.0
    for bad, match in (("zoom@2x:clock", "pans only"), ("pan@-1x:camera", "speed factor"), ("pan@fastx:camera", "speed")):
        with pytest.raises(InputError, match=match):
            scene_entry(bad, (200, 100))
    assert fast_motion.scene_names("1,4", "camera,clock") == (
        "pan@1x:camera", "pan@1x:clock", "pan@4x:camera", "pan@4x:clock")
    with pytest.raises(InputError, match="--speeds"):
        fast_motion.scene_names("0,2", "camera")


def test_the_summary_is_the_mean_of_the_results_and_faster_pans_blur_the_whole_window(tmp_path, one_torch_thread):
    out = tmp_path / "fm"
    code = fast_motion.main(["--size", "64x40", "--speeds", "1,16", "--photos", "camera", "--lights", "1/4",
                             "--methods", "tfp-w8,tfp,tfi", "--out", str(out), "--no-progress", "--no-report",
                             "--threads", "1"])
    assert code == 0
    rows = pd.read_csv(out / "results.csv")
    rows = rows[rows["metric"] == "psnr"]
    table = pd.read_csv(out / "fast_motion.csv")
    for (method, scene), value in rows.groupby(["method", "scene"])["value"].mean().items():
        got = table[(table["method"] == method) & (table["speed"] == fast_motion.speed_of(scene))]["psnr"]
        assert float(got.iloc[0]) == pytest.approx(value, abs=1e-4)
    whole = table[table["method"] == "tfp"].set_index("speed")["psnr"]
    assert whole[16.0] < whole[1.0] - 1.0  # 16 times the motion within the window: more blur
    text = (out / "fast_motion.md").read_text()
    assert "| `tfp` |" in text and "16x" in text
    assert not (out / "support.csv").exists()  # no learned method requested


def test_the_temporal_support_shares_sum_to_one(tmp_path, one_torch_thread):
    from bench.fast_motion import _spec, build_parser, temporal_support

    args = build_parser().parse_args(["--size", "48x32", "--speeds", "1", "--photos", "camera", "--lights", "1/4",
                                      "--methods", "neuspike-net-spike"])
    path = temporal_support(tmp_path, _spec(args))
    sup = pd.read_csv(path)
    bins = sup[[f"bin{i:02d}" for i in range(16)]].to_numpy()
    assert np.allclose(bins.sum(axis=1), 1.0, atol=1e-4) and (bins >= 0).all()
    assert ((sup["support_planes"] >= 16 - 1e-6) & (sup["support_planes"] <= 256 + 1e-6)).all()


def test_the_edge_support_is_measured_on_the_edges_and_its_shares_sum_to_one(tmp_path, one_torch_thread):
    from bench.fast_motion import _spec, build_parser, edge_mask, temporal_support

    step = np.zeros((20, 30))
    step[:, 15:] = 1.0  # one vertical edge: the two columns beside it carry all the gradient
    mask = edge_mask(step, fraction=40 / step.size)
    assert mask.sum() == 40 and mask[:, 14:16].all()
    assert edge_mask(np.zeros((4, 4))).any()  # a flat image still gives a pixel
    args = build_parser().parse_args(["--size", "48x32", "--speeds", "1", "--photos", "camera", "--lights", "1/4",
                                      "--methods", "neuspike-net-spike"])
    sup = pd.read_csv(temporal_support(tmp_path, _spec(args)))
    edge = sup[[f"edge_bin{i:02d}" for i in range(16)]].to_numpy()
    assert np.allclose(edge.sum(axis=1), 1.0, atol=1e-4) and (edge >= 0).all()
    assert ((sup["edge_support_planes"] >= 16 - 1e-6) & (sup["edge_support_planes"] <= 256 + 1e-6)).all()
