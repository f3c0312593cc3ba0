"""Video-level benchmark: what accuracy costs in time, per method: ``python -m bench.video``.

The standard recording is the paper's fastest real scene, simulated: the fan at 2600 RPM over the
``camera`` photograph, 400x250, light L = 1/4, both sensors, in continuous mode (a sample per plane,
20,000 planes/s), with exact ground truth at every instant (:mod:`neuspike.video.truth`). Every
method streams it (:func:`neuspike.video.reconstruct_video`) at ``--fps`` output frames per second
of sensor time; per method the benchmark records

``frames_per_s``
    frames per second of the method's own time (reading and cutting the windows excluded: they are
    shared by all methods and measured once, in the ``read-only`` reference rows);
``real_time_factor``
    sensor seconds reconstructed per second of method time at that output rate
    (``frames_per_s / fps``; 1 = real time);
``mean_psnr_db``, ``mean_ssim``, ``mean_flicker_rmse``
    over the frames, against the ground truth (``data_range = 1``; flicker: RMS error of consecutive
    differences, see :mod:`neuspike.video.truth`).

Reference rows, measured in the same run: ``read-only spikes`` and ``read-only events`` (the stream
alone: reading spikes by plane range or events by time range and cutting each frame's sample, no
method; a method reads only the modalities it needs) and
``tfp (single-frame calls)`` (TFP through :func:`neuspike.formats.samples.load_sample` once per frame,
as ``python -m neuspike.reconstruct`` would: what streaming with shared windows saves).

Frames: the output instants start half a spike window (6.4 ms) into the recording and the recording
runs half a window past the last one, so every frame's spike window is centred on it (NeuSpike-Net
refuses shifted windows) and every method sees the same frames. Learned methods stream (recurrent
ones carry their state, NeuSpike-Net's representations slide); every learned method with weights
runs: ours from ``neuspike/trained/``, FireNet's published ones from ``--weights``, on ``--device``
(``cpu`` by default; ``cuda`` where torch sees a GPU; a device this machine lacks, or one that no
requested method runs on, is refused before anything is simulated or written). A method's time ends
when its image is back on the host: a learned method copies it from the device with a blocking copy
(:meth:`neuspike.methods.learned.LearnedMethod.to_image`), so on a GPU the clock is read after the
device's work, never while it is still queued.

Size of the run: the issue's standard is a 1 s recording (``--full``: 20,000 planes, 1,000 frames per
method at 1,000 frames/s; about 72 million events for this fan). On two shared cores that takes the
slow methods (SNM, TFSTP, FireNet) many minutes each, so the default is the first 50 ms of the same
recording (50 frames per method). A method that fails becomes a row with its error, not a crash.

Outputs (``--out``, default ``reports/video/bench``): ``results.csv`` (one row per method; ``device``:
the torch device of a learned method's row, empty for the others; ``read_out``: a recurrent event
network's read-out, empty for the others), ``metadata.json`` (spec with the
device, commit, versions, machine, threads), ``README.md`` (the table) and
``accuracy_vs_speed.png`` (from ``results.csv`` alone; ``--plot-only`` redraws it).

``--compile`` runs the learned methods' networks through ``torch.compile``: each method first streams
two frames untimed (a cold start and a continued step build every graph the stream uses; their time
is the row's ``compile_s``), then the timed stream starts afresh. ``--precision`` overrides ``auto``.
``--read-out window`` makes the recurrent event networks show the last full event window instead of
stepping the rest of the events up to each frame's instant (``read_out`` of
:class:`baselines.firenet.FireNet`); their rows say so in the note.

    python -m bench.video [--full | --duration S] [--fps F] [--methods a,b] [--weights DIR]
                          [--device D] [--precision P] [--compile] [--read-out R] [--cache DIR] [--out DIR]
                          [--threads N]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from neuspike.errors import InputError, NeuSpikeError, one_line
from neuspike.utils.cli import MethodOptions
from neuspike.utils.parallel import set_threads

COLUMNS = ("method", "inputs", "status", "frames", "fps", "method_s", "frames_per_s", "real_time_factor",
           "mean_psnr_db", "mean_ssim", "mean_flicker_rmse", "normalisation", "steps_per_frame", "threads", "device",
           "compile_s", "read_out", "error")
READ_ONLY = "read-only"
SINGLE_FRAME = "tfp (single-frame calls)"
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "reports" / "video" / "bench"
#: Where ``--full`` writes unless told (so the full run never overwrites the default run's report).
DEFAULT_OUT_FULL = DEFAULT_OUT.parent / "bench-full"


@dataclass(frozen=True)
class VideoBenchSpec:
    """The benchmark's settings (the parsed command line)."""

    duration_s: float = 0.05
    fps: float = 1000.0
    methods: tuple[str, ...] = ()
    width: int = 400
    height: int = 250
    rpm: float = 2600.0
    light: float = 0.25
    seed: int = 0
    event_history_s: float = 1.0
    single_frame_frames: int = 10
    #: torch intra-op threads, set again before every method (compiled kernels of other stages may
    #: change the process's OpenMP thread count); ``None`` leaves torch's own choice
    threads: int | None = None
    #: torch device of the learned methods (the others run on the CPU whatever it is)
    device: str = "cpu"
    #: run the learned methods' networks through ``torch.compile`` (compiled on two untimed frames
    #: streamed first, their time the row's ``compile_s``; see :class:`~neuspike.methods.learned.LearnedMethod`)
    compiled: bool = False
    #: precision of the learned methods (``None``: each method's own, ``auto`` for those shipped)
    precision: str | None = None
    #: what a streamed frame of the recurrent event networks shows (``None``: their own, ``"key"``;
    #: ``"window"``: the last full window, :class:`baselines.firenet.FireNet`); the others ignore it
    read_out: str | None = None


def simulate_standard(spec: VideoBenchSpec, folder: Path) -> dict[str, Any]:
    """Write the standard recording into ``folder`` (reused when its ``meta.json`` matches)."""
    from neuspike.conditions import Condition
    from neuspike.utils.rng import derive_rng
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.writing import write_sequence

    meta_path = folder / "meta.json"
    scene_spec = SceneSpec(kind="fan", size=(spec.width, spec.height), rpm=spec.rpm)
    if meta_path.is_file():
        meta = json.loads(meta_path.read_text())
        if (meta.get("scene", {}).get("spec") == scene_spec.as_dict() and meta.get("light") == spec.light
                and meta.get("seed") == spec.seed and meta.get("planes") == round(recorded_s(spec) * 20_000)):
            return meta
    scene = make_scene(scene_spec)
    condition = Condition(light=spec.light, motion=128)
    return write_sequence(scene, condition, folder, rng=derive_rng(spec.seed, "bench.video"), start_s=0.0,
                          duration_s=recorded_s(spec), seed=spec.seed, progress=False)


#: Spike window of every frame (planes at 20,000 planes/s) and the margin it needs at either end.
WINDOW_PLANES = 256
MARGIN_S = WINDOW_PLANES / 2 / 20_000.0


def recorded_s(spec: VideoBenchSpec) -> float:
    """Sensor seconds simulated: the frames' span plus half a window at either end."""
    return spec.duration_s + 2 * MARGIN_S


def _row(**fields: Any) -> dict[str, Any]:
    row = {c: None for c in COLUMNS}
    row.update(fields)
    return row


def measure_method(name: str, rec: Any, times: np.ndarray, truth: Any, spec: VideoBenchSpec,
                   weights_dir: Path | None) -> dict[str, Any]:
    """Stream one method over ``times``; its row (an ``error`` row when it fails)."""
    from neuspike.methods import create_many, entry, uses_device
    from neuspike.methods.registry import reads_windows
    from neuspike.video import stream_methods
    from neuspike.video.truth import FlickerMeter, score_frame

    inputs, device = "", None
    _apply_threads(spec)
    try:
        e = entry(name)
        inputs = "+".join(sorted(e.inputs))
        device = spec.device if uses_device(e) else None  # a classical method alone would refuse a GPU device
        method = create_many([name], weights_dir=weights_dir, device=device or "cpu", compiled=spec.compiled,
                             precision=spec.precision, read_out=spec.read_out if reads_windows(e) else None,
                             skip_unavailable=False)[name].method
        compile_s = None
        if method.params.get("compiled", False):
            # compile untimed first: the first two frames build every graph the stream uses (a cold
            # start and a continued step); the timed stream below starts afresh (stream_methods resets)
            t0 = time.perf_counter()
            for _ in stream_methods([method], rec, times[:2], event_history_s=spec.event_history_s):
                pass
            compile_s = time.perf_counter() - t0
        busy, psnrs, ssims, flicks, steps = 0.0, [], [], [], []
        meter = FlickerMeter()
        for sample, images, seconds in stream_methods([method], rec, times, event_history_s=spec.event_history_s):
            busy += seconds[name]
            img = images[name]
            _, gt = truth.at(sample.key_time_s)
            p, s = score_frame(img, gt)
            psnrs.append(p)
            ssims.append(s)
            f = meter.update(img, gt)
            if not math.isnan(f):
                flicks.append(f)
            if method.last_steps is not None:
                steps.append(method.last_steps)
        n = len(times)
        return _row(method=name, inputs=inputs, status="ok", frames=n, fps=spec.fps, method_s=busy,
                    frames_per_s=n / busy, real_time_factor=n / busy / spec.fps,
                    mean_psnr_db=float(np.mean(psnrs)), mean_ssim=float(np.mean(ssims)),
                    mean_flicker_rmse=float(np.mean(flicks)) if flicks else None,
                    normalisation=method.last_normalisation,
                    steps_per_frame=float(np.mean(steps)) if steps else None, threads=_threads(), device=device,
                    compile_s=compile_s, read_out=method.params.get("read_out"), error="")
    except Exception as exc:  # a failing method is a row with its error, not a crash of the benchmark
        return _row(method=name, inputs=inputs, status="error", frames=0, fps=spec.fps, device=device,
                    error=one_line(exc))


def _check_device(device: str, names: Sequence[str]) -> None:
    """Refuse ``device`` before any work when no requested method can use it
    (:func:`neuspike.methods.check_device` over the names the registry knows; an unknown name becomes
    its own error row, as any method that fails)."""
    from neuspike.methods import available, check_device, entry

    known = set(available())
    check_device(device, [entry(name) for name in names if name in known])


def _threads() -> int:
    import torch

    return torch.get_num_threads()


def _apply_threads(spec: VideoBenchSpec) -> None:
    if spec.threads is not None:
        set_threads(spec.threads)


def measure_references(rec: Any, times: np.ndarray, spec: VideoBenchSpec, folder: Path) -> list[dict[str, Any]]:
    """The ``read-only`` stream and TFP through per-frame :func:`load_sample` calls."""
    from neuspike.methods import create_many
    from neuspike.formats.samples import load_sample
    from neuspike.video import stream_samples

    _apply_threads(spec)
    rows = []
    for modality in sorted(rec.modalities):
        t0 = time.perf_counter()
        n = sum(1 for _ in stream_samples(rec, times, inputs={modality}, event_history_s=spec.event_history_s))
        read_s = time.perf_counter() - t0
        rows.append(_row(method=f"{READ_ONLY} {modality}", inputs=modality, status="ok", frames=n, fps=spec.fps,
                         method_s=read_s, frames_per_s=n / read_s, real_time_factor=n / read_s / spec.fps,
                         threads=_threads(), error=""))
    sub = times[np.linspace(0, len(times) - 1, min(spec.single_frame_frames, len(times))).round().astype(int)]
    tfp = create_many(["tfp"])["tfp"].method
    t0 = time.perf_counter()
    for t in sub:
        tfp.reconstruct(load_sample(spikes=folder / "spikes.dat", at_s=float(t)))
    single_s = time.perf_counter() - t0
    rows.append(_row(method=SINGLE_FRAME, inputs="spikes", status="ok", frames=len(sub), fps=spec.fps,
                     method_s=single_s, frames_per_s=len(sub) / single_s,
                     real_time_factor=len(sub) / single_s / spec.fps, normalisation=tfp.last_normalisation,
                     threads=_threads(), error="reading included"))
    return rows


def run(spec: VideoBenchSpec, out: Path, *, cache: Path | None = None, weights_dir: Path | None = None,
        progress: bool = True) -> list[dict[str, Any]]:
    """Simulate (or reuse) the standard recording, measure every method, write the outputs."""
    import pandas as pd
    import torch

    from bench.harness.provenance import LoadWatch, collect, finish, now_iso
    from neuspike.utils.atomic import write_text
    from neuspike.methods import available
    from neuspike.video import frame_times, open_recording
    from neuspike.video.truth import ground_truth_for
    from neuspike.video.writers import check_writable

    names = list(spec.methods) or [n for n in available()]
    _check_device(spec.device, names)  # before anything is simulated or the output folder is created
    out = check_writable(out)
    _apply_threads(spec)
    run_meta = collect(executor={"kind": "in-process"}, threads_per_worker=torch.get_num_threads(),
                       start=now_iso(), contended=None)
    load_start = _load_average()
    watch = LoadWatch(torch.get_num_threads())  # other jobs' load, read after every method
    with tempfile.TemporaryDirectory(prefix="video-bench-") as tmp:
        folder = Path(cache) if cache is not None else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        meta = simulate_standard(spec, folder)
        sim_s = time.perf_counter() - t0
        print(f"standard recording: fan {spec.rpm:g} RPM, {spec.width}x{spec.height}, {spec.duration_s:g} s, "
              f"{meta.get('planes')} planes, {meta.get('event_count', 0):,} events ({sim_s:.1f} s)", file=sys.stderr)
        rows: list[dict[str, Any]] = []
        with open_recording(folder) as rec:
            times = frame_times(MARGIN_S, MARGIN_S + spec.duration_s, spec.fps)
            truth = ground_truth_for(folder, rec.meta, height=rec.height, width=rec.width, tolerance_s=0.5 / spec.fps)
            rows += measure_references(rec, times, spec, folder)
            bar = None
            if progress:
                from tqdm import tqdm

                bar = tqdm(names, unit="method", desc="video bench", file=sys.stderr)
            for name in names:
                if bar is not None:
                    bar.set_postfix_str(name)
                rows.append(measure_method(name, rec, times, truth, spec, weights_dir))
                watch.read()
                r = rows[-1]
                shown = (f"{r['frames_per_s']:.1f} frames/s, PSNR {r['mean_psnr_db']:.2f} dB" if r["status"] == "ok"
                         else r["error"])
                print(f"{name}: {shown}", file=sys.stderr)
                if bar is not None:
                    bar.update(1)
            if bar is not None:
                bar.close()
    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    from neuspike.utils.atomic import replacing

    with replacing(out / "results.csv") as tmp_csv:
        frame.to_csv(tmp_csv, index=False, float_format="%.6g")
    run_meta = finish(run_meta, load_average_start=load_start, load_average_end=_load_average(), simulation_s=sim_s,
                      recording=meta.get("scene"), event_count=meta.get("event_count"),
                      spike_count=meta.get("spike_count"), torch_threads=torch.get_num_threads(),
                      **watch.summary())
    if run_meta["timing_contended"]:
        print("note: timings contended: " + "; ".join(run_meta["contention"]), file=sys.stderr)
    write_text(out / "metadata.json", json.dumps({"spec": asdict(spec), "run": run_meta}, indent=2, default=str) + "\n")
    write_text(out / "README.md", markdown(frame, spec, run_meta))
    plot(out / "results.csv", out / "accuracy_vs_speed.png")
    return rows


def _load_average() -> list[float] | None:
    """The machine's 1, 5 and 15 minute load averages (other work slows every figure down)."""
    try:
        import os

        return [round(v, 2) for v in os.getloadavg()]
    except (AttributeError, OSError):
        return None


def _contention_sentence(run_meta: dict[str, Any]) -> str:
    """What the page says about other jobs' load (:class:`bench.harness.provenance.LoadWatch`'s verdict)."""
    contended = run_meta.get("timing_contended")
    if contended:
        return " **Timings contended**: " + "; ".join(run_meta.get("contention", [])) + ", so frames/s is lower than quiet."
    if contended is None:
        return " Whether other jobs shared the machine is unknown (no load average here)."
    return f" Timings uncontended (other jobs' load at most {run_meta.get('other_load', 0.0):.2f})."


def _fmt(v: Any, spec: str) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return format(v, spec)


def markdown(frame: Any, spec: VideoBenchSpec, run_meta: dict[str, Any]) -> str:
    """The results as a Markdown page."""
    m = run_meta.get("machine", {})
    lines = [
        "# Video benchmark",
        "",
        f"The fan at {spec.rpm:g} RPM, {spec.width}x{spec.height}, L = {spec.light:g}, simulated in continuous mode "
        f"({spec.duration_s:g} s of sensor time), streamed at {spec.fps:g} output frames per second of sensor time; "
        f"{len(frame)} rows. Machine: {m.get('cpu_model') or '?'}, {m.get('usable_cpus')} usable CPUs, torch threads "
        f"{spec.threads if spec.threads is not None else 'torch default'} (per row: threads), learned methods on "
        f"device {spec.device}, load average {run_meta.get('load_average_start')} at the start and "
        f"{run_meta.get('load_average_end')} at the end; commit {run_meta.get('source', {}).get('commit', '?')}. "
        "frames/s is the method's own time (reading excluded; see the read-only rows); real-time factor = frames/s "
        "divided by the output rate. Scores against the exact ground truth, data_range 1; flicker = RMS error of "
        "consecutive differences. Regenerate: `python -m bench.video"
        + (" --full" if spec.duration_s >= 1.0 else "") + (f" --device {spec.device}" if spec.device != "cpu" else "")
        + (f" --precision {spec.precision}" if spec.precision else "")
        + (" --compile" if spec.compiled else "") + (f" --read-out {spec.read_out}" if spec.read_out else "")
        + "`." + _contention_sentence(run_meta),
        "",
        "| method | inputs | frames/s | real-time factor | PSNR (dB) | SSIM | flicker | steps/frame | threads | note |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in frame.to_dict("records"):
        lines.append(
            f"| {r['method']} | {r['inputs'] or ''} | {_fmt(r['frames_per_s'], '.1f')} | {_fmt(r['real_time_factor'], '.3g')} "
            f"| {_fmt(r['mean_psnr_db'], '.2f')} | {_fmt(r['mean_ssim'], '.3f')} | {_fmt(r['mean_flicker_rmse'], '.4f')} "
            f"| {_fmt(r['steps_per_frame'], '.1f')} | {_fmt(r['threads'], '.0f')} "
            f"| {_note(r)} |"
        )
    return "\n".join(lines) + "\n"


def _note(r: dict[str, Any]) -> str:
    """A row's note: its error, or that its network was compiled (untimed, before its frames) and
    that its frames show the last full event window (``--read-out window``)."""
    if isinstance(r.get("error"), str) and r["error"]:
        return r["error"]
    notes = []
    compile_s = r.get("compile_s")
    if compile_s is not None and not (isinstance(compile_s, float) and math.isnan(compile_s)):
        notes.append(f"compiled (torch.compile; {compile_s:.1f} s for two untimed frames first)")
    if r.get("read_out") == "window":
        notes.append("frames read out at the last full event window")
    return "; ".join(notes)


def plot(csv_path: Path, png_path: Path) -> Path:
    """Mean PSNR against frames/s (log scale), one point per method, from ``results.csv`` alone."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from neuspike.utils.atomic import replacing

    frame = pd.read_csv(csv_path)
    ok = frame[(frame["status"] == "ok") & frame["mean_psnr_db"].notna()]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in ok.to_dict("records"):
        marker = {"spikes": "o", "events": "s"}.get(r["inputs"], "D")
        ax.scatter(r["frames_per_s"], r["mean_psnr_db"], marker=marker)
        ax.annotate(r["method"], (r["frames_per_s"], r["mean_psnr_db"]), fontsize=7, xytext=(4, 3),
                    textcoords="offset points")
    for r, ls in zip(frame[frame["method"].str.startswith(READ_ONLY)].to_dict("records"), ("--", ":")):
        ax.axvline(float(r["frames_per_s"]), color="grey", ls=ls, lw=1, label=r["method"])
        ax.legend(fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("frames per second of method time (log)")
    ax.set_ylabel("mean PSNR (dB)")
    ax.set_title("video: accuracy against speed (o spikes, s events, D both)", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with replacing(png_path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
    return png_path


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 400x250, got {text!r}") from None
    return w, h


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.video", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--full", action="store_true", help="the standard 1 s recording (default: its first 50 ms)")
    p.add_argument("--duration", type=float, help="seconds of sensor time (default: 0.05; --full: 1)")
    p.add_argument("--fps", type=float, default=1000.0, help="output frames per second of sensor time (default: 1000)")
    p.add_argument("--methods", default="", help="comma list (default: every registered method)")
    p.add_argument("--size", type=_size, default=(400, 250), help="sensor WxH (default: 400x250)")
    p.add_argument("--event-history", type=float, default=1.0, help="seconds of event history per frame (default: 1)")
    MethodOptions.add_arguments(p, flags=("weights", "plugin"))
    p.add_argument("--cache", type=Path, help="keep the simulated recording here and reuse it")
    p.add_argument("--threads", type=int, help="torch intra-op threads (default: the usable CPUs that other "
                   "processes leave idle)")
    MethodOptions.add_arguments(p, flags=("device", "precision", "compile", "read_out"))
    p.add_argument("--out", type=Path, default=None,
                   help=f"output folder (default: {DEFAULT_OUT}; with --full: {DEFAULT_OUT_FULL})")
    p.add_argument("--plot-only", action="store_true", help="redraw accuracy_vs_speed.png from --out/results.csv")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.out is None:
        args.out = DEFAULT_OUT_FULL if args.full else DEFAULT_OUT
    try:
        if args.plot_only:
            plot(args.out / "results.csv", args.out / "accuracy_vs_speed.png")
            return 0
        options = MethodOptions.from_args(args)
        if args.threads is not None and args.threads < 1:
            raise InputError(f"--threads must be >= 1, got {args.threads}")
        duration = args.duration if args.duration is not None else (1.0 if args.full else 0.05)
        if not duration > 0:
            raise InputError(f"--duration must be positive, got {duration}")
        from neuspike.methods.plugins import load_requested

        load_requested(args.plugin)  # their methods run beside the registered ones
        methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
        threads = args.threads
        if threads is None:  # the CPUs other processes leave idle
            from neuspike.utils.resources import announce_default_threads

            threads = announce_default_threads()
        spec = VideoBenchSpec(duration_s=duration, fps=args.fps, methods=methods, width=args.size[0],
                              height=args.size[1], event_history_s=args.event_history, threads=threads,
                              device=options.device, compiled=options.compiled,
                              precision=options.precision, read_out=options.read_out)
        rows = run(spec, args.out, cache=args.cache, weights_dir=options.weights_dir,
                   progress=not args.no_progress)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}/results.csv ({len(rows)} rows), README.md, metadata.json, accuracy_vs_speed.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
