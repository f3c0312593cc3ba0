"""The dark level: recorded by every simulation that runs a dark-current stage, subtracted by every
method that counts a level, estimated from the data where it is unknown (and said so)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from neuspike.conditions import effect
from neuspike.methods import create
from neuspike.methods.normalisation import (DARK_RATE_CAP, dark_level, estimate_dark_rate, rate_to_image,
                                            stream_rate_to_image)
from neuspike.nets.method import count_level
from neuspike.sample import Sample
from neuspike.sensors.spike_camera import SpikeCamera
from neuspike.streams import SpikeStream

H, W, T = 32, 48, 4096
LIGHT = 1 / 16


def half_black(value: float = 0.5) -> np.ndarray:
    """Radiance 0 on the left half, ``value`` on the right half, (H, W)."""
    frame = np.zeros((H, W), np.float32)
    frame[:, W // 2:] = value
    return frame


def capture(frame: np.ndarray, *, dark: bool, seed: int = 3, planes: int = T) -> SpikeStream:
    effects = (effect("initial_charge"),) + ((effect("dark_current", isi_std_planes=10.0),) if dark else ())
    cam = SpikeCamera(W, H, light=LIGHT, effects=effects, rng=np.random.default_rng(seed))
    return cam.capture(frame[None], hold_planes=planes)


def sample_of(stream: SpikeStream, frame: np.ndarray) -> Sample:
    end_s = stream.num_planes / stream.plane_rate_hz
    return Sample(spikes=stream, events=None, height=H, width=W, key_time_s=end_s / 2, window_start_s=0.0,
                  window_end_s=end_s, ground_truth=frame)


def test_the_camera_states_the_mean_rate_of_its_dark_current():
    """Darkness alone: the spikes counted per plane and pixel are the camera's stated dark rate (the
    charge integrates d per plane, so T planes hold d T spikes less at most one per pixel)."""
    stream = capture(np.zeros((H, W), np.float32), dark=True)
    assert stream.dark_rate == pytest.approx(1 / 180, rel=0.05)  # the Vidar's measured one spike per 180 planes
    counted = stream.planes.sum() / stream.planes.size
    assert counted == pytest.approx(stream.dark_rate, abs=1.0 / T)
    assert capture(np.zeros((H, W), np.float32), dark=False).dark_rate == 0.0  # known to be none


def test_counting_methods_subtract_the_known_dark_rate():
    """TFP over a long window of a half-black frame: the black half reads 0 and the lit half its
    radiance once the dark rate comes off; without it the black half would read d / gain (0.09)."""
    frame = half_black()
    stream = capture(frame, dark=True)
    d = stream.dark_rate
    assert d / stream.gain > 0.08  # the error the subtraction removes
    image = create("tfp").reconstruct(sample_of(stream, frame))
    assert abs(float(image[:, : W // 2].mean())) < 0.01
    assert float(image[:, W // 2:].mean()) == pytest.approx(0.5, abs=0.01)
    method = create("tfp")
    method.reconstruct(sample_of(stream, frame))
    assert method.last_normalisation == "gain, dark rate subtracted"
    clean = create("tfp")
    clean.reconstruct(sample_of(capture(frame, dark=False), frame))
    assert clean.last_normalisation == "gain"  # a known zero rate changes nothing, label included


@pytest.mark.parametrize("name", ["tfi", "snm", "tfstp"])
def test_every_spike_method_takes_the_dark_rate_off(name):
    """The other counting methods: on the lit half (nothing clipped) the image moves down by exactly
    the dark rate's radiance d / gain, towards the truth; the black half can only move down."""
    frame = half_black()
    stream = capture(frame, dark=True, planes=256)
    known = create(name).reconstruct(sample_of(stream, frame))
    ignored = SpikeStream(stream.planes, gain=stream.gain, dark_rate=0.0)
    as_light = create(name).reconstruct(sample_of(ignored, frame))
    lit = (slice(None), slice(W // 2 + 4, None))
    unclipped = (as_light[lit] < 1) & (known[lit] > 0)
    shift = (as_light[lit] - known[lit])[unclipped]
    np.testing.assert_allclose(shift, stream.dark_rate / stream.gain, rtol=1e-4)
    assert abs(float(known[lit].mean()) - 0.5) < abs(float(as_light[lit].mean()) - 0.5)
    assert (known[:, : W // 2] <= as_light[:, : W // 2]).all()


def test_an_unknown_dark_rate_is_estimated_from_the_black_in_view():
    frame = half_black()
    stream = capture(frame, dark=True, planes=1024)
    estimate = estimate_dark_rate(stream.planes)
    assert estimate == pytest.approx(stream.dark_rate, rel=0.25)
    unknown = SpikeStream(stream.planes, gain=stream.gain)  # as a bare .dat with a gain given
    rate, how = dark_level(unknown)
    assert (rate, how) == (estimate, "estimated")
    counts = np.count_nonzero(stream.planes, axis=0)  # the counts a caller has already: the same estimate
    assert dark_level(unknown, counts) == (estimate, "estimated")
    with pytest.raises(ValueError, match="counts: expected shape"):
        estimate_dark_rate(stream.planes, counts=counts[1:])
    image, label = stream_rate_to_image(unknown.planes.mean(axis=0), unknown)
    assert label == "gain, dark rate estimated"
    assert abs(float(image[:, : W // 2].mean())) < 0.03
    # the network's counted level uses the same estimate, and says so
    level = count_level(sample_of(unknown, frame))
    assert level == pytest.approx(float(frame.mean()), abs=0.02)


def test_the_estimate_is_capped_where_the_view_holds_no_black():
    """A uniformly lit view: its darkest blocks are light, not darkness; the estimate stops at the cap."""
    stream = capture(np.full((H, W), 0.5, np.float32), dark=False, planes=512)
    assert estimate_dark_rate(stream.planes) == DARK_RATE_CAP
    assert estimate_dark_rate(np.zeros((8, 4, 4), bool)) == 0.0  # all dark, no spike


def test_rate_to_image_refuses_a_meaningless_dark_rate():
    with pytest.raises(ValueError, match="dark_rate"):
        rate_to_image(np.zeros((2, 2)), 0.5, dark_rate=-0.1)
    with pytest.raises(ValueError, match="dark_rate"):
        rate_to_image(np.zeros((2, 2)), 0.5, dark_rate=float("nan"))


def test_a_simulated_window_records_its_dark_rate_and_files_carry_it(tmp_path):
    """``neuspike.simulate`` writes the dark rate into meta.json (0 without noise), and a recording
    opened from the folder hands it to the methods, so a file-based reconstruction subtracts it."""
    from neuspike.formats.samples import load_sample
    from neuspike.simulate import main

    noisy, clean = tmp_path / "noisy", tmp_path / "clean"
    assert main(["--size", "48x32", "--light", "1/32", "--noise", "small", "--modalities", "spikes",
                 "--out", str(noisy), "--seed", "1"]) == 0
    assert main(["--size", "48x32", "--light", "1/32", "--modalities", "spikes", "--out", str(clean)]) == 0
    meta = json.loads((noisy / "meta.json").read_text())
    assert meta["dark_rate"] == pytest.approx(1 / 180, rel=0.1)
    assert json.loads((clean / "meta.json").read_text())["dark_rate"] == 0.0
    sample = load_sample(spikes=noisy / "spikes.dat")
    assert sample.spikes.dark_rate == pytest.approx(meta["dark_rate"])
    # and how its sensor started (Algorithm 1's random charge), which the counted level's model needs
    from neuspike.methods.counting import initial_state

    assert initial_state(sample.spikes) == "normal"


def test_spike_counts_are_count_nonzero_for_every_plane_dtype(rng):
    """spike_counts (the byte sum the counted level and the dark estimate share) is np.count_nonzero over the
    planes for bool planes, 0/1 bytes, other byte values and wider integers, and keeps its counts past 255."""
    from neuspike.methods.normalisation import spike_counts

    planes = rng.random((300, 5, 7)) < 0.4
    planes[:, 0, 0] = True  # 300 spikes: past a byte
    want = np.count_nonzero(planes, axis=0)
    for given in (planes, planes.view(np.uint8), planes.astype(np.uint8) * 3, planes.astype(np.int32)):
        got = spike_counts(given)
        assert got.shape == (5, 7) and np.array_equal(got, want), given.dtype
    assert int(spike_counts(planes)[0, 0]) == 300
