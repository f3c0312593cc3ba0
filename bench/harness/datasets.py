"""Every method on every recording of a dataset (the library behind ``python -m bench.dataset``).

A dataset is a folder of recordings described by a manifest (:mod:`bench.harness.manifest`). Each instant of
each recording is one task of the harness's loop (:func:`bench.harness.runner.run_tasks`): the same method
creation (once per worker, :func:`bench.harness.cells.instances`), timing (:func:`bench.harness.cells.run_method`),
failure-as-a-row, resume and executors as the sweeps, and the same tidy ``results.csv``
(:mod:`bench.harness.results`; a row per recording, instant, method and metric).

At each instant
---------------
1. The sample is cut by :func:`neuspike.formats.samples.load_sample`, the function
   ``python -m neuspike.reconstruct`` uses, with the manifest's size, plane rate, gain, window and
   the instant (a plane, or a time): the same recording and instant give the same image.
2. Each method that reads only inputs the recording has (an *applicable* method) reconstructs
   without the ground truth; a method that reads a modality the recording lacks has no rows for it.
3. The image is scored against the manifest's ground truth for that instant (PSNR, SSIM with the
   pinned settings, their affine-aligned variants; ``data_range=1``), and with the no-reference
   measures (``noise_sigma``, ``laplacian_var``) always; ``ms_per_frame`` is the timed call.
   A ground truth found beside a file but not named by the manifest is not used.

A recording whose files exist but cannot be read gives failed rows (the reader's error) while the
others run; everything else wrong with a manifest is refused before any work (:func:`bench.harness.manifest.resolve`).

Outputs (``--out``): ``manifest.json`` (the manifest used, inferred or given), ``config.json`` (the
dataset, the resolved instants and the protocol), ``metadata.json``, ``parts/``, ``errors/``,
``results.csv``, ``images/<recording>/<method>.png`` and ``gt.png`` (the recording's middle instant,
for the contact sheets) and the report (:func:`bench.reporting.dataset_report.build_dataset_report`).
"""

from __future__ import annotations

import math
import os
import time
import traceback
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bench.harness.cells import WorkerSetup, instances, method_slots, prepare_worker, run_method
from bench.harness.runner import Execution, SweepOutcome, arithmetic, check_config, prepare_execution, run_tasks
from bench.harness.manifest import Instant, Manifest, Resolved, resolve, write_manifest, MANIFEST_NAME
from bench.harness.results import ERROR, OK, base_row
from neuspike.errors import InputError, one_line
from neuspike.utils.jsonio import portable_path, stable_hash

#: Bump when a change here changes the rows an instant produces (part of every task id).
DATASET_HARNESS_VERSION = "1"
DATA_RANGE = 1.0


@dataclass(frozen=True)
class DatasetSpec:
    """What a dataset run measures.

    Parameters
    ----------
    name : str
        A label (the folder's name by default).
    root : str
        The dataset folder; the manifest's paths are relative to it.
    manifest : Manifest
    methods : tuple of str
        Registry names requested; each recording runs those that read only inputs it has.
    weights : str or None
        Folder of published weights.
    allow_outside : bool
        Read files the manifest names outside ``root`` (refused by default: :func:`bench.harness.manifest.resolve`).
    """

    name: str
    root: str
    manifest: Manifest
    methods: tuple[str, ...]
    weights: str | None = None
    allow_outside: bool = False

    def __post_init__(self) -> None:
        if not self.methods:
            raise InputError("a dataset run needs at least one method")
        if len(set(self.methods)) != len(self.methods):
            raise InputError(f"methods repeat a name: {list(self.methods)}")
        object.__setattr__(self, "root", str(Path(self.root).resolve()))
        if self.weights is not None:
            object.__setattr__(self, "weights", str(Path(self.weights).resolve()))


@dataclass(frozen=True)
class InstantTask:
    """One instant of one recording, with the methods that apply to it."""

    cell_id: str
    recording: Resolved
    instant: Instant
    methods: tuple[str, ...]
    setup: WorkerSetup
    keep_images: bool = False


def protocol(resolved: list[Resolved]) -> dict[str, Any]:
    """How every number of the run was made: windows, instants, rates, normalisation, metrics, timing."""
    from neuspike.formats.recording import EVENT_HISTORY_S
    from neuspike.metrics import NO_REFERENCE_MEASURES, SSIM_SETTINGS, describe_metrics

    per = {}
    for r in resolved:
        first = r.instants[0]
        per[r.recording.name] = {
            "inputs": "+".join(sorted(r.recording.inputs)), "size": f"{r.width}x{r.height}",
            "plane_rate_hz": r.plane_rate_hz, "window_planes": r.window_planes,
            "gain": r.gain, "gain_source": r.gain_source, "instants": len(r.instants),
            "first_instant": ({"plane": first.plane} if first.plane is not None else {"time_s": first.time_s}),
            "ground_truth": sum(i.ground_truth is not None for i in r.instants),
            **({"damaged": r.damaged} if r.damaged else {}),
        }
    return {
        "window": ("spike window: window_planes planes centred on the key plane (planes K - N//2 .. K + N//2 - 1), "
                   "shifted, not shortened, to stay inside the file; a file no longer than the window is used whole. "
                   f"Events: the window's span, plus {EVENT_HISTORY_S:g} s of history before it; event methods "
                   "read the events before the key instant"),
        "key_instant": ("a key plane's centre, or a time in sensor seconds, as the manifest names it; 'centre' is "
                        "plane T // 2 of the spike file, else midway between the first and last event"),
        "rate": ("gain = expected spikes per plane at intensity 1; where unknown, each method normalises by its own "
                 "rule (the normalisation column)"),
        "normalisation": "none by the harness: each method's own output in [0, 1], labelled in the normalisation column",
        "ground_truth": ("8-bit images / 255, 16-bit / 65535, .npy as stored; values above 1 clipped to 1; a ground "
                         "truth not named by the manifest is not used"),
        "data_range": DATA_RANGE,
        "ssim": dict(SSIM_SETTINGS),
        "metrics": describe_metrics(),
        "no_reference": {"measures": list(NO_REFERENCE_MEASURES),
                         "noise_sigma": "Haar-wavelet MAD noise estimate (lower: less noise)",
                         "laplacian_var": "variance of the Laplacian (higher: sharper, or noisier)"},
        "timing": ("ms_per_frame: wall time of one reconstruct call, after one untimed call per worker process; "
                   "reset() before each call, so recurrent methods start each instant afresh and warm up on its history"),
        "recordings": per,
    }


def applicable(methods: tuple[str, ...], inputs: frozenset[str]) -> tuple[str, ...]:
    """The methods whose inputs the recording has, in the order given."""
    from neuspike import methods as registry

    return tuple(m for m in methods if frozenset(registry.entry(m).inputs) <= inputs)


def _middle(r: Resolved) -> int:
    return len(r.instants) // 2


def plan(spec: DatasetSpec, setup: WorkerSetup, resolved: list[Resolved]) -> tuple[dict[str, Any], list[InstantTask]]:
    """The run's identity (``config.json``'s ``dataset``) and its tasks."""
    prepare_worker(setup)
    setup = replace(setup, weights=spec.weights)
    per_recording = {r.recording.name: applicable(spec.methods, r.recording.inputs) for r in resolved}
    used = tuple(m for m in spec.methods if any(m in ms for ms in per_recording.values()))
    if not used:
        have = sorted({"+".join(sorted(r.recording.inputs)) for r in resolved})
        raise InputError(f"no requested method reads what the recordings hold ({', '.join(have)})")
    unavailable, recurrent, inputs = {}, [], {}
    for name, (entry, created, _) in instances(used, setup).items():
        inputs[name] = sorted(entry.inputs)
        if created.unavailable is not None:
            unavailable[name] = one_line(created.unavailable)
        elif created.error is not None:
            raise created.error
        elif created.method.recurrent:
            recurrent.append(name)
    arith = arithmetic(replace(spec, methods=used), setup)
    identity = {
        "name": spec.name, "harness_version": DATASET_HARNESS_VERSION, "manifest": spec.manifest.as_dict(),
        "methods": list(spec.methods), "applicable": {k: list(v) for k, v in per_recording.items()},
        "weights": portable_path(spec.weights) if spec.weights is not None else None,
        "resolved": {"inputs": inputs, "unavailable": unavailable, "recurrent": recurrent},
        "protocol": protocol(resolved), **arith,
    }
    tasks = []
    for r in resolved:
        methods = per_recording[r.recording.name]
        if not methods:
            continue
        for inst in r.instants:
            ident = {"harness": DATASET_HARNESS_VERSION, "recording": r.identity(),
                     "instant": [inst.index, inst.plane, inst.at_s, inst.ground_truth],
                     "methods": list(methods), "weights": spec.weights, "arithmetic": arith}
            tasks.append(InstantTask(cell_id=stable_hash(ident), recording=r, instant=inst, methods=methods,
                                     setup=setup, keep_images=inst.index == _middle(r)))
    return identity, tasks


# ----------------------------------------------------------------------------------------------
# One instant
# ----------------------------------------------------------------------------------------------

def load_instant(r: Resolved, inst: Instant) -> tuple[Any, np.ndarray | None]:
    """The sample of ``inst`` (without ground truth) and the manifest's ground truth (or ``None``),
    cut by :func:`neuspike.formats.samples.load_sample` exactly as ``neuspike.reconstruct`` cuts it."""
    from neuspike.formats.samples import load_sample

    rec = r.recording
    gt = r.path(inst.ground_truth)
    sample = load_sample(spikes=r.path(rec.spikes), events=r.path(rec.events), height=rec.height, width=rec.width,
                         raw_width=rec.raw_width, plane_rate_hz=rec.plane_rate_hz, gain=rec.gain,
                         plane=inst.plane, at_s=inst.at_s, window_planes=rec.window_planes, gt=gt)
    truth = sample.ground_truth if gt is not None else None
    return sample.without_ground_truth(), truth


def run_instant(task: InstantTask) -> Any:
    """Reconstruct one instant with every applicable method and score it (module docstring).

    Returns a :class:`bench.harness.cells.CellResult`; never raises for a method's or a file's failure.
    """
    from bench.harness.cells import CellResult
    from neuspike.metrics import FULL_REFERENCE_METRICS, NO_REFERENCE_MEASURES, evaluate, no_reference

    t_start = time.perf_counter()
    r, inst = task.recording, task.instant
    rec = r.recording
    metrics = ((*FULL_REFERENCE_METRICS, *NO_REFERENCE_MEASURES) if inst.ground_truth is not None
               else NO_REFERENCE_MEASURES)
    common = dict(
        cell=task.cell_id, scene=rec.name, kind="+".join(sorted(rec.inputs)),
        image="+".join(p for p in (rec.spikes, rec.events) if p), width=r.width or 0, height=r.height or 0,
        planes=r.window_planes or 0, light=math.nan, motion=math.nan, noise="", seed=math.nan,
        time_s=inst.time_s, instant=inst.index, reference=inst.ground_truth or "",
    )
    failures: dict[str, str] = {}
    skipped: dict[str, str] = {}
    threads = None
    try:
        threads = prepare_worker(task.setup)
        resolved, info = method_slots(task.methods, task.setup, failures, skipped)
    except Exception as exc:  # e.g. a plug-in that does not import: every method fails
        failures["setup"] = traceback.format_exc()
        resolved, info = {}, {m: {"method": m, "error": f"worker set-up failed: {one_line(exc)}"} for m in task.methods}

    sample = truth = None
    if resolved:
        if r.damaged is not None:
            failures["recording"] = r.damaged
            for name in resolved:
                info[name]["error"] = f"reading the recording failed: {r.damaged}"
            resolved = {}
        else:
            try:
                sample, truth = load_instant(r, inst)
                common["time_s"] = float(sample.key_time_s)
            except Exception as exc:
                failures["recording"] = traceback.format_exc()
                for name in resolved:
                    info[name]["error"] = f"reading the recording failed: {one_line(exc)}"
                resolved = {}

    images: dict[str, np.ndarray] = {}
    if task.keep_images and truth is not None:
        images["gt"] = truth
    rows: list[dict[str, Any]] = []
    for name in task.methods:
        meta = info[name]
        row = dict(common, method=name, inputs=meta.get("inputs", ""), recurrent=meta.get("recurrent", False),
                   parameters=meta.get("parameters", 0), method_params=meta.get("method_params", ""))
        def score(image: np.ndarray) -> dict[str, float]:
            values = evaluate(image, truth, data_range=DATA_RANGE) if truth is not None else {}
            values.update(no_reference(image))
            return values

        values = run_method(name, meta, resolved, sample, row, score, images=images if task.keep_images else None,
                            skipped=skipped, failures=failures)
        for metric in metrics:
            rows.append(base_row(**row, metric=metric, value=float(values.get(metric, np.nan))))
    status = ERROR if failures else OK
    return CellResult(task.cell_id, rows, status, False, math.nan, failures, skipped, threads, os.getpid(),
                      time.perf_counter() - t_start, images)


# ----------------------------------------------------------------------------------------------
# The run
# ----------------------------------------------------------------------------------------------

def _write_images(out: Path, task: InstantTask, images: dict[str, np.ndarray]) -> None:
    from bench.harness.images import recording_image_path
    from neuspike.formats.images import write_png

    for name, image in images.items():
        write_png(recording_image_path(out / "images", task.recording.recording.name, name), image, clip=name == "gt")


def prepare(spec: DatasetSpec) -> list[Resolved]:
    """Check the manifest against the files (every refusal before any work)."""
    return resolve(spec.manifest, spec.root, allow_outside=spec.allow_outside)


def run_dataset(spec: DatasetSpec, out_dir: str | os.PathLike, execution: Execution = Execution(),
                resolved: list[Resolved] | None = None) -> SweepOutcome:
    """Run (or resume) every applicable method on every instant of the dataset into ``out_dir``.

    Raises
    ------
    InputError
        A bad manifest (naming the recording), unknown methods, an unusable device, invalid options,
        before any work and before ``out_dir`` is created.
    ConfigMismatch
        ``out_dir`` holds results of another dataset run and ``execution.force`` is false.
    """
    from neuspike.formats.staging import check_writable_folder

    t_start = time.perf_counter()
    out = check_writable_folder(out_dir, what="output folder", create=False)
    if resolved is None:
        resolved = prepare(spec)
    executor, threads, remote, setup = prepare_execution(execution, spec.weights)
    identity, tasks = plan(spec, setup, resolved)  # unknown names and an unusable device refuse here
    check_writable_folder(out, what="output folder")  # every input accepted: only now is the folder created
    stale = check_config(out, identity, execution.force, key="dataset")
    write_manifest(out / MANIFEST_NAME, spec.manifest)
    outcome = run_tasks(
        out, tasks, run_instant, config={"dataset": identity}, stale=stale, executor=executor, threads=threads,
        remote=remote, execution=execution, label=f"{spec.name} dataset", run_info={"dataset": spec.name},
        execution_info={"plugins": list(setup.plugins)}, skipped=dict(identity["resolved"]["unavailable"]),
        t_start=t_start, write_images=lambda task, images: _write_images(out, task, images),
    )
    outcome.use_cache = False
    return outcome
