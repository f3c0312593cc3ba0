"""The reconstruction command line, run in-process with dummy methods on tiny recordings."""

from __future__ import annotations

import importlib.util
import re

import cv2
import numpy as np
import pytest

from neuspike import methods as registry
from neuspike import metrics
from neuspike.errors import InputError
from neuspike.methods import Method, MethodUnavailable
from neuspike.reconstruct import ReconstructSpec, _prepare_methods, build_parser, main, spec_from_args
from tests.doubles import WithWeights


def _has(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


needs_npz_reader = pytest.mark.skipif(not _has("neuspike.formats.spike_npz"), reason="reader not yet available")

SPIKES_NAME = "zz-test-rate"
EVENTS_NAME = "zz-test-events"
WEIGHTS_NAME = "zz-test-weights"


class RateMethod(Method):
    """Mean firing rate divided by the rate's maximum (a tiny TFP; label "test-max")."""

    inputs = frozenset({"spikes"})

    def _reconstruct(self, sample):
        rate = sample.spikes.planes.mean(axis=0, dtype=np.float64)
        peak = rate.max()
        image = rate / peak if peak > 0 else rate
        return image.astype(np.float32), "test-max"


class EventsMethod(Method):
    inputs = frozenset({"events"})

    def _reconstruct(self, sample):
        return np.zeros((sample.height, sample.width), np.float32), "none"


class WeightsMethod(WithWeights):
    inputs = frozenset({"spikes"})

    def _reconstruct(self, sample):
        return np.zeros((sample.height, sample.width), np.float32), "none"


@pytest.fixture
def dummies():
    registry.available()  # load the installed entry points first, as a user's run does
    registry.register(SPIKES_NAME, RateMethod, description="test: mean rate over max")
    registry.register(EVENTS_NAME, EventsMethod)
    registry.register(WEIGHTS_NAME, WeightsMethod, weights="test.safetensors")
    yield
    for name in (SPIKES_NAME, EVENTS_NAME, WEIGHTS_NAME):
        registry.unregister(name)


@pytest.fixture
def npz_recording(tmp_path):
    """A (T=40, H=24, W=32) uint8 0/1 spike array whose rate ramps left to right, and a ground truth."""
    rng = np.random.default_rng(7)
    h, w, t = 24, 32, 40
    rate = np.tile(np.linspace(0.05, 0.9, w), (h, 1))
    spk = (rng.uniform(size=(t, h, w)) < rate).astype(np.uint8)
    path = tmp_path / "rec" / "tiny.npz"
    path.parent.mkdir()
    np.savez(path, spk=spk)
    gt = np.round(rate / rate.max() * 255).astype(np.uint8)
    gt_path = tmp_path / "truth.png"
    cv2.imwrite(str(gt_path), gt)
    return path, gt_path, spk


def test_help_explains_with_an_example(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "--method" in out and "--spikes" in out and "examples:" in out and "NEUSPIKE_WEIGHTS" in out


def test_list_shows_registered_methods_with_their_inputs(dummies, capsys):
    assert main(["--list"]) == 0
    out = capsys.readouterr().out
    lines = {line.split()[0]: line for line in out.splitlines() if line.strip()}
    assert SPIKES_NAME in lines and "spikes" in lines[SPIKES_NAME].split()[1]
    assert EVENTS_NAME in lines and "events" in lines[EVENTS_NAME].split()[1]
    assert "mean rate over max" in lines[SPIKES_NAME]


def test_unknown_method_exits_2_with_one_line(dummies, tmp_path, capsys):
    rc = main(["--method", "no-such-method", "--spikes", str(tmp_path / "x.npz"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "unknown method 'no-such-method'" in err and SPIKES_NAME in err
    errors = [line for line in err.splitlines() if not line.startswith("warning: entry point")]
    assert len(errors) == 1 and errors[0].startswith("error: ") and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_spike_method_without_spikes_exits_2(dummies, tmp_path, capsys):
    events = tmp_path / "e.h5"
    events.write_bytes(b"")
    rc = main(["--method", SPIKES_NAME, "--events", str(events), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "needs --spikes" in err and SPIKES_NAME in err
    assert not (tmp_path / "o").exists()


def test_dat_without_size_exits_2(dummies, tmp_path, capsys):
    dat = tmp_path / "bare" / "rec.dat"
    dat.parent.mkdir()
    dat.write_bytes(bytes(12_500 * 2))
    rc = main(["--method", SPIKES_NAME, "--spikes", str(dat), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "--height" in err and "--width" in err and "Traceback" not in err


def test_missing_file_and_usage_errors_exit_2(dummies, tmp_path, capsys):
    rc = main(["--method", SPIKES_NAME, "--spikes", str(tmp_path / "absent.npz"), "--out", str(tmp_path / "o")])
    assert rc == 2 and "no such file" in capsys.readouterr().err
    rc = main(["--method", SPIKES_NAME, "--spikes", "x.npz", "--plane", "3", "--at", "0.1", "--out", "o"])
    assert rc == 2 and "not allowed with" in capsys.readouterr().err
    assert main(["--method", SPIKES_NAME, "--spikes", "x.npz"]) == 2
    assert "--out" in capsys.readouterr().err


def test_weights_folder_reaches_only_entries_that_declare_weights(dummies, tmp_path, monkeypatch):
    monkeypatch.delenv("NEUSPIKE_WEIGHTS", raising=False)
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "test.safetensors").write_bytes(b"")
    spec = ReconstructSpec(methods=(WEIGHTS_NAME, SPIKES_NAME), out=tmp_path, spikes=tmp_path / "s.npz",
                           weights=tmp_path / "w")
    with_weights, plain = _prepare_methods(spec)
    assert with_weights.weights_path == tmp_path / "w" / "test.safetensors"
    assert with_weights.params == {"weights_file": "test.safetensors", "device": "cpu"}
    assert "weights_dir" not in plain.params and "weights_file" not in plain.params
    # only the command line reads the environment; the library takes the folder as given
    monkeypatch.setenv("NEUSPIKE_WEIGHTS", str(tmp_path / "w"))
    with pytest.raises(MethodUnavailable, match="test.safetensors"):
        _prepare_methods(ReconstructSpec(methods=(WEIGHTS_NAME,), out=tmp_path, spikes=tmp_path / "s.npz"))
    monkeypatch.setenv("NEUSPIKE_WEIGHTS", str(tmp_path / "env"))
    args = build_parser().parse_args(["--method", WEIGHTS_NAME, "--spikes", "s.npz", "--out", str(tmp_path)])
    with pytest.raises(InputError, match=r"\$NEUSPIKE_WEIGHTS: .* is not a folder"):  # as every command says it
        spec_from_args(args)
    (tmp_path / "env").mkdir()
    assert spec_from_args(args).weights == (tmp_path / "env").resolve()


@needs_npz_reader
def test_spike_run_writes_png_and_npy_and_scores_against_gt(dummies, npz_recording, tmp_path, capsys):
    path, gt_path, spk = npz_recording
    out = tmp_path / "out"
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "test.safetensors").write_bytes(b"")
    rc = main(["--method", f"{SPIKES_NAME},{WEIGHTS_NAME}", "--spikes", str(path), "--gt", str(gt_path),
               "--weights", str(tmp_path / "w"), "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    image = np.load(out / f"{SPIKES_NAME}.npy")
    assert image.dtype == np.float32 and image.shape == spk.shape[1:]
    # a 40-plane file is shorter than the default window: the whole file is used
    rate = spk.mean(axis=0)
    np.testing.assert_allclose(image, rate / rate.max(), atol=1e-6)
    png = cv2.imread(str(out / f"{SPIKES_NAME}.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint8 and png.shape == spk.shape[1:]
    np.testing.assert_array_equal(png, np.round(image.astype(np.float64) * 255).astype(np.uint8))
    assert (out / f"{WEIGHTS_NAME}.png").is_file()
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]  # no temp files left
    text = captured.out
    assert "normalisation test-max" in text and "sigma=1.5" in text
    gt = cv2.imread(str(gt_path), cv2.IMREAD_UNCHANGED) / 255.0
    line = next(l for l in text.splitlines() if l.startswith(f"{SPIKES_NAME}:"))
    printed = float(re.search(r"PSNR (\S+) dB", line).group(1))
    assert printed == pytest.approx(metrics.psnr(image, gt, data_range=1.0), abs=0.006)
    assert "affine-aligned" in line


@needs_npz_reader
def test_spike_run_without_gt_prints_no_reference_measures(dummies, npz_recording, tmp_path, capsys):
    path, _, _ = npz_recording
    assert main(["--method", SPIKES_NAME, "--spikes", str(path), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "noise_sigma" in out and "laplacian_var" in out and "PSNR" not in out


@needs_npz_reader
def test_window_and_key_plane_select_the_planes(dummies, npz_recording, tmp_path, capsys):
    path, _, spk = npz_recording
    out = tmp_path / "o"
    rc = main(["--method", SPIKES_NAME, "--spikes", str(path), "--plane", "3", "--window-planes", "8",
               "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    # the window is shifted (not shortened) to stay inside the file: planes 0..7
    rate = spk[0:8].mean(axis=0)
    expected = rate / rate.max() if rate.max() > 0 else rate
    np.testing.assert_allclose(np.load(out / f"{SPIKES_NAME}.npy"), expected, atol=1e-6)
    rc = main(["--method", SPIKES_NAME, "--spikes", str(path), "--plane", "40", "--out", str(out)])
    assert rc == 2 and "outside" in capsys.readouterr().err


@needs_npz_reader
def test_bad_size_and_bad_gt_exit_2(dummies, npz_recording, tmp_path, capsys):
    path, gt_path, _ = npz_recording
    rc = main(["--method", SPIKES_NAME, "--spikes", str(path), "--height", "10", "--width", "10",
               "--out", str(tmp_path / "o")])
    assert rc == 2 and "10x10" in capsys.readouterr().err
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((5, 5), np.uint8))
    rc = main(["--method", SPIKES_NAME, "--spikes", str(path), "--gt", str(small), "--out", str(tmp_path / "o")])
    assert rc == 2 and "ground truth" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@needs_npz_reader
def test_gain_and_dark_rate_given_reach_the_sample_and_a_bad_dark_rate_exits_2(dummies, npz_recording, tmp_path,
                                                                                 capsys, monkeypatch):
    path, _, _ = npz_recording
    seen = []
    monkeypatch.setattr(RateMethod, "_reconstruct", lambda self, sample: (
        seen.append((sample.spikes.gain, sample.spikes.dark_rate)) or np.zeros((24, 32), np.float32), "none"))
    assert main(["--method", SPIKES_NAME, "--spikes", str(path), "--out", str(tmp_path / "o")]) == 0
    assert main(["--method", SPIKES_NAME, "--spikes", str(path), "--gain", "0.5", "--dark-rate", "0.0055",
                 "--out", str(tmp_path / "o")]) == 0
    assert seen == [(None, None), (0.5, 0.0055)]  # unknown unless given (the file stores neither)
    assert "dark rate 0.0055" in capsys.readouterr().out
    rc = main(["--method", SPIKES_NAME, "--spikes", str(path), "--dark-rate", "-1", "--out", str(tmp_path / "o")])
    assert rc == 2 and "dark_rate" in capsys.readouterr().err


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_precision_flag_reaches_the_learned_methods(tmp_path, precision):
    """``--precision`` overrides a learned method's shipped ``auto``; the method reports what it runs in."""
    args = build_parser().parse_args(["--events", str(tmp_path / "e.h5"), "--method", "firenet-sim",
                                      "--precision", precision, "--out", str(tmp_path / "out")])
    spec = spec_from_args(args)
    assert spec.precision == precision
    (method,) = _prepare_methods(spec)
    assert method.params["precision"] == precision and method.describe()["params"]["precision"] == precision


@needs_npz_reader
def test_a_plug_in_file_registers_a_method_the_command_lists_and_runs(npz_recording, tmp_path, capsys):
    """--plugin (as the benchmarks take it): the file's method is listed and reconstructs like any other."""
    from neuspike.methods.plugins import forget_plugin

    path, _, spk = npz_recording
    plugin = tmp_path / "zz_plugin.py"
    plugin.write_text("from tests.neuspike.test_reconstruct_cli import RateMethod\n\n\n"
                      "def register_methods(register):\n    register('zz-plugged', RateMethod)\n")
    try:
        assert main(["--plugin", str(plugin), "--list"]) == 0
        assert "zz-plugged" in capsys.readouterr().out
        assert main(["--plugin", str(plugin), "--method", "zz-plugged", "--spikes", str(path),
                     "--out", str(tmp_path / "o")]) == 0
    finally:
        registry.unregister("zz-plugged")
        forget_plugin(str(plugin))
    rate = spk.mean(axis=0)
    np.testing.assert_allclose(np.load(tmp_path / "o" / "zz-plugged.npy"), rate / rate.max(), atol=1e-6)


def test_a_missing_plug_in_file_exits_2_with_one_line(tmp_path, capsys):
    assert main(["--plugin", str(tmp_path / "absent.py"), "--list"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: plug-in file") and "does not exist" in err and err.count("\n") == 1
