"""Every command that takes ``--device`` refuses a device this machine lacks in one line, before any
work, and leaves nothing behind: no output folder, not even an empty one."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bench import dataset, fast_motion, noise, sweep, timing
from bench.harness import grid as grids
from bench import video as video_bench
from bench.harness.datasets import DatasetSpec, run_dataset
from bench.harness.runner import Execution, SweepSpec, run_sweep
from bench.harness.manifest import infer_manifest
from neuspike import reconstruct
from neuspike.errors import InputError
from neuspike.formats.spike_npz import write_spike_npz
from neuspike.streams import SpikeStream
from neuspike.video import cli as video

#: A learned method reading only spikes, so that one small spike file serves every file-reading command.
LEARNED = "neuspike-net-spike"
QUIET = ["--no-report", "--no-progress"]

# (command's main, its arguments before --device and --out; RECORDING stands for a small spike file,
# DATASET for the folder that holds it)
COMMANDS = {
    "bench.sweep": (sweep.main, ["--axis", "light", "--methods", LEARNED, *QUIET]),
    "bench.noise": (noise.main, ["--level", "small", "--methods", LEARNED, *QUIET]),
    "bench.fast_motion": (fast_motion.main, ["--methods", LEARNED, *QUIET]),
    "bench.dataset": (dataset.main, ["DATASET", "--methods", LEARNED, *QUIET]),
    "bench.timing": (timing.main, ["--methods", LEARNED, "--sizes", "32x24", "--results", "none", "--no-report"]),
    "bench.video": (video_bench.main, ["--methods", LEARNED, "--size", "48x32", "--duration", "0.005",
                                       "--no-progress"]),
    "neuspike.reconstruct": (reconstruct.main, ["--method", LEARNED, "--spikes", "RECORDING"]),
    "neuspike.video": (video.main, ["RECORDING", "--method", LEARNED, "--no-progress"]),
}


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A spike file of 300 empty 32x48 planes, alone in its folder (a dataset in the ``files`` layout)."""
    path = tmp_path_factory.mktemp("dataset") / "still.npz"
    write_spike_npz(path, SpikeStream(np.zeros((300, 32, 48), dtype=bool), plane_rate_hz=20_000.0))
    return path


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA device")
@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_missing_cuda_device_is_refused_in_one_line_and_nothing_is_written(command, recording, tmp_path, capsys):
    main, argv = COMMANDS[command]
    argv = [str(recording) if a == "RECORDING" else str(recording.parent) if a == "DATASET" else a for a in argv]
    out = tmp_path / "out" / "run"  # a parent that does not exist either: neither may be created
    code = main([*argv, "--device", "cuda", "--out", str(out)])
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert code != 0
    assert len(errors) == 1 and "'cuda'" in errors[0] and "no CUDA device" in errors[0], errors
    assert not (tmp_path / "out").exists()
    assert sorted(p.name for p in recording.parent.iterdir()) == ["still.npz"]  # nothing beside the input


def _sweep(recording, out, execution):
    g = grids.Grid(scenes=(grids.scene_entry("pan:camera", (32, 24)),), lights=(0.5,), motions=(16,),
                   noises=("none",), seeds=(0,), effects=grids.DEFAULT_EFFECTS)
    run_sweep(SweepSpec(name="id", grid=g, methods=(LEARNED,)), out, execution)


def _dataset(recording, out, execution):
    folder = recording.parent
    spec = DatasetSpec(name="d", root=str(folder), manifest=infer_manifest(folder), methods=(LEARNED,))
    run_dataset(spec, out, execution)


@pytest.mark.parametrize("run", [_sweep, _dataset], ids=["run_sweep", "run_dataset"])
def test_the_harness_creates_its_folder_only_once_the_device_is_accepted(run, recording, tmp_path):
    """The library calls behind the commands: the same refusal, and no folder left behind."""
    missing = f"cuda:{torch.cuda.device_count() + 7}"
    with pytest.raises(InputError, match=f"device: '{missing}' was asked for"):
        run(recording, tmp_path / "out", Execution(device=missing, progress=False, report=False))
    assert not (tmp_path / "out").exists()
