"""NeuSpike-Net in a video: compiled and sliding representations equal the NumPy per-frame reference
exactly, streamed images equal single-frame ones, shifted windows are refused."""

import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.formats.event_writers import write_events_h5
from neuspike.formats.vidar_dat import write_dat
from neuspike.methods import create
from neuspike.nets import representations as reps
from neuspike.nets.sliding import SlidingRepresentation
from neuspike.sample import Sample
from neuspike.streams import EventStream, SpikeStream
from neuspike.video import centred_span, frame_times, open_recording, reconstruct_video, stream_samples

H, W, PLANES, RATE = 24, 32, 900, 20_000.0

pytestmark = pytest.mark.skipif(not reps._kernels_usable(), reason="numba kernels cannot run here")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """900 planes with a left-to-right rate ramp, and events with microsecond stamps (so that many lie
    exactly on plane boundaries, every 50 us) from 10 ms before the first plane."""
    rng = np.random.default_rng(7)
    d = tmp_path_factory.mktemp("sliding")
    rate = np.linspace(0.02, 0.8, W)[None, :] * np.linspace(0.6, 1.0, H)[:, None]
    write_dat(d / "spikes.dat", rng.random((PLANES, H, W)) < rate)
    n = 60_000
    t = np.sort(np.round(rng.uniform(-0.01, PLANES / RATE, n) * 1e6) / 1e6)
    write_events_h5(d / "events.h5", EventStream(t, rng.integers(0, W, n), rng.integers(0, H, n),
                                                 rng.choice(np.array([-1, 1], np.int8), n), W, H))
    return d


def _open(folder, gain=0.5):
    return open_recording(spikes=folder / "spikes.dat", events=folder / "events.h5", height=H, width=W, gain=gain)


def _times(kind):
    every_plane = frame_times(0.0, PLANES / RATE, RATE)
    return {
        "1000 fps (20 planes)": frame_times(0.0, PLANES / RATE, 1000.0),
        "every plane": every_plane[100:400],
        "1250 fps (16 planes)": frame_times(0.0, PLANES / RATE, 1250.0),
        "irregular, with steps back": np.random.default_rng(3).uniform(0.0, PLANES / RATE, 30),
        "far apart (no overlap)": every_plane[::300],
    }[kind]


@pytest.mark.parametrize("kind", ["1000 fps (20 planes)", "every plane", "1250 fps (16 planes)",
                                  "irregular, with steps back", "far apart (no overlap)"])
@pytest.mark.parametrize("spike_kind", reps.SPIKE_REPRESENTATIONS)
def test_sliding_representations_equal_the_per_frame_reference_bit_for_bit(folder, kind, spike_kind):
    sliding = SlidingRepresentation(spike_kind, "contrast")
    modes = []
    with _open(folder) as rec:
        for sample in stream_samples(rec, _times(kind)):
            x_t, x_m = sliding(sample)
            modes.append(sliding.last_mode)
            np.testing.assert_array_equal(x_t, reps.spike_representation(sample, spike_kind, backend="numpy"))
            np.testing.assert_array_equal(x_m, reps.event_representation(sample, "contrast", backend="numpy"))
    assert modes.count("sliding") == len(modes)
    overlapping = kind in ("1000 fps (20 planes)", "every plane", "1250 fps (16 planes)")
    assert sliding.starts == 1 if overlapping else sliding.starts > 1


def test_an_unknown_gain_is_estimated_alike_when_sliding(folder):
    sliding = SlidingRepresentation("counts_interval", None)
    with _open(folder, gain=None) as rec:
        for sample in stream_samples(rec, _times("1000 fps (20 planes)")[:12]):
            x_t, x_m = sliding(sample)
            assert x_m is None
            np.testing.assert_array_equal(x_t, reps.spike_representation(sample, "counts_interval", backend="numpy"))


def test_events_on_a_bin_boundary_go_where_the_per_frame_formula_puts_them():
    """An event at the exact time of the boundary between bins 3 and 4 (and one a rounding step
    before it) in a window of 256 planes: the sliding bins agree with int((t - t0) / span * 32)."""
    rate, t_len = RATE, 256
    start = 0.123
    boundary = start + 4 * 8 / rate
    times = np.array([np.nextafter(boundary, -1.0), boundary, np.nextafter(boundary, 2.0)])
    ev = EventStream(times, np.array([1, 2, 3]), np.array([0, 0, 0]), np.array([1, 1, -1], np.int8), W, H)
    planes = np.zeros((t_len, H, W), bool)
    sample = Sample(height=H, width=W, key_time_s=start + t_len / 2 / rate, window_start_s=start,
                    window_end_s=start + t_len / rate,
                    spikes=SpikeStream(planes, plane_rate_hz=rate, start_s=start, gain=0.5),
                    events=ev, event_threshold=0.2, meta={"window_planes_in_file": [1000, 1000 + t_len]})
    x_t, x_m = SlidingRepresentation("counts", "contrast")(sample)
    np.testing.assert_array_equal(x_m, reps.event_representation(sample, "contrast", backend="numpy"))


@pytest.mark.parametrize("spike_kind", reps.SPIKE_REPRESENTATIONS)
def test_compiled_window_kernels_equal_the_numpy_reference(folder, spike_kind):
    with _open(folder, gain=None) as rec:
        for sample in stream_samples(rec, _times("far apart (no overlap)")):
            np.testing.assert_array_equal(reps.spike_representation(sample, spike_kind),
                                          reps.spike_representation(sample, spike_kind, backend="numpy"))
            np.testing.assert_array_equal(reps.event_representation(sample, "contrast"),
                                          reps.event_representation(sample, "contrast", backend="numpy"))


@pytest.mark.parametrize("name", ["neuspike-net", "neuspike-net-spike"])
def test_streamed_images_equal_single_frame_reconstructions(folder, name, one_torch_thread):
    method = create(name)
    with _open(folder) as rec:
        lo, hi = centred_span(rec)
        times = frame_times(lo, lo + 0.004, 1000.0)
        streamed = list(reconstruct_video(method, rec, times))
        single = create(name)
        for sample, (t, image) in zip(stream_samples(rec, times), streamed):
            assert t == sample.key_time_s
            np.testing.assert_array_equal(image, single.reconstruct(sample))
    # one start from a whole window, then every frame from the bins shared with the previous ones
    assert method._sliding.last_mode == "sliding" and method._sliding.starts == 1
    method.reset()  # a new sequence starts the bins afresh
    with _open(folder) as rec:
        list(reconstruct_video(method, rec, times[:2]))
    assert method._sliding.starts == 2


def test_a_window_shifted_at_the_recording_end_is_refused(folder, one_torch_thread):
    method = create("neuspike-net-spike")
    with _open(folder) as rec:
        lo, hi = centred_span(rec)
        assert lo == pytest.approx(128 / RATE) and hi == pytest.approx((PLANES - 128 + 1) / RATE)
        inside, outside = next(stream_samples(rec, [lo + 0.5 / RATE])), next(stream_samples(rec, [lo - 3.5 / RATE]))
        method.reconstruct(inside)
        with pytest.raises(InputError, match="refused"):
            method.reconstruct(outside)


def test_streamed_images_with_key_estimates_equal_single_frame_ones(folder, one_torch_thread):
    """The key estimates are computed from each frame's window in a video too: a network whose
    refinement is not zero streams the images it gives frame by frame."""
    import torch

    from neuspike.nets import DEFAULT_DESIGN, NeuSpikeNetMethod

    design = {**DEFAULT_DESIGN, "spike_only": True, "head": "support-count", "key_estimates": "isi-sequence"}
    methods = [NeuSpikeNetMethod("neuspike-net-spike", precision="float32", **design) for _ in range(2)]
    torch.manual_seed(3)
    with torch.no_grad():
        methods[0].module.key_refine.out.weight.normal_(0, 0.2)
        methods[0].module.key_refine.out.bias.fill_(0.3)
    methods[1].module.load_state_dict(methods[0].module.state_dict())
    for m in methods:
        m.module.eval()
    with _open(folder) as rec:
        lo, _ = centred_span(rec)
        times = frame_times(lo, lo + 0.003, 1000.0)
        streamed = list(reconstruct_video(methods[0], rec, times))
        for sample, (_, image) in zip(stream_samples(rec, times), streamed):
            np.testing.assert_array_equal(image, methods[1].reconstruct(sample))
    assert methods[0]._sliding.last_mode == "sliding"
