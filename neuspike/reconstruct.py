"""Reconstruct images from a real or simulated recording with any registered method.

``python -m neuspike.reconstruct --list`` lists the methods; ``python -m neuspike.reconstruct
--method NAME ... --out DIR`` writes ``DIR/NAME.png`` (8-bit) and ``DIR/NAME.npy`` (float32, [0, 1])
for each method, prints the normalisation each method applied and, with a ground truth, PSNR and
SSIM (plus their affine-aligned variants) with the pinned settings; without one, the no-reference
measures. The flags are parsed into a frozen :class:`ReconstructSpec` and :func:`run` does the work.
How the recording becomes a sample (key instant, windows, gain, size) is documented in
:mod:`neuspike.formats.samples`.

Errors (an unknown method, an input a method needs but was not given, a file that cannot be read,
weights that are missing) print one line to stderr and exit with status 2; nothing is written for
a run whose checks fail.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence, TextIO

from neuspike.utils.cli import WEIGHTS_ENV, ArgumentParser, MethodOptions, UsageError
from neuspike.errors import InputError, NeuSpikeError, one_line

if TYPE_CHECKING:  # numpy, OpenCV and torch load after the arguments are parsed: --help answers at once
    import numpy as np

#: The data range every metric is computed with (methods return images in [0, 1]).
DATA_RANGE = 1.0
#: Command-line flag of each input modality.
INPUT_FLAGS = {"spikes": "--spikes", "events": "--events"}


@dataclass(frozen=True)
class ReconstructSpec:
    """Everything one reconstruction run needs (the parsed command line)."""

    methods: tuple[str, ...]
    out: Path
    spikes: Path | None = None
    events: Path | None = None
    height: int | None = None
    width: int | None = None
    raw_width: int | None = None
    plane_rate_hz: float | None = None
    plane: int | None = None
    at_s: float | None = None
    gain: float | None = None
    dark_rate: float | None = None
    window_planes: int | None = None
    weights: Path | None = None
    gt: Path | None = None
    device: str = "cpu"
    #: precision of the learned methods (``None``: each method's own, ``auto`` for those shipped)
    precision: str | None = None


@dataclass(frozen=True)
class MethodResult:
    """What one method produced: the image, its files, its normalisation and its scores."""

    name: str
    image: np.ndarray
    png: Path
    npy: Path
    normalisation: str | None
    seconds: float
    scores: dict[str, float]


def _split_methods(values: Sequence[str]) -> tuple[str, ...]:
    names: list[str] = []
    for v in values:
        for part in v.split(","):
            part = part.strip()
            if part and part not in names:
                names.append(part)
    return tuple(names)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="python -m neuspike.reconstruct",
        description=(
            "Reconstruct an image from a spike recording (Vidar .dat, or .npz holding a (T, H, W) 0/1\n"
            "array), an event recording (HDF5, E2VID .txt, .npz, .aedat4) or both, with any registered\n"
            "method. Writes OUT/NAME.png (8-bit) and OUT/NAME.npy (float32 in [0, 1]) per method and\n"
            "prints the normalisation each method used. With a ground truth (--gt, or gt.npy / gt.png in\n"
            "a folder written by python -m neuspike.simulate) it prints PSNR and SSIM (data_range 1, the\n"
            "SSIM settings printed) and their affine-aligned variants; without one, a noise estimate and\n"
            "a sharpness measure. A meta.json beside the recording (simulated data) supplies the size,\n"
            "plane rate, gain and key instant. The spike window is 256 planes (12.8 ms at 20 kHz) centred\n"
            "on the key plane unless --window-planes says otherwise; a shorter file is used whole."
        ),
        epilog=(
            "examples:\n"
            "  python -m neuspike.reconstruct --list\n"
            "  python -m neuspike.simulate --out out/pan\n"
            "  python -m neuspike.reconstruct --method tfp,tfi --spikes out/pan/spikes.dat --out out/pan/rec\n"
            "  python -m neuspike.reconstruct --method tfp-w32 --spikes rec.dat --height 250 --width 400 --plane 500 --out rec\n"
            "  python -m neuspike.reconstruct --method tfp,tfi --spikes helicopter.npz --out rec\n"
            "  python -m neuspike.reconstruct --method firenet --events driving.hdf5 --at 3.4 --weights weights/ --out rec\n"
            "  python -m neuspike.reconstruct --plugin my_methods.py --method mine,tfi --spikes rec.npz --out rec\n"
            "\n"
            f"Learned methods read their weights from --weights DIR or the {WEIGHTS_ENV} environment variable.\n"
            "Exit status: 0 on success, 2 on an error (one line on stderr)."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--list", action="store_true", help="list the registered methods and the inputs each needs, then exit")
    p.add_argument("--method", action="append", default=[], metavar="NAME",
                   help="method to run; repeat the flag or give a comma list (e.g. --method tfp,tfi)")
    p.add_argument("--spikes", type=Path, metavar="FILE", help="spike recording: .dat (Vidar) or .npz")
    p.add_argument("--events", type=Path, metavar="FILE", help="event recording: .h5/.hdf5, .txt, .npz or .aedat4")
    p.add_argument("--height", type=int, metavar="H", help="sensor height; required for a .dat without meta.json")
    p.add_argument("--width", type=int, metavar="W", help="sensor width; required for a .dat without meta.json")
    p.add_argument("--raw-width", type=int, metavar="W",
                   help="stored width of a .dat with extra columns (e.g. 416); the extra columns are dropped")
    p.add_argument("--plane-rate", type=float, metavar="HZ",
                   help="spike planes per second (default: meta.json's, else 20000)")
    key = p.add_mutually_exclusive_group()
    key.add_argument("--plane", type=int, metavar="K", help="key instant as a plane index into the spike file")
    key.add_argument("--at", type=float, metavar="SECONDS", dest="at_s",
                     help="key instant in sensor seconds (default: meta.json's key time, else the recording's centre)")
    p.add_argument("--gain", type=float, metavar="G",
                   help="spikes per plane per unit radiance; overrides the recording's (real data: unknown, "
                        "so methods normalise robustly and say so)")
    p.add_argument("--dark-rate", type=float, metavar="D",
                   help="the spike sensor's dark rate: spikes per plane a pixel fires in darkness, mean over "
                        "pixels (from a capped calibration); overrides the recording's. With the gain it lets "
                        "neuspike-net set its image's mean level from the spike count")
    p.add_argument("--window-planes", type=int, metavar="N",
                   help="spike window length in planes (default: a simulated window's own length, else 256)")
    MethodOptions.add_arguments(p, flags=("weights", "device", "precision", "plugin"))
    p.add_argument("--gt", type=Path, metavar="IMAGE", help="ground-truth image (.png or .npy) for PSNR and SSIM")
    p.add_argument("--out", type=Path, metavar="DIR", help="output folder (created if missing)")
    return p


def list_methods(stream: TextIO | None = None) -> None:
    """Print every registered method with the inputs it needs (to ``stream``, default stdout)."""
    stream = stream if stream is not None else sys.stdout
    from neuspike.methods import available, entry

    _warn_entry_point_problems()
    names = available()
    if not names:
        print("no methods registered", file=stream)
        return
    width = max(len(n) for n in names)
    for name in names:
        e = entry(name)
        inputs = "+".join(sorted(e.inputs))
        params = ", ".join(f"{k}={v}" for k, v in e.params.items())
        extra = "  ".join(x for x in (e.description, f"({params})" if params else "") if x)
        print(f"{name:<{width}}  {inputs:<13}  {extra}".rstrip(), file=stream)


def _warn_entry_point_problems() -> None:
    """Load the ``neuspike.methods`` entry points (once) and say on stderr which ones failed."""
    from neuspike.methods import load_entry_points

    for problem in load_entry_points():
        print(f"warning: {problem}", file=sys.stderr)


def _write_atomic(path: Path, data: bytes) -> None:
    from neuspike.utils.atomic import write_bytes

    write_bytes(path, data)


def write_outputs(out: Path, name: str, image: np.ndarray) -> tuple[Path, Path]:
    """Write ``out/name.png`` (8-bit, round(255 * image)) and ``out/name.npy`` (float32), atomically.

    Parameters
    ----------
    image : ndarray float32 (H, W) in [0, 1] (a method's checked output)
    """
    import io

    import numpy as np

    from neuspike.formats.images import encode_png

    out.mkdir(parents=True, exist_ok=True)
    png = encode_png(image, clip=False)
    npy = io.BytesIO()
    np.save(npy, np.asarray(image, dtype=np.float32))
    png_path, npy_path = out / f"{name}.png", out / f"{name}.npy"
    _write_atomic(npy_path, npy.getvalue())
    _write_atomic(png_path, png)
    return png_path, npy_path


def _prepare_methods(spec: ReconstructSpec) -> list[Any]:
    """Check every requested method against the inputs given and create them (before any work)."""
    from neuspike.methods import create_many, entry

    _warn_entry_point_problems()
    given = {m for m, path in (("spikes", spec.spikes), ("events", spec.events)) if path is not None}
    entries = []
    for name in spec.methods:
        e = entry(name)  # unknown names raise InputError listing the available ones
        if Path(name).name != name or name in (".", ".."):
            raise InputError(f"method name {name!r} cannot be used as a file name")
        missing = sorted(set(e.inputs) - given)
        if missing:
            flags = " and ".join(INPUT_FLAGS[m] for m in missing)
            raise InputError(f"method {name!r} needs {flags} (it reads {', '.join(sorted(e.inputs))})")
        entries.append(e)
    made = create_many([e.name for e in entries], weights_dir=spec.weights, device=spec.device,
                       precision=spec.precision, skip_unavailable=False)
    return [c.method for c in made.values()]


def run(spec: ReconstructSpec, stream: TextIO | None = None) -> list[MethodResult]:
    """Reconstruct with every method of ``spec``, write the images and print a summary to ``stream``
    (default stdout).

    Returns
    -------
    list of MethodResult, one per method, in the order given.

    Raises
    ------
    NeuSpikeError
        Any failed check (nothing is written when the checks before reconstruction fail).
    """
    from neuspike.metrics import describe_metrics, evaluate, no_reference
    from neuspike.formats.samples import describe_sample, load_sample

    stream = stream if stream is not None else sys.stdout
    if not spec.methods:
        raise InputError("give at least one --method (see --list)")
    methods = _prepare_methods(spec)
    sample = load_sample(
        spikes=spec.spikes, events=spec.events, height=spec.height, width=spec.width, plane=spec.plane,
        at_s=spec.at_s, gain=spec.gain, dark_rate=spec.dark_rate, window_planes=spec.window_planes, gt=spec.gt,
        raw_width=spec.raw_width, plane_rate_hz=spec.plane_rate_hz,
    )
    print(f"sample: {describe_sample(sample)}", file=stream)
    for note in sample.meta.get("notes", []):
        print(f"note: {note}", file=stream)
    ground_truth = sample.ground_truth
    blind = sample.without_ground_truth()  # methods never see the ground truth
    if ground_truth is not None:
        print(f"ground truth: {sample.meta.get('ground_truth_path')}", file=stream)
        print(f"{describe_metrics()}; data_range={DATA_RANGE}", file=stream)
    else:
        print("no ground truth: no-reference measures (noise_sigma: Haar-MAD noise estimate; "
              "laplacian_var: sharpness), see neuspike.metrics", file=stream)
    print("times: one call per method, its first, so one-time compilation (numba kernels, torch.compile) "
          "and a recurrent method's warm-up are in it; python -m bench.timing times warm frames", file=stream)
    results = []
    for method in methods:
        method.reset()
        t0 = time.perf_counter()
        image = method.reconstruct(blind)
        seconds = time.perf_counter() - t0
        png, npy = write_outputs(spec.out, method.name, image)
        if ground_truth is not None:
            scores = evaluate(image, ground_truth, data_range=DATA_RANGE)
            shown = (f"PSNR {scores['psnr']:.2f} dB, SSIM {scores['ssim']:.4f}; affine-aligned: "
                     f"PSNR {scores['psnr_affine']:.2f} dB, SSIM {scores['ssim_affine']:.4f}")
        else:
            scores = no_reference(image)
            shown = f"noise_sigma {scores['noise_sigma']:.4f}, laplacian_var {scores['laplacian_var']:.4g}"
        print(f"{method.name}: wrote {png} and {npy}; normalisation {method.last_normalisation}; "
              f"{seconds * 1e3:.1f} ms first call; {shown}", file=stream)
        results.append(MethodResult(method.name, image, png, npy, method.last_normalisation, seconds, scores))
    return results


def spec_from_args(args: argparse.Namespace) -> ReconstructSpec:
    """The frozen spec of parsed arguments."""
    if args.out is None:
        raise InputError("give an output folder with --out DIR")
    options = MethodOptions.from_args(args)
    return ReconstructSpec(
        methods=_split_methods(args.method), out=args.out, spikes=args.spikes, events=args.events,
        height=args.height, width=args.width, raw_width=args.raw_width, plane_rate_hz=args.plane_rate,
        plane=args.plane, at_s=args.at_s, gain=args.gain, dark_rate=args.dark_rate, window_planes=args.window_planes,
        weights=options.weights_dir, gt=args.gt, device=options.device, precision=options.precision,
    )


def _load_plugins(args: argparse.Namespace) -> None:
    """Import the plug-ins named by --plugin and NEUSPIKE_PLUGINS: their methods are listed and run like the
    others (after the usage checks, so that a usage error imports nothing heavy)."""
    from neuspike.methods.plugins import load_requested

    load_requested(args.plugin)


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status (0 ok, 2 error).

    Every expected failure (a usage error, an unknown method, a missing input, an unreadable file,
    unavailable weights) prints one ``error: ...`` line to stderr and returns 2, without a traceback.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        print(f"error: {exc} (see --help)", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    try:
        if args.list:
            _load_plugins(args)
            list_methods()
            return 0
        if not args.method:
            raise InputError("give --method NAME (see --list) or --list")
        _load_plugins(args)
        spec = spec_from_args(args)
        from neuspike.formats.staging import check_writable_folder

        check_writable_folder(spec.out, what="--out", create=False)  # before computing anything
        run(spec)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (OSError, ValueError, ImportError) as exc:  # a reader's or the system's own error
        print(f"error: {one_line(exc)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
