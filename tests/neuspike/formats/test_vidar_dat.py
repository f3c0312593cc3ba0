"""Vidar .dat files: hand-built bytes pin the bit order and the row flip; round trips; errors."""

from __future__ import annotations

import os

import numpy as np
import pytest

from neuspike.errors import FormatError, InputError
from neuspike.formats import vidar_dat
from neuspike.formats.vidar_dat import DatWriter, count_planes, read_dat, read_spike_stream, write_dat
from neuspike.streams import SpikeStream


def _planes(t, h, w, seed=0, p=0.3):
    return np.random.default_rng(seed).random((t, h, w)) < p


# ---------------------------------------------------------------------------------------------
# the byte layout, written out by hand
# ---------------------------------------------------------------------------------------------

def test_single_pixel_of_a_2x8_sensor():
    # image row 0 is stored last (rows upside down): pixel (0, 1) is stored index 8 + 1 = 9,
    # i.e. bit 1 of byte 1 of the plane
    plane = np.zeros((1, 2, 8), bool)
    plane[0, 0, 1] = True
    assert vidar_dat._pack(plane) == bytes([0x00, 0x02])


def test_hand_built_4x8_fixture(tmp_path):
    # plane 0: (0,0) -> stored row 3, index 24: byte 3 bit 0; (3,7) -> stored row 0, index 7:
    #          byte 0 bit 7; (1,2) -> stored row 2, index 18: byte 2 bit 2
    # plane 1: image row 2 full -> stored row 1 = byte 1; (0,1) -> index 25: byte 3 bit 1
    fixture = bytes([0x80, 0x00, 0x04, 0x01,
                     0x00, 0xFF, 0x00, 0x02])
    expected = np.zeros((2, 4, 8), bool)
    expected[0, 0, 0] = expected[0, 3, 7] = expected[0, 1, 2] = True
    expected[1, 2, :] = True
    expected[1, 0, 1] = True

    path = tmp_path / "fixture.dat"
    path.write_bytes(fixture)
    np.testing.assert_array_equal(read_dat(path, height=4, width=8), expected)
    out = tmp_path / "written.dat"
    write_dat(out, expected)
    assert out.read_bytes() == fixture


def test_bits_run_across_row_boundaries_for_widths_not_divisible_by_8(tmp_path):
    # 4 x 6 sensor, 3 bytes per plane. (0,5) -> stored row 3: index 23 = byte 2 bit 7;
    # (3,2) -> stored row 0: index 2 = byte 0 bit 2; (1,4) -> stored row 2: index 16 = byte 2 bit 0;
    # (2,1) -> stored row 1: index 7 = byte 0 bit 7
    fixture = bytes([0x84, 0x00, 0x81])
    expected = np.zeros((1, 4, 6), bool)
    expected[0, 0, 5] = expected[0, 3, 2] = expected[0, 1, 4] = expected[0, 2, 1] = True
    path = tmp_path / "f.dat"
    path.write_bytes(fixture)
    np.testing.assert_array_equal(read_dat(path, height=4, width=6), expected)
    write_dat(tmp_path / "g.dat", expected)
    assert (tmp_path / "g.dat").read_bytes() == fixture


def test_416_wide_capture_drops_the_16_columns_at_the_right(tmp_path):
    # 2 rows of 416 columns = 52 bytes per stored row. Image row 0 is stored row 1 (bytes 52..103):
    # column 3 -> index 419 = byte 52 bit 3; column 405 (an extra column) -> index 821 = byte 102 bit 5
    raw = bytearray(104)
    raw[52] |= 1 << 3
    raw[102] |= 1 << 5
    path = tmp_path / "wide.dat"
    path.write_bytes(bytes(raw))
    planes = read_dat(path, height=2, width=400, raw_width=416)
    expected = np.zeros((1, 2, 400), bool)
    expected[0, 0, 3] = True
    np.testing.assert_array_equal(planes, expected)
    assert planes.flags.c_contiguous


def test_416_wide_random_planes(tmp_path):
    raw = _planes(5, 250, 416, seed=3)
    write_dat(tmp_path / "w.dat", raw)
    got = read_dat(tmp_path / "w.dat", height=250, width=400, raw_width=416, start=1, stop=4)
    np.testing.assert_array_equal(got, raw[1:4, :, :400])
    assert count_planes(tmp_path / "w.dat", height=250, width=400, raw_width=416) == 5


# ---------------------------------------------------------------------------------------------
# round trips and plane ranges
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("h, w", [(250, 400), (260, 346), (180, 240), (1, 8), (3, 8), (4, 6)])
def test_round_trip(tmp_path, h, w):
    planes = _planes(7, h, w, seed=h + w)
    path = tmp_path / "s.dat"
    assert write_dat(path, planes) == path
    assert path.stat().st_size == 7 * h * w // 8
    got = read_dat(path, height=h, width=w)
    assert got.dtype == np.bool_ and got.flags.c_contiguous
    np.testing.assert_array_equal(got, planes)
    assert count_planes(path, height=h, width=w) == 7


def test_plane_ranges_equal_slices_of_the_full_read(tmp_path):
    planes = _planes(23, 12, 10, seed=5)
    path = tmp_path / "r.dat"
    write_dat(path, planes)
    full = read_dat(path, height=12, width=10)
    for start, stop in [(0, 1), (5, 9), (22, 23), (0, 23), (7, 7), (3, None)]:
        part = read_dat(path, height=12, width=10, start=start, stop=stop)
        np.testing.assert_array_equal(part, full[start:stop])
        assert part.flags.c_contiguous


def test_range_read_does_not_load_the_whole_file(tmp_path):
    # a sparse 1.25 GB file: reading two planes at its end must touch only those planes
    path = tmp_path / "huge.dat"
    tail = _planes(2, 250, 400, seed=1)
    n = 100_000
    with open(path, "wb") as f:
        f.truncate((n - 2) * 12_500)
        f.seek((n - 2) * 12_500)
        f.write(vidar_dat._pack(tail))
    assert count_planes(path, height=250, width=400) == n
    np.testing.assert_array_equal(read_dat(path, height=250, width=400, start=n - 2), tail)
    assert not read_dat(path, height=250, width=400, start=10, stop=12).any()


def test_chunked_packing_matches_single_chunk(tmp_path, monkeypatch):
    planes = _planes(9, 6, 8, seed=2)
    write_dat(tmp_path / "one.dat", planes)
    monkeypatch.setattr(vidar_dat, "_CHUNK_PIXELS", 2 * 48)  # two planes per chunk
    write_dat(tmp_path / "many.dat", planes)
    assert (tmp_path / "one.dat").read_bytes() == (tmp_path / "many.dat").read_bytes()
    np.testing.assert_array_equal(read_dat(tmp_path / "many.dat", height=6, width=8, start=1), planes[1:])


def test_writer_appends_chunks(tmp_path):
    planes = _planes(10, 8, 16, seed=4)
    with DatWriter(tmp_path / "a.dat") as w:
        for a, b in ((0, 3), (3, 4), (4, 10)):
            w.write(planes[a:b])
        assert not (tmp_path / "a.dat").exists()  # nothing visible before close
        assert w.planes_written == 10
    write_dat(tmp_path / "b.dat", planes)
    assert (tmp_path / "a.dat").read_bytes() == (tmp_path / "b.dat").read_bytes()


def test_spike_stream_in_and_out(tmp_path):
    planes = _planes(12, 8, 8, seed=6)
    write_dat(tmp_path / "s.dat", SpikeStream(planes))
    s = read_spike_stream(tmp_path / "s.dat", height=8, width=8, plane_rate_hz=10_000, gain=0.25, start=4)
    np.testing.assert_array_equal(s.planes, planes[4:])
    assert (s.start_s, s.gain, s.plane_rate_hz) == (4 / 10_000, 0.25, 10_000)
    assert s.meta["first_plane"] == 4


def test_zero_planes(tmp_path):
    write_dat(tmp_path / "e.dat", np.zeros((0, 4, 8), bool))
    assert (tmp_path / "e.dat").stat().st_size == 0
    assert read_dat(tmp_path / "e.dat", height=4, width=8).shape == (0, 4, 8)


# ---------------------------------------------------------------------------------------------
# errors, and nothing half-written
# ---------------------------------------------------------------------------------------------

def test_size_not_a_whole_number_of_planes(tmp_path):
    path = tmp_path / "cut.dat"
    path.write_bytes(bytes(3 * 4 + 3))
    with pytest.raises(FormatError, match=r"size 15 bytes .* 4-byte planes .* remainder of 3 bytes"):
        read_dat(path, height=4, width=8)
    with pytest.raises(FormatError, match="remainder of 3 bytes"):
        count_planes(path, height=4, width=8)


def test_wrong_width(tmp_path):
    path = tmp_path / "v.dat"
    write_dat(path, _planes(3, 250, 400))
    with pytest.raises(FormatError, match=r"37500 bytes .* 12000-byte planes .* remainder of 1500 bytes"):
        read_dat(path, height=250, width=384)


def test_sizes_that_do_not_pack_into_bytes_are_refused(tmp_path):
    with pytest.raises(InputError, match="multiple of 8"):
        write_dat(tmp_path / "x.dat", np.zeros((2, 3, 5), bool))
    with pytest.raises(InputError, match="multiple of 8"):
        read_dat(tmp_path / "x.dat", height=3, width=5)
    assert os.listdir(tmp_path) == []


def test_bad_ranges_and_values(tmp_path):
    path = tmp_path / "r.dat"
    write_dat(path, _planes(4, 2, 8))
    for start, stop in [(0, 5), (3, 2), (-1, 2)]:
        with pytest.raises(InputError, match="outside the file's 4 planes"):
            read_dat(path, height=2, width=8, start=start, stop=stop)
    with pytest.raises(InputError, match="raw_width"):
        read_dat(path, height=2, width=8, raw_width=4)
    with pytest.raises(InputError, match="only 0 and 1"):
        write_dat(tmp_path / "bad.dat", np.full((1, 2, 8), 2, np.uint8))
    assert not (tmp_path / "bad.dat").exists()


def test_failure_inside_a_writer_leaves_no_file(tmp_path):
    with pytest.raises(RuntimeError):
        with DatWriter(tmp_path / "w.dat") as w:
            w.write(_planes(3, 4, 8))
            raise RuntimeError("simulation failed midway")
    assert os.listdir(tmp_path) == []


def test_failure_while_packing_leaves_no_file_and_keeps_the_old_one(tmp_path, monkeypatch):
    path = tmp_path / "s.dat"
    path.write_bytes(b"old content")
    real_pack, calls = vidar_dat._pack, []

    def failing_pack(planes):
        calls.append(1)
        if len(calls) == 2:
            raise OSError("disk full")
        return real_pack(planes)

    monkeypatch.setattr(vidar_dat, "_CHUNK_PIXELS", 32)  # one plane per chunk
    monkeypatch.setattr(vidar_dat, "_pack", failing_pack)
    with pytest.raises(OSError, match="disk full"):
        write_dat(path, _planes(5, 4, 8))
    assert path.read_bytes() == b"old content"
    assert sorted(os.listdir(tmp_path)) == ["s.dat"]


def test_a_writer_that_failed_midway_cannot_be_closed_into_a_partial_file(tmp_path, monkeypatch):
    real_pack, calls = vidar_dat._pack, []

    def failing_pack(planes):
        calls.append(1)
        if len(calls) == 3:
            raise OSError("disk full")
        return real_pack(planes)

    monkeypatch.setattr(vidar_dat, "_CHUNK_PIXELS", 32)
    monkeypatch.setattr(vidar_dat, "_pack", failing_pack)
    w = DatWriter(tmp_path / "p.dat")
    with pytest.raises(OSError):
        w.write(_planes(4, 4, 8))  # two planes reach the temporary file, then packing fails
    with pytest.raises(InputError, match="aborted"):
        w.close()
    assert os.listdir(tmp_path) == []


def test_writer_refuses_a_size_change_and_stays_usable(tmp_path):
    first = _planes(2, 4, 8, seed=1)
    w = DatWriter(tmp_path / "w.dat")
    w.write(first)
    with pytest.raises(InputError, match="like the earlier ones"):
        w.write(_planes(1, 8, 4))
    w.close()
    np.testing.assert_array_equal(read_dat(tmp_path / "w.dat", height=4, width=8), first)
    with pytest.raises(InputError, match="closed"):
        w.write(first)
    aborted = DatWriter(tmp_path / "gone.dat")
    aborted.write(first)
    aborted.abort()
    assert sorted(os.listdir(tmp_path)) == ["w.dat"]
