"""Every reader turns every malformed input into a typed error naming the file, or a valid stream.

Seeded mutation loops (:mod:`tests.neuspike.formats.fuzzing`) over files built from valid ones,
plus the inputs that once crashed a reader, kept as files in ``tests/fixtures/readers``.
"""

from __future__ import annotations

import collections
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from neuspike.errors import FormatError, InputError
from neuspike.formats import read_dat, read_events, read_spike_npz
from tests.neuspike.formats.fuzzing import READERS, cases, outcome

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "readers"
HAVE_AEDAT = importlib.util.find_spec("aedat") is not None
#: Cases per reader; AEDAT4 files that pass the in-process checks are decoded in a child process.
CASES = {name: 300 for name in READERS} | {"aedat4": 150}


@pytest.mark.parametrize("name", READERS)
def test_fuzzed_files_give_typed_errors_or_valid_streams(name, tmp_path):
    if name == "aedat4" and not HAVE_AEDAT:
        pytest.skip("the optional aedat package is not installed")
    counts: collections.Counter[str] = collections.Counter()
    failures = []
    for label, file_name, run in cases(name, CASES[name], seed=0, folder=tmp_path):
        verdict = outcome(run, file_name)
        counts["ok" if verdict == "ok" else "typed" if verdict == "typed" else "untyped"] += 1
        if verdict not in ("ok", "typed"):
            failures.append(f"{label}: {verdict}")
    assert not failures, f"{len(failures)} of {CASES[name]} cases: " + "\n".join(failures[:10])
    # the loop must exercise both sides of the contract, or it proves nothing
    assert counts["ok"] > 0 and counts["typed"] > 0, counts


def _fixture_cases():
    index = json.loads((FIXTURES / "index.json").read_text())
    return [pytest.param(entry, id=entry["file"]) for entry in index]


@pytest.mark.parametrize("entry", _fixture_cases())
def test_inputs_that_once_crashed_a_reader_give_a_format_error(entry, tmp_path):
    """Each fixture names the reader, what it once did, and a phrase the error must contain."""
    if entry["reader"] == "aedat4" and not HAVE_AEDAT:
        pytest.skip("the optional aedat package is not installed")
    path = FIXTURES / entry["file"]
    read = {"spike_npz": read_spike_npz, "events": read_events, "aedat4": read_events}[entry["reader"]]
    with pytest.raises(FormatError, match=entry["match"]) as info:
        read(path)
    assert path.name in str(info.value)


def test_read_dat_plane_range_of_the_wrong_type_is_an_input_error(tmp_path):
    path = tmp_path / "s.dat"
    path.write_bytes(bytes(3 * 16))  # three 16x8 planes
    for start, stop in ((float("inf"), None), (None, None), (1.5, None), ("1", None), (True, None), (0, 2.0)):
        with pytest.raises(InputError, match="(start|stop): expected a whole plane index"):
            read_dat(path, height=8, width=16, start=start, stop=stop)
    assert read_dat(path, height=8, width=16, start=np.int64(1), stop=np.uint8(3)).shape == (2, 8, 16)


@pytest.mark.skipif(not HAVE_AEDAT, reason="the optional aedat package is not installed")
def test_a_decoder_crash_is_contained_in_its_child_process():
    """Past the in-process checks, a file that aborts the decoder still gives a FormatError here."""
    from neuspike.formats import event_readers

    path = FIXTURES / "aedat4-abort-171.aedat4"  # once aborted the interpreter ("panic in a destructor")
    with pytest.raises(FormatError, match="not a readable AEDAT4 file"):
        event_readers._aedat4_decode(path, 0)


def test_fuzzed_meta_json_beside_a_recording_gives_typed_errors_or_samples(tmp_path):
    """``meta.json`` values of every wrong type: load_sample raises typed errors, never TypeError."""
    from neuspike.errors import NeuSpikeError
    from neuspike.formats import write_spike_npz
    from neuspike.formats.samples import load_sample
    from neuspike.streams import SpikeStream

    rng = np.random.default_rng(5)
    write_spike_npz(tmp_path / "s.npz", SpikeStream(rng.random((64, 16, 24)) < 0.2, gain=0.25))
    good = {"width": 24, "height": 16, "plane_rate_hz": 20_000.0, "start_s": 0.0, "gain": 0.25, "threshold": 1.0,
            "key_time_s": 0.0016, "mode": "window", "planes": 64, "event_threshold": 0.2}
    odd = (None, "abc", [1, 2], {"a": 1}, -1, 0, 1.5, 1e300, float("nan"), True, "24", 10**30)
    counts: collections.Counter[str] = collections.Counter()
    for _ in range(150):
        meta = dict(good)
        for key in rng.choice(list(good), size=int(rng.integers(1, 4)), replace=False):
            meta[str(key)] = odd[int(rng.integers(len(odd)))]
        text = json.dumps(meta) if rng.random() < 0.9 else json.dumps(meta)[: int(rng.integers(1, 40))]
        (tmp_path / "meta.json").write_text(text)
        try:
            load_sample(spikes=tmp_path / "s.npz")
            counts["ok"] += 1
        except NeuSpikeError as exc:
            assert isinstance(exc, ValueError), f"{type(exc).__name__}: {exc} for {text}"
            counts["typed"] += 1
    assert counts["ok"] and counts["typed"], counts
