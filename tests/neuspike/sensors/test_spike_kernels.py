"""The compiled spike-camera kernel against the NumPy reference path, and the packed-plane layout."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings

from neuspike.errors import InputError
from neuspike.formats.vidar_dat import DatWriter, read_dat, write_dat
from neuspike.sensors import spike_camera
from neuspike.utils.parallel import NUMBA_AVAILABLE, resolve_backend
from neuspike.sensors.spike_camera import PackedPlanes, SpikeCamera, integrate_and_fire, pack_planes
from tests.neuspike.sensors.test_spike_camera import BOTH, reference_loop, scenes

numba = pytest.importorskip("numba") if NUMBA_AVAILABLE else None
needs_numba = pytest.mark.skipif(not NUMBA_AVAILABLE, reason="numba is not importable")


def packed_by_definition(planes: np.ndarray) -> np.ndarray:
    """The .dat layout written out bit by bit: stored row s = image row H-1-s, pixel p -> bit p%8 of byte p//8."""
    t, h, w = planes.shape
    out = np.zeros((t, h * w // 8), np.uint8)
    for s_row in range(h):
        for c in range(w):
            p = s_row * w + c
            out[:, p // 8] |= planes[:, h - 1 - s_row, c].astype(np.uint8) << (p % 8)
    return out


def both_backends(frames, **kw):
    got = integrate_and_fire(frames, backend="numba", **kw)
    ref = integrate_and_fire(frames, backend="numpy", **kw)
    return got, ref


@needs_numba
@settings(max_examples=60, deadline=None)
@given(scenes())
def test_compiled_kernel_equals_numpy_path_bit_for_bit(scene):
    frames, hold, light, threshold, initial, dark = scene
    kw = dict(hold_planes=hold, light=light, threshold=threshold, initial_charge=initial, dark_charge=dark)
    (planes, charge), (ref_planes, ref_charge) = both_backends(frames, **kw)
    np.testing.assert_array_equal(planes, ref_planes)
    assert charge.tobytes() == ref_charge.tobytes()  # bytes: also -0.0 against 0.0
    assert planes.dtype == np.bool_ and planes.flags.c_contiguous


@needs_numba
@pytest.mark.parametrize("band_pixels", [1, 3 * 8, 1 << 20])  # one row, a few rows, the whole sensor
@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("shape", [(16, 8), (13, 24), (6, 4), (8, 3)])  # H x W; the last two pack across rows
def test_bands_threads_and_widths_never_change_the_planes(band_pixels, threads, shape, monkeypatch):
    monkeypatch.setattr(spike_camera, "_KERNEL_BAND_PIXELS", band_pixels)
    rng = np.random.default_rng(5)
    h, w = shape
    frames = rng.random((9, h, w), dtype=np.float32) * 1.3
    initial = rng.normal(size=(h, w)).astype(np.float32)
    dark = rng.random((h, w), dtype=np.float32) * 0.05
    kw = dict(hold_planes=2, light=0.7, threshold=0.9, initial_charge=initial, dark_charge=dark)
    ref, ref_charge = reference_loop(frames, 2, 0.7, 0.9, initial, dark)
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        planes, charge = integrate_and_fire(frames, backend="numba", **kw)
        packed, packed_charge = integrate_and_fire(frames, backend="numba", packed=True, **kw)
    finally:
        numba.set_num_threads(previous)
    np.testing.assert_array_equal(planes, ref)
    np.testing.assert_array_equal(charge, ref_charge)
    np.testing.assert_array_equal(packed.data, packed_by_definition(ref))
    np.testing.assert_array_equal(packed_charge, ref_charge)


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=needs_numba)])
def test_packed_planes_are_the_dat_bytes_and_unpack_back(backend, tmp_path):
    rng = np.random.default_rng(8)
    frames = rng.random((5, 10, 12), dtype=np.float32)
    packed, charge = integrate_and_fire(frames, hold_planes=3, light=0.6, threshold=0.5, packed=True,
                                        backend=backend)
    planes, charge2 = integrate_and_fire(frames, hold_planes=3, light=0.6, threshold=0.5, backend="numpy")
    np.testing.assert_array_equal(charge, charge2)
    assert isinstance(packed, PackedPlanes) and packed.num_planes == 15
    np.testing.assert_array_equal(packed.data, packed_by_definition(planes))
    np.testing.assert_array_equal(packed.unpack(), planes)
    assert packed.count() == int(planes.sum()) == int(spike_camera._BITS_SET[packed.data].sum())
    path = write_dat(tmp_path / "s.dat", planes)  # the format's own writer, an independent packer
    assert path.read_bytes() == packed.data.tobytes()
    np.testing.assert_array_equal(read_dat(path, height=10, width=12), planes)
    np.testing.assert_array_equal(pack_planes(planes).data, packed.data)


def test_dat_writer_takes_packed_planes_as_they_are(tmp_path):
    rng = np.random.default_rng(6)
    cam = SpikeCamera(16, 6, light=0.5, threshold=1.0, rng=None)
    frames = rng.random((7, 6, 16), dtype=np.float32)
    packed, _ = cam.capture_packed(frames[:4], hold_planes=2)
    later = cam.capture(frames[4:], hold_planes=2).planes
    with DatWriter(tmp_path / "mixed.dat") as w:
        w.write_packed(packed.data, height=6, width=16)
        w.write(later)  # packed and bool planes mix in one file
        assert w.planes_written == 14
    expected = np.concatenate([packed.unpack(), later])
    assert (tmp_path / "mixed.dat").read_bytes() == write_dat(tmp_path / "ref.dat", expected).read_bytes()
    with DatWriter(tmp_path / "bad.dat") as w:
        with pytest.raises(InputError, match="packed planes"):
            w.write_packed(packed.data, height=4, width=16)  # wrong plane size
        with pytest.raises(InputError, match="packed planes"):
            w.write_packed(packed.data.astype(np.int16), height=6, width=16)
        w.write_packed(packed.data, height=6, width=16)
        with pytest.raises(InputError, match="like the earlier ones"):
            w.write_packed(np.zeros((1, 12), np.uint8), height=8, width=12)


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=needs_numba)])
def test_packing_needs_a_whole_number_of_bytes(backend):
    with pytest.raises(InputError, match="multiple of 8"):
        integrate_and_fire(np.ones((2, 3, 5), np.float32), hold_planes=1, light=1.0, threshold=1.0,
                           packed=True, backend=backend)
    with pytest.raises(InputError, match="multiple of 8"):
        pack_planes(np.zeros((1, 3, 3), bool))


@needs_numba
def test_cameras_on_both_backends_agree_across_captures_with_every_effect():
    rng = np.random.default_rng(4)
    h, w = 12, 16
    cams = {b: SpikeCamera(w, h, light=0.4, threshold=0.7, effects=BOTH, rng=np.random.default_rng(9), backend=b)
            for b in ("numba", "numpy")}
    packed_cam = SpikeCamera(w, h, light=0.4, threshold=0.7, effects=BOTH, rng=np.random.default_rng(9),
                             backend="numba")
    assert cams["numba"].backend == "numba" and cams["numpy"].backend == "numpy"
    for hold in (1, 4, 2):
        frames = rng.random((5, h, w)) * 2  # float64: converted value by value
        a = cams["numba"].capture(frames, hold_planes=hold)
        b = cams["numpy"].capture(frames, hold_planes=hold)
        p, meta = packed_cam.capture_packed(frames, hold_planes=hold, start_s=0.25)
        np.testing.assert_array_equal(a.planes, b.planes)
        np.testing.assert_array_equal(p.unpack(), b.planes)
        assert meta["spike_count"] == a.meta["spike_count"] == b.meta["spike_count"]
        assert meta["start_s"] == 0.25 and meta["gain"] == pytest.approx(0.4 / 0.7)
        assert a.meta["stages"][-1]["params"]["backend"] == "numba"
        assert b.meta["stages"][-1]["params"]["backend"] == "numpy"
    assert cams["numba"].charge.tobytes() == cams["numpy"].charge.tobytes() == packed_cam.charge.tobytes()


@needs_numba
@pytest.mark.parametrize("packed", [False, True])
@pytest.mark.parametrize("bad, frame, match", [
    (np.nan, 2, r"frames\[2\].*nan"),
    (-0.5, 1, r"frames\[1\].*-0\.5"),
    (np.inf, 1, "overflowed"),
])
def test_invalid_radiance_gives_the_same_error_on_both_backends(packed, bad, frame, match):
    frames = np.full((4, 4, 6), 0.5, np.float32)
    frames[frame, 2, 3] = bad
    if bad != np.inf:
        frames[3, 0, 0] = -1.0  # a later bad frame is not the one reported
    messages = []
    for backend in ("numba", "numpy"):
        with pytest.raises(InputError, match=match) as info:
            integrate_and_fire(frames, hold_planes=2, light=1.0, threshold=1.0, packed=packed, backend=backend)
        messages.append(str(info.value))
    assert messages[0] == messages[1]


@needs_numba
@pytest.mark.parametrize("packed", [False, True])
def test_float64_frames_converted_a_few_at_a_time_give_the_same_planes(packed, monkeypatch):
    monkeypatch.setattr(spike_camera, "_CONVERT_CHUNK_PIXELS", 2 * 6 * 8)  # two frames per chunk
    rng = np.random.default_rng(17)
    frames = rng.random((7, 6, 8)) * 1.7  # float64
    kw = dict(hold_planes=3, light=0.9, threshold=0.8, dark_charge=rng.random((6, 8)) * 0.01, packed=packed)
    (planes, charge), (ref, ref_charge) = both_backends(frames, **kw)
    got, want = (planes.data, ref.data) if packed else (planes, ref)
    np.testing.assert_array_equal(got, want)
    assert charge.tobytes() == ref_charge.tobytes()
    frames[5, 1, 1] = -2.0  # in the third chunk
    with pytest.raises(InputError, match=r"frames\[5\].*-2\.0"):
        integrate_and_fire(frames, backend="numba", **kw)


@needs_numba
def test_negative_zero_and_float64_underflow_are_accepted_like_the_numpy_path():
    frames = np.full((2, 2, 4), 0.25)
    frames[0, 0, 0] = -0.0
    frames[1, 1, 1] = -1e-300  # rounds to -0.0 in float32: radiance 0 after conversion
    (planes, charge), (ref, ref_charge) = both_backends(frames, hold_planes=3, light=1.0, threshold=0.5)
    np.testing.assert_array_equal(planes, ref)
    assert charge.tobytes() == ref_charge.tobytes()


def _planes_in_child(frames, queue):
    stream = SpikeCamera(frames.shape[2], frames.shape[1], light=0.7, rng=None).capture(frames, hold_planes=2)
    queue.put((stream.planes.tobytes(), stream.meta["stages"][-1]["params"]["backend"]))


@needs_numba
@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
def test_a_process_forked_after_the_kernel_ran_still_simulates():
    import multiprocessing

    frames = np.random.default_rng(3).random((6, 8, 16), dtype=np.float32)
    parent = SpikeCamera(16, 8, light=0.7, rng=None).capture(frames, hold_planes=2)  # the kernel runs here
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_planes_in_child, args=(frames, queue))
    child.start()
    planes, backend = queue.get(timeout=60)
    child.join(60)
    import numba

    # GNU OpenMP cannot start in such a child: the NumPy path runs; other layers can: the kernel runs
    expected = "numpy" if numba.threading_layer() == "omp" else "numba"
    assert child.exitcode == 0 and backend == expected
    assert planes == parent.planes.tobytes()


def test_backend_names_are_checked():
    with pytest.raises(InputError, match="backend"):
        resolve_backend("cuda")
    with pytest.raises(InputError, match="backend"):
        integrate_and_fire(np.ones((1, 2, 4), np.float32), hold_planes=1, light=1.0, threshold=1.0, backend="gpu")
    with pytest.raises(InputError, match="backend"):
        SpikeCamera(4, 2, light=1.0, rng=None, backend="fast")
    assert resolve_backend("numpy") == "numpy"
    assert resolve_backend("auto") == ("numba" if NUMBA_AVAILABLE else "numpy")
