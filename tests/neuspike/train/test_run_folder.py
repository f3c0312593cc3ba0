"""The run folder across kills and trainers: old spec files and checkpoints resume, stale temporaries
go, the log never repeats a step, a file size limit is a one-line error, the command answers fast."""

from __future__ import annotations

from neuspike.train.checkpoint import read_checkpoint_file

import csv
import dataclasses
import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from neuspike.errors import FormatError, InputError
from neuspike.train import checkpoint as ck
from neuspike.train.__main__ import build_parser, main, spec_from_args
from neuspike.train.loop import Trainer, train
from neuspike.train.spec import NOISE_LEVELS, SequenceData, TrainSpec, WindowData, spec_from_dict

ROOT = Path(__file__).resolve().parents[3]
pytestmark = pytest.mark.usefixtures("one_torch_thread")

PHOTOS = ["astronaut", "brick", "cat", "cell", "coffee", "grass", "hubble_deep_field", "immunohistochemistry", "page",
          "rocket"]
# spec.json as the sequence trainer (python -m neuspike.train.sequences e2vid --train-items 166 --threads 1) wrote it
OLD_E2VID = {"batch": 4, "checkpoint_every": 10, "crop": 48, "data": {
    "displacement_px": 8.0, "events_per_pixel": 0.35, "hdr_fraction": 0.5, "kinds": ["pan", "zoom", "fan"],
    "noise_levels": ["none", "small", "medium", "high"], "photos": PHOTOS, "size": 128, "threshold_range": [0.1, 0.4],
    "view": None, "windows": 8}, "init_from": None, "l1": 1.0, "length": 6, "lr": 0.0005, "lr_min": None,
    "lr_warmup_steps": 50, "method": "e2vid", "occlusion_alpha": 50.0, "precision": "auto", "seed": 0, "ssim": 1.0,
    "steps": 4000, "temporal": 1.0, "train_items": 166, "val_every": 50, "val_items": 8, "warmup": 2}
# spec.json as the single-window trainer wrote it for the README's first NeuSpike-Net stage
OLD_NSN = {"batch": 8, "checkpoint_every": 100, "crop": 64, "export": True, "init_from": None,
           "light_range": [0.025, 0.6], "lr": 0.001, "lr_min": 1e-05, "method": "neuspike-net",
           "motions": [16, 32, 64, 128, 256], "noise_levels": ["none", "small", "medium", "high"],
           "out_dir": "runs/neuspike-net", "params": {}, "photos": PHOTOS, "precision": "auto", "seed": 0,
           "shard_dir": "runs/shard", "shard_size": 2000, "spike_only_fraction": 0.3, "ssim_weight": 1.0,
           "ssim_window": 11, "steps": 1600, "threads": 1, "val_every": 200, "val_size": 32, "view": 128,
           "warmup": 100, "weight_decay": 0.0001, "workers": 2}


def _args(line: str):
    return spec_from_args(build_parser().parse_args(line.split()))


def test_the_light_spec_module_agrees_with_the_heavy_ones():
    from neuspike.conditions import NOISE_LEVELS as levels
    from neuspike.scenes.photos import TRAIN_PHOTOS

    assert tuple(NOISE_LEVELS) == tuple(levels) and WindowData().photos == tuple(TRAIN_PHOTOS) == tuple(PHOTOS)


def test_range_flags_set_the_window_ranges_and_refuse_anything_but_two_numbers():
    spec = _args("neuspike-net --speed-range 100,20000 --scale-range 0.5,1.5")
    assert spec.data.speed_range == (100.0, 20000.0) and spec.data.scale_range == (0.5, 1.5)
    assert _args("neuspike-net").data.scale_range is None
    for flag, bad in (("--speed-range", "1,x"), ("--scale-range", "1"), ("--scale-range", "1,2,3")):
        with pytest.raises(InputError, match=flag):
            _args(f"neuspike-net {flag} {bad}")


def test_specs_of_the_earlier_trainers_are_refused_by_name_and_the_current_form_round_trips(tmp_path):
    """The earlier single-window and sequence trainers' spec files served only runs that left the tree; they are
    refused naming the commit that still reads them. The current form (what a run folder and a card hold)
    round-trips, and unknown keys are refused."""
    for old in (OLD_E2VID, OLD_NSN):
        with pytest.raises(InputError, match="earlier trainer.*61a150f8"):
            spec_from_dict(old, out_dir="runs/x")
    current = _tiny_sequences(tmp_path, "run")
    assert spec_from_dict(json.loads(json.dumps(current.as_dict()))) == current
    without_folder = {k: v for k, v in current.as_dict().items() if k != "out_dir"}
    assert spec_from_dict(without_folder, out_dir="runs/y").out_dir == "runs/y"
    with pytest.raises(InputError, match="unknown spec keys"):
        spec_from_dict({**current.as_dict(), "colour": 1})


def test_the_shipped_cards_specs_read_as_specs_of_this_trainer():
    """The specs inside the shipped weights' cards are runs of this trainer (the current form); a spike-only
    file is exported by a run of the fusion network or trained as the spike-only network itself."""
    from neuspike.methods.weights import PACKAGE_WEIGHTS

    kinds = {}
    for card in sorted(PACKAGE_WEIGHTS.glob("*.json")):
        data = json.loads(card.read_text())
        raw = data["spec"] if "spec" in data else data["training"]["spec"]
        spec = spec_from_dict(raw, where=card.name, out_dir="runs/x")
        assert spec.method in (data["method"], data["method"].removesuffix("-spike"))
        kinds[card.stem] = spec.kind
    assert kinds == {"e2vid": "sequences", "firenet-sim": "sequences", "neuspike-net": "windows",
                     "neuspike-net-spike": "windows"}


def _tiny_windows(tmp_path, out: str) -> TrainSpec:
    data = WindowData(shard_dir=str(tmp_path / "shard"), view=16, train_items=3, val_items=2, workers=1)
    return TrainSpec(data=data, out_dir=str(tmp_path / out), steps=4, batch=2, crop=16, val_every=2,
                     checkpoint_every=2, warmup=2, precision="float32", threads=1)


def _tiny_sequences(tmp_path, out: str) -> TrainSpec:
    data = SequenceData(size=32, windows=3, kinds=("pan",), noise_levels=("none",), displacement_px=6.0,
                        train_items=2, val_items=1, length=3, warmup_windows=1, shard_root=str(tmp_path / "shards"))
    return TrainSpec(method="firenet-sim", data=data, out_dir=str(tmp_path / out), crop=24, batch=2,
                     optimizer="adam", weight_decay=0.0, lr=2e-4, lr_min=None, warmup=1, steps=4, val_every=2,
                     checkpoint_every=1, precision="float32", threads=None)


def _old_window_folder(spec: TrainSpec) -> None:
    """Turn a run folder killed after step 2 into what the single-window trainer left."""
    out = Path(spec.out_dir)
    state = read_checkpoint_file(out / "checkpoint.pt")
    old = {"step": state["step"], "model": state["module"], "optim": state["optimizer"],
           "best": {v: b["val_psnr"] for v, b in state["best"].items()}, "torch_rng": state["torch_rng"]}
    buf = io.BytesIO()
    torch.save(old, buf)
    (out / "checkpoint.pt").write_bytes(buf.getvalue())
    d = spec.data
    flat = {**{k: v for k, v in spec.as_dict().items() if k not in ("data", "optimizer", "export_dir")},
            "shard_dir": d.shard_dir, "view": d.view, "shard_size": d.train_items, "val_size": d.val_items,
            "light_range": list(d.light_range), "motions": list(d.motions), "noise_levels": list(d.noise_levels),
            "photos": list(d.photos), "workers": d.workers, "ssim_weight": d.losses["ssim"]["weight"],
            "ssim_window": d.losses["ssim"]["window"], "spike_only_fraction": d.spike_only_fraction}
    (out / "spec.json").write_text(json.dumps(flat))
    rows = list(csv.DictReader(open(out / "train_log.csv")))
    old_cols = ("step", "kind", "loss", "l1", "ssim_loss", "lr", "seconds", "samples_per_s", "val_l1", "val_psnr",
                "val_ssim", "variant")
    with open(out / "train_log.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=old_cols)
        w.writeheader()
        w.writerows({k: r[k] for k in old_cols} for r in rows)
        w.writerow({"step": 3, "kind": "train", "loss": 9.0, "variant": "fusion"})  # logged, then killed


def _old_sequence_folder(spec: TrainSpec) -> None:
    """Turn a run folder killed after step 2 into what the sequence trainer left."""
    out = Path(spec.out_dir)
    state = read_checkpoint_file(out / "checkpoint.pt")
    best = state["best"].get("main", {"val_ssim": -1.0})
    old = {"module": state["module"], "optimizer": state["optimizer"], "step": state["step"], "best": best,
           "wall_s": state["wall_s"]}
    buf = io.BytesIO()
    torch.save(old, buf)
    (out / "checkpoint.pt").write_bytes(buf.getvalue())
    d = spec.data
    data = {k: v for k, v in dataclasses.asdict(d).items() if k in SequenceData.KEY_FIELDS}
    seq = {"method": spec.method, "data": data, "seed": spec.seed, "train_items": d.train_items,
           "val_items": d.val_items, "crop": spec.crop, "batch": spec.batch, "length": d.length,
           "warmup": d.warmup_windows, "lr": spec.lr, "lr_warmup_steps": spec.warmup, "lr_min": spec.lr_min,
           "l1": d.losses["l1"]["weight"], "ssim": d.losses["ssim"]["weight"],
           "temporal": d.losses["temporal"]["weight"], "occlusion_alpha": d.losses["temporal"]["occlusion_alpha"],
           "steps": spec.steps, "val_every": spec.val_every, "checkpoint_every": spec.checkpoint_every,
           "precision": spec.precision, "init_from": spec.init_from}
    (out / "spec.json").write_text(json.dumps(seq))
    rows = list(csv.DictReader(open(out / "train_log.csv")))
    cols = ["step", "loss", "l1", "ssim_loss", "temporal", "lr", "seconds_per_step", "wall_s", "val_l1", "val_ssim",
            "val_ssim_last"]
    merged: dict[str, dict] = {}
    for r in rows:  # the sequence trainer wrote a validation's scores into its step's row
        if r["kind"] == "train":
            merged[r["step"]] = {**{k: r.get(k, "") for k in cols}, "seconds_per_step": r["seconds"]}
        else:
            merged[r["step"]].update({k: r[k] for k in ("val_l1", "val_ssim", "val_ssim_last")})
    with open(out / "train_log.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(merged.values())
        w.writerow({"step": 3, "loss": 9.0})  # logged, then killed before the checkpoint


@pytest.mark.parametrize("make", [_tiny_windows, _tiny_sequences])
def test_a_killed_run_resumes_to_the_straight_runs_weights(tmp_path, make):
    """Kill after step 2 (in-process), add the temporaries a kill mid-write leaves and a log row past the
    checkpoint; the rerun ends with the straight run's weights, no temporaries and a log without repeated steps."""
    straight = train(make(tmp_path, "a"), quiet=True)
    spec = make(tmp_path, "b")
    assert train(spec, quiet=True, until=2)["step"] == 2
    out = Path(spec.out_dir)
    with open(out / "train_log.csv", "a", newline="") as f:  # logged, then killed before the checkpoint
        csv.writer(f).writerow(["3", "train", "fusion", "9.0"])
    stale = [out / ".checkpoint.pt.x1y2.tmp", out / ".spec.json.z3w4.tmp", out / ".train_log.csv.q5.tmp"]
    for p in stale:
        p.write_bytes(b"half-written")
    again = train(spec, quiet=True)
    assert again["resumed"] and again["step"] == straight["step"] == 4
    a = read_checkpoint_file(tmp_path / "a" / "checkpoint.pt")
    b = read_checkpoint_file(out / "checkpoint.pt")
    assert b["format"] == ck.CHECKPOINT_FORMAT
    for k in a["module"]:
        assert torch.equal(a["module"][k], b["module"][k]), k
    assert not [p for p in stale if p.exists()] and not list(out.glob(".*.tmp"))
    rows = list(csv.DictReader(open(out / "train_log.csv")))
    train_steps = [int(r["step"]) for r in rows if r["kind"] == "train"]
    assert train_steps == [1, 2, 3, 4]
    assert "9.0" not in {r["loss"] for r in rows}


@pytest.mark.parametrize("make,old", [(_tiny_windows, _old_window_folder), (_tiny_sequences, _old_sequence_folder)])
def test_a_folder_of_an_earlier_trainer_is_refused_naming_where_it_resumes(tmp_path, make, old):
    spec = make(tmp_path, "b")
    assert train(spec, quiet=True, until=2)["step"] == 2
    old(spec)
    with pytest.raises(InputError, match="earlier trainer.*61a150f8"):  # its spec.json
        train(spec, quiet=True)
    (Path(spec.out_dir) / "spec.json").write_text(json.dumps(spec.as_dict()))  # a current spec, the old checkpoint
    with pytest.raises(FormatError, match="earlier trainer.*61a150f8"):
        train(spec, quiet=True)


def test_temporaries_of_a_shared_folder_go_only_when_long_dead(tmp_path):
    dead, live, kept = tmp_path / ".000001.npz.ab.tmp", tmp_path / ".000002.npz.cd.tmp", tmp_path / "000000.npz"
    for p in (dead, live, kept):
        p.write_bytes(b"x")
    os.utime(dead, (time.time() - 3600, time.time() - 3600))
    assert ck.remove_temporaries(tmp_path, older_than_s=600) == [dead]
    assert live.exists() and kept.exists() and not dead.exists()
    assert ck.remove_temporaries(tmp_path) == [live] and kept.exists()


def test_an_unknown_checkpoint_is_a_format_error(tmp_path):
    with pytest.raises(FormatError, match="not a training checkpoint"):
        ck.checked_checkpoint({"weights": 1})
    (tmp_path / "checkpoint.pt").write_bytes(b"not torch")
    with pytest.raises(FormatError, match="checkpoint"):
        ck.load_checkpoint(tmp_path)


def test_a_method_of_the_wrong_data_kind_is_refused(tmp_path):
    spec = dataclasses.replace(_tiny_sequences(tmp_path, "x"), method="neuspike-net")
    with pytest.raises(InputError, match="trains on windows"):
        Trainer(spec, quiet=True)


def _run(code: str, **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=kw.get("cwd"),
                          timeout=600)


def test_help_and_usage_errors_answer_before_torch_is_imported(capsys):
    probe = _run("import sys\nfrom neuspike.train.__main__ import build_parser\n"
                 "build_parser().parse_args(['e2vid', '--steps', '3'])\nprint('torch' in sys.modules)")
    assert probe.stdout.strip() == "False", probe.stderr
    t0 = time.perf_counter()
    helped = subprocess.run([sys.executable, "-m", "neuspike.train", "--help"], capture_output=True, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert helped.returncode == 0 and "sequences" in helped.stdout and "--run-dir" in helped.stdout
    assert time.perf_counter() - t0 < 5  # well under torch's import time on a loaded machine
    with pytest.raises(SystemExit) as exit_:
        main(["e2vid", "--steps", "many"])
    assert exit_.value.code == 2
    capsys.readouterr()
    assert main(["neuspike-net", "--size", "64", "--kinds", "pan"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--size, --kinds: not for 'neuspike-net'" in err[0]
    assert main(["e2vid", "--spike-only-fraction", "0.5"]) == 2
    assert main(["e2vid", "--export", "--no-export"]) == 2


def test_a_file_size_limit_is_a_one_line_error_and_leaves_no_temporaries(tmp_path):
    """``ulimit -f`` during training: the checkpoint cannot be written; one line, exit 2, nothing half-written."""
    code = f"""
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, 1 << 20))
from neuspike.train.__main__ import main
sys.exit(main(["neuspike-net", "--out", {str(tmp_path / "run")!r}, "--shard", {str(tmp_path / "shard")!r},
               "--quick", "--steps", "2", "--workers", "1", "--precision", "float32", "--quiet"]))
"""
    done = _run(code)
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr[-2000:]
    assert len(err) == 1 and "File too large" in err[0] and "Traceback" not in done.stderr
    assert not list((tmp_path / "run").glob(".*.tmp"))


def test_a_spec_file_runs_as_written_and_flags_that_would_change_it_are_refused(tmp_path):
    from neuspike.train.__main__ import build_parser, spec_from_args

    path = tmp_path / "spec.json"
    spec = _tiny_windows(tmp_path, "run")
    path.write_text(json.dumps(spec.as_dict()))

    def parse(line: str):
        return spec_from_args(build_parser().parse_args(line.split()))

    again = parse(f"neuspike-net --spec {path} --out {tmp_path / 'other'} --device cpu --max-minutes 3 --quiet")
    assert again.out_dir == str(tmp_path / "other") and again.identity() == spec.identity()
    # where it writes and on what it runs apply, and leave what it trains alone
    moved = parse(f"neuspike-net --spec {path} --shard {tmp_path / 's'} --workers 3 --threads 2 "
                  f"--export-dir {tmp_path / 'e'}")
    assert (moved.data.shard_dir, moved.data.workers, moved.threads) == (str(tmp_path / "s"), 3, 2)
    assert moved.export_dir == str(tmp_path / "e")
    assert dataclasses.replace(moved, data=dataclasses.replace(moved.data, shard_dir=spec.data.shard_dir)).identity() \
        == spec.identity()
    assert parse(f"neuspike-net --spec {path} --export").export
    assert not parse(f"neuspike-net --spec {path} --no-export").export
    for flags in ("--steps 5", "--batch 2 --lr 1e-3", "--seed 0", "--windows 6", "--crop-trim 2", "--param head=1",
                  "--quick"):
        with pytest.raises(InputError, match="as written") as err:
            parse(f"neuspike-net --spec {path} {flags}")
        for flag in flags.split():
            if flag.startswith("--"):
                assert flag in str(err.value), (flag, str(err.value))


def test_training_never_replaces_the_shipped_weights_unless_told_to(tmp_path, capsys):
    """Every method's default run, a quick run and a spec file that asks for an export in its own
    text: none writes into the package; only --export does, and a quick run refuses even that."""
    from neuspike.train.__main__ import build_parser, spec_from_args

    def parse(line: str):
        return spec_from_args(build_parser().parse_args(line.split()))

    for method in ("neuspike-net", "neuspike-net-spike", "e2vid", "firenet-sim"):
        assert not parse(method).export
        assert not parse(f"{method} --quick").export
    assert main(["e2vid", "--quick", "--export"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "never replaces the shipped weights" in err[0]
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({**_tiny_windows(tmp_path, "run").as_dict(), "export": True}))
    assert not parse(f"neuspike-net --spec {path}").export
    assert parse(f"neuspike-net --spec {path} --export").export


def test_a_checkpoint_damaged_after_it_was_written_is_refused_not_resumed(tmp_path):
    """A checkpoint is sealed with the sha256 of its content: one changed byte of a tensor (which the
    file's container does not notice) is refused on resume; an unsealed checkpoint of an earlier
    version still loads."""
    import io

    import torch

    module = torch.nn.Linear(3, 2)
    optimizer = torch.optim.Adam(module.parameters())
    ck.save_checkpoint(tmp_path, step=7, module=module, optimizer=optimizer, best={}, wall_s=1.0)
    path = tmp_path / "checkpoint.pt"
    state = ck.load_checkpoint(tmp_path)
    assert state["step"] == 7 and torch.equal(state["module"]["weight"], module.weight.detach())
    outer = torch.load(path, weights_only=True)
    data = bytearray(outer["sealed"])
    data[len(data) // 2] ^= 0x01
    buf = io.BytesIO()
    torch.save({"sealed": bytes(data), "sha256": outer["sha256"]}, buf)
    path.write_bytes(buf.getvalue())
    with pytest.raises(FormatError, match="damaged"):
        ck.load_checkpoint(tmp_path)
    path.write_bytes(outer["sealed"])  # the form written before checkpoints were sealed
    assert ck.load_checkpoint(tmp_path)["step"] == 7
