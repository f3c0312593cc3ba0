"""Event files: round trips, the field's layouts, the real sample recordings, and bad input."""

from __future__ import annotations

import gzip
import os
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from neuspike.errors import FormatError, InputError, SourceError
from neuspike.formats import event_writers
from neuspike.formats.event_readers import read_events
from neuspike.formats.event_writers import EventsH5Writer, write_events_h5, write_events_npz, write_events_txt
from neuspike.streams import EventStream
from tests.shared_data import SHARED

PKU = SHARED / "realdata" / "events" / "pku_vidar_dvs_driving_outdoor3.hdf5"
AEDAT = SHARED / "realdata" / "events" / "dvxplorer_sample.aedat4"


def sample_stream(n=5000, width=40, height=30, seed=0, t0=2.5):
    rng = np.random.default_rng(seed)
    t = t0 + np.sort(rng.random(n)) * 0.1
    t[n // 4:n // 4 + n // 100 + 2] = t[n // 4]  # ties
    return EventStream(t, rng.integers(0, width, n), rng.integers(0, height, n),
                       rng.choice([-1, 1], n), width, height)


def same(a, b):
    return ((a.width, a.height) == (b.width, b.height) and np.array_equal(a.t_s, b.t_s)
            and np.array_equal(a.x, b.x) and np.array_equal(a.y, b.y) and np.array_equal(a.p, b.p))


def leftovers(folder: Path, name: str):
    return [p.name for p in folder.iterdir() if p.name != name]


# --------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("name, writer", [("e.h5", write_events_h5), ("e.hdf5", write_events_h5),
                                          ("e.txt", write_events_txt), ("e.txt.gz", write_events_txt),
                                          ("e.npz", write_events_npz)])
def test_round_trip_is_exact(tmp_path, name, writer):
    stream = sample_stream()
    assert writer(tmp_path / name, stream) == tmp_path / name
    back = read_events(tmp_path / name)
    assert same(back, stream)
    assert back.p.dtype == np.int8 and back.x.dtype == np.uint16 and back.t_s.dtype == np.float64
    assert leftovers(tmp_path, name) == []  # no temporary file left behind


@pytest.mark.parametrize("writer", [write_events_h5, write_events_txt, write_events_npz])
def test_empty_stream_round_trip(tmp_path, writer):
    empty = EventStream.empty(8, 6)
    path = tmp_path / {"write_events_h5": "e.h5", "write_events_txt": "e.txt"}.get(writer.__name__, "e.npz")
    writer(path, empty)
    back = read_events(path)
    assert len(back) == 0 and back.size == (8, 6)


def test_content_sniffing_for_unknown_extensions(tmp_path):
    stream = sample_stream(n=100)
    for name, writer in (("a.h5", write_events_h5), ("b.npz", write_events_npz), ("c.txt", write_events_txt)):
        writer(tmp_path / name, stream)
        os.replace(tmp_path / name, tmp_path / (name + ".bin"))
        assert same(read_events(tmp_path / (name + ".bin")), stream)


def test_h5_layout_matches_the_common_convention(tmp_path):
    stream = sample_stream(width=40, height=30)
    write_events_h5(tmp_path / "e.h5", stream)
    with h5py.File(tmp_path / "e.h5", "r") as f:
        assert list(f.attrs["sensor_resolution"]) == [30, 40]  # (height, width)
        assert set(f["events"].keys()) == {"xs", "ys", "ts", "ps"}
        assert set(np.unique(f["events/ps"][()])) == {0, 1}
        assert f.attrs["num_events"] == len(stream)
        assert f.attrs["num_pos"] == np.count_nonzero(stream.p > 0)
        assert f.attrs["t0"] == stream.t_s[0] and f.attrs["tk"] == stream.t_s[-1]


def test_txt_layout_matches_e2vid(tmp_path):
    stream = EventStream([0.5, 0.25 + 0.5], [3, 0], [1, 2], [1, -1], 4, 3)
    write_events_txt(tmp_path / "e.txt", stream)
    lines = (tmp_path / "e.txt").read_text().splitlines()
    assert lines[0] == "4 3"
    assert [line.split() for line in lines[1:]] == [["0.5", "3", "1", "1"], ["0.75", "0", "2", "0"]]


def _write_h5(path, xs, ys, ts, ps, resolution=(30, 40), **extra):
    with h5py.File(path, "w") as f:
        g = f.create_group("events")
        for k, v in (("xs", xs), ("ys", ys), ("ts", ts), ("ps", ps)):
            if v is not None:
                g.create_dataset(k, data=np.asarray(v))
        if resolution is not None:
            f.attrs["sensor_resolution"] = np.asarray(resolution)
        for k, v in extra.items():
            f.attrs[k] = v


@pytest.mark.parametrize("ps", [[0, 1, 1], [-1, 1, 1], [False, True, True]])
def test_reads_h5_from_other_tools(tmp_path, ps):
    _write_h5(tmp_path / "o.h5", [39, 0, 5], [0, 29, 7], [0.1, 0.2, 0.2], ps)
    s = read_events(tmp_path / "o.h5")
    assert s.size == (40, 30)
    np.testing.assert_array_equal(s.p, [-1, 1, 1])


def test_h5_without_resolution_needs_a_size(tmp_path):
    _write_h5(tmp_path / "o.h5", [3, 0], [0, 2], [0.1, 0.2], [0, 1], resolution=None)
    with pytest.raises(FormatError, match="sensor_resolution"):
        read_events(tmp_path / "o.h5")
    assert read_events(tmp_path / "o.h5", width=4, height=3).size == (4, 3)


def test_pku_layout_synthetic(tmp_path):
    rec = np.zeros(3, dtype=[("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
    rec["timestamp"] = [2_891_006, 2_891_012, 3_999_991]
    rec["x"], rec["y"], rec["polarity"] = [232, 4, 345], [229, 240, 259], [1, 0, 1]
    with h5py.File(tmp_path / "pku.hdf5", "w") as f:
        f.create_dataset("events", data=rec)
    s = read_events(tmp_path / "pku.hdf5")
    assert s.size == (346, 260)
    np.testing.assert_array_equal(s.t_s, [2.891006, 2.891012, 3.999991])
    np.testing.assert_array_equal(s.p, [1, -1, 1])
    assert s.meta["t_first_s"] == 2.891006


# --------------------------------------------------------------------------- appending writer
def test_appending_writer_equals_one_shot_writer(tmp_path):
    stream = sample_stream()
    with EventsH5Writer(tmp_path / "a.h5", 40, 30, chunk_events=1000) as w:
        for a, b in ((0, 1), (1, 1), (1, 1777), (1777, 5000)):
            w.write(EventStream(stream.t_s[a:b], stream.x[a:b], stream.y[a:b], stream.p[a:b], 40, 30))
        assert not (tmp_path / "a.h5").exists()  # only the temporary file exists until close
    assert w.count == len(stream)
    assert same(read_events(tmp_path / "a.h5"), stream)
    write_events_h5(tmp_path / "b.h5", stream)
    with h5py.File(tmp_path / "a.h5") as fa, h5py.File(tmp_path / "b.h5") as fb:
        for key in ("num_events", "num_pos", "num_neg", "t0", "tk", "duration"):
            assert fa.attrs[key] == fb.attrs[key]
    assert sorted(leftovers(tmp_path, "")) == ["a.h5", "b.h5"]


def test_appending_writer_rejects_bad_streams_and_leaves_nothing_on_error(tmp_path):
    stream = sample_stream()
    with pytest.raises(RuntimeError):
        with EventsH5Writer(tmp_path / "a.h5", 40, 30) as w:
            w.write(stream.between(2.55, 3.0))
            with pytest.raises(InputError, match="precedes"):
                w.write(stream.between(2.5, 2.55))
            with pytest.raises(InputError, match="40x30"):
                w.write(EventStream.empty(41, 30))
            raise RuntimeError("simulation failed")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- real recordings
@pytest.mark.skipif(not PKU.is_file(), reason="shared real data absent")
def test_reads_pku_vidar_dvs_recording():
    s = read_events(PKU)
    assert len(s) == 169_474 and s.size == (346, 260)
    assert (np.diff(s.t_s) >= 0).all()
    assert s.t_s[0] == pytest.approx(2.891006) and s.t_s[-1] - s.t_s[0] == pytest.approx(1.108985)
    assert set(np.unique(s.p)) == {-1, 1}


@pytest.mark.skipif(not AEDAT.is_file(), reason="shared real data absent")
def test_reads_aedat4_recording():
    s = read_events(AEDAT)
    assert len(s) == 111_954 and s.size == (320, 240)
    assert (np.diff(s.t_s) >= 0).all()
    assert 0.5 < s.t_s[-1] - s.t_s[0] < 0.7
    assert set(np.unique(s.p)) == {-1, 1}


def test_aedat4_without_the_extra_names_the_extra(tmp_path, monkeypatch):
    path = tmp_path / "x.aedat4"
    path.write_bytes(b"#!AER-DAT4.0\r\n")
    monkeypatch.setitem(sys.modules, "aedat", None)
    with pytest.raises(SourceError, match=r"\[aedat\]"):
        read_events(path)


# --------------------------------------------------------------------------- bad input
def test_coordinates_outside_the_sensor_name_the_event(tmp_path):
    _write_h5(tmp_path / "o.h5", [3, 40, 5], [0, 2, 7], [0.1, 0.2, 0.3], [0, 1, 1])
    with pytest.raises(FormatError, match=r"event 1 at \(x=40, y=2\).*40x30"):
        read_events(tmp_path / "o.h5")
    (tmp_path / "o.txt").write_text("4 3\n0.1 0 0 1\n0.2 1 3 0\n")
    with pytest.raises(FormatError, match=r"event 1 .*y must be in \[0, 3\)"):
        read_events(tmp_path / "o.txt")


def test_unsorted_timestamps_name_the_event(tmp_path):
    _write_h5(tmp_path / "o.h5", [3, 1, 5], [0, 2, 7], [0.1, 0.3, 0.2], [0, 1, 1])
    with pytest.raises(FormatError, match="event 2 at 0.2 s comes after event 1 at 0.3 s"):
        read_events(tmp_path / "o.h5")


def test_missing_datasets_name_what_was_expected(tmp_path):
    _write_h5(tmp_path / "a.h5", [3], [0], [0.1], None)
    with pytest.raises(FormatError, match="events/ps"):
        read_events(tmp_path / "a.h5")
    with h5py.File(tmp_path / "b.h5", "w") as f:
        f.create_dataset("frames", data=np.zeros(3))
    with pytest.raises(FormatError, match="xs, ys, ts, ps.*found \\['frames'\\]"):
        read_events(tmp_path / "b.h5")
    np.savez(tmp_path / "c.npz", t_s=np.zeros(1), x=np.zeros(1))
    with pytest.raises(FormatError, match="missing array.*'y'"):
        read_events(tmp_path / "c.npz")


@pytest.mark.parametrize("text, match", [
    ("0.1 0 0 1\n", "first line must be 'width height'"),
    ("4 3\n0.1 0 0\n", "four numbers"),
    ("4 3\n0.1 0 0 2\n", "polarity 2"),
    ("4 3\n0.1 0.5 0 1\n", "non-integer x"),
    ("4 3\nnan 0 0 1\n", "non-finite"),
])
def test_bad_text_files(tmp_path, text, match):
    (tmp_path / "e.txt").write_text(text)
    with pytest.raises(FormatError, match=match):
        read_events(tmp_path / "e.txt")


def test_missing_file_and_bad_arguments(tmp_path):
    with pytest.raises(SourceError, match="no such file"):
        read_events(tmp_path / "nothing.h5")
    write_events_npz(tmp_path / "e.npz", sample_stream(n=10))
    with pytest.raises(InputError, match="both width and height"):
        read_events(tmp_path / "e.npz", width=40)
    with pytest.raises(InputError, match="EventStream"):
        write_events_h5(tmp_path / "x.h5", {"t": []})
    with pytest.raises(SourceError, match="does not exist"):
        write_events_npz(tmp_path / "no" / "e.npz", sample_stream(n=10))


def test_failed_write_leaves_no_partial_file(tmp_path, monkeypatch):
    target = tmp_path / "e.txt"
    write_events_txt(target, sample_stream(n=10))
    before = target.read_bytes()

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(event_writers.np, "savez", broken)
    with pytest.raises(OSError, match="disk full"):
        write_events_npz(tmp_path / "e.npz", sample_stream(n=10))
    import pandas as pd

    monkeypatch.setattr(pd.DataFrame, "to_csv", broken)
    with pytest.raises(OSError, match="disk full"):
        write_events_txt(target, sample_stream(n=20))
    assert target.read_bytes() == before  # the old file is untouched
    assert leftovers(tmp_path, "e.txt") == []


def test_gzip_text_is_really_compressed(tmp_path):
    write_events_txt(tmp_path / "e.txt.gz", sample_stream(n=50))
    with gzip.open(tmp_path / "e.txt.gz", "rt") as fh:
        assert fh.readline().strip() == "40 30"
