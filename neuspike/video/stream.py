"""Stream a recording through methods: one image per output instant, memory bounded by the window.

The recording is opened by :func:`neuspike.formats.recording.open_recording` and cut into samples by
:func:`neuspike.formats.samples.stream_samples` (the same cut as a single-frame
:func:`neuspike.formats.samples.load_sample` at that instant, reading spikes by plane range and events by
time range, each read once however high the frame rate); both are re-exported here.

:func:`reconstruct_video` yields ``(time_s, image)`` for one method, :func:`stream_methods` runs
several over one pass. Stateless methods give exactly the images of single-frame reconstructions at
the same instants (the samples are equal). Recurrent methods are reset once, at the first frame
(which warms up on the history as a single-frame call does); later frames go through
:meth:`~neuspike.methods.Method.reconstruct_next` where a method offers it, which continues the
recurrent state with only the input after the previous frame; the event filters
(:class:`baselines.event_integration.RunningEventSum`) update their sums over the history the same
way, giving the single-frame images (integration bit for bit, the decayed sums to rounding).
"""

from __future__ import annotations

import math
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from neuspike.utils.checks import check_positive
from neuspike.errors import InputError
from neuspike.formats.recording import RecordingReader, open_recording
from neuspike.formats.samples import EVENT_HISTORY_S, stream_samples
from neuspike.sample import Sample

__all__ = [
    "VideoRecording",
    "open_recording",
    "frame_times",
    "check_fps",
    "centred_span",
    "needs_centred_window",
    "stream_samples",
    "stream_methods",
    "reconstruct_video",
]

#: The opened recording a video streams from (:class:`neuspike.formats.recording.RecordingReader`).
VideoRecording = RecordingReader


# --------------------------------------------------------------------------- instants
def frame_times(start_s: float, end_s: float, fps: float) -> np.ndarray:
    """Output instants: the centres of the ``1 / fps`` intervals that tile ``[start_s, end_s)``.

    Returns
    -------
    ndarray float64 (n,), ``start_s + (k + 0.5) / fps`` for ``k = 0 .. n - 1`` with
    ``n = floor((end_s - start_s) * fps)``. At ``fps`` equal to the plane rate, starting on a plane
    boundary, these are the plane centres: one frame per plane.

    Raises
    ------
    InputError
        ``end_s <= start_s``, a non-positive rate, or a range shorter than one frame.
    """
    fps = check_positive("fps", fps)
    start_s, end_s = float(start_s), float(end_s)
    if not (math.isfinite(start_s) and math.isfinite(end_s)):
        raise InputError(f"start and end must be finite, got {start_s!r}, {end_s!r}")
    if end_s <= start_s:
        raise InputError(f"the start {start_s:.6f} s is not before the end {end_s:.6f} s")
    n = int(math.floor((end_s - start_s) * fps + 1e-9))
    if n < 1:
        raise InputError(
            f"the range [{start_s:.6f}, {end_s:.6f}) s is shorter than one frame at {fps:g} frames/s "
            f"({1.0 / fps:.6f} s): no frame to write"
        )
    return start_s + (np.arange(n, dtype=np.float64) + 0.5) / fps


def check_fps(fps: float, recording: VideoRecording, inputs: Iterable[str]) -> float:
    """Refuse an output rate above the plane rate when a spike method is asked for.

    Spike methods cannot make more distinct frames than the sensor made planes (neighbouring frames
    inside one plane would repeat it); event-only methods may go higher (events are continuous).
    """
    fps = check_positive("fps", fps)
    if "spikes" in set(inputs) and fps > recording.plane_rate_hz * (1 + 1e-9):
        raise InputError(
            f"--fps {fps:g} is above the spike plane rate {recording.plane_rate_hz:g} planes/s: a spike "
            "method cannot make more frames than the sensor made planes (event-only methods can)"
        )
    return fps


def needs_centred_window(method: Any) -> bool:
    """Whether ``method`` refuses spike windows shifted off their key instant (``needs_centred_window``)."""
    return bool(getattr(method, "needs_centred_window", False))


def centred_span(recording: VideoRecording, window_planes: int | None = None) -> tuple[float, float]:
    """The instants whose spike window is centred on them and lies inside the file: ``[lo, hi)`` seconds.

    A window of N planes around the key plane K spans planes ``K - N // 2 .. K - N // 2 + N - 1``;
    it lies inside a file of P planes for ``N // 2 <= K <= P - N + N // 2``. Elsewhere the cut
    shifts the window (:mod:`neuspike.formats.samples`), which methods trained on centred windows
    refuse (:func:`needs_centred_window`).

    Raises
    ------
    InputError
        A recording without spikes, or one shorter than the window.
    """
    if recording.spikes_path is None:
        raise InputError("centred_span: the recording has no spikes")
    n = recording.default_window_planes() if window_planes is None else int(window_planes)
    total, rate = recording.num_planes, recording.plane_rate_hz
    first, last = n // 2, total - n + n // 2
    if last < first:
        raise InputError(f"the recording has {total} planes, fewer than one {n}-plane window: no frame has a "
                         "centred window")
    return recording.start_s + first / rate, recording.start_s + (last + 1) / rate


# --------------------------------------------------------------------------- streaming
def _next_image(method: Any, sample: Sample, previous_s: float | None) -> np.ndarray:
    hook = getattr(method, "reconstruct_next", None)
    if previous_s is None or hook is None:
        return method.reconstruct(sample)
    return hook(sample, previous_s=previous_s)


def stream_methods(
    methods: Sequence[Any],
    recording: VideoRecording,
    times_s: Sequence[float] | np.ndarray,
    *,
    window_planes: int | None = None,
    event_history_s: float = EVENT_HISTORY_S,
) -> Iterator[tuple[Sample, dict[str, np.ndarray], dict[str, float]]]:
    """Run several methods over one pass of the recording.

    Yields
    ------
    (sample, images, seconds)
        The instant's sample, each method's image by name, and each method's wall time for it
        (seconds, the method call only: reading and cutting the sample are shared and not counted).
    """
    import time

    names = [m.name for m in methods]
    if len(set(names)) != len(names):
        raise InputError(f"methods must have distinct names, got {names}")
    inputs: set[str] = set()
    for m in methods:
        inputs |= set(m.inputs)
    missing = inputs - recording.modalities
    if missing:
        who = [m.name for m in methods if set(m.inputs) & missing]
        raise InputError(f"method(s) {', '.join(who)} need {sorted(missing)}, which the recording lacks")
    for m in methods:
        m.reset()
    previous: float | None = None
    try:
        for sample in stream_samples(recording, times_s, inputs=inputs, window_planes=window_planes,
                                     event_history_s=event_history_s):
            images, seconds = {}, {}
            for m in methods:
                t0 = time.perf_counter()
                images[m.name] = _next_image(m, sample, previous)
                seconds[m.name] = time.perf_counter() - t0
            previous = sample.key_time_s
            yield sample, images, seconds
    finally:  # the carried state (a recurrent state, the last sample's events) is not kept past the video
        for m in methods:
            m.reset()


def reconstruct_video(
    method: Any,
    recording: VideoRecording,
    times_s: Sequence[float] | np.ndarray,
    *,
    window_planes: int | None = None,
    event_history_s: float = EVENT_HISTORY_S,
) -> Iterator[tuple[float, np.ndarray]]:
    """Yield ``(time_s, image)`` for each output instant, reading the recording as it goes.

    Parameters
    ----------
    method : neuspike.methods.Method
        Any registered method; it is reset before the first frame.
    recording : VideoRecording
        From :func:`open_recording`.
    times_s : sequence of float
        Output instants, sensor seconds (e.g. :func:`frame_times`).
    window_planes, event_history_s
        As for :func:`stream_samples`.

    Yields
    ------
    (float, ndarray float32 (H, W) in [0, 1])
        For stateless methods each image equals ``method.reconstruct(load_sample(..., at_s=t))``.
    """
    for sample, images, _ in stream_methods([method], recording, times_s, window_planes=window_planes,
                                            event_history_s=event_history_s):
        yield sample.key_time_s, images[method.name]
