"""Loading recordings into samples: key instant, windows, meta.json, gain, ground truth."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from neuspike.errors import FormatError, InputError, SourceError
from neuspike.formats.samples import DEFAULT_WINDOW_PLANES, EVENT_HISTORY_S, load_ground_truth, load_sample
from neuspike.streams import EventStream
from tests.shared_data import SHARED

REAL = SHARED / "realdata"


def _has(module: str, name: str | None = None) -> bool:
    try:
        if importlib.util.find_spec(module) is None:
            return False
    except ModuleNotFoundError:
        return False
    if name is None:
        return True
    return hasattr(importlib.import_module(module), name)


needs_npz_reader = pytest.mark.skipif(not _has("neuspike.formats.spike_npz"), reason="reader not yet available")
needs_dat = pytest.mark.skipif(
    not (_has("neuspike.formats.vidar_dat", "write_dat") and _has("neuspike.formats.vidar_dat", "read_dat")),
    reason="reader not yet available",
)
needs_events_io = pytest.mark.skipif(
    not (_has("neuspike.formats.event_readers", "read_events") and _has("neuspike.formats.event_writers", "write_events_h5")),
    reason="reader not yet available",
)


def _write_spikes(path: Path, planes: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, spk=planes.astype(np.uint8))
    return path


def _indexed_planes(t: int, h: int = 12, w: int = 14) -> np.ndarray:
    """Plane j fires exactly at pixel (0, 0) when j is odd and nowhere else, plus a plane-index code
    in the first row: pixel (0, 1 + b) fires on plane j when bit b of j is set (j < 2**13)."""
    planes = np.zeros((t, h, w), np.uint8)
    for j in range(t):
        for b in range(min(w - 1, 13)):
            planes[j, 0, 1 + b] = (j >> b) & 1
    return planes


def _first_plane_index(sample) -> int:
    bits = sample.spikes.planes[0, 0, 1:14]
    return int(sum(int(v) << b for b, v in enumerate(bits)))


def _simulated_folder(tmp_path: Path, *, t: int = 64, h: int = 12, w: int = 14, rate: float = 20_000.0) -> Path:
    folder = tmp_path / "sim"
    _write_spikes(folder / "spikes.npz", _indexed_planes(t, h, w))
    meta = {"width": w, "height": h, "plane_rate_hz": rate, "gain": 0.25, "threshold": 1.0,
            "event_threshold": 0.2, "start_s": 0.0, "key_time_s": t / (2 * rate), "planes": t, "mode": "window",
            "dark_rate": 0.004}
    (folder / "meta.json").write_text(json.dumps(meta))
    np.save(folder / "gt.npy", np.linspace(0, 1.5, h * w, dtype=np.float32).reshape(h, w))
    return folder


def test_needs_some_input_and_one_key_instant(tmp_path):
    with pytest.raises(InputError):
        load_sample()
    with pytest.raises(SourceError, match="no such file"):
        load_sample(spikes=tmp_path / "absent.npz")
    (tmp_path / "folder.dat").mkdir()
    with pytest.raises(SourceError, match="is a folder, not a file"):
        load_sample(spikes=tmp_path / "folder.dat")
    f = tmp_path / "x.npz"
    f.write_bytes(b"")
    with pytest.raises(InputError, match="not both"):
        load_sample(spikes=f, plane=1, at_s=0.0)
    other = tmp_path / "x.bin"
    other.write_bytes(b"")
    with pytest.raises(InputError, match="expected one of"):
        load_sample(spikes=other)


def test_bare_dat_needs_a_size(tmp_path):
    dat = tmp_path / "rec.dat"
    dat.write_bytes(bytes(500))
    with pytest.raises(InputError, match="--height H --width W"):
        load_sample(spikes=dat)
    with pytest.raises(InputError, match="both height and width"):
        load_sample(spikes=dat, height=10)


def test_ground_truth_reader_scales_and_checks(tmp_path):
    import cv2

    img16 = (np.arange(20 * 30, dtype=np.uint16).reshape(20, 30) * 100)
    cv2.imwrite(str(tmp_path / "g16.png"), img16)
    gt, notes = load_ground_truth(tmp_path / "g16.png", height=20, width=30)
    np.testing.assert_allclose(gt, img16 / 65535.0, atol=1e-7)
    assert gt.dtype == np.float32 and not notes
    colour = np.zeros((20, 30, 3), np.uint8)
    colour[..., 2] = 200
    cv2.imwrite(str(tmp_path / "c.png"), colour)
    with pytest.raises(InputError, match="greyscale"):
        load_ground_truth(tmp_path / "c.png", height=20, width=30)
    with pytest.raises(InputError, match="shape"):
        load_ground_truth(tmp_path / "g16.png", height=30, width=20)
    np.save(tmp_path / "hdr.npy", np.full((4, 5), 2.0))
    gt, notes = load_ground_truth(tmp_path / "hdr.npy", height=4, width=5)
    assert gt.max() == 1.0 and "20 pixels" in notes[0]


@needs_npz_reader
def test_simulated_folder_uses_meta_json(tmp_path):
    folder = _simulated_folder(tmp_path)
    s = load_sample(spikes=folder / "spikes.npz")
    assert s.spikes.num_planes == 64 and _first_plane_index(s) == 0  # a window recording is used whole
    assert s.spikes.gain == 0.25 and s.meta["gain_source"] == "meta.json" and s.spikes.dark_rate == 0.004
    assert s.key_time_s == pytest.approx(32 / 20_000.0) and s.key_plane == 32
    assert s.event_threshold == 0.2
    # gt.npy (not quantised) is preferred; HDR values above 1 are clipped, and noted
    assert s.ground_truth is not None and s.ground_truth.max() == 1.0
    assert s.meta["ground_truth_path"].endswith("gt.npy") and any("clipped" in n for n in s.meta["notes"])
    # an explicit gain overrides; a key instant in another plane leaves the ground truth out
    s = load_sample(spikes=folder / "spikes.npz", gain=0.5, plane=10)
    assert s.spikes.gain == 0.5 and s.meta["gain_source"] == "given"
    assert s.ground_truth is None and any("not used" in n for n in s.meta["notes"])
    with pytest.raises(InputError, match="meta.json states"):
        load_sample(spikes=folder / "spikes.npz", height=5, width=5)
    meta = json.loads((folder / "meta.json").read_text())
    (folder / "meta.json").write_text(json.dumps({**meta, "dark_rate": -0.001}))
    with pytest.raises(FormatError, match="dark_rate"):
        load_sample(spikes=folder / "spikes.npz")


@needs_npz_reader
def test_long_file_window_is_centred_on_the_key_plane_and_shifted_inside(tmp_path):
    t = 600
    path = _write_spikes(tmp_path / "long.npz", _indexed_planes(t))
    s = load_sample(spikes=path)  # default: the middle plane (300), 256 planes around it
    assert s.spikes.num_planes == DEFAULT_WINDOW_PLANES
    assert _first_plane_index(s) == 300 - 128 and s.key_plane == 128
    assert s.key_time_s == pytest.approx(300.5 / 20_000.0)
    assert s.spikes.gain is None and s.meta["gain_source"] == "unknown"
    s = load_sample(spikes=path, plane=400, window_planes=32)
    assert _first_plane_index(s) == 384 and s.key_plane == 16
    assert s.key_time_s == pytest.approx((400 + 0.5) / 20_000.0)
    s = load_sample(spikes=path, at_s=(590 + 0.25) / 20_000.0, window_planes=32)  # near the end: shifted
    assert _first_plane_index(s) == t - 32 and s.key_plane == 590 - (t - 32)
    assert s.window_start_s <= s.key_time_s <= s.window_end_s
    with pytest.raises(InputError, match="outside"):
        load_sample(spikes=path, at_s=1.0)
    with pytest.raises(InputError, match="outside"):
        load_sample(spikes=path, plane=t)


@needs_dat
def test_dat_reads_only_the_window_range(tmp_path):
    from neuspike.formats.vidar_dat import write_dat

    planes = _indexed_planes(300, h=16, w=16).astype(bool)
    path = write_dat(tmp_path / "rec.dat", planes)
    s = load_sample(spikes=path, height=16, width=16, plane=200, window_planes=40)
    np.testing.assert_array_equal(s.spikes.planes, planes[180:220])
    assert s.spikes.start_s == pytest.approx(180 / 20_000.0) and s.key_plane == 20
    assert s.spikes.gain is None
    s = load_sample(spikes=path, height=16, width=16, gain=0.3, plane_rate_hz=40_000.0)
    assert s.spikes.num_planes == 256 and s.spikes.gain == 0.3 and s.spikes.plane_rate_hz == 40_000.0
    assert s.key_time_s == pytest.approx(150.5 / 40_000.0)


@needs_npz_reader
def test_rate_start_and_gain_stored_in_an_npz_are_used(tmp_path):
    from neuspike.formats.spike_npz import write_spike_npz
    from neuspike.streams import SpikeStream

    stream = SpikeStream(_indexed_planes(50).astype(bool), plane_rate_hz=40_000.0, start_s=1.0, gain=0.5)
    path = write_spike_npz(tmp_path / "own.npz", stream)
    s = load_sample(spikes=path, at_s=1.0 + 10.2 / 40_000.0)
    assert s.spikes.plane_rate_hz == 40_000.0 and s.spikes.start_s == 1.0
    assert s.spikes.gain == 0.5 and s.meta["gain_source"] == "file"
    assert s.meta["key_plane_in_file"] == 10 and s.key_plane == 10


@needs_npz_reader
@needs_events_io
def test_events_are_cut_to_the_window_plus_history(tmp_path):
    from neuspike.formats.event_writers import write_events_h5

    folder = _simulated_folder(tmp_path, t=64)
    t = np.array([-2.0, -0.5, 0.0005, 0.0031, 0.00319, 0.0032, 0.01])
    n = t.size
    ev = EventStream(t, np.zeros(n), np.zeros(n), np.ones(n), 14, 12)
    write_events_h5(folder / "events.h5", ev)
    s = load_sample(spikes=folder / "spikes.npz", events=folder / "events.h5")
    # window = the spike window [0, 3.2 ms); history = the second before it
    np.testing.assert_allclose(s.events.t_s, [-0.5, 0.0005, 0.0031, 0.00319])
    assert len(s.window_events()) == 3 and len(s.history_events()) == 1
    assert s.meta["events_left_out_before"] == 1 and s.meta["events_left_out_after"] == 2
    assert EVENT_HISTORY_S == 1.0
    # events only, no meta.json: a 256-plane (12.8 ms) window centred on the recording's middle
    lone = tmp_path / "lone"
    lone.mkdir()
    write_events_h5(lone / "e.h5", EventStream(np.array([1.0, 1.002, 1.1]), np.zeros(3), np.zeros(3), np.ones(3), 14, 12))
    s = load_sample(events=lone / "e.h5")
    assert s.key_time_s == pytest.approx(1.05)
    assert s.window_end_s - s.window_start_s == pytest.approx(256 / 20_000.0)
    with pytest.raises(InputError, match="--at"):
        load_sample(events=lone / "e.h5", plane=3)
    with pytest.raises(InputError, match="outside"):
        load_sample(events=lone / "e.h5", at_s=5.0)


@needs_npz_reader
@pytest.mark.skipif(not (REAL / "spike" / "uhsr_helicopter.npz").is_file(), reason="shared real data absent")
def test_real_spike_sample_loads_whole_with_unknown_gain():
    s = load_sample(spikes=REAL / "spike" / "uhsr_helicopter.npz")
    assert (s.height, s.width) == (250, 250)
    assert s.spikes.num_planes == 200 and s.spikes.gain is None and s.ground_truth is None
    assert 0.02 < s.spikes.planes.mean() < 0.05  # the README's 0.031 spikes/pixel/plane


@needs_events_io
@pytest.mark.skipif(not (REAL / "events" / "pku_vidar_dvs_driving_outdoor3.hdf5").is_file(),
                    reason="shared real data absent")
def test_real_event_sample_takes_a_window_at_the_centre():
    s = load_sample(events=REAL / "events" / "pku_vidar_dvs_driving_outdoor3.hdf5")
    assert (s.width, s.height) == (346, 260)
    assert s.window_end_s - s.window_start_s == pytest.approx(256 / 20_000.0)
    assert 2.8 < s.key_time_s < 4.1 and len(s.window_events()) > 0


def test_a_window_longer_than_the_file_reads_the_file_whole_without_a_huge_buffer(tmp_path):
    """A window of 10**12 planes on a 256-plane file: the whole file, read at once (the buffer had
    been sized to twice the window, a 1 PiB MemoryError on every row of a dataset)."""
    from neuspike.formats.samples import load_sample
    from neuspike.simulate import main as simulate

    assert simulate(["--size", "48x32", "--modalities", "spikes", "--out", str(tmp_path / "rec")]) == 0
    sample = load_sample(spikes=tmp_path / "rec" / "spikes.dat", window_planes=10**12)
    assert sample.spikes.planes.shape == (256, 32, 48)
