"""Ground truth for simulated videos, and per-frame scores: PSNR, SSIM and temporal flicker.

Where the ground truth of an output instant comes from (:func:`ground_truth_for`):

Analytic scenes in continuous mode (``meta.json`` with ``mode`` ``"continuous"`` and a scene of a
kind other than ``"video"``)
    The scene is rebuilt from the spec that ``meta.json`` stores and rendered at the instant's scene
    time, ``scene_start_s + time_scale * (t - start_s)``: exact ground truth at every output frame,
    float, with no interpolation and no 8-bit quantisation.
Video scenes, and anything else with ``frames/timestamps.txt``
    The source frames are the only true images (frames between them are interpolated by the
    simulator, not observed). An output frame is matched to the nearest listed frame when their
    sensor times differ by at most ``tolerance_s`` (the command passes half the output frame
    interval); other frames have no ground truth and no score.
Window recordings (``gt.npy`` or ``gt.png`` beside ``meta.json``)
    The one ground-truth image, matched to the output frame nearest the key instant as above.

Radiance above 1 (HDR) is clipped to [0, 1], as the harness does.

Scores (:func:`score_frame`, :class:`FlickerMeter`): PSNR and SSIM from :mod:`neuspike.metrics`
with ``data_range = 1``; *flicker* is the root-mean-square, over pixels, of the error of
consecutive differences, ``(I_k - I_{k-1}) - (G_k - G_{k-1})``, between consecutive frames that both
have ground truth (the first frame has none). It is 0 for any output whose error is constant in
time (a fixed bias does not flicker) and grows with frame-to-frame noise and with motion the
output misses or invents.
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from neuspike.errors import FormatError
from neuspike.metrics import psnr, ssim

__all__ = ["GroundTruth", "ground_truth_for", "score_frame", "FlickerMeter", "METRIC_COLUMNS", "plot_metrics"]

#: Columns of the per-frame metrics CSV, in order.
METRIC_COLUMNS = ("method", "frame", "time_s", "gt_time_s", "gt_source", "psnr_db", "ssim", "flicker_rmse",
                  "normalisation")
DATA_RANGE = 1.0


class GroundTruth:
    """Ground truth of a recording: ``at(time_s)`` gives float32 (H, W) in [0, 1] or ``None``.

    Attributes
    ----------
    source : str
        ``"scene"`` (rendered), ``"frames"`` (listed frames) or ``"gt"`` (a window's image).
    """

    def __init__(self, source: str, lookup: Callable[[float], tuple[float, np.ndarray] | None]) -> None:
        self.source = source
        self._lookup = lookup

    def at(self, time_s: float) -> tuple[float, np.ndarray] | None:
        """``(ground-truth time, image)`` for an output instant, or ``None`` when there is none."""
        return self._lookup(float(time_s))


def _scene_truth(meta: dict[str, Any]) -> GroundTruth:
    from neuspike.scenes import SceneSpec, make_scene

    spec = dict(meta["scene"]["spec"])
    spec["effects"] = ()  # sensor effects do not change what the scene looks like
    for key in ("size", "velocity_px_s", "focus"):
        if spec.get(key) is not None:
            spec[key] = tuple(spec[key])
    try:
        scene = make_scene(SceneSpec(**spec))
    except TypeError as exc:
        raise FormatError(f"meta.json: the scene spec cannot be rebuilt ({exc})") from None
    start = float(meta.get("start_s") or 0.0)
    scene_start = float(meta.get("scene_start_s") or 0.0)
    scale = float(meta.get("time_scale") or 1.0)

    def lookup(t: float) -> tuple[float, np.ndarray]:
        img = scene.render(np.array([scene_start + scale * (t - start)]))[0]
        return t, np.clip(img, 0.0, 1.0).astype(np.float32)

    return GroundTruth("scene", lookup)


def _listed_truth(source: str, times: np.ndarray, files: list[Path], tolerance_s: float,
                  height: int, width: int) -> GroundTruth:
    from neuspike.formats.samples import load_ground_truth

    cache: dict[int, np.ndarray] = {}

    def lookup(t: float) -> tuple[float, np.ndarray] | None:
        if times.size == 0:
            return None
        i = int(np.argmin(np.abs(times - t)))
        if abs(times[i] - t) > tolerance_s:
            return None
        if i not in cache:
            cache.clear()
            cache[i] = load_ground_truth(files[i], height=height, width=width)[0]
        return float(times[i]), cache[i]

    return GroundTruth(source, lookup)


def ground_truth_for(folder: str | os.PathLike, meta: dict[str, Any] | None, *, height: int, width: int,
                     tolerance_s: float) -> GroundTruth | None:
    """The ground truth of a simulated recording folder (rules in the module docstring), or ``None``.

    Parameters
    ----------
    folder : path
        The recording's folder.
    meta : dict or None
        Its ``meta.json`` (``None``: a real recording, no ground truth).
    height, width : int
        Sensor size.
    tolerance_s : float
        Largest time difference between an output frame and a listed ground-truth frame.
    """
    if meta is None:
        return None
    folder = Path(folder)
    scene = meta.get("scene") if isinstance(meta.get("scene"), dict) else None
    if meta.get("mode") == "continuous" and scene is not None and scene.get("kind") != "video" and scene.get("spec"):
        return _scene_truth(meta)
    stamps = folder / "frames" / "timestamps.txt"
    if stamps.is_file():
        times, files = [], []
        for line in stamps.read_text().splitlines():
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            if len(parts) < 4:
                raise FormatError(f"{stamps}: expected '<index> <sensor_time_s> <scene_time_s> <file>', got {line!r}")
            times.append(float(parts[1]))
            files.append(stamps.parent / parts[3])
        return _listed_truth("frames", np.asarray(times), files, tolerance_s, height, width)
    for name in ("gt.npy", "gt.png"):
        if (folder / name).is_file() and meta.get("key_time_s") is not None:
            return _listed_truth("gt", np.asarray([float(meta["key_time_s"])]), [folder / name], tolerance_s,
                                 height, width)
    return None


def score_frame(image: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """``(PSNR in dB, SSIM)`` of one frame against its ground truth, ``data_range = 1``."""
    return psnr(image, reference, data_range=DATA_RANGE), ssim(image, reference, data_range=DATA_RANGE)


class FlickerMeter:
    """Temporal flicker of one method's frames: RMS of ``(I_k - I_{k-1}) - (G_k - G_{k-1})``.

    Feed every output frame in order with :meth:`update`; frames without ground truth break the chain
    (the next frame with ground truth starts a new one and gets no flicker value).
    """

    def __init__(self) -> None:
        self._prev: tuple[np.ndarray, np.ndarray] | None = None

    def update(self, image: np.ndarray, reference: np.ndarray | None) -> float:
        """The flicker of this frame against the previous one (NaN when there is no previous pair)."""
        if reference is None:
            self._prev = None
            return math.nan
        img = np.asarray(image, dtype=np.float64)
        ref = np.asarray(reference, dtype=np.float64)
        value = math.nan
        if self._prev is not None:
            err = (img - self._prev[0]) - (ref - self._prev[1])
            value = float(np.sqrt(np.mean(err * err)))
        self._prev = (img, ref)
        return value


def plot_metrics(csv_path: str | os.PathLike, png_path: str | os.PathLike) -> Path:
    """PSNR, SSIM and flicker over time, one line per method, from the metrics CSV alone."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from neuspike.utils.atomic import replacing

    rows: dict[str, list[tuple[float, float, float, float]]] = {}
    with open(csv_path, newline="") as fh:
        for r in csv.DictReader(fh):
            if r["psnr_db"] == "":
                continue
            rows.setdefault(r["method"], []).append(
                (float(r["time_s"]), float(r["psnr_db"]), float(r["ssim"]),
                 float(r["flicker_rmse"]) if r["flicker_rmse"] not in ("", "nan") else math.nan))
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for name, values in rows.items():
        a = np.asarray(values)
        for ax, col in zip(axes, (1, 2, 3)):
            ax.plot(1e3 * a[:, 0], a[:, col], label=name, lw=1)
    for ax, lab in zip(axes, ("PSNR (dB)", "SSIM", "flicker RMSE")):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("sensor time (ms)")
    axes[0].legend(fontsize=7, ncol=3)
    axes[0].set_title("per-frame scores against the ground truth (data_range 1)")
    fig.tight_layout()
    out = Path(png_path)
    with replacing(out) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
    return out
