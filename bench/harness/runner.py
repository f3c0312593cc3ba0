"""The sweep harness: every cell of a grid with every requested method, resumable (the library behind
``python -m bench.sweep`` and ``python -m bench.noise``; the commands live in :mod:`bench.sweep`).

A sweep runs every cell of a grid (:mod:`bench.harness.grid`) with every requested method through
:func:`run_tasks`, the resumable loop that :mod:`bench.harness.datasets` shares (its tasks are the instants
of real recordings), and writes into its output folder:

``config.json``     the resolved sweep (grid, scene specs, sensor, methods, what each method needs,
                    the device and each learned method's precision) and how it was executed
``metadata.json``   provenance (:mod:`bench.harness.provenance`): commit, versions, machine, executor,
                    threads per worker, start and end of each run
``parts/<cell>.csv`` one cell's rows, written atomically when the cell finishes
``results.csv``     every row (:mod:`bench.harness.results`), assembled from the parts, sorted
``errors/<cell>.txt`` tracebacks of the failures of a cell, when any
``images/``         reconstructions and ground truth for the report's figure grid, in the layout
                    of :mod:`bench.harness.images` (``images/<scene>/<axis>=<value>/<method>.png``): for the
                    swept axis, of the first seed with the other axes at their first value
``cache/``          simulated recordings (:mod:`neuspike.simulation.cache`), unless ``--cache`` points elsewhere:
                    one file per modality, so a method added to a finished sweep simulates nothing
                    again, except the events when it is the sweep's first recurrent method that reads
                    them (its warm-up history changes the event camera's state; the summary says so)

Resuming
    Finished cells are never recomputed: a rerun of the same command after a crash, an interrupt or
    a kill runs only the cells without a part file, then assembles ``results.csv``, which equals an
    uninterrupted run's in every column except the timing columns
    (:data:`bench.harness.results.TIMING_COLUMNS`), which measure each run anew. A rerun with a different
    configuration in the same folder is refused, another ``--device`` or a precision resolved
    differently included (``--force`` replaces the old results; cached
    recordings stay valid since their keys hold everything that determines them). Cells whose
    methods failed are kept as results; ``--retry-failed`` runs them again.

Exit status
    0 when every cell ran without failure; 1 when a method or a simulation failed (error rows)
    unless ``--allow-failures``, and always when cells are missing (a worker died); 2 for invalid
    options or a changed configuration; 130 when interrupted. Methods that cannot run here (e.g.
    learned weights not given) are skipped with the reason in their rows; a skip is not a failure.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterator

import pandas as pd

from bench.harness import grid as grids
from bench.harness.axes import AXES
from bench.harness.cells import CellTask, WorkerSetup, instances, prepare_worker, run_cell
from bench.harness.executors import DaskExecutor, make_executor
from bench.harness.grid import Grid
from bench.harness.provenance import LoadWatch, collect, finish, now_iso
from bench.harness.results import ERROR, OK, assemble, part_path, read_csv, write_part
from neuspike.methods.plugins import plugin_names
from neuspike.utils.atomic import write_json, write_text
from neuspike.errors import InputError, NeuSpikeError, one_line
from neuspike.utils.checks import check_positive_int
from neuspike.utils.resources import announce_default_threads, usable_cpus
from neuspike.utils.jsonio import canonical_json, portable_path, stable_hash
from neuspike.simulation.recording import DEFAULT_HISTORY_WINDOWS

#: Bump when a change of the harness changes the rows a cell produces (part of every cell id).
HARNESS_VERSION = "3"  # 2: the static_texture metric; 3: the specks metric, the dark rate subtracted
#: Default event history for recurrent methods, in windows of the spike window's duration.


class ConfigMismatch(InputError):
    """The output folder holds results of a different configuration."""


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep measures (everything that determines its results).

    Parameters
    ----------
    name : str
        ``"light"``, ``"motion"``, ``"noise"`` or any label.
    grid : Grid
    methods : tuple of str
        Registry names, in the order rows are produced.
    sensor : SensorConfig
        Planes per window, plane rate, thresholds.
    history_windows : float
        Event history before the window, in window durations, simulated only when a requested
        method is recurrent (it warms up on it).
    weights : str or None
        Folder of published weights (the command line's ``--weights`` or ``$NEUSPIKE_WEIGHTS``).
    axis : str or None
        The swept axis (``"light"``, ``"motion"``, ``"noise"``) whose reconstructions are saved
        as images for the report's figure grid; ``None`` saves none.
    """

    name: str
    grid: Grid
    methods: tuple[str, ...]
    sensor: Any = None
    history_windows: float = DEFAULT_HISTORY_WINDOWS
    weights: str | None = None
    axis: str | None = None

    def __post_init__(self) -> None:
        from neuspike.simulation.recording import SensorConfig

        if self.sensor is None:
            object.__setattr__(self, "sensor", SensorConfig())
        methods = tuple(self.methods)
        if not methods:
            raise InputError("a sweep needs at least one method")
        if len(set(methods)) != len(methods):
            raise InputError(f"methods repeat a name: {list(methods)}")
        object.__setattr__(self, "methods", methods)
        hw = float(self.history_windows)
        if not hw >= 0 or hw != hw or hw == float("inf"):
            raise InputError(f"history_windows: expected a finite number >= 0, got {self.history_windows!r}")
        object.__setattr__(self, "history_windows", hw)
        if self.weights is not None:
            object.__setattr__(self, "weights", str(Path(self.weights).resolve()))
        if self.axis is not None and self.axis not in AXES:
            raise InputError(f"axis: expected one of {', '.join(AXES)} or None, got {self.axis!r}")
        self.grid.check_planes(self.sensor.planes)

    def keeps_images(self, cell: grids.Cell) -> bool:
        """Whether ``cell``'s reconstructions go to ``images/``: the first seed, and every axis
        other than :attr:`axis` at its first value (so each image path names one cell)."""
        if self.axis is None or cell.seed != self.grid.seeds[0]:
            return False
        firsts = {"light": self.grid.lights[0], "motion": self.grid.motions[0], "noise": self.grid.noises[0]}
        c = cell.condition
        return all(getattr(c, ax) == v for ax, v in firsts.items() if ax != self.axis)

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "grid": self.grid.as_dict(),
            "methods": list(self.methods),
            "sensor": self.sensor.as_dict(),
            "history_windows": self.history_windows,
            # as the folder's config records it: no absolute path of this machine (the cells' ids hold
            # the resolved folder)
            "weights": portable_path(self.weights) if self.weights is not None else None,
            "axis": self.axis,
        }


@dataclass(frozen=True)
class Execution:
    """How a sweep runs (nothing here changes its results, only the timing columns, except ``device``).

    Parameters
    ----------
    executor : str or executor object
        ``"local"`` or ``"dask"``, or an instance of :class:`~bench.harness.executors.LocalExecutor` /
        :class:`~bench.harness.executors.DaskExecutor`.
    workers : int
        Worker processes (local) or LocalCluster workers (dask).
    scheduler : str or None
        Address of an existing Dask scheduler.
    threads : int or None
        torch threads per worker; ``None``: the usable CPUs other processes leave idle, divided by the
        workers (at least 1),
        or 1 on a remote Dask cluster.
    cache_dir : path or None
        Where simulated recordings are cached; ``None`` means ``<out>/cache``.
    use_cache : bool
        ``False`` simulates every cell afresh and stores nothing.
    plugins : tuple of str
        Plug-in modules each worker imports (see :func:`neuspike.methods.plugins.load_plugins`).
    device : str
        Torch device of learned methods (default ``"cpu"``). It and the precision each learned
        method resolves on it change the results, so both are part of the sweep's identity
        (:func:`arithmetic`); a device no selected method runs on is refused.
    precision : str or None
        The precision of every learned method (``"auto"``, ``"float32"`` or ``"bfloat16"``); ``None``
        keeps each method's own (``"auto"``). Like the device, what it resolves to is part of the
        sweep's identity.
    allow_failures, force, retry_failed, progress :
        See the command line's help. ``progress=None`` shows the bar only on a terminal.
    report :
        Whether the command builds the report after the run (the harness itself never does: it writes the
        results and the images; :func:`bench.reporting.build.report_after_run` records the report on the
        outcome).
    """

    executor: Any = "local"
    workers: int = 1
    scheduler: str | None = None
    threads: int | None = None
    cache_dir: str | os.PathLike | None = None
    use_cache: bool = True
    plugins: tuple[str, ...] = ()
    allow_failures: bool = False
    force: bool = False
    retry_failed: bool = False
    progress: bool | None = None
    report: bool = True
    device: str = "cpu"
    precision: str | None = None


@dataclass
class SweepOutcome:
    """What a sweep did. ``exit_code`` is the command's exit status (module docstring)."""

    out_dir: Path
    results_path: Path
    n_cells: int
    n_ok: int
    n_failed: int
    n_missing: int
    n_computed: int
    n_cache_hits: int
    skipped: dict[str, str]
    allow_failures: bool
    seconds: float
    time_split: dict[str, Any] = field(default_factory=dict)
    report_path: Path | None = None
    report_note: str | None = None
    report_failed: bool = False
    #: Cells of this run that simulated each modality (the rest came from the recording cache).
    simulated: dict[str, int] = field(default_factory=dict)
    #: The event history simulated before each window, seconds (part of a cached event recording's key).
    history_s: float = 0.0
    use_cache: bool = True

    @property
    def exit_code(self) -> int:
        if self.n_missing or self.report_failed:
            return 1
        if self.n_failed and not self.allow_failures:
            return 1
        return 0

    def summary(self) -> str:
        lines = [f"{self.n_ok} cells ok, {self.n_failed} failed"
                 + (f", {self.n_missing} missing (rerun to complete them)" if self.n_missing else "")
                 + f" ({self.n_computed} computed now, {self.n_cache_hits} from the recording cache; "
                 f"{self.seconds:.1f} s)"]
        if self.use_cache and any(self.simulated.values()):
            lines.append(self._cache_note())
        for name, reason in sorted(self.skipped.items()):
            lines.append(f"skipped {name}: {reason}")
        if self.time_split:
            sim = self.time_split["simulation_s_per_cell"]
            if sim == sim:  # NaN: nothing was simulated (datasets)
                lines.append(f"time: simulation {sim:.3f} s per cell")
            lines += accuracy_and_time_lines(self.time_split)
        if self.n_failed and self.allow_failures:
            lines.append("failures allowed (--allow-failures): see the error column and errors/")
        return "\n".join(lines)


    def _cache_note(self) -> str:
        """What was simulated and when the recording cache serves it (one line)."""
        done = ", ".join(f"{m} for {n}" for m, n in sorted(self.simulated.items()) if n)
        history = (f"{self.history_s:g} s here, as a recurrent method reads events" if self.history_s
                   else "none here, as no recurrent method reads events")
        return (f"simulated now: {done} of {self.n_computed} recordings (cached spikes serve every later sweep "
                f"of the same cells; cached events only one with the same event history: {history})")


# ----------------------------------------------------------------------------------------------
# Resolving a sweep
# ----------------------------------------------------------------------------------------------

def resolve_methods(spec: SweepSpec, setup: WorkerSetup) -> dict[str, Any]:
    """Which methods can run here, what they consume, and the event history they need.

    The methods are built here by :func:`bench.harness.cells.instances`, the same per-process instances the
    cells of this process use (so each is built once per worker): unknown names and a device that
    cannot be used raise :class:`InputError` before anything runs; a creation that fails raises;
    :class:`~neuspike.methods.MethodUnavailable` marks a method as skipped. The modalities simulated
    are the union of the inputs of the available methods; the event history is ``history_windows``
    window durations when one of them is recurrent, else 0.
    """
    prepare_worker(setup)
    setup = replace(setup, weights=spec.weights)  # the spec's folder decides what is available
    inputs: dict[str, list[str]] = {}
    unavailable: dict[str, str] = {}
    recurrent: list[str] = []
    for name, (entry, created, _) in instances(spec.methods, setup).items():
        if created.unavailable is not None:
            unavailable[name] = one_line(created.unavailable)
            continue
        if created.error is not None:
            raise created.error
        inputs[name] = sorted(entry.inputs)
        if created.method.recurrent:
            recurrent.append(name)
    modalities = sorted({m for ins in inputs.values() for m in ins})
    window_s = spec.sensor.planes / spec.sensor.plane_rate_hz
    history_s = spec.history_windows * window_s if recurrent and "events" in modalities else 0.0
    return {"inputs": inputs, "unavailable": unavailable, "recurrent": recurrent,
            "modalities": modalities, "history_s": history_s}


#: The device of every sweep before the sweep's identity held its arithmetic (their part files keep their ids).
LEGACY_DEVICE = "cpu"


def arithmetic(spec: SweepSpec, setup: WorkerSetup) -> dict[str, Any]:
    """The device and the precisions the methods compute with: part of the sweep's identity.

    ``{"device": str, "precision": {method: "float32" | "bfloat16"}}``, the precision of each
    available method that has one (the learned ones, as resolved on this machine for this device).
    Both change the results, so a resumed sweep must use the same (:func:`_check_config`).
    """
    precision = {}
    for name, (_, created, _) in instances(spec.methods, replace(setup, weights=spec.weights)).items():
        if created.method is not None and "precision" in created.method.params:
            precision[name] = str(created.method.params["precision"])
    return {"device": setup.device.strip().lower(), "precision": precision}


def cell_id(spec: SweepSpec, resolved: dict[str, Any], cell: grids.Cell,
            arith: dict[str, Any] | None = None) -> str:
    """The id of a cell's part file: a hash of the cell and of what the sweep does with it.

    ``arith`` (:func:`arithmetic`) enters the hash unless it is the CPU in float32, what every
    sweep before it ran with, so that the parts of those folders keep their ids.
    """
    ident = {
        "harness": HARNESS_VERSION, "cell": cell.identity(), "sensor": spec.sensor.as_dict(),
        "methods": list(spec.methods), "modalities": resolved["modalities"],
        "history_s": resolved["history_s"], "weights": spec.weights,
    }
    if arith is not None and (arith["device"] != LEGACY_DEVICE
                              or any(p != "float32" for p in arith["precision"].values())):
        ident["arithmetic"] = arith
    return stable_hash(ident)


def _diff_paths(old: Any, new: Any, path: str = "") -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(old) | set(new)):
            out += _diff_paths(old.get(key), new.get(key), f"{path}.{key}" if path else str(key))
        return out
    if old == new:
        return []
    if path.split(".")[0] in ("device", "precision"):  # short values: say what they were and are
        return [f"{path} {old if old is not None else 'absent'} -> {new if new is not None else 'absent'}"]
    return [path or "(everything)"]


def check_config(out: Path, config: dict[str, Any], force: bool, *, key: str = "sweep") -> bool:
    """Compare ``config`` with the ``key`` entry of an existing ``config.json`` (``"sweep"``, or
    ``"dataset"`` for :mod:`bench.harness.datasets`); return whether the old results are stale.

    Raises
    ------
    ConfigMismatch
        The folder holds results of another configuration and ``force`` is false.
    """
    path = out / "config.json"
    if not path.exists():
        return False
    try:
        old = json.loads(path.read_text()).get(key)
    except (OSError, ValueError, AttributeError) as exc:
        old = {"unreadable": str(exc)}
    new = json.loads(canonical_json(config))
    if old == new:
        return False
    if not force:
        changed = ", ".join(_diff_paths(old, new)[:8])
        raise ConfigMismatch(
            f"{out} holds results of a different {key} (changed: {changed}). Use a new --out folder, "
            "or --force to replace those results" + (" (cached recordings are kept and reused)." if key == "sweep" else ".")
        )
    return True


_check_config = check_config


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


class ProgressLines:
    """Progress as plain lines for a stream that is not a terminal (a log file, a pipe): one line at
    most every ``every_s`` seconds and one at the end, with the time left at the rate so far."""

    def __init__(self, label: str, total: int, initial: int, *, every_s: float = 30.0, stream: Any = None) -> None:
        self.label, self.total, self.initial, self.every_s = label, total, initial, every_s
        self.stream = stream if stream is not None else sys.stderr
        self.start = self.last = time.monotonic()

    def update(self, finished: int, failed: int) -> None:
        now = time.monotonic()
        if now - self.last < self.every_s and finished < self.total:
            return
        self.last = now
        rate = (finished - self.initial) / max(now - self.start, 1e-9)
        left = (self.total - finished) / rate if rate > 0 else float("nan")
        eta = "" if finished >= self.total or left != left else f", about {max(left, 1) / 60:.0f} min left"
        print(f"{self.label}: {finished} of {self.total} cells finished ({failed} failed){eta}",
              file=self.stream, flush=True)


def accuracy_and_time_lines(split: dict[str, Any]) -> list[str]:
    """Each method's mean PSNR and SSIM beside its median ms per frame, fastest first (the sweep's last lines)."""
    times = split.get("method_ms_per_frame", {})
    accuracy = split.get("method_accuracy", {})
    if not times:
        return []
    width = max(len("method"), *(len(m) for m in times))
    lines = ["accuracy and time (mean over the ok cells; ms per frame: median of one reconstruct call, "
             "a recurrent method's warm-up on its event history included):",
             f"  {'method':<{width}}  {'PSNR dB':>7}  {'SSIM':>6}  {'ms/frame':>9}"]
    for m, ms in sorted(times.items(), key=lambda kv: kv[1]):
        psnr, ssim = accuracy.get(m, (float("nan"), float("nan")))
        lines.append(f"  {m:<{width}}  {psnr:7.2f}  {ssim:6.4f}  {ms:9.1f}")
    return lines


def _time_split(frame: pd.DataFrame) -> dict[str, Any]:
    """Where the time went (simulation per cell, each method's median ms per frame) and what it bought
    (each method's mean PSNR and SSIM over its ok rows)."""
    if frame.empty:
        return {}
    ok = frame[frame["status"] == OK]
    means = {metric: ok[ok["metric"] == metric].groupby("method")["value"].mean() for metric in ("psnr", "ssim")}
    one = frame[frame["metric"] == frame["metric"].iloc[0]]
    sim = one.drop_duplicates("cell")["sim_seconds"].dropna()
    per_method = (one[one["status"] == OK].groupby("method", sort=True)["ms_per_frame"].median().dropna())
    return {
        "simulation_s_per_cell": float(sim.mean()) if len(sim) else float("nan"),
        "simulation_s_total": float(sim.sum()),
        "method_ms_per_frame": {m: float(v) for m, v in per_method.items()},
        "method_accuracy": {m: (float(means["psnr"].get(m, float("nan"))), float(means["ssim"].get(m, float("nan"))))
                            for m in per_method.index},
        "method_s_total": {m: float(v) / 1e3 for m, v in
                           one[one["status"] == OK].groupby("method", sort=True)["ms_per_frame"].sum().items()},
    }


def preflight(spec: SweepSpec) -> None:
    """Refuse, before the first cell, a sweep whose cells cannot give results.

    Checks every scene's size against the SSIM window and that its source image loads (a missing
    photograph would otherwise fail every cell and report ``nan`` seconds per cell).

    Raises
    ------
    InputError
        One message naming the scene and the problem.
    """
    from neuspike.metrics import SSIM_WINDOW_SIDE
    from neuspike.utils.resources import check_memory
    from neuspike.scenes import make_scene
    from neuspike.simulation.budget import window_budget

    conditions = {c.condition for c in spec.grid.cells()}
    for entry in spec.grid.scenes:
        size = entry.spec.size
        if size is not None and min(size) < SSIM_WINDOW_SIDE:
            raise InputError(
                f"size {size[0]}x{size[1]}: both sides must be at least {SSIM_WINDOW_SIDE} pixels, the side of "
                f"the pinned SSIM window (scene {entry.name})"
            )
        if size is not None:  # before the scene is built: every cell renders the frames of one window at least
            frames = max(window_budget(*size, sensor=spec.sensor, condition=c, modalities=("spikes",),
                                       history_s=0.0).memory["frames"] for c in conditions)
            check_memory(frames, f"a cell of scene {entry.name} at {size[0]}x{size[1]}", "the frames of one window")
        try:
            make_scene(entry.spec)
        except NeuSpikeError as exc:
            raise InputError(f"scene {entry.name}: {exc}") from None


def _remove_stale_temporaries(out: Path) -> None:
    """Hidden ``.*.tmp`` files a killed run left in its own outputs (never in a shared cache)."""
    from neuspike.formats.staging import remove_stale_temporaries

    remove_stale_temporaries(out)
    for folder in ("parts", "errors", "images"):
        if (out / folder).is_dir():
            for sub in [out / folder, *(p for p in (out / folder).rglob("*") if p.is_dir())]:
                remove_stale_temporaries(sub)


def _write_images(images_dir: Path, axis: str, cell: grids.Cell, images: dict[str, Any]) -> None:
    """Write a cell's images in the layout of :mod:`bench.harness.images` (the report reads them back)."""
    from bench.harness.images import image_path, write_image_png

    value = getattr(cell.condition, axis)
    for name, image in images.items():
        write_image_png(image_path(images_dir, cell.scene.name, axis, value, name), image)


def _check_oversubscription(workers: int, threads: int) -> None:
    """Refuse local workers x threads beyond the usable CPUs: oversubscribed threads wait on each other
    at every small operation, and the timings would measure that instead of the methods."""
    usable = usable_cpus()
    if workers * threads > usable:
        raise InputError(f"--workers {workers} x --threads {threads} = {workers * threads} threads exceed the "
                         f"{usable} usable CPU(s) here; use --threads {max(1, usable // workers)} (or fewer workers)")


# ----------------------------------------------------------------------------------------------
# Running a sweep
# ----------------------------------------------------------------------------------------------

def prepare_execution(execution: Execution, weights: str | None) -> tuple[Any, int, bool, WorkerSetup]:
    """The executor, the threads per worker, whether the workers are remote, and the workers' set-up.

    Threads default to the usable CPUs that other processes leave idle, divided by the workers (1 on a
    remote Dask cluster); local
    workers x threads beyond the usable CPUs are refused (:class:`InputError`).
    """
    executor = execution.executor
    threads = execution.threads
    if threads is not None:
        threads = check_positive_int("threads", threads)
    if isinstance(executor, str):
        executor = make_executor(executor, workers=execution.workers, scheduler=execution.scheduler)
    remote = bool(isinstance(executor, DaskExecutor) and executor.scheduler)
    if threads is None:
        if remote:
            threads = 1
        else:  # the CPUs other processes leave idle, shared by the workers
            threads = announce_default_threads(executor.workers)
    if not remote:  # workers on this machine, with the threads given or the default
        _check_oversubscription(executor.workers, threads)
    plugins = tuple(str(Path(p).resolve()) if p.endswith(".py") else p for p in plugin_names(execution.plugins))
    setup = WorkerSetup(plugins=plugins, weights=weights, threads=threads, device=execution.device,
                        precision=execution.precision)
    return executor, threads, remote, setup


def run_sweep(spec: SweepSpec, out_dir: str | os.PathLike, execution: Execution = Execution()) -> SweepOutcome:
    """Run (or resume) a sweep into ``out_dir`` and assemble its ``results.csv``.

    Raises
    ------
    InputError
        Unknown methods, an unusable device or invalid options (before anything runs, and before
        ``out_dir`` is created: a refused sweep leaves no folder behind).
    ConfigMismatch
        ``out_dir`` holds results of a different sweep and ``execution.force`` is false.
    """
    from neuspike.formats.staging import check_writable_folder

    t_start = time.perf_counter()
    out = check_writable_folder(out_dir, what="output folder", create=False)
    preflight(spec)
    executor, threads, remote, setup = prepare_execution(execution, spec.weights)

    resolved = resolve_methods(spec, setup)  # unknown names and an unusable device refuse here
    arith = arithmetic(spec, setup)
    sweep_config = {**spec.as_dict(), "harness_version": HARNESS_VERSION, "resolved": resolved, **arith}
    check_writable_folder(out, what="output folder")  # every input accepted: only now is the folder created
    stale = check_config(out, sweep_config, execution.force)
    cache_dir = None
    if execution.use_cache:
        cache_dir = str(Path(execution.cache_dir).resolve() if execution.cache_dir else (out / "cache").resolve())

    cells = spec.grid.cells()
    tasks = []
    for cell in cells:
        tasks.append(CellTask(
            cell_id=cell_id(spec, resolved, cell, arith), cell=cell, sensor=spec.sensor, methods=spec.methods,
            modalities=tuple(resolved["modalities"]), history_s=resolved["history_s"],
            cache_dir=cache_dir, setup=setup, keep_images=spec.keeps_images(cell),
        ))
    if len({t.cell_id for t in tasks}) != len(tasks):
        raise InputError("two cells of the grid are identical; check the scene names and axes")
    extra = {"cache_dir": portable_path(cache_dir) if cache_dir is not None else None, "plugins": list(setup.plugins)}
    outcome = run_tasks(
        out, tasks, run_cell, config={"sweep": sweep_config}, stale=stale, executor=executor, threads=threads,
        remote=remote, execution=execution, label=f"{spec.name} sweep", run_info={"sweep": spec.name},
        execution_info=extra, skipped=dict(resolved["unavailable"]), t_start=t_start,
        write_images=lambda task, images: _write_images(out / "images", spec.axis, task.cell, images),
    )
    outcome.history_s = resolved["history_s"]
    outcome.use_cache = cache_dir is not None
    return outcome


@contextlib.contextmanager
def out_lock(out: Path) -> Iterator[None]:
    """Hold ``out/.lock`` for a run: a second run on the same folder is refused in one line instead of
    removing the first one's temporaries and mixing its parts. The lock is the kernel's (``flock``): it
    goes with the process, so a killed run leaves nothing that blocks the next."""
    try:
        import fcntl
    except ImportError:  # no flock here: run unlocked
        yield
        return
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "a+") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise InputError(f"{out}: another run is writing to this folder now; wait for it to finish, or use "
                             f"another --out") from None
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def run_tasks(out: Path, tasks: list[Any], run_fn: Any, **kwargs: Any) -> Any:
    """:func:`_run_tasks` with the output folder locked (:func:`out_lock`)."""
    with out_lock(out):
        return _run_tasks(out, tasks, run_fn, **kwargs)


def _run_tasks(
    out: Path, tasks: list[Any], run_fn: Any, *, config: dict[str, Any], stale: bool, executor: Any, threads: int,
    remote: bool, execution: Execution, label: str, run_info: dict[str, Any], execution_info: dict[str, Any],
    skipped: dict[str, str], t_start: float, write_images: Any = None,
) -> SweepOutcome:
    """Run every task without a part file, resumably, and assemble ``results.csv``: the loop every
    harness command shares (a sweep's cells, a dataset's recording instants).

    Parameters
    ----------
    out : Path
        The output folder (checked writable).
    tasks : list
        Picklable tasks with a unique ``cell_id``; ``run_fn(task)`` returns a
        :class:`~bench.harness.cells.CellResult` and never raises for a method's failure.
    config : dict
        What ``config.json`` holds besides ``execution`` (the identity :func:`check_config` compared).
    stale : bool
        The folder's old results belong to another configuration: they are removed first.
    executor, threads, remote
        From :func:`prepare_execution`.
    label : str
        The progress bar's name.
    run_info, execution_info : dict
        Extra entries of ``metadata.json`` and of ``config.json``'s ``execution``.
    skipped : dict
        Methods known to be unavailable, with the reason.
    write_images : callable or None
        ``write_images(task, images)`` stores a finished task's images before its part is written.
    """
    parts_dir, errors_dir = out / "parts", out / "errors"
    ids = [t.cell_id for t in tasks]
    if stale:
        for path in (out / "results.csv",):
            path.unlink(missing_ok=True)
        for folder in (parts_dir, errors_dir, out / "images"):
            shutil.rmtree(folder, ignore_errors=True)
    parts_dir.mkdir(exist_ok=True)
    _remove_stale_temporaries(out)  # left by a run killed while writing; never a result
    wanted = set(ids)
    for path in parts_dir.glob("*.csv"):  # parts of an older harness version or of a forced rerun
        if path.stem not in wanted:
            path.unlink()

    execution_config = {
        **executor.describe(), "threads_per_worker": threads, **execution_info,
        "allow_failures": execution.allow_failures,
    }
    write_json(out / "config.json", {**config, "execution": execution_config})

    done: dict[str, str] = {}
    for cid in ids:
        path = part_path(parts_dir, cid)
        if path.exists():
            try:
                status = ERROR if (read_csv(path)["status"] == ERROR).any() else OK
            except (OSError, ValueError):
                path.unlink()  # not a part this harness wrote; recompute
                continue
            if status == ERROR and execution.retry_failed:
                continue
            done[cid] = status
    todo = [t for t in tasks if t.cell_id not in done]

    previous = _read_json(out / "metadata.json") if not stale else None
    history = []
    if previous:
        history = list(previous.get("previous_runs", [])) + [
            {k: previous.get(k) for k in ("start", "end", "executor", "threads_per_worker",
                                           "cells_computed", "source")}]
    watch = None if remote else LoadWatch(threads * executor.workers, side_by_side=executor.workers > 1)
    run = collect(executor=executor.describe(), threads_per_worker=threads, start=now_iso(),
                  contended=None if remote else executor.workers > 1)
    run.update(run_info)
    run["previous_runs"] = history
    write_json(out / "metadata.json", run)

    n_failed_now = n_hits = n_computed = 0
    n_simulated: dict[str, int] = {}
    crashed: dict[str, str] = {}
    observed_threads: set[int] = set()
    skipped = dict(skipped)
    from tqdm import tqdm

    n_done_failed = sum(1 for s in done.values() if s == ERROR)
    bar = tqdm(total=len(tasks), initial=len(done), unit="cell", desc=label,
               disable=(None if execution.progress is None else not execution.progress),
               file=sys.stderr, dynamic_ncols=True)

    def postfix() -> None:
        bar.set_postfix(done=len(done), failed=n_done_failed + n_failed_now + len(crashed),
                        remaining=len(tasks) - len(done) - len(crashed), refresh=False)

    # no bar because stderr is a file or a pipe (not because --no-progress): a plain line now and then
    plain = ProgressLines(label, len(tasks), len(done)) if execution.progress is None and bar.disable else None

    postfix()
    try:
        with (executor if todo else contextlib.nullcontext()):
            for task, result in (executor.run(run_fn, todo) if todo else ()):
                if isinstance(result, BaseException):
                    crashed[task.cell_id] = one_line(result)
                else:
                    if result.images and write_images is not None:  # before the part: a finished cell has its images
                        write_images(task, result.images)
                    write_part(parts_dir, task.cell_id, result.rows)
                    if result.failures:
                        text = "\n".join(f"== {k} ==\n{v}" for k, v in result.failures.items())
                        write_text(errors_dir / f"{task.cell_id}.txt", text)
                    else:  # a retried cell that now succeeds
                        (errors_dir / f"{task.cell_id}.txt").unlink(missing_ok=True)
                    done[task.cell_id] = result.status
                    n_computed += 1
                    n_hits += int(result.cache_hit)
                    for modality in result.simulated:
                        n_simulated[modality] = n_simulated.get(modality, 0) + 1
                    n_failed_now += int(result.status == ERROR)
                    skipped.update(result.skipped)
                    if result.threads is not None:
                        observed_threads.add(result.threads)
                if watch is not None:
                    watch.read()
                postfix()
                bar.update(1)
                if plain is not None:
                    plain.update(len(done) + len(crashed), n_done_failed + n_failed_now + len(crashed))
    finally:
        bar.close()

    results_path = out / "results.csv"
    frame = assemble(parts_dir, ids, results_path)
    n_failed = sum(1 for s in done.values() if s == ERROR)
    n_missing = len(tasks) - len(done)
    split = _time_split(frame)
    outcome = SweepOutcome(
        out_dir=out, results_path=results_path, n_cells=len(tasks), n_ok=len(done) - n_failed,
        n_failed=n_failed, n_missing=n_missing, n_computed=n_computed, n_cache_hits=n_hits,
        skipped=skipped, allow_failures=execution.allow_failures,
        seconds=time.perf_counter() - t_start, time_split=split, simulated=n_simulated,
    )
    run = finish(run, cells_total=len(tasks), cells_computed=n_computed, cells_failed=n_failed,
                 cells_missing=n_missing, crashed=crashed, recording_cache_hits=n_hits,
                 threads_observed=sorted(observed_threads), time_split=split,
                 wall_seconds=outcome.seconds, **(watch.summary() if watch is not None else {}))
    write_json(out / "metadata.json", run)
    return outcome


# ----------------------------------------------------------------------------------------------
# Command line (shared with bench.noise)
# ----------------------------------------------------------------------------------------------
