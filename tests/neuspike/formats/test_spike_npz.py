"""Spike planes in .npz archives: our own layout, the Spike-Zoo/UHSR layout, the real sample."""

from __future__ import annotations

import os

import numpy as np
import pytest

from neuspike.errors import FormatError, InputError, SourceError
from neuspike.formats.spike_npz import read_spike_npz, write_spike_npz
from neuspike.streams import SpikeStream
from tests.shared_data import SHARED

UHSR = SHARED / "realdata" / "spike" / "uhsr_helicopter.npz"


def _planes(t=6, h=5, w=7, seed=0):
    return np.random.default_rng(seed).random((t, h, w)) < 0.3


def test_round_trip_keeps_planes_and_sensor_fields(tmp_path):
    stream = SpikeStream(_planes(), plane_rate_hz=40_000, start_s=0.25, gain=0.125, threshold=2.0, dark_rate=0.0055,
                         meta={"stages": [{"name": "integrate_and_fire", "seconds": np.float64(0.5)}]})
    path = write_spike_npz(tmp_path / "s.npz", stream)
    back = read_spike_npz(path)
    np.testing.assert_array_equal(back.planes, stream.planes)
    assert (back.plane_rate_hz, back.start_s, back.gain, back.threshold, back.dark_rate) == (40_000, 0.25, 0.125, 2.0,
                                                                                             0.0055)
    assert back.meta["stages"] == [{"name": "integrate_and_fire", "seconds": 0.5}]
    assert os.listdir(tmp_path) == ["s.npz"]


def test_unknown_gain_stays_unknown(tmp_path):
    write_spike_npz(tmp_path / "s.npz", SpikeStream(_planes()))
    back = read_spike_npz(tmp_path / "s.npz")
    assert back.gain is None and back.threshold is None and back.dark_rate is None and back.plane_rate_hz == 20_000


def test_spk_layout_is_read_upright(tmp_path):
    spk = np.zeros((3, 4, 5), np.uint8)
    spk[1, 0, 2] = 1  # top row stays the top row: no flip in .npz files
    np.savez(tmp_path / "z.npz", spk=spk, label=np.int64(3))
    s = read_spike_npz(tmp_path / "z.npz", plane_rate_hz=10_000)
    assert s.planes.dtype == np.bool_ and s.planes.flags.c_contiguous
    assert s.planes[1, 0, 2] and s.planes.sum() == 1
    assert s.plane_rate_hz == 10_000 and s.gain is None
    assert s.meta["key"] == "spk"


def test_values_other_than_0_and_1_are_a_format_error(tmp_path):
    spk = np.zeros((2, 3, 4), np.uint8)
    spk[0, 1, 1] = 255
    np.savez(tmp_path / "bad.npz", spk=spk)
    with pytest.raises(FormatError, match=r"only 0 and 1, found 1 other entries \(e.g. \[255\]\)"):
        read_spike_npz(tmp_path / "bad.npz")


def test_missing_key_wrong_shape_and_missing_file(tmp_path):
    np.savez(tmp_path / "k.npz", frames=np.zeros((2, 3, 4), np.uint8))
    with pytest.raises(FormatError, match=r"holds \['frames'\]"):
        read_spike_npz(tmp_path / "k.npz")
    s = read_spike_npz(tmp_path / "k.npz", key="frames")
    assert s.shape == (2, 3, 4)
    np.savez(tmp_path / "flat.npz", spk=np.zeros((3, 4), np.uint8))
    with pytest.raises(FormatError, match=r"shape \(T, H, W\)"):
        read_spike_npz(tmp_path / "flat.npz")
    with pytest.raises(SourceError):
        read_spike_npz(tmp_path / "absent.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(FormatError, match="junk.npz: not a readable .npz archive"):
        read_spike_npz(tmp_path / "junk.npz")


def test_contradicting_plane_rate_raises(tmp_path):
    write_spike_npz(tmp_path / "s.npz", SpikeStream(_planes(), plane_rate_hz=40_000))
    with pytest.raises(InputError, match="stores 40000.0 planes/s"):
        read_spike_npz(tmp_path / "s.npz", plane_rate_hz=20_000)
    assert read_spike_npz(tmp_path / "s.npz", plane_rate_hz=40_000).plane_rate_hz == 40_000


def test_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(InputError):
        write_spike_npz(tmp_path / "s.npz", SpikeStream(_planes(), meta={"bad": object()}))
    with pytest.raises(InputError):
        write_spike_npz(tmp_path / "s.npz", _planes())
    assert os.listdir(tmp_path) == []


@pytest.mark.skipif(not UHSR.is_file(), reason="shared real-data folder not present")
def test_real_uhsr_helicopter_sample():
    s = read_spike_npz(UHSR)
    assert s.shape == (200, 250, 250)
    assert s.gain is None and s.plane_rate_hz == 20_000
    assert abs(s.planes.mean() - 0.031) < 0.002
