"""``python -m neuspike.video``: a recording in, videos out.

The flags are parsed into a frozen :class:`VideoSpec`; :func:`run` checks everything that can be
checked before any work (the methods exist and have their inputs, the output rate suits them, the
time range is inside the recording and holds at least one frame, the output folder is writable),
then streams the recording once through every method (:func:`neuspike.video.stream.stream_methods`)
and writes, in ``--out``:

``NAME.mp4``
    each method's video (OpenCV, ``mp4v``, played at ``--play-fps``);
``NAME/frame_000000.png`` (and ``.npy`` with ``--frames png,npy``)
    each frame, 8-bit (``round(255 x)``) and float32 in [0, 1];
``compare.mp4``
    the methods side by side with their names burnt in (plus the ground truth when there is one);
``contact_sheet.png``
    ``--sheet-frames`` instants evenly spread, one row per method;
``metrics.csv`` and ``metrics.png``
    with ground truth (simulated folders): PSNR, SSIM and flicker per frame and per method, and
    their plot over time (:mod:`neuspike.video.truth`);
``video.json``
    the settings, the frame times, the recording's metadata and each method's frames per second.

The folder is written whole under a temporary name beside ``--out`` and swapped in when complete
(:func:`neuspike.formats.staging.staged_folder`): after a failure or a kill ``--out`` is entirely the
earlier run's. A run replaces every output of the earlier one, the videos and frames of methods it
no longer runs included (its ``video.json`` names them); other files in ``--out`` are kept. A video
is published only when it is a whole MPEG-4 file (OpenCV does not report failed writes: a full disk
or a file size limit is an error, not a truncated video). Ground truth of a recording smaller than
the SSIM window is not used, as for a single frame (:mod:`neuspike.formats.samples`). Errors print one
line and exit with status 2.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from neuspike.utils.cli import ArgumentParser, MethodOptions, UsageError
from neuspike.errors import InputError, NeuSpikeError, one_line

if TYPE_CHECKING:  # numpy, OpenCV and torch load after the arguments are parsed: --help answers at once
    import numpy as np

__all__ = ["VideoSpec", "build_parser", "run", "main"]

FRAME_KINDS = ("png", "npy")


@dataclass(frozen=True)
class VideoSpec:
    """Everything one video run needs (the parsed command line)."""

    methods: tuple[str, ...]
    out: Path
    recording: Path | None = None
    spikes: Path | None = None
    events: Path | None = None
    fps: float = 1000.0
    start_s: float | None = None
    end_s: float | None = None
    play_fps: float = 25.0
    frames: tuple[str, ...] = ("png",)
    sheet_frames: int = 6
    sheet_width: int = 1600
    window_planes: int | None = None
    event_history_s: float | None = None
    height: int | None = None
    width: int | None = None
    raw_width: int | None = None
    plane_rate_hz: float | None = None
    gain: float | None = None
    dark_rate: float | None = None
    weights: Path | None = None
    device: str = "cpu"
    #: precision of the learned methods (``None``: each method's own, ``auto`` for those shipped)
    precision: str | None = None
    #: run the learned methods' networks through ``torch.compile`` (the first frames pay the compile)
    compiled: bool = False
    #: what a streamed frame of the recurrent event networks shows (``None``: their own, ``"key"``)
    read_out: str | None = None
    progress: bool = True


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="python -m neuspike.video",
        description=(
            "Reconstruct a video from a spike recording (.dat, .npz), an event recording (.h5/.hdf5, .txt,\n"
            ".npz, .aedat4), both, or a simulated recording folder, with any registered methods. Writes per\n"
            "method an .mp4 and its frames, a side-by-side comparison video and a contact sheet; with\n"
            "ground truth (simulated folders) per-frame PSNR, SSIM and flicker in metrics.csv and a plot.\n"
            "The recording is read as it goes (spikes by plane range, events by time range): memory is\n"
            "bounded by the window, not by the recording."
        ),
        epilog=(
            "examples:\n"
            "  python -m neuspike.simulate --scene fan --rpm 2600 --mode continuous --duration 0.05 --out out/fan\n"
            "  python -m neuspike.video out/fan --method tfp,tfi,events-highpass --fps 2000 --out out/fan/video\n"
            "  python -m neuspike.video --spikes helicopter.npz --method tfp-w32,tfi --fps 20000 --out out/heli\n"
            "  python -m neuspike.video --events driving.hdf5 --method events-highpass --fps 200 --start 3.0 --end 3.5 --out out/drive\n"
            "\n"
            "--fps is frames per second of sensor time; up to the plane rate for spike methods (one frame per\n"
            "plane), any rate for event-only methods. Exit status: 0 on success, 2 on an error (one line on stderr)."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("recording", nargs="?", type=Path,
                   help="a simulated recording folder, or one spike or event file")
    p.add_argument("--spikes", type=Path, metavar="FILE", help="spike recording: .dat (Vidar) or .npz")
    p.add_argument("--events", type=Path, metavar="FILE", help="event recording: .h5/.hdf5, .txt, .npz or .aedat4")
    p.add_argument("--method", action="append", default=[], metavar="NAME",
                   help="method to run; repeat the flag or give a comma list (see python -m neuspike.reconstruct --list)")
    p.add_argument("--fps", type=float, default=1000.0,
                   help="output frames per second of sensor time (default: 1000)")
    p.add_argument("--start", type=float, metavar="SECONDS", help="first instant, sensor seconds (default: recording start; with a method that needs "
                        "centred spike windows, e.g. neuspike-net, half a window in)")
    p.add_argument("--end", type=float, metavar="SECONDS", help="last instant, sensor seconds (default: recording end; half a window before it for such methods)")
    p.add_argument("--play-fps", type=float, default=25.0, help="playback rate of the .mp4 files (default: 25)")
    p.add_argument("--frames", default="png", help="per-frame files: png, npy, png,npy or none (default: png)")
    p.add_argument("--sheet-frames", type=int, default=6, help="instants in the contact sheet (default: 6)")
    p.add_argument("--sheet-width", type=int, default=1600,
                   help="largest width of the contact sheet in pixels; tiles shrink to fit (default: 1600)")
    p.add_argument("--window-planes", type=int, metavar="N",
                   help="spike window length in planes (default: 256; a simulated window's own length)")
    p.add_argument("--event-history", type=float, metavar="SECONDS",
                   help="seconds of events before each window given to event methods (default: 1, as "
                        "python -m neuspike.reconstruct; memory grows with it)")
    p.add_argument("--height", type=int, metavar="H", help="sensor height; required for a .dat without meta.json")
    p.add_argument("--width", type=int, metavar="W", help="sensor width; required for a .dat without meta.json")
    p.add_argument("--raw-width", type=int, metavar="W", help="stored width of a .dat with extra columns (e.g. 416)")
    p.add_argument("--plane-rate", type=float, metavar="HZ", help="spike planes per second (default: meta.json's, else 20000)")
    p.add_argument("--gain", type=float, metavar="G", help="spikes per plane per unit radiance (default: the recording's)")
    p.add_argument("--dark-rate", type=float, metavar="D",
                   help="spikes per plane a pixel fires in darkness, mean over pixels (a capped calibration; "
                        "default: the recording's)")
    MethodOptions.add_arguments(p, flags=MethodOptions.FLAGS)
    p.add_argument("--out", type=Path, metavar="DIR", help="output folder (created if missing)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def _split(values: Sequence[str]) -> tuple[str, ...]:
    names: list[str] = []
    for v in values:
        for part in v.split(","):
            part = part.strip()
            if part and part not in names:
                names.append(part)
    return tuple(names)


def spec_from_args(args: argparse.Namespace) -> VideoSpec:
    """The frozen spec of parsed arguments (usage checks only; files are checked by :func:`run`)."""
    if args.out is None:
        raise InputError("give an output folder with --out DIR")
    methods = _split(args.method)
    if not methods:
        raise InputError("give at least one --method NAME (see python -m neuspike.reconstruct --list)")
    frames = tuple(f for f in _split([args.frames]) if f != "none")
    bad = [f for f in frames if f not in FRAME_KINDS]
    if bad:
        raise InputError(f"--frames: expected png, npy, png,npy or none, got {args.frames!r}")
    options = MethodOptions.from_args(args)
    return VideoSpec(
        methods=methods, out=args.out, recording=args.recording, spikes=args.spikes, events=args.events,
        fps=args.fps, start_s=args.start, end_s=args.end, play_fps=args.play_fps, frames=frames,
        sheet_frames=args.sheet_frames, sheet_width=args.sheet_width, window_planes=args.window_planes,
        event_history_s=args.event_history,
        height=args.height, width=args.width, raw_width=args.raw_width, plane_rate_hz=args.plane_rate,
        gain=args.gain, dark_rate=args.dark_rate, weights=options.weights_dir, device=options.device,
        precision=options.precision, compiled=options.compiled, read_out=options.read_out,
        progress=not args.no_progress,
    )


def _create_methods(spec: VideoSpec, modalities: frozenset[str]) -> list[Any]:
    from neuspike.methods import create_many, entry, load_entry_points

    for problem in load_entry_points():
        print(f"warning: {problem}", file=sys.stderr)
    entries = []
    for name in spec.methods:
        e = entry(name)
        if Path(name).name != name or name in (".", "..") or name in ("compare", "contact_sheet", "metrics"):
            raise InputError(f"method name {name!r} cannot be used as an output name")
        missing = sorted(set(e.inputs) - modalities)
        if missing:
            raise InputError(f"method {name!r} needs {' and '.join(missing)}, which the recording lacks "
                             f"(it has {', '.join(sorted(modalities))})")
        entries.append(e)
    made = create_many([e.name for e in entries], weights_dir=spec.weights, device=spec.device,
                       precision=spec.precision, compiled=spec.compiled, read_out=spec.read_out,
                       skip_unavailable=False)
    return [c.method for c in made.values()]


def _range(spec: VideoSpec, span: tuple[float, float]) -> tuple[float, float]:
    lo, hi = span
    start = lo if spec.start_s is None else float(spec.start_s)
    end = hi if spec.end_s is None else float(spec.end_s)
    if not (math.isfinite(start) and math.isfinite(end)):
        raise InputError(f"--start and --end must be finite, got {start!r}, {end!r}")
    if start >= end:
        raise InputError(f"--start {start:.6f} s is not before --end {end:.6f} s")
    if start < lo - 1e-12 or end > hi + 1e-12:
        raise InputError(f"the range [{start:.6f}, {end:.6f}] s is not inside the recording [{lo:.6f}, {hi:.6f}] s")
    return start, end


def _centred_range(spec: VideoSpec, rec: Any, methods: Sequence[Any], start: float, end: float,
                   stream: Any) -> tuple[float, float]:
    """Keep frames whose spike window is centred when a method needs it (NeuSpike-Net): a default
    end is moved in, with a note; a range the user gave that reaches outside is refused."""
    from neuspike.video.stream import centred_span, needs_centred_window

    strict = [m.name for m in methods if needs_centred_window(m)]
    if not strict or rec.spikes_path is None:
        return start, end
    lo, hi = centred_span(rec, spec.window_planes)
    for given, value, inside in (("--start", spec.start_s, start >= lo - 1e-12), ("--end", spec.end_s, end <= hi + 1e-12)):
        if value is not None and not inside:
            raise InputError(
                f"{given} {value:.6f} s: {', '.join(strict)} need(s) the spike window centred on each frame, which "
                f"holds for instants in [{lo:.6f}, {hi:.6f}) s only (half a window from either end)")
    new_start, new_end = max(start, lo), min(end, hi)
    if new_start >= new_end:
        raise InputError(f"no instant of [{start:.6f}, {end:.6f}) s has a centred spike window, which "
                         f"{', '.join(strict)} need(s): use [{lo:.6f}, {hi:.6f}) s")
    if (new_start, new_end) != (start, end):
        print(f"note: frames limited to [{new_start:.6f}, {new_end:.6f}) s, where the spike window is centred on "
              f"the frame ({', '.join(strict)} refuse(s) windows shifted at the recording's ends)", file=stream)
    return new_start, new_end


def _history(spec: VideoSpec) -> float:
    """Seconds of event history before each window (``--event-history``, default the single-frame one)."""
    from neuspike.formats.samples import EVENT_HISTORY_S

    history = EVENT_HISTORY_S if spec.event_history_s is None else spec.event_history_s
    if history < 0 or not math.isfinite(history):
        raise InputError(f"--event-history must be >= 0 seconds, got {history!r}")
    return history


def run(spec: VideoSpec, stream: Any = None) -> dict[str, Any]:
    """Write the videos of ``spec`` (see the module docstring); returns the summary written to ``video.json``.

    Raises
    ------
    NeuSpikeError
        A failed check; nothing is written when the checks before the work fail, and nothing
        under a final name when the work fails.
    """
    import numpy as np

    from neuspike.formats.staging import check_writable_folder, staged_folder
    from neuspike.metrics import SSIM_WINDOW_SIDE
    from neuspike.video.stream import check_fps, frame_times, open_recording
    from neuspike.video.truth import ground_truth_for

    stream = stream if stream is not None else sys.stdout
    if spec.play_fps <= 0 or not math.isfinite(spec.play_fps):
        raise InputError(f"--play-fps must be positive, got {spec.play_fps!r}")
    if spec.sheet_frames < 1:
        raise InputError(f"--sheet-frames must be at least 1, got {spec.sheet_frames}")
    if spec.sheet_width < 64:
        raise InputError(f"--sheet-width must be at least 64 pixels, got {spec.sheet_width}")
    _history(spec)
    with open_recording(spec.recording, spikes=spec.spikes, events=spec.events, height=spec.height,
                        width=spec.width, raw_width=spec.raw_width, plane_rate_hz=spec.plane_rate_hz,
                        gain=spec.gain, dark_rate=spec.dark_rate) as rec:
        methods = _create_methods(spec, rec.modalities)
        inputs = set().union(*(m.inputs for m in methods))
        fps = check_fps(spec.fps, rec, inputs)
        start, end = _range(spec, rec.span_s())
        start, end = _centred_range(spec, rec, methods, start, end, stream)
        times = frame_times(start, end, fps)
        final = check_writable_folder(spec.out, what="--out", create=False)
        truth = ground_truth_for(rec.folder, rec.meta, height=rec.height, width=rec.width, tolerance_s=0.5 / fps)
        if truth is not None and min(rec.height, rec.width) < SSIM_WINDOW_SIDE:
            # as a single-frame load: ground truth found beside a recording too small to score is not used
            print(f"note: ground truth ({truth.source}) not used: {rec.width}x{rec.height} is smaller than the "
                  f"{SSIM_WINDOW_SIDE}x{SSIM_WINDOW_SIDE} SSIM window, so no frame can be scored", file=stream)
            truth = None
        n = len(times)
        sheet_idx = sorted(set(np.linspace(0, n - 1, min(spec.sheet_frames, n)).round().astype(int).tolist()))
        print(f"recording: {rec.width}x{rec.height}, {', '.join(sorted(rec.modalities))}, "
              f"[{start:.6f}, {end:.6f}) s; {n} frames at {fps:g} frames/s of sensor time; "
              f"ground truth: {truth.source if truth else 'none'}", file=stream)

        names = [m.name for m in methods]
        staging = None
        try:
            with staged_folder(final, ours=_our_entries(final, names)) as staging:
                summary = _write(spec, rec, methods, times, fps, start, end, truth, sheet_idx, staging, stream)
        except (NeuSpikeError, OSError) as exc:
            if staging is not None:  # name the output folder, not its temporary stand-in
                _rename_in(exc, str(staging), str(final))
            raise
    for name, m in summary["methods"].items():
        line = f"{name}: {m['method_frames_per_s']:.1f} frames/s (method time)"
        if m["mean_psnr_db"] is not None:
            line += f"; mean PSNR {m['mean_psnr_db']:.2f} dB, SSIM {m['mean_ssim']:.4f}"
            if m["mean_flicker_rmse"] is not None:
                line += f", flicker {m['mean_flicker_rmse']:.4f}"
        print(line, file=stream)
    n, wall = summary["frames"], summary["wall_seconds"]
    scored = any(m["scored_frames"] for m in summary["methods"].values())
    print(f"wrote {final}/: {', '.join(name + '.mp4' for name in names)}, compare.mp4, contact_sheet.png"
          f"{', metrics.csv, metrics.png' if scored else ''}, video.json "
          f"({n} frames in {wall:.2f} s, {n / wall:.1f} frames/s)", file=stream)
    return summary


def _rename_in(exc: BaseException, old: str, new: str) -> None:
    """Replace the path ``old`` by ``new`` in the message of ``exc`` (in place)."""
    if isinstance(exc, OSError) and not isinstance(exc, NeuSpikeError) and exc.strerror is not None:
        for attr in ("filename", "filename2"):
            value = getattr(exc, attr, None)
            if isinstance(value, str):
                setattr(exc, attr, value.replace(old, new))
    else:
        exc.args = tuple(a.replace(old, new) if isinstance(a, str) else a for a in exc.args)


#: What a run writes besides its methods' ``NAME.mp4`` and ``NAME/``.
OUTPUTS = ("compare.mp4", "contact_sheet.png", "metrics.csv", "metrics.png", "video.json")


def _our_entries(out: Path, names: Sequence[str]) -> set[str]:
    """The entries of ``out`` a run replaces: its own, and those of the run that wrote ``out`` before
    (named by its ``video.json``), so that no method's old video stays beside the new ones."""
    methods = set(names)
    try:
        methods |= {str(name) for name in json.loads((out / "video.json").read_text()).get("methods", {})}
    except (OSError, ValueError, AttributeError):
        pass
    return {e for name in methods for e in (name, f"{name}.mp4")} | set(OUTPUTS)


def _write(spec: VideoSpec, rec: Any, methods: list[Any], times: np.ndarray, fps: float, start: float, end: float,
           truth: Any, sheet_idx: list[int], out: Path, stream: Any) -> dict[str, Any]:
    """Stream ``rec`` through ``methods`` and write every output into ``out`` (a staging folder);
    return the summary written to ``video.json``."""
    import numpy as np

    from neuspike.utils.atomic import write_text
    from neuspike.formats.images import to_uint8, write_png
    from neuspike.utils.jsonio import portable_path
    from neuspike.video.stream import stream_methods
    from neuspike.video.truth import METRIC_COLUMNS, FlickerMeter, plot_metrics, score_frame
    from neuspike.video.writers import (
        LABEL_BAND_PX, FrameFolder, Mp4Writer, contact_sheet, label_image, tile_row,
    )

    history = _history(spec)
    n = len(times)
    names = [m.name for m in methods]
    rows = names + (["ground truth"] if truth is not None else [])
    h, w = rec.height, rec.width
    band = LABEL_BAND_PX
    writers: list[Any] = []
    try:
        videos = {name: Mp4Writer(out / f"{name}.mp4", fps=spec.play_fps, width=w, height=h) for name in names}
        writers += videos.values()
        folders = {}
        if spec.frames:
            folders = {name: FrameFolder(out / name, png="png" in spec.frames, npy="npy" in spec.frames)
                       for name in names}
            writers += folders.values()
        cmp_w = len(rows) * w + 4 * (len(rows) - 1)
        compare = Mp4Writer(out / "compare.mp4", fps=spec.play_fps, width=cmp_w, height=h + band)
        writers.append(compare)
        metric_rows: list[dict[str, Any]] = []
        flicker = {name: FlickerMeter() for name in names}
        sheet: dict[str, list[np.ndarray]] = {r: [] for r in rows}
        busy = {name: 0.0 for name in names}
        bar = None
        if spec.progress:
            from tqdm import tqdm

            bar = tqdm(total=n, unit="frame", desc="video", file=sys.stderr)
        wall0 = time.perf_counter()
        for k, (sample, images, seconds) in enumerate(
            stream_methods(methods, rec, times, window_planes=spec.window_planes, event_history_s=history)
        ):
            t = sample.key_time_s
            gt = truth.at(t) if truth is not None else None
            tiles = []
            for name in names:
                img = images[name]
                busy[name] += seconds[name]
                img8 = to_uint8(img, clip=True)
                videos[name].write(img8)
                if name in folders:
                    folders[name].write(img)
                tiles.append(label_image(img8, name))
                if gt is not None:
                    p, s = score_frame(img, gt[1])
                    f = flicker[name].update(img, gt[1])
                    metric_rows.append({"method": name, "frame": k, "time_s": f"{t:.9f}",
                                        "gt_time_s": f"{gt[0]:.9f}", "gt_source": truth.source,
                                        "psnr_db": f"{p:.4f}", "ssim": f"{s:.5f}",
                                        "flicker_rmse": "" if math.isnan(f) else f"{f:.6f}",
                                        "normalisation": getattr(methods[names.index(name)], "last_normalisation", "")})
                elif truth is not None:
                    flicker[name].update(img, None)
                if k in sheet_idx:
                    sheet[name].append(img)
            if truth is not None:
                gimg = gt[1] if gt is not None else np.zeros((h, w), np.float32)
                tiles.append(label_image(to_uint8(gimg, clip=True), "ground truth" if gt is not None else "(no ground truth)"))
                if k in sheet_idx:
                    sheet["ground truth"].append(gimg)
            compare.write(tile_row(tiles))
            if bar is not None:
                bar.update(1)
        wall = time.perf_counter() - wall0
        if bar is not None:
            bar.close()
        sheet_img = contact_sheet([(r, sheet[r]) for r in rows], [float(times[i]) for i in sheet_idx],
                                  max_width_px=spec.sheet_width)
        for wtr in writers:
            wtr.close()
    except BaseException:
        for wtr in writers:
            wtr.abort()
        raise
    write_png(out / "contact_sheet.png", sheet_img, clip=False)
    if metric_rows:
        from neuspike.utils.atomic import replacing

        with replacing(out / "metrics.csv") as tmp, open(tmp, "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=list(METRIC_COLUMNS))
            wr.writeheader()
            wr.writerows(metric_rows)
        plot_metrics(out / "metrics.csv", out / "metrics.png")
    per_method = {}
    for m in methods:
        scored = [r for r in metric_rows if r["method"] == m.name]
        fl = [float(r["flicker_rmse"]) for r in scored if r["flicker_rmse"] != ""]
        per_method[m.name] = {
            "inputs": sorted(m.inputs),
            "normalisation": m.last_normalisation,
            # learned methods: the precision they ran in (``auto`` resolved) and whether compiled
            "precision": m.params.get("precision"),
            "compiled": bool(m.params.get("compiled", False)),
            "read_out": m.params.get("read_out"),  # recurrent event networks only
            "method_seconds": busy[m.name],
            "method_frames_per_s": n / busy[m.name] if busy[m.name] > 0 else None,
            "scored_frames": len(scored),
            "mean_psnr_db": float(np.mean([float(r["psnr_db"]) for r in scored])) if scored else None,
            "mean_ssim": float(np.mean([float(r["ssim"]) for r in scored])) if scored else None,
            "mean_flicker_rmse": float(np.mean(fl)) if fl else None,
        }
    summary = {
        "spec": {k: (portable_path(v) if isinstance(v, Path) else v) for k, v in asdict(spec).items()},
        "recording": {"width": w, "height": h, "modalities": sorted(rec.modalities),
                      "plane_rate_hz": rec.plane_rate_hz, "span_s": list(rec.span_s()), "gain": rec.gain,
                      "gain_source": rec.gain_source, "dark_rate": rec.dark_rate,
                      "folder": portable_path(rec.folder) if rec.folder is not None else None},
        "frames": n, "fps": fps, "start_s": start, "end_s": end,
        "ground_truth": truth.source if truth is not None else None,
        "wall_seconds": wall, "wall_frames_per_s": n / wall if wall > 0 else None,
        "real_time_factor": (end - start) / wall if wall > 0 else None,
        "methods": per_method,
    }
    write_text(out / "video.json", json.dumps(summary, indent=2, default=str) + "\n")
    return summary

def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status (0 ok, 2 error with one line on stderr)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        print(f"error: {exc} (see --help)", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    try:
        spec = spec_from_args(args)
        from neuspike.methods.plugins import load_requested

        load_requested(args.plugin)  # after the usage checks: those import nothing heavy
        run(spec)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (OSError, ValueError, ImportError) as exc:
        print(f"error: {one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted; nothing was published", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
