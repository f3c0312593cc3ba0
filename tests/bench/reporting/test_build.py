"""Report generation: figures, tables and the PDF from a results folder alone; the Pareto front; claims."""

from __future__ import annotations

import functools
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.reporting import claims as cl
from bench.reporting import figures as figs
from bench import report
from bench.harness import images as layout
from bench.reporting import build as reporting
from bench.reporting import tables as tb
from bench.harness.results import base_row, rows_frame, to_csv_text
from neuspike import methods as registry
from neuspike.utils.jsonio import canonical_json

LIGHTS = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2)
SCENES = ("pan:camera", "fan:coins")
SEEDS = (0, 1)
INPUTS = {"tfp-w8": "spikes", "tfi": "spikes", "events-integrate": "events", "fusion-x": "events+spikes",
          "broken": "spikes"}


def expected_psnr(method: str, light: float, scene: str, seed: int) -> float:
    """Closed-form PSNR of the synthetic results (scene and seed add a known offset)."""
    k = math.log2(light * 32)  # 0 .. 4
    offset = (0.5 if scene == "fan:coins" else -0.5) + 0.25 * seed
    base = {"tfp-w8": 10 + 4 * k, "tfi": 20 + 3 * k - k * k, "events-integrate": 12 + 0.2 * k,
            "fusion-x": 30 + 0.1 * k}[method]
    return base + offset


@functools.lru_cache(maxsize=None)
def description(method: str) -> str:
    """The ``method_params`` a sweep records: the registered method's own description (empty for made-up names)."""
    if method not in registry.available():
        return ""
    try:
        return canonical_json(registry.create(method).describe())
    except registry.MethodUnavailable:
        return ""


def row(method, *, metric, value, light=0.25, motion=128, noise="none", scene="pan:camera", seed=0, status="ok",
        error="", ms=1.0, inputs=None):
    kind, image = scene.split(":")
    return base_row(cell=f"{scene}-{light}-{motion}-{noise}-{seed}", scene=scene, kind=kind, image=image, width=40,
                    height=24, planes=256, light=light, motion=motion, noise=noise, effects="", seed=seed,
                    method=method, inputs=inputs if inputs is not None else INPUTS.get(method, "spikes"),
                    recurrent=False, parameters=0, normalisation="gain" if status == "ok" else "",
                    method_params=description(method), metric=metric,
                    value=value, status=status, error=error, ms_per_frame=ms if status == "ok" else np.nan,
                    sim_seconds=0.1, stage_seconds="{}")


def synthetic_results() -> pd.DataFrame:
    """A light sweep: 4 working methods, 2 scenes, 2 seeds, and one method that failed everywhere."""
    rows = []
    ms = {"tfp-w8": 0.2, "tfi": 1.0, "events-integrate": 0.5, "fusion-x": 5.0}
    for scene in SCENES:
        for light in LIGHTS:
            for seed in SEEDS:
                for method in ("tfp-w8", "tfi", "events-integrate", "fusion-x"):
                    p = expected_psnr(method, light, scene, seed)
                    for metric, value in (("psnr", p), ("ssim", p / 40), ("psnr_affine", p + 1),
                                          ("ssim_affine", p / 40 + 0.01)):
                        rows.append(row(method, metric=metric, value=value, light=light, scene=scene, seed=seed,
                                        ms=ms[method]))
                for metric in tb.METRICS:
                    rows.append(row("broken", metric=metric, value=np.nan, light=light, scene=scene, seed=seed,
                                    status="error", error="RuntimeError: deliberate failure"))
    return rows_frame(rows)


def write_results(folder: Path, frame: pd.DataFrame) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "results.csv").write_text(to_csv_text(frame))
    return folder


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A light sweep's folder with provenance and reconstruction images, its report built once."""
    d = write_results(tmp_path_factory.mktemp("light"), synthetic_results())
    (d / "config.json").write_text('{"sweep": {"name": "light", "methods": ["tfp-w8"]}}\n')
    (d / "metadata.json").write_text('{"source": {"commit": "abc", "dirty": false}, "machine": {"cpu_model": "x"}}\n')
    truth = np.random.default_rng(0).random((24, 40))
    for light in LIGHTS:
        layout.write_image_png(layout.image_path(d / "images", "pan:camera", "light", light, "gt"), truth)
        for method in ("tfp-w8", "tfi"):
            layout.write_image_png(layout.image_path(d / "images", "pan:camera", "light", light, method),
                                   truth * light * 2)
    return d, reporting.build_report(d), truth


def table_bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((folder / "tables").iterdir())}


# ----------------------------------------------------------------------------------------------
# The report
# ----------------------------------------------------------------------------------------------

def test_build_report_writes_figures_tables_and_pdf(built):
    d, pdf, _ = built
    assert pdf == d / "report.pdf"
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF") and len(data) > 10_000
    for name in ("light_psnr_ssim", "light_affine", "accuracy_vs_time", "grid_pan_camera_light"):
        assert (d / "figures" / f"{name}.png").read_bytes().startswith(b"\x89PNG")
    for name in ("summary", "light", "failures", "claims", "accuracy_vs_time"):
        assert (d / "tables" / f"{name}.md").stat().st_size > 0
        assert (d / "tables" / f"{name}.csv").stat().st_size > 0
    assert not list(d.rglob("*.tmp"))  # atomic writes leave no temporary files
    failures = (d / "tables" / "failures.md").read_text()
    assert "broken" in failures and "RuntimeError: deliberate failure" in failures
    assert "noise_table3.md" not in table_bytes(d)  # no noise axis, no Table 3


def test_axis_table_holds_the_means_over_scenes_and_seeds(built):
    d, _, _ = built
    table = pd.read_csv(d / "tables" / "light.csv")
    psnr = table[table["metric"] == "psnr"]
    for method in ("tfp-w8", "tfi", "events-integrate", "fusion-x"):
        for light in LIGHTS:
            want = np.mean([expected_psnr(method, light, s, k) for s in SCENES for k in SEEDS])
            got = psnr[(psnr["method"] == method) & np.isclose(psnr["light"], light)]
            assert len(got) == 1 and got["mean"].iloc[0] == pytest.approx(want, abs=1e-12)
            assert got["n"].iloc[0] == len(SCENES) * len(SEEDS)
    assert "broken" not in set(table["method"])  # failures never enter an average
    md = (d / "tables" / "light.md").read_text()
    want_cell = f"{np.mean([expected_psnr('tfi', 1 / 8, s, k) for s in SCENES for k in SEEDS]):.2f}"
    assert want_cell in md and "| 1/32 | 1/16 | 1/8 | 1/4 | 1/2 |" in md


def test_report_from_the_csv_alone_gives_identical_tables(built, tmp_path):
    d, _, _ = built
    # a folder with nothing but results.csv, rebuilt through the command line into another folder
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(d / "results.csv", bare / "results.csv")
    out = tmp_path / "out"
    assert report.main([str(bare), "--out", str(out)]) == 0
    assert table_bytes(out) == table_bytes(d)
    assert (out / "report.pdf").read_bytes().startswith(b"%PDF")
    assert not list((out / "figures").glob("grid_*"))  # no images/, no grid, nothing else changes


def test_a_rerun_removes_a_killed_reports_temporaries_and_an_unwritable_out_is_one_line(built, tmp_path, capsys):
    d, _, _ = built
    bare = write_results(tmp_path / "bare", pd.read_csv(d / "results.csv"))
    (bare / "figures").mkdir()
    for stale in (bare / ".report.pdf.x1y2.tmp", bare / "figures" / ".light_affine.png.a8.tmp"):
        stale.write_bytes(b"half written")  # what a killed report leaves
    (bare / "keep.tmp").write_text("not ours: no leading dot")
    assert report.main([str(bare)]) == 0
    assert not list(bare.rglob(".*.tmp")) and (bare / "keep.tmp").exists()
    (tmp_path / "file").write_text("x")
    assert report.main([str(bare), "--out", str(tmp_path / "file" / "sub")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --out") and "cannot write there" in err[0]


def test_report_refuses_a_folder_without_results(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing to report"):
        reporting.build_report(tmp_path)
    assert report.main([str(tmp_path)]) == 2


def test_noise_table_puts_the_paper_beside_ours():
    rows = []
    for noise, drop in (("small", 0.0), ("medium", 1.0), ("high", 3.0)):
        for method in ("tfi", "events-integrate"):
            p = (25.0 if method == "tfi" else 12.0) - drop
            rows += [row(method, metric="psnr", value=p, noise=noise), row(method, metric="ssim", value=p / 40, noise=noise)]
    ours = tb.noise_table(rows_frame(rows))
    table = tb.noise_csv(ours)
    tfi = table[(table["source"] == "ours") & (table["method"] == "tfi")].iloc[0]
    assert tfi["psnr_small"] == 25.0 and tfi["psnr_high"] == 22.0 and tfi["ssim_medium"] == pytest.approx(24 / 40)
    paper = table[(table["source"] == "paper") & (table["method"] == "TFI")].iloc[0]
    assert paper["psnr_high"] == 18.56 and paper["ssim_small"] == 0.6911
    md = tb.noise_markdown(ours)
    assert "NeuSpike-Net (events+spikes)" in md and "26.07" in md and "| tfi | 25.00 | 24.00 | 22.00 |" in md
    # the paper's columns regenerated: our tfi beside the published TFI; absent methods left out
    regenerated = md.split("Table 3 regenerated", 1)[1].split("Published", 1)[0]
    assert "| TFI: ours (`tfi`) | 25.00 | 24.00 | 22.00 |" in regenerated
    assert "| TFI: paper | 21.76 | 21.03 | 18.56 |" in regenerated and "E2VID" not in regenerated


def test_image_convention_round_trip(built):
    d, _, truth = built
    images = d / "images"
    path = layout.image_path(images, "pan:camera", "light", 1 / 32, "tfi")
    assert path == images / "pan_camera" / "light=0.03125" / "tfi.png"
    loaded = reporting.load_images(images, synthetic_results(), "light")
    assert set(loaded) == {"pan:camera"}
    np.testing.assert_allclose(loaded["pan:camera"][("gt", 1 / 32)], np.round(truth * 255) / 255, atol=1e-6)
    np.testing.assert_allclose(loaded["pan:camera"][("tfi", 0.5)], np.round(truth * 255) / 255, atol=1e-6)
    with pytest.raises(ValueError):
        layout.write_image_png(d / "bad.png", truth + 1.0)  # out of range is refused, never clipped
    assert not (d / "bad.png").exists()


# ----------------------------------------------------------------------------------------------
# Pareto front
# ----------------------------------------------------------------------------------------------

def test_pareto_front_on_hand_made_points():
    #          A    B    C    D    E (=B)  F (no time)  G    H (slower and worse than G)
    t = [1.0, 2.0, 3.0, 0.5, 2.0, np.nan, 4.0, 5.0]
    s = [10., 12., 11., 5.0, 12., 20.0, 13.0, 13.0]
    front = tb.pareto_front(t, s)
    assert front.tolist() == [True, True, False, True, True, False, True, False]


def test_pareto_front_single_and_dominated_by_one():
    assert tb.pareto_front([1.0], [1.0]).tolist() == [True]
    assert tb.pareto_front([1.0, 1.0], [2.0, 1.0]).tolist() == [True, False]  # same time, better score wins
    assert tb.pareto_front([1.0, 2.0], [1.0, 1.0]).tolist() == [True, False]  # same score, faster wins
    with pytest.raises(ValueError):
        tb.pareto_front([1.0, 2.0], [1.0])


def test_accuracy_points_use_sweep_means_and_mark_the_front():
    pts = tb.accuracy_points(synthetic_results()).set_index("method")
    assert "broken" not in pts.index
    want = np.mean([expected_psnr("tfi", L, s, k) for L in LIGHTS for s in SCENES for k in SEEDS])
    assert pts.loc["tfi", "psnr"] == pytest.approx(want)
    # times 0.2 (tfp-w8), 0.5 (events), 1.0 (tfi), 5.0 (fusion); fusion is best, tfp-w8 fastest
    assert pts["front_psnr"].to_dict() == {"tfp-w8": True, "tfi": True, "events-integrate": False, "fusion-x": True}


# ----------------------------------------------------------------------------------------------
# Claims
# ----------------------------------------------------------------------------------------------

def curves(spec: dict[str, dict], axis: str, inputs: dict[str, str] | None = None, kind: str = "pan") -> pd.DataFrame:
    """Results whose mean PSNR of ``method`` at ``axis`` value ``v`` is ``spec[method][v]`` (SSIM = PSNR / 40)."""
    rows = []
    for method, points in spec.items():
        for v, p in points.items():
            cond = {"light": 0.25, "motion": 128, "noise": "none"}
            cond[axis] = v
            for seed, delta in ((0, -0.5), (1, 0.5)):  # two seeds around the mean
                for metric, value in (("psnr", p + delta), ("ssim", (p + delta) / 40)):
                    rows.append(row(method, metric=metric, value=value, seed=seed, scene=f"{kind}:camera",
                                    inputs=(inputs or INPUTS).get(method, "spikes"), **cond))
    return rows_frame(rows)


L5 = dict(zip(LIGHTS, range(5)))
S5 = dict(zip((16, 32, 64, 128, 256), range(5)))


def test_claim_spike_light_sensitivity():
    holds = curves({"tfi": {L: 10 + 5 * k for L, k in L5.items()}, "events-integrate": {L: 12 + 0.5 * k for L, k in L5.items()}}, "light")
    assert cl.spike_light_sensitive(holds)[0] == cl.HOLDS
    fails = curves({"tfi": {L: 10 + 5 * k for L, k in L5.items()}, "events-integrate": {L: 12 + 4 * k for L, k in L5.items()}}, "light")
    status, evidence = cl.spike_light_sensitive(fails)
    assert status == cl.FAILS and "20.00" in evidence and "16.00" in evidence
    only_spikes = curves({"tfi": {L: 10 + 5 * k for L, k in L5.items()}}, "light")
    assert cl.spike_light_sensitive(only_spikes)[0] == cl.UNCHECKED
    motion = curves({"tfi": {S: 10.0 for S in S5}}, "motion")
    assert cl.spike_light_sensitive(motion)[0] == cl.UNCHECKED


def test_claim_tfp_low_light_and_large_motion():
    rising = curves({"tfp-w8": {L: 8 + 3 * k for L, k in L5.items()}, "tfp-w32": {L: 15 + k for L, k in L5.items()}}, "light")
    assert cl.tfp_noisy_low_light(rising)[0] == cl.HOLDS
    falling = curves({"tfp-w8": {L: 20 - 3 * k for L, k in L5.items()}}, "light")
    assert cl.tfp_noisy_low_light(falling)[0] == cl.FAILS
    assert cl.tfp_noisy_low_light(curves({"tfi": {L: 1.0 for L in L5}}, "light"))[0] == cl.UNCHECKED
    blur = curves({"tfp": {S: 30 - 2 * k for S, k in S5.items()}}, "motion")
    assert cl.tfp_blurs_large_motion(blur)[0] == cl.HOLDS
    sharp = curves({"tfp": {S: 20 + k for S, k in S5.items()}}, "motion")
    assert cl.tfp_blurs_large_motion(sharp)[0] == cl.FAILS


def test_claim_tfi_high_light():
    peaked = curves({"tfi": {L: 20 + 4 * k - k * k for L, k in L5.items()}}, "light")  # peak at k = 2
    status, evidence = cl.tfi_noisy_high_light(peaked)
    assert status == cl.HOLDS and "peak at L = 1/8" in evidence
    monotone = curves({"tfi": {L: 20 + k for L, k in L5.items()}}, "light")
    assert cl.tfi_noisy_high_light(monotone)[0] == cl.FAILS


def test_claim_tfi_snm_keep_motion():
    keeps = curves({"tfp": {S: 30 - 2.5 * k for S, k in S5.items()}, "tfi": {S: 25 - 0.2 * k for S, k in S5.items()}}, "motion")
    assert cl.tfi_snm_keep_motion(keeps)[0] == cl.HOLDS
    loses = curves({"tfp": {S: 30 - 0.5 * k for S, k in S5.items()}, "tfi": {S: 25 - 3 * k for S, k in S5.items()}}, "motion")
    assert cl.tfi_snm_keep_motion(loses)[0] == cl.FAILS
    assert cl.tfi_snm_keep_motion(curves({"tfi": {S: 1.0 for S in S5}}, "motion"))[0] == cl.UNCHECKED


def test_claim_events_better_with_motion():
    better = curves({"events-integrate": {S: 8 + k for S, k in S5.items()}}, "motion")
    assert cl.events_better_with_motion(better)[0] == cl.HOLDS
    worse = curves({"events-integrate": {S: 12 - k for S, k in S5.items()}}, "motion")
    assert cl.events_better_with_motion(worse)[0] == cl.FAILS


def test_claim_fusion_best_everywhere():
    best = curves({"fusion-x": {L: 30.0 for L in L5}, "tfi": {L: 20 + k for L, k in L5.items()}}, "light")
    assert cl.fusion_best_everywhere(best)[0] == cl.HOLDS
    beaten = curves({"fusion-x": {L: 22.0 for L in L5}, "tfi": {L: 20 + k for L, k in L5.items()}}, "light")
    status, evidence = cl.fusion_best_everywhere(beaten)
    assert status == cl.FAILS and "3 of 5" in evidence and "-2.00 dB" in evidence
    assert cl.fusion_best_everywhere(curves({"tfi": {L: 1.0 for L in L5}}, "light"))[0] == cl.UNCHECKED


def test_claim_fusion_degrades_least_with_noise():
    levels = ("small", "medium", "high")
    least = curves({"fusion-x": dict(zip(levels, (26.0, 25.8, 25.5))), "tfi": dict(zip(levels, (22.0, 21.0, 18.5)))}, "noise")
    assert cl.fusion_degrades_least(least)[0] == cl.HOLDS
    most = curves({"fusion-x": dict(zip(levels, (26.0, 24.0, 20.0))), "tfi": dict(zip(levels, (22.0, 21.0, 18.5)))}, "noise")
    assert cl.fusion_degrades_least(most)[0] == cl.FAILS
    assert cl.fusion_degrades_least(curves({"fusion-x": {L: 1.0 for L in L5}}, "light"))[0] == cl.UNCHECKED


def test_claim_events_miss_static_texture_is_decided_by_the_static_texture_measure():
    def texture(values, kind="still"):
        return rows_frame([row(m, metric="static_texture", value=v, seed=0, scene=f"{kind}:camera",
                               inputs=INPUTS.get(m, "spikes"), light=0.25, motion=128, noise="none")
                           for m, v in values.items()])

    # PSNR/SSIM alone never decide it: a uniform event output can outscore a noisy spike method
    still = curves({"events-integrate": {0.25: 24.0}, "tfi": {0.25: 4.0}}, "light", kind="still")
    status, evidence = cl.events_miss_static_texture(still)
    assert status == cl.UNCHECKED and "no static-texture values" in evidence
    holds = texture({"events-integrate": 0.2, "tfi": 0.9, "snm": 0.7})
    status, evidence = cl.events_miss_static_texture(holds)
    assert status == cl.HOLDS and "event methods mean 0.200" in evidence and "spike methods mean 0.800" in evidence
    fails = texture({"events-integrate": 0.45, "tfi": 0.8})  # 0.45 >= 0.5 * 0.8
    assert cl.events_miss_static_texture(fails)[0] == cl.FAILS
    assert cl.events_miss_static_texture(texture({"tfi": 0.8}))[0] == cl.UNCHECKED  # no event method
    nan_only = texture({"events-integrate": float("nan"), "tfi": float("nan")}, kind="pan")
    assert cl.events_miss_static_texture(nan_only)[0] == cl.UNCHECKED


def test_evaluate_claims_reports_every_claim_and_contains_a_failing_check():
    verdicts = cl.evaluate_claims(synthetic_results())
    assert list(verdicts["key"]) == [c.key for c in cl.CLAIMS]
    assert set(verdicts["status"]) <= set(cl.STATUSES)
    by_key = verdicts.set_index("key")["status"]
    assert by_key["spike-light"] == cl.HOLDS and by_key["fusion-best"] == cl.HOLDS
    assert by_key["tfp-motion"] == cl.UNCHECKED  # a light sweep cannot speak about motion

    def boom(frame):
        raise KeyError("x")

    out = cl.evaluate_claims(synthetic_results(), [cl.Claim("boom", "s", "t", "", boom)])
    assert out["status"].tolist() == [cl.UNCHECKED] and "KeyError" in out["evidence"].iloc[0]


def test_spearman_against_known_values():
    assert cl.spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert cl.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert cl.spearman([1, 2, 3], [5, 5, 5]) == 0.0
    # d = rank differences (0, 0, 1, -1): rho = 1 - 6 * 2 / (4 * 15)
    assert cl.spearman([1, 2, 3, 4], [1, 2, 4, 3]) == pytest.approx(1 - 12 / 60)


def test_a_merged_folder_compares_noise_levels_at_one_condition_only():
    """A light sweep at noise none merged with a noise sweep at L = 1/4: "none" is taken at L = 1/4."""
    rows = []
    for light in LIGHTS:  # the light sweep: noise none at every L, PSNR = 40 * L
        rows.append(row("tfi", metric="psnr", value=40 * light, light=light, scene="pan:camera", seed=0))
    for noise, loss in (("small", 1.0), ("high", 3.0)):  # the noise sweep at L = 1/4 only
        rows.append(row("tfi", metric="psnr", value=40 * 0.25 - loss, light=0.25, scene="pan:camera", seed=0,
                        noise=noise))
    frame = rows_frame(rows)
    wide = tb.axis_means(frame, "noise")
    assert wide.loc["tfi"].to_dict() == pytest.approx({"none": 10.0, "small": 9.0, "high": 7.0})
    assert tb.held_conditions(frame, "noise") == "at L = 1/4, S = 128"
    # along light, the noise levels measured at one L only are left out, not mixed in
    assert tb.axis_means(frame, "light").loc["tfi"].to_dict() == pytest.approx({v: 40 * v for v in LIGHTS})


def test_claims_say_when_the_run_is_too_small_to_conclude(built):
    d, _, _ = built
    full = cl.evaluate_claims(synthetic_results())  # 2 scenes x 2 seeds per point
    assert full.attrs["caveat"] == ""
    small = synthetic_results()
    small = small[(small["scene"] == SCENES[0]) & (small["seed"] == SEEDS[0])]
    verdicts = cl.evaluate_claims(small)
    assert "only 1 cell (scenes x seeds)" in verdicts.attrs["caveat"]
    text = cl.claims_markdown(verdicts)
    assert verdicts.attrs["caveat"] in text and "REFERENCE" not in text
    assert "Caution" not in (d / "tables" / "claims.md").read_text()


def test_grid_rows_leave_room_for_long_method_names():
    image = np.zeros((24, 40))
    long_name = "fusion-complementary-with-a-longer-name"
    fig = figs.recon_grid_figure({("gt", 1): image, (long_name, 1): image}, ["gt", long_name], [1], "motion", "t")
    fig.canvas.draw()
    label = fig.axes[1].yaxis.label.get_window_extent()
    assert label.x0 >= 0, f"the row label starts {label.x0:.0f} px left of the figure"
    figs.close_all([fig])


def test_fusion_claims_are_checked_against_the_fusion_network_not_the_classical_filter():
    inputs = {"neuspike-net": "events+spikes", "fusion-complementary": "events+spikes", "tfi": "spikes"}
    classical_best = curves({"neuspike-net": {L: 20 + k for L, k in L5.items()},
                             "fusion-complementary": {L: 30 + k for L, k in L5.items()},
                             "tfi": {L: 10 + k for L, k in L5.items()}}, "light", inputs=inputs)
    assert cl.paper_fusion(classical_best) == ["neuspike-net"]
    status, evidence = cl.fusion_best_everywhere(classical_best)
    assert status == cl.FAILS and "fusion-complementary" in evidence
    network_best = curves({"neuspike-net": {L: 31 + k for L, k in L5.items()},
                           "fusion-complementary": {L: 30 + k for L, k in L5.items()}}, "light", inputs=inputs)
    assert cl.fusion_best_everywhere(network_best)[0] == cl.HOLDS


def test_a_light_noise_grid_gets_the_light_axis_at_each_noise_level(tmp_path):
    """Two swept axes: a table and a figure of the light axis per noise level, each level's means its own."""
    rows = []
    for noise, drop in (("none", 0.0), ("high", 6.0)):
        for light in LIGHTS:
            for seed in SEEDS:
                for method in ("tfp-w8", "tfi"):
                    p = expected_psnr(method, light, "pan:camera", seed) - drop
                    for metric, value in (("psnr", p), ("ssim", p / 40), ("specks", 0.001 * (drop > 0))):
                        rows.append(row(method, metric=metric, value=value, light=light, noise=noise, seed=seed))
    d = write_results(tmp_path / "ln", rows_frame(rows))
    reporting.build_report(d)
    tidy = pd.read_csv(d / "tables" / "light_by_noise.csv")
    got = tidy[(tidy.metric == "psnr") & (tidy.method == "tfi") & (tidy.light == 1 / 8)].set_index("noise")["mean"]
    want = np.mean([expected_psnr("tfi", 1 / 8, "pan:camera", s) for s in SEEDS])
    assert got["none"] == pytest.approx(want) and got["high"] == pytest.approx(want - 6.0)
    text = (d / "tables" / "light_by_noise.md").read_text()
    assert "### noise level high" in text and "isolated outliers" in text
    assert "| tfi | 1.00 |" in text  # specks written per mille
    for level in ("none", "high"):
        assert (d / "figures" / f"light_psnr_ssim_noise={level}.png").stat().st_size > 0


def test_the_light_noise_preset_spans_five_lights_at_four_noise_levels():
    from bench.harness import grid as grids

    g = grids.preset("light-noise", full=True)
    assert g.lights == grids.PAPER_LIGHTS and g.motions == (128,)
    assert g.noises == ("none", "small", "medium", "high")
    assert len(g.cells()) == 5 * 4 * len(grids.full_scene_names()) * len(grids.FULL_SEEDS)
    # its noisy cells at L = 1/4 are the noise preset's cells, so one cache serves both
    noise_ids = {repr(c.identity()) for c in grids.preset("noise", full=True).cells()}
    assert noise_ids <= {repr(c.identity()) for c in g.cells()}


def test_the_methods_table_summarises_each_methods_notes_in_one_short_cell():
    """A recurrent method's per-cell warm-up notes become one note with its cell count (they had joined
    into 250 characters that printed over other rows); every cell's own note stays in the CSV."""
    notes = ["clamp; short history: warmed up on 13 of 24 windows", "clamp; short history: warmed up on 9 of 24 windows",
             "clamp", "clamp"]
    rows = [dict(row("tfi", metric=m, value=1.0, light=light), normalisation=note)
            for light, note in zip(LIGHTS, notes) for m in ("psnr", "ssim")]
    summary = tb.method_summary(rows_frame(rows))
    assert summary.loc[0, "normalisation"] == "clamp; short history: warmed up on # of # windows (2 of 4 cells)"
    assert tb.summarise_notes(pd.Series(["robust-p99", "robust-p99"])) == "robust-p99"


def test_a_committed_report_may_keep_its_results_gzipped(tmp_path):
    """``results.csv.gz`` alone is read as ``results.csv``; the tables are the same byte for byte."""
    import gzip

    plain = write_results(tmp_path / "plain", synthetic_results())
    packed = tmp_path / "packed"
    packed.mkdir()
    (packed / "results.csv.gz").write_bytes(gzip.compress((plain / "results.csv").read_bytes()))
    assert reporting.results_file(packed) == packed / "results.csv.gz"
    assert reporting.results_file(plain) == plain / "results.csv"
    reporting.build_report(plain)
    reporting.build_report(packed)
    assert table_bytes(plain) == table_bytes(packed)
