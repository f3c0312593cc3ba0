"""``python -m neuspike.simulate``: a scene or a video in; ``spikes.dat``, ``events.h5``, ground truth out.

Arguments are parsed and checked before the simulator is imported, so ``--help`` and usage errors
answer at once; the work the command would do is measured before it starts (memory, disk, the
file size limit) and refused, naming the size, when it cannot fit.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from neuspike.utils.checks import check_nonnegative, check_positive, parse_size
from neuspike.conditions import EFFECT_DEFAULTS, EVENTS, NOISE_LEVELS, SPIKES, Condition, parse_effects
from neuspike.errors import InputError, NeuSpikeError, one_line
from neuspike.streams import VIDAR_PLANE_RATE_HZ


def _parse_size(text: str) -> tuple[int, int]:
    try:
        return parse_size(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parse_fraction(text: str) -> float:
    try:
        if "/" in text:
            a, b = text.split("/")
            return float(a) / float(b)
        return float(text)
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"expected a number such as 0.25 or 1/4, got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m neuspike.simulate",
        description=(
            "Simulate a spike camera (Vidar, integrate-and-fire) and an event camera (DVS) looking at "
            "a scene or a video. Writes spikes.dat (Vidar format), events.h5 (events/xs, ys, ts, ps), "
            "the ground truth (gt.png and gt.npy for a window; frames/ with timestamps for a video) "
            "and meta.json (gain, threshold, plane rate, size, the stages that ran with their "
            "parameters and seconds, spike and event counts)."
        ),
        epilog=(
            "examples:\n"
            "  python -m neuspike.simulate --out out/pan\n"
            "  python -m neuspike.simulate --scene fan --rpm 2600 --light 1/8 --motion 256 --noise high --out out/fan\n"
            "  python -m neuspike.simulate --video ../shared/realdata/video/slider_depth --duration 0.2 --out out/slider\n"
            "  python -m neuspike.simulate --effects 'refractory:period_s=5e-4,leak:rate_hz=0.1' --out out/pan_fx"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--scene", choices=["pan", "zoom", "fan", "still"], default="pan",
                   help="analytic scene kind (default: pan); ignored with --video")
    p.add_argument("--image", default="camera",
                   help="photograph: a scikit-image bundled name (e.g. camera, astronaut) or an image file (default: camera)")
    p.add_argument("--video", help="a video file or a folder of images (optional images.txt with '<t> <file>' lines)")
    p.add_argument("--velocity", type=float, nargs=2, metavar=("VX", "VY"), help="pan velocity in px/s of scene time")
    p.add_argument("--rpm", type=float, help="fan speed in revolutions per minute")
    p.add_argument("--zoom-rate", type=float, help="zoom: the view scale grows as exp(rate * t), rate in 1/s")
    p.add_argument("--dynamic-range", type=float, help="HDR: map the photograph's luma to radiance spanning this ratio (e.g. 1000)")
    p.add_argument("--light", type=_parse_fraction, default=0.25, help="light scale L, e.g. 1/4 (default: 1/4)")
    p.add_argument("--motion", type=int, default=128, help="motion scale S in 16..256 (default: 128; window mode)")
    p.add_argument("--noise", choices=list(NOISE_LEVELS), default="none",
                   help="the paper's noise level (default: none = no noise stage runs)")
    p.add_argument("--effects",
                   help="extra stages, e.g. 'threshold_mismatch:sigma=0.05,refractory:period_s=5e-4,shot_noise:rate_hz=5'; "
                   f"spike camera: {', '.join(n for n, (m, _) in EFFECT_DEFAULTS.items() if m == SPIKES)}; "
                   f"event camera: {', '.join(n for n, (m, _) in EFFECT_DEFAULTS.items() if m == EVENTS)} "
                   "(an effect of a camera that --modalities leaves out is refused)")
    p.add_argument("--size", type=_parse_size, help="sensor size WxH (default: 400x250; a video's own size for --video)")
    p.add_argument("--planes", type=int, default=256, help="spike planes per window T (default: 256)")
    p.add_argument("--plane-rate", type=float, default=VIDAR_PLANE_RATE_HZ,
                   help=f"spike planes per second (default: {VIDAR_PLANE_RATE_HZ:g})")
    p.add_argument("--threshold", type=float, default=1.0, help="spike threshold phi (default: 1)")
    p.add_argument("--event-threshold", type=float, default=0.2, help="DVS contrast threshold (default: 0.2)")
    p.add_argument("--modalities", default="spikes,events", help="what to simulate (default: spikes,events)")
    p.add_argument("--mode", choices=["window", "continuous"],
                   help="window = Algorithm 1 (default for scenes); continuous = a sample per plane (default for --video)")
    p.add_argument("--at", type=float, default=0.0, help="scene time of the key instant / start, seconds (default: 0)")
    p.add_argument("--duration", type=float, help="continuous mode: scene seconds to simulate (default: the whole video, or 0.0128 s)")
    p.add_argument("--time-scale", type=float, default=1.0, help="continuous mode: scene seconds per sensor second (default: 1)")
    p.add_argument("--upsample", type=int, help="video: snap render instants to U x the video frame rate (default: continuous flow interpolation)")
    p.add_argument("--history", type=float, default=0.0, help="window mode: seconds of event history before the window (default: 0)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (OSError, MemoryError) as exc:  # the system's own refusal while working (disk full, file size limit)
        print(f"error: {one_line(exc)}", file=sys.stderr)
        return 2


def _check_motion(args: argparse.Namespace, mode: str) -> None:
    if mode == "window" and isinstance(args.motion, int) and args.motion >= 1 and isinstance(args.planes, int) \
            and args.planes >= 1 and args.planes % args.motion:
        s_, t_ = args.motion, args.planes
        plane_counts = sorted({n for n in ((t_ // s_) * s_, (t_ // s_ + 1) * s_) if n > 0})
        motions = [d for d in range(1, t_ + 1) if t_ % d == 0]
        near = sorted(motions, key=lambda d: (abs(d - s_), d))[:2]
        raise InputError(
            f"--planes {t_} is not a whole multiple of --motion {s_} (Algorithm 1 holds each of the S frames "
            f"for T // S planes): use {' or '.join(f'--planes {n}' for n in plane_counts)}, or "
            f"{' or '.join(f'--motion {d}' for d in sorted(near))}"
        )


def _sequence_span(args: argparse.Namespace, sensor: Any, scene: Any = None) -> tuple[float, float]:
    """Continuous mode: (scene start, scene duration) in seconds (a video's own span needs its scene)."""
    video = scene is not None and args.video
    start = args.at if not video or args.at else float(getattr(scene, "start_s", 0.0))
    if args.duration is not None:
        return start, args.duration
    if video:
        return start, float(scene.end_s) - start
    return start, sensor.planes / sensor.plane_rate_hz * args.time_scale


def _declared_effects(text: str | None, modalities: frozenset[str]) -> tuple[Any, ...]:
    """``--effects`` parsed; an empty one, or an effect of a camera that is not simulated, is refused."""
    if text is None:
        return ()
    if not text.strip():
        raise InputError("--effects: empty; leave the option out for no extra stages")
    effects = parse_effects(text)
    idle = [e.name for e in effects if e.modality not in modalities]
    if idle:
        camera = {SPIKES: "spike", EVENTS: "event"}
        names = ", ".join(f"{n} ({camera[EFFECT_DEFAULTS[n][0]]} camera)" for n in idle)
        raise InputError(f"--effects: {names} would not run: --modalities {','.join(sorted(modalities))} does not "
                         f"simulate that camera (simulate only the effects a scene calls for)")
    return effects


def _check_work(args: argparse.Namespace, out: Path, mode: str, size: tuple[int, int], *, sensor: Any,
                condition: Condition, modalities: frozenset[str], scene: Any = None) -> None:
    """Refuse, before any work, a simulation whose memory, disk or largest file cannot fit (naming the size)."""
    from neuspike.simulation.budget import check_budget, sequence_budget, window_budget

    width, height = size
    if mode == "window":
        history_s = check_nonnegative("--history", args.history)
        budget = window_budget(width, height, sensor=sensor, condition=condition, modalities=modalities,
                               history_s=history_s)
    else:
        start, duration = _sequence_span(args, sensor, scene)
        check_positive("--duration", duration)
        check_positive("--time-scale", args.time_scale)
        planes = duration / args.time_scale * sensor.plane_rate_hz
        frames = getattr(scene, "frame_times_s", None) if scene is not None else None
        if frames is not None:
            n_truth = float(sum(1 for t in frames if start <= t <= start + duration))
        else:
            n_truth = planes / 256 + 1
        budget = sequence_budget(width, height, sensor=sensor, condition=condition, modalities=modalities,
                                 planes=planes, ground_truth_frames=n_truth)
    check_budget(budget, what=f"the simulation ({mode} mode, {width}x{height})", folder=out.parent)


def _run(args: argparse.Namespace) -> int:
    from neuspike.formats.staging import check_writable_folder
    from neuspike.simulation.recording import SensorConfig, check_modalities

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")
    # before any work: the folder the recording is swapped into, and an existing one whose entries move
    check_writable_folder(out.parent, what="--out: the folder", create=False)
    if out.is_dir():
        check_writable_folder(out, what="--out", create=False)
    mode = args.mode or ("continuous" if args.video else "window")
    _check_motion(args, mode)
    modalities = check_modalities(m.strip() for m in args.modalities.split(",") if m.strip())
    sensor = SensorConfig(planes=args.planes, plane_rate_hz=args.plane_rate, spike_threshold=args.threshold,
                          event_threshold=args.event_threshold)
    condition = Condition(light=args.light, motion=args.motion, noise=args.noise,
                          effects=_declared_effects(args.effects, modalities))
    size = args.size or (None if args.video else (400, 250))
    if size is not None:
        _check_work(args, out, mode, size, sensor=sensor, condition=condition, modalities=modalities)

    from neuspike.utils.rng import derive_rng
    from neuspike.scenes import SceneSpec, make_scene
    from neuspike.simulation.window import simulate_window
    from neuspike.simulation.writing import write_recording, write_sequence

    spec_kwargs: dict[str, Any] = {}
    if args.video:
        spec_kwargs.update(kind="video", video=args.video, size=args.size)
        if args.upsample is not None:
            spec_kwargs["upsample"] = args.upsample
    else:
        spec_kwargs.update(kind=args.scene, image=args.image, size=size)
        if args.velocity is not None:
            spec_kwargs["velocity_px_s"] = tuple(args.velocity)
        if args.rpm is not None:
            spec_kwargs["rpm"] = args.rpm
        if args.zoom_rate is not None:
            spec_kwargs["zoom_rate_hz"] = args.zoom_rate
    if args.dynamic_range is not None:
        spec_kwargs["dynamic_range"] = args.dynamic_range
    scene = make_scene(SceneSpec(**spec_kwargs))
    if args.video:  # its own size and frames are known now
        _check_work(args, out, mode, (scene.width, scene.height), sensor=sensor, condition=condition,
                    modalities=modalities, scene=scene)
    rng = derive_rng(args.seed, "simulate", scene.describe(), condition.as_dict(), mode)
    t0 = time.perf_counter()
    if mode == "window":
        rec = simulate_window(scene, condition, rng=rng, sensor=sensor, center_s=args.at, modalities=modalities,
                              history_s=args.history, seed=args.seed)
        write_recording(rec, out)
        meta = rec.meta
    else:
        start, duration = _sequence_span(args, sensor, scene)
        meta = write_sequence(scene, condition, out, rng=rng, start_s=start, duration_s=duration, sensor=sensor,
                              time_scale=args.time_scale, modalities=modalities,
                              progress=not args.no_progress, seed=args.seed)
    elapsed = time.perf_counter() - t0
    parts = [f"{meta['planes']} planes at {scene.width}x{scene.height}"]
    if "spike_count" in meta:
        parts.append(f"{meta['spike_count']:,} spikes")
    if "event_count" in meta:
        parts.append(f"{meta['event_count']:,} events")
    ran = ", ".join(f"{s['name']} {s['seconds'] * 1e3:.1f} ms" for s in meta["stages"])
    print(f"wrote {out}/: {'; '.join(parts)} in {elapsed:.2f} s")
    print(f"stages: {ran}")
    saturated = json.loads((out / "meta.json").read_text()).get("saturated_fraction")
    if saturated:
        print(f"warning: {saturated:.1%} of the pixels fired on every plane (saturated: the light scale "
              f"{condition.light:g} is too high for threshold {sensor.spike_threshold:g}; spike methods cannot "
              f"tell their radiance apart)", file=sys.stderr)
    return 0
