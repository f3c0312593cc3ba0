"""Running one cell: simulate once, reconstruct with every method, score, return tidy rows.

:func:`run_cell` is what every executor runs, in the main process or in a worker. It takes a
:class:`CellTask` (plain, picklable data) and returns a :class:`CellResult`; it never raises for a
method's or the simulator's failure: those become rows with ``status="error"`` and the exception in
``error``. A method that cannot run here (:class:`neuspike.methods.MethodUnavailable`, e.g. learned
weights not given) becomes rows with ``status="skipped"`` and the reason; a skip is not a failure.

In each cell
------------
1. The recording is simulated once, with only the modalities the sweep's methods consume, plus
   ``history_s`` seconds of event history when a recurrent method needs warm-up, and cached on disk,
   by :func:`neuspike.simulation.cell.simulate_recording` (the one way from a cell to a recording, shared
   with the timing benchmark and the training datasets): same seed, same bytes. Each modality is
   cached on its own and serves any later sweep of the same cell (the events: one with the same
   event history), so a method added to a finished sweep simulates nothing again. The static
   region (where the scene never moves) comes with the recording.
2. Every method reconstructs from that same recording, given without its ground truth. Before the
   timed call, a method's first use in a process is one untimed call on the same sample, so one-off
   costs (lazy imports, thread pools, first-call allocation) stay out of the timing. ``reset()``
   runs before every call, so results do not depend on call history.
3. The image is scored with :func:`neuspike.metrics.evaluate` (``data_range=1``) against the ground
   truth clipped to [0, 1].

Worker set-up (:class:`WorkerSetup`, applied once per process and idempotent): plug-in modules are
imported (:func:`neuspike.methods.plugins.load_plugins`; also those named in the ``NEUSPIKE_PLUGINS`` environment variable)
and torch's intra-op thread count is set. The weights folder and device travel in the set-up and are
passed to :func:`neuspike.methods.create_many`, which builds each method once per process
(:func:`instances`); nothing is exported through the environment.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from bench.harness.grid import Cell
from bench.harness.results import ERROR, OK, SKIPPED, base_row
from neuspike import methods as registry
from neuspike.errors import one_line
from neuspike.methods.plugins import load_plugins, plugin_names
from neuspike.utils.jsonio import canonical_json
from neuspike.utils.parallel import set_threads
from neuspike.metrics import FULL_REFERENCE_METRICS, STATIC_MIN_FRACTION, evaluate, isolated_outliers, static_texture
from neuspike.simulation.cache import RecordingCache
from neuspike.simulation.cell import simulate_recording
from neuspike.simulation.recording import Recording, SensorConfig
from neuspike.simulation.window import static_region

#: The metrics of every row, in the order rows are produced.
METRICS: tuple[str, ...] = (*FULL_REFERENCE_METRICS, "static_texture", "specks")
DATA_RANGE = 1.0


@dataclass(frozen=True)
class WorkerSetup:
    """What each worker process needs before it runs a cell.

    Parameters
    ----------
    plugins : tuple of str
        Modules (dotted names or paths to ``.py`` files) to import; each registers its methods
        with :func:`neuspike.methods.register` when imported.
    weights : str or None
        Folder of published weights the user named (passed to :func:`neuspike.methods.create_many`).
    threads : int or None
        torch intra-op threads per worker (``None`` leaves torch's default).
    device : str
        Torch device of learned methods.
    precision : str or None
        The precision of every learned method (``"auto"``, ``"float32"``, ``"bfloat16"``); ``None``
        keeps each registry entry's own (``"auto"``: chosen by measurement).
    """

    plugins: tuple[str, ...] = ()
    weights: str | None = None
    threads: int | None = None
    device: str = "cpu"
    precision: str | None = None


@dataclass(frozen=True)
class CellTask:
    """One cell to run: the cell, the sensor, the methods and where to cache the recording."""

    cell_id: str
    cell: Cell
    sensor: SensorConfig
    methods: tuple[str, ...]
    modalities: tuple[str, ...]
    history_s: float = 0.0
    cache_dir: str | None = None
    setup: WorkerSetup = field(default_factory=WorkerSetup)
    keep_images: bool = False


@dataclass
class CellResult:
    """What :func:`run_cell` returns.

    ``rows`` are the tidy rows (:mod:`bench.harness.results`); ``status`` is ``"error"`` when any method or
    the simulation failed; ``failures`` maps a method (or ``"simulation"``) to its traceback;
    ``skipped`` maps a method to the reason it could not run; ``cache_hit`` says whether the
    recording came from the cache, all of it; ``simulated`` names the modalities simulated now;
    ``threads`` is torch's thread count in the worker. With
    ``task.keep_images``, ``images`` maps ``"gt"`` and each method that succeeded to its float32
    (H, W) image in [0, 1] (the figure grid of the report).
    """

    cell_id: str
    rows: list[dict[str, Any]]
    status: str
    cache_hit: bool
    sim_seconds: float
    failures: dict[str, str]
    skipped: dict[str, str]
    threads: int | None
    pid: int
    wall_seconds: float
    images: dict[str, np.ndarray] = field(default_factory=dict)
    simulated: tuple[str, ...] = ()


# ----------------------------------------------------------------------------------------------
# Worker set-up
# ----------------------------------------------------------------------------------------------

#: (name, weights folder, device) -> [registry entry, Created, warmed-up flag], per process.
_INSTANCES: dict[tuple[str, str | None, str], list[Any]] = {}


def prepare_worker(setup: WorkerSetup) -> int:
    """Apply ``setup`` in this process (idempotent); return the thread count of torch and numba.

    Both pools get ``setup.threads`` threads, so that workers sharing the cores do not each start a
    pool of every core (a waiting thread stalls each small operation of the others).
    """
    load_plugins(plugin_names(setup.plugins))
    if setup.threads is not None:
        return set_threads(int(setup.threads))
    return int(torch.get_num_threads())


def instances(names: tuple[str, ...] | list[str], setup: WorkerSetup) -> dict[str, list[Any]]:
    """``{name: [entry, created, warmed]}``: each method built once per process by
    :func:`neuspike.methods.create_many` (again only when its registry entry changed).

    ``created`` is a :class:`neuspike.methods.Created` (the instance, or why there is none);
    ``warmed`` says whether the untimed first call ran. Unknown names and an unusable device raise
    :class:`~neuspike.errors.InputError`.
    """
    entries = {name: registry.entry(name) for name in names}
    key = lambda name: (name, setup.weights, setup.device, setup.precision)  # noqa: E731
    todo = [n for n in names if key(n) not in _INSTANCES or _INSTANCES[key(n)][0] is not entries[n]]
    if todo:
        made = registry.create_many(todo, weights_dir=setup.weights, device=setup.device,
                                    precision=setup.precision, keep_errors=True)
        for name in todo:
            _INSTANCES[key(name)] = [entries[name], made[name], False]
    return {name: _INSTANCES[key(name)] for name in names}


# ----------------------------------------------------------------------------------------------
# Running a cell
# ----------------------------------------------------------------------------------------------

def simulate_cell(task: CellTask) -> tuple[Recording, frozenset[str]]:
    """The cell's recording, from the cache or simulated (then cached). Returns ``(recording, modalities simulated now)``."""
    cell = task.cell
    return simulate_recording(cell.scene.spec, cell.condition, sensor=task.sensor, seed=cell.seed,
                              modalities=task.modalities, history_s=task.history_s,
                              cache=RecordingCache(task.cache_dir) if task.cache_dir is not None else None)


def _stage_summary(meta: dict[str, Any]) -> tuple[list[tuple[str, str]], float, str]:
    """(modality, name) of every stage that ran, total seconds, and seconds per stage as JSON."""
    stages = list(meta.get("stages", []))
    names: list[tuple[str, str]] = []
    seconds: dict[str, float] = {}
    for s in stages:
        mod, name = str(s.get("modality", "")), str(s.get("name", ""))
        if (mod, name) not in names:
            names.append((mod, name))
        key = f"{mod}:{name}"
        seconds[key] = seconds.get(key, 0.0) + float(s.get("seconds", 0.0))
    return names, float(sum(seconds.values())), json.dumps(seconds, sort_keys=True)


def method_slots(methods: tuple[str, ...], setup: WorkerSetup, failures: dict[str, str],
                 skipped: dict[str, str]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The per-process instances of ``methods`` that can run, and what each row says about every method.

    Returns ``(resolved, info)``: ``resolved`` maps the methods that can run to their slot of
    :func:`instances`; ``info`` maps every method to its row fields (``inputs``, ``recurrent``,
    ``parameters``, ``method_params``) and a ``skip`` or ``error`` text where it cannot run.
    Tracebacks go to ``failures``, reasons for skipping to ``skipped`` (both updated in place).
    """
    resolved: dict[str, Any] = {}
    info: dict[str, dict[str, Any]] = {name: {"method": name} for name in methods}
    try:
        slots = instances(methods, setup)
    except Exception as exc:  # an unknown name or an unusable device (the driver refuses both first)
        slots = {}
        for name in methods:
            failures[name] = traceback.format_exc()
            info[name]["error"] = f"creating the method failed: {one_line(exc)}"
    for name, slot in slots.items():
        entry, created = slot[0], slot[1]
        info[name]["inputs"] = "+".join(sorted(entry.inputs))
        if created.unavailable is not None:
            skipped[name] = one_line(created.unavailable)
            info[name]["skip"] = f"unavailable: {skipped[name]}"
        elif created.error is not None:
            failures[name] = created.traceback
            info[name]["error"] = f"creating the method failed: {one_line(created.error)}"
        else:
            method = created.method
            try:
                info[name].update(recurrent=bool(method.recurrent), parameters=int(method.parameter_count()),
                                  method_params=canonical_json(method.describe()))
                resolved[name] = slot
            except Exception as exc:
                failures[name] = traceback.format_exc()
                info[name]["error"] = f"creating the method failed: {one_line(exc)}"
    return resolved, info


def timed_reconstruct(slot: list[Any], sample: Any) -> tuple[np.ndarray, float]:
    """``(image, ms)``: the method of ``slot`` on ``sample`` after ``reset()``, timed; its first use in
    this process is one untimed call before (one-off costs stay out of the timing)."""
    method = slot[1].method
    if not slot[2]:
        method.reset()
        method.reconstruct(sample)  # untimed first use in this process
        slot[2] = True
    method.reset()
    t0 = time.perf_counter_ns()
    image = method.reconstruct(sample)
    return image, (time.perf_counter_ns() - t0) / 1e6


def run_method(name: str, meta: dict[str, Any], resolved: dict[str, Any], sample: Any, row: dict[str, Any],
               score: Any, *, images: dict[str, np.ndarray] | None, skipped: dict[str, str],
               failures: dict[str, str]) -> dict[str, float]:
    """One method on one sample, as a row: a skip or an error recorded at set-up, else the timed call
    (:func:`timed_reconstruct`) and ``score(image)``; the status, error, time and normalisation go
    into ``row``, the image into ``images`` (when given), an unavailable method into ``skipped`` and
    a failure's traceback into ``failures``. Returns the metric values (empty unless it ran)."""
    if "skip" in meta:
        row.update(status=SKIPPED, error=meta["skip"])
        return {}
    if "error" in meta:
        row.update(status=ERROR, error=meta["error"])
        return {}
    slot = resolved[name]
    method = slot[1].method
    try:
        image, ms = timed_reconstruct(slot, sample)
        row.update(ms_per_frame=ms, normalisation=method.last_normalisation or "")
        values = score(image)
        row.update(status=OK, error="")
        if images is not None:
            images[name] = np.array(image, dtype=np.float32, copy=True)  # not a reused buffer
        return values
    except registry.MethodUnavailable as exc:
        skipped[name] = one_line(exc)
        row.update(status=SKIPPED, error=f"unavailable: {skipped[name]}")
    except Exception as exc:
        failures[name] = traceback.format_exc()
        row.update(status=ERROR, error=one_line(exc))
    return {}


def run_cell(task: CellTask) -> CellResult:
    """Simulate the cell once and evaluate every method on it (see the module docstring).

    Returns
    -------
    CellResult
        ``len(task.methods) * len(METRICS)`` rows, in method order then :data:`METRICS` order.
    """
    t_start = time.perf_counter()
    cell = task.cell
    width, height = cell.scene.spec.size
    common = dict(
        cell=task.cell_id, scene=cell.scene.name, kind=cell.scene.kind, image=cell.scene.image,
        width=width, height=height, planes=task.sensor.planes, light=cell.condition.light,
        motion=cell.condition.motion, noise=cell.condition.noise, seed=cell.seed,
    )
    failures: dict[str, str] = {}
    skipped: dict[str, str] = {}
    threads = None
    try:
        threads = prepare_worker(task.setup)
    except Exception as exc:  # e.g. a plug-in that does not import: every method fails
        failures["setup"] = traceback.format_exc()
        rows = [base_row(**common, method=m, metric=k, status=ERROR, error=f"worker set-up failed: {one_line(exc)}")
                for m in task.methods for k in METRICS]
        return CellResult(task.cell_id, rows, ERROR, False, float("nan"), failures, skipped, threads,
                          os.getpid(), time.perf_counter() - t_start)

    # Resolve the methods first: the simulation is not needed when none can run.
    resolved, info = method_slots(task.methods, task.setup, failures, skipped)

    recording = None
    cache_hit = False
    simulated: frozenset[str] = frozenset()
    sim_seconds = float("nan")
    stage_names: list[tuple[str, str]] = []
    stage_json = ""
    if resolved:
        try:
            recording, simulated = simulate_cell(task)
            cache_hit = not simulated
            stage_names, sim_seconds, stage_json = _stage_summary(recording.meta)
        except Exception as exc:
            failures["simulation"] = traceback.format_exc()
            for name in resolved:
                info[name]["error"] = f"simulation failed: {one_line(exc)}"
            resolved = {}

    sample = truth = static = None
    images: dict[str, np.ndarray] = {}
    if recording is not None:
        full = recording.to_sample()
        truth = full.ground_truth
        sample = full.without_ground_truth()
        try:  # where the scene never moves: the static-texture measure of the claims
            static = recording.static_region()  # kept with the recording; rendered for older cache entries
            if static is None:
                static = static_region(cell.scene.spec, cell.condition, sensor=task.sensor, modalities=task.modalities,
                                       history_s=task.history_s, min_fraction=STATIC_MIN_FRACTION)
        except Exception:
            failures["static region"] = traceback.format_exc()
            static = None
        if task.keep_images:
            images["gt"] = truth

    rows: list[dict[str, Any]] = []
    for name in task.methods:
        meta = info[name]
        row = dict(common, method=name, inputs=meta.get("inputs", ""),
                   recurrent=meta.get("recurrent", False), parameters=meta.get("parameters", 0),
                   method_params=meta.get("method_params", ""),
                   sim_seconds=sim_seconds, stage_seconds=stage_json)
        if recording is not None and meta.get("inputs"):
            used = set(meta["inputs"].split("+"))
            row["effects"] = ";".join(f"{m}:{n}" for m, n in stage_names if m in used)
        def score(image: np.ndarray) -> dict[str, float]:
            values = evaluate(image, truth, data_range=DATA_RANGE)
            values["specks"] = isolated_outliers(image, truth, data_range=DATA_RANGE)
            if static is not None:
                values["static_texture"] = static_texture(image, truth, static, data_range=DATA_RANGE)
            return values

        values = run_method(name, meta, resolved, sample, row, score, images=images if task.keep_images else None,
                            skipped=skipped, failures=failures)
        for metric in METRICS:
            rows.append(base_row(**row, metric=metric, value=float(values.get(metric, np.nan))))
    status = ERROR if failures else OK
    return CellResult(task.cell_id, rows, status, cache_hit, sim_seconds, failures, skipped, threads,
                      os.getpid(), time.perf_counter() - t_start, images, tuple(sorted(simulated)))
