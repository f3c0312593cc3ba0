"""One path from a file to a sample: ``reconstruct`` and ``video`` refuse the same bad files, for the same cause.

Each case is a file that one of the two commands once accepted wrongly (polarities 0/0.5 read as
all-negative, an x of 3.5 cut to 3, a plane rate of 0 replaced by 20 kHz) or refused for the wrong
cause (unsorted timestamps reported as an empty time range, a missing field as a bare ValueError, a
2-D timestamp array as a TypeError traceback). Both commands now answer with one line naming the
cause, exit 2, and write nothing.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from neuspike.errors import FormatError
from neuspike.formats.vidar_dat import write_dat
from neuspike.formats.samples import load_sample, open_recording, stream_samples
from neuspike.reconstruct import main as reconstruct_main
from neuspike.video.cli import main as video_main

H, W = 24, 32
N = 40


def _common_h5(path, *, t=None, x=None, p=None):
    t = np.linspace(0.0, 0.01, N) if t is None else t
    x = np.arange(N) % W if x is None else x
    p = np.where(np.arange(N) % 2, 1, -1) if p is None else p
    with h5py.File(path, "w") as f:
        f.attrs["sensor_resolution"] = (H, W)
        g = f.create_group("events")
        g["ts"], g["xs"], g["ys"], g["ps"] = t, x, np.arange(N) % H, p
    return path


def _pku_h5(path, *, stamps_us, fields=("timestamp", "x", "y", "polarity")):
    types = {"timestamp": "<i8", "x": "<u2", "y": "<u2", "polarity": "u1"}
    rec = np.zeros(len(stamps_us), dtype=[(k, types[k]) for k in fields])
    rec["timestamp"] = stamps_us
    for k in fields:
        if k in ("x", "y"):
            rec[k] = np.arange(len(stamps_us)) % 10
        elif k == "polarity":
            rec[k] = np.arange(len(stamps_us)) % 2
    with h5py.File(path, "w") as f:
        f["events"] = rec
    return path


def _polarity_half(tmp_path):
    return _common_h5(tmp_path / "e.h5", p=np.where(np.arange(N) % 2, 0.5, 0.0))


def _x_fraction(tmp_path):
    x = (np.arange(N) % W).astype(np.float64)
    x[5] = 3.5
    return _common_h5(tmp_path / "e.h5", x=x)


def _two_column_times(tmp_path):
    path = tmp_path / "e.h5"
    with h5py.File(path, "w") as f:
        f.attrs["sensor_resolution"] = (H, W)
        g = f.create_group("events")
        g["ts"] = np.stack([np.linspace(0, 0.01, N)] * 2, axis=1)
        g["xs"], g["ys"], g["ps"] = np.arange(N) % W, np.arange(N) % H, np.ones(N)
    return path


def _pku_reversed(tmp_path):
    return _pku_h5(tmp_path / "e.h5", stamps_us=np.arange(N)[::-1] * 100 + 1000)


def _pku_unsorted_inside(tmp_path):
    stamps = np.arange(N) * 100 + 1000
    stamps[10], stamps[11] = stamps[11], stamps[10]
    return _pku_h5(tmp_path / "e.h5", stamps_us=stamps)


def _pku_without_y(tmp_path):
    return _pku_h5(tmp_path / "e.h5", stamps_us=np.arange(N) * 100, fields=("timestamp", "x", "polarity"))


EVENT_CASES = {
    "polarities 0 and 0.5": (_polarity_half, r"polarity 0\.5; expected values in \[0, 1\]"),
    "an x of 3.5": (_x_fraction, r"non-integer x coordinate 3\.5"),
    "N x 2 timestamps": (_two_column_times, r"1-D arrays of one length.*ts \(40, 2\)"),
    "PKU timestamps in reverse": (_pku_reversed, r"timestamps are not sorted"),
    "PKU timestamps unsorted inside": (_pku_unsorted_inside, r"timestamps must not decrease; event 11"),
    "PKU without a y field": (_pku_without_y, r"lacks field\(s\) \['y'\]"),
}


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("case", list(EVENT_CASES))
def test_both_commands_refuse_a_bad_event_file_for_its_cause(tmp_path, capsys, case):
    import re

    make, cause = EVENT_CASES[case]
    path = make(tmp_path)
    with pytest.raises(FormatError, match=cause):
        load_sample(events=path, at_s=0.0015)
    rc = reconstruct_main(["--method", "events-integrate", "--events", str(path), "--out", str(tmp_path / "r")])
    assert rc == 2 and re.search(cause, _one_error_line(capsys))
    rc = video_main(["--method", "events-integrate", "--events", str(path), "--out", str(tmp_path / "v"),
                     "--fps", "2000", "--no-progress"])
    assert rc == 2 and re.search(cause, _one_error_line(capsys))
    assert not (tmp_path / "r").exists() and not (tmp_path / "v").exists()


def test_a_range_read_gives_the_whole_reads_events(tmp_path):
    """A good HDF5 file read by range (the stream) equals its whole read (event_readers), 0/1 polarities included."""
    from neuspike.formats.event_readers import read_events

    path = _common_h5(tmp_path / "e.h5", p=np.arange(N) % 2)
    whole = read_events(path)
    with open_recording(events=path) as rec:
        cut = next(stream_samples(rec, [0.005], window_planes=400, event_history_s=1.0)).events  # [-0.005, 0.015)
    assert np.array_equal(cut.p, whole.p) and np.array_equal(cut.t_s, whole.t_s) and set(cut.p.tolist()) == {-1, 1}


@pytest.mark.parametrize("rate", [0, -5, "fast", True])
def test_a_plane_rate_in_meta_json_that_is_not_positive_is_refused(tmp_path, capsys, rate):
    planes = np.zeros((64, H, W), dtype=bool)
    write_dat(tmp_path / "spikes.dat", planes)
    (tmp_path / "meta.json").write_text(json.dumps({"width": W, "height": H, "plane_rate_hz": rate}))
    cause = f"meta.json: plane_rate_hz must be a positive number, got {rate!r}"
    with pytest.raises(FormatError, match=cause.replace("(", r"\(").replace(")", r"\)")):
        load_sample(spikes=tmp_path / "spikes.dat")
    assert reconstruct_main(["--method", "tfp", "--spikes", str(tmp_path / "spikes.dat"),
                             "--out", str(tmp_path / "r")]) == 2
    assert cause in _one_error_line(capsys)
    assert video_main([str(tmp_path), "--method", "tfp", "--out", str(tmp_path / "v"), "--no-progress"]) == 2
    assert cause in _one_error_line(capsys)


@pytest.mark.parametrize("methods, cause", [
    ("tfp", r"device 'cuda:7': none of the methods \(tfp\) runs on a torch device"),
    ("tfp,e2vid", r"device: 'cuda:7' was asked for but this machine has"),
])
def test_both_commands_refuse_a_device_they_cannot_use_before_any_work(tmp_path, capsys, methods, cause):
    import re

    import torch

    if torch.cuda.device_count() > 7:
        pytest.skip("this machine has a cuda:7")
    write_dat(tmp_path / "spikes.dat", np.zeros((64, H, W), dtype=bool))
    events = _common_h5(tmp_path / "e.h5")
    inputs = ["--spikes", str(tmp_path / "spikes.dat"), "--events", str(events), "--height", str(H), "--width", str(W)]
    rc = reconstruct_main(["--method", methods, *inputs, "--device", "cuda:7", "--out", str(tmp_path / "r")])
    assert rc == 2 and re.search(cause, _one_error_line(capsys))
    rc = video_main(["--method", methods, *inputs, "--device", "cuda:7", "--out", str(tmp_path / "v"), "--no-progress"])
    assert rc == 2 and re.search(cause, _one_error_line(capsys))
    assert not (tmp_path / "r").exists() and not (tmp_path / "v").exists()
