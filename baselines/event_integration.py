"""Classical event-only reconstructions: direct integration and Scheerlinck's high-pass filter.

Both work in log intensity. An event i at pixel (y_i, x_i), time t_i, polarity p_i in {-1, +1}
contributes c_i = p_i * theta, where theta is the contrast threshold in log units: the sample's
``event_threshold`` when known, otherwise :data:`DEFAULT_THRESHOLD` = 0.2 (the nominal threshold of
v2e and of the suite's event camera), unless the method is given its own ``threshold``. The
threshold used and where it came from are kept in the method's ``last_threshold`` and
``last_threshold_source`` (``"parameter"``, ``"sample"`` or ``"default"``).

``events-integrate`` — direct integration (Scheerlinck et al., ACCV 2018, eq. 1)::

    L(x, y, t) = L(x, y, t_0) + sum of c_i over the pixel's events with t_0 <= t_i < t

``L(x, y, t_0)`` is unknown and taken as uniform. The sum runs from the first event the sample
carries (the start of its history) to the key instant. Integrating the history as well as the
window is a deliberate choice: direct integration yields ``L(t) - L(t_0)``, which shows the present
image of a moving texture only once the scene has moved by more than the texture's correlation
length since ``t_0``; over a window of a few milliseconds alone it is little more than an edge map.
The price is drift: noise events and threshold mismatch accumulate without bound. Bounding that
drift is what the high-pass filter is for, so the two baselines bracket the trade-off.

``events-highpass`` — the high-pass filter (Scheerlinck et al., eq. 5–6): at each event
``L <- exp(-alpha * (t_i - t_last)) * L + c_i``, and before output a global decay
``L <- L * exp(-alpha * (t - t_last))``; ``alpha = 2 * pi * cutoff_hz``. Starting from L = 0, the
recursion is linear, so its value at the output time t has the closed form::

    L(x, y, t) = sum over the pixel's events of c_i * exp(-alpha * (t - t_i))

which is what is computed, for all pixels at once (one weighted ``bincount``; a million events take
milliseconds). The default cutoff is 5 Hz (time constant 1 / alpha = 32 ms): the authors' 0.06 Hz
suits recordings of seconds, but for the suite's windows of milliseconds (256 planes at 20 kHz =
12.8 ms) it would make the filter indistinguishable from direct integration. With 5 Hz an event one
window old keeps 67 % of its weight, one from ten windows back 2 %: the recent past builds the image
and older drift fades.

The output time is the sample's key instant for both methods: events after it are not used, so the
reconstruction shows the scene at the instant the ground truth is taken.

Output scale: the absolute level is unknown (``L(t_0)`` is), so the log image is turned into an
intensity image with ``exp`` and divided by its 99th percentile, clipped to [0, 1] (label
``"robust-p99"``, as for spike methods without a gain). The division is done in the log domain,
``exp(L - q99(L))``, so no overflow can occur however many events a pixel has. A uniform log image
(e.g. no events at all) therefore maps to 1 everywhere.
"""

from __future__ import annotations

import math

import numpy as np

from neuspike.methods.normalisation import ROBUST, ROBUST_PERCENTILE
from neuspike.utils.checks import check_positive, check_positive_int
from neuspike.errors import InputError
from neuspike.methods import Method
from neuspike.sample import Sample
from neuspike.streams import EventStream

__all__ = [
    "DEFAULT_THRESHOLD",
    "DEFAULT_CUTOFF_HZ",
    "event_contributions",
    "integrate_events",
    "highpass_events",
    "RunningEventSum",
    "StreamsEventSum",
    "log_to_image",
    "resolve_threshold",
    "EventIntegration",
    "EventHighPass",
    "register_methods",
]

#: Contrast threshold (log units) assumed when the sample does not give one.
DEFAULT_THRESHOLD = 0.2
#: Default cutoff frequency of the high-pass filter, in Hz.
DEFAULT_CUTOFF_HZ = 5.0


def _check_events(events: EventStream, height: int, width: int) -> None:
    if not isinstance(events, EventStream):
        raise InputError(f"events: expected an EventStream, got {type(events).__name__}")
    if (events.height, events.width) != (height, width):
        raise InputError(
            f"events come from a {events.width}x{events.height} sensor, expected {width}x{height}"
        )


def event_contributions(events: EventStream, *, threshold: float) -> np.ndarray:
    """Signed log-intensity steps ``c_i = p_i * threshold``, float64 (N,)."""
    threshold = check_positive("threshold", threshold)
    return events.p.astype(np.float64) * threshold


def integrate_events(events: EventStream, *, threshold: float, height: int, width: int) -> np.ndarray:
    """Direct integration: the sum of ``p_i * threshold`` per pixel.

    Parameters
    ----------
    events : EventStream
        The events to integrate (all of them).
    threshold : float
        Contrast threshold in log units (> 0).
    height, width : int
        Sensor size (must match the stream).

    Returns
    -------
    ndarray, float64, shape (H, W): the change of log intensity since before the first event.
    """
    height = check_positive_int("height", height)
    width = check_positive_int("width", width)
    _check_events(events, height, width)
    threshold = check_positive("threshold", threshold)
    return _net_polarity(events, height, width) * threshold


def _net_polarity(events: EventStream, height: int, width: int) -> np.ndarray:
    """Sum of polarities per pixel, float64 (H, W): whole numbers, so sums and differences of such
    images are exact, and a running image equals one summed afresh."""
    pixel = events.y.astype(np.int64) * width + events.x.astype(np.int64)
    return np.bincount(pixel, weights=events.p.astype(np.float64), minlength=height * width).reshape(height, width)


def highpass_events(
    events: EventStream,
    *,
    threshold: float,
    cutoff_hz: float,
    time_s: float,
    height: int,
    width: int,
) -> np.ndarray:
    """Scheerlinck's high-pass filter of the events, read out at ``time_s``.

    ``L(t) = sum_i c_i * exp(-alpha * (t - t_i))`` with ``alpha = 2 * pi * cutoff_hz`` — the exact
    value of the per-event recursion ``L <- exp(-alpha * dt) * L + c_i`` followed by the global decay
    to ``time_s``, started from L = 0.

    Parameters
    ----------
    events : EventStream
        Events with ``t_i <= time_s``.
    threshold : float
        Contrast threshold in log units (> 0).
    cutoff_hz : float
        Cutoff frequency of the filter in Hz (> 0).
    time_s : float
        Output time in seconds.
    height, width : int
        Sensor size (must match the stream).

    Returns
    -------
    ndarray, float64, shape (H, W): high-passed log intensity (0 = no recent change).

    Raises
    ------
    InputError
        On events after ``time_s`` or invalid parameters.
    """
    height = check_positive_int("height", height)
    width = check_positive_int("width", width)
    _check_events(events, height, width)
    cutoff_hz = check_positive("cutoff_hz", cutoff_hz)
    time_s = float(time_s)
    if not math.isfinite(time_s):
        raise InputError(f"time_s: expected a finite time, got {time_s!r}")
    if len(events) and events.t_s[-1] > time_s:
        raise InputError(f"highpass_events: the last event at {events.t_s[-1]!r} s is after the output time {time_s!r} s")
    threshold = check_positive("threshold", threshold)
    return _weighted_polarity(events, 2.0 * math.pi * cutoff_hz, time_s, height, width) * threshold


def _weighted_polarity(events: EventStream, alpha: float, time_s: float, height: int, width: int) -> np.ndarray:
    """``sum_i p_i * exp(-alpha * (time_s - t_i))`` per pixel, float64 (H, W); ``alpha = 0``: the
    plain polarity sum, whole numbers (so running sums of it are exact)."""
    if alpha == 0.0:
        return _net_polarity(events, height, width)
    pixel = events.y.astype(np.int64) * width + events.x.astype(np.int64)
    # exp of a large negative argument underflows quietly to 0: such events have decayed away.
    weights = events.p.astype(np.float64) * np.exp(-alpha * (time_s - events.t_s))
    return np.bincount(pixel, weights=weights, minlength=height * width).reshape(height, width)


class RunningEventSum:
    """The per-pixel sum ``sum_i p_i * exp(-alpha * (t - t_i))`` over the events a sample carries up
    to its key instant ``t`` (``alpha = 0``: the plain polarity sum), kept up to date along a video.

    Summing a 1 s history afresh at every frame costs the history's events (tens of millions for a
    busy scene); the sum is linear in the events, so :meth:`at` with the previous frame's instant
    instead ages the previous sum, adds the events between the two instants and takes away those
    that left the history: the previous sample's events before the first one the new sample carries
    (both samples being time slices of one recording, as :func:`neuspike.formats.samples.stream_samples`
    cuts them). A frame then costs its new events. With ``alpha = 0`` the sums are whole numbers
    and the update is exact; with ``alpha > 0`` it agrees with a fresh sum to float64 rounding
    (~1e-12 relative).

    It sums afresh when there is no previous frame at ``previous_s`` of the same size, when time
    went back, when the new events reach back before the previous ones (a longer history), or when
    ``alpha`` changed by more than rounding. The last sample's events stay referenced until
    :meth:`reset` (the video stream resets its methods when it ends).
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the previous frame."""
        self._carried: tuple[float, float, int, int, EventStream, np.ndarray] | None = None
        #: Whether the last sum was updated from the previous frame's (``False``: summed afresh).
        self.last_streamed = False

    def at(self, events: EventStream, *, time_s: float, alpha: float, height: int, width: int,
           previous_s: float | None = None) -> np.ndarray:
        """The sum at ``time_s`` over ``events`` (all before ``time_s``; the sample's, from its first).

        ``previous_s``: the key instant of the previous frame of the same video, or ``None`` for a
        frame summed afresh. Returns float64 (H, W), read-only (it is carried to the next frame).

        Raises
        ------
        InputError
            On events of another sensor size, or at or after ``time_s``.
        """
        _check_events(events, height, width)
        if len(events) and not events.t_s[-1] < time_s:
            raise InputError(f"RunningEventSum: an event at {float(events.t_s[-1])!r} s is not before the "
                             f"output time {float(time_s)!r} s")
        state = None if previous_s is None else self._update(events, float(time_s), float(alpha), height, width,
                                                             float(previous_s))
        self.last_streamed = state is not None
        if state is None:
            state = _weighted_polarity(events, alpha, time_s, height, width)
        state.flags.writeable = False
        self._carried = (float(time_s), float(alpha), height, width, events, state)
        return state

    def _update(self, events: EventStream, time_s: float, alpha: float, height: int, width: int,
                previous_s: float) -> np.ndarray | None:
        if self._carried is None:
            return None
        before_s, before_alpha, h, w, before, state = self._carried
        if (before_s != previous_s or (h, w) != (height, width) or time_s < before_s
                or not math.isclose(alpha, before_alpha, rel_tol=1e-9, abs_tol=0.0)):
            return None
        first = events.t_s[0] if len(events) else np.inf
        if len(before) and first < before.t_s[0]:
            return None  # this sample reaches further back (a longer history): not a slice after the last
        if alpha:
            state = state * math.exp(-alpha * (time_s - before_s))
        # what left the history: the previous events before the first one this sample carries
        if len(before) and before.t_s[0] < first:
            gone = before if not len(events) else before.between(float(before.t_s[0]), float(first))
            state = state - _weighted_polarity(gone, alpha, time_s, height, width)
        new = events.between(before_s, time_s)
        if len(new):
            state = state + _weighted_polarity(new, alpha, time_s, height, width)
        return state


def log_to_image(log_image: np.ndarray) -> tuple[np.ndarray, str]:
    """Turn a log-intensity image of unknown offset into a float32 image in [0, 1].

    ``exp(L - q)``, clipped to [0, 1], with ``q`` the 99th percentile of ``L``: intensity divided by
    its 99th percentile (up to the interpolation between neighbouring order statistics), computed
    without overflow.

    Parameters
    ----------
    log_image : ndarray, float, (H, W), finite

    Returns
    -------
    image : float32 (H, W) in [0, 1]
    label : ``"robust-p99"``
    """
    log_image = np.asarray(log_image, dtype=np.float64)
    if log_image.size == 0:
        return log_image.astype(np.float32), ROBUST
    q = float(np.percentile(log_image, ROBUST_PERCENTILE))
    image = np.exp(np.minimum(log_image - q, 0.0))
    return image.astype(np.float32), ROBUST


def resolve_threshold(sample: Sample, override: float | None) -> tuple[float, str]:
    """The contrast threshold (log units) to use for ``sample``, and where it came from.

    Parameters
    ----------
    sample : Sample
    override : float or None
        A method's own ``threshold`` parameter; wins when given.

    Returns
    -------
    threshold : float, > 0
    source : ``"parameter"``, ``"sample"`` (its ``event_threshold``) or ``"default"``
        (:data:`DEFAULT_THRESHOLD`).
    """
    if override is not None:
        return check_positive("threshold", override), "parameter"
    if sample.event_threshold is not None:
        return check_positive("sample.event_threshold", sample.event_threshold), "sample"
    return DEFAULT_THRESHOLD, "default"


class StreamsEventSum:
    """Video support for a method whose events' term is a :class:`RunningEventSum` (``self._running``):
    :meth:`reset` forgets the previous frame, :meth:`reconstruct_next` passes the previous frame's
    instant on to the sum (as ``self._next_from``, read by the method's ``_reconstruct``)."""

    _running: RunningEventSum
    _next_from: float | None = None

    def reset(self) -> None:
        """Forget the previous frame (the next one sums its events afresh)."""
        self._running.reset()

    @property
    def last_streamed(self) -> bool:
        """Whether the last events' sum was updated from the previous frame's (``False``: summed afresh)."""
        return self._running.last_streamed

    def reconstruct_next(self, sample: Sample, *, previous_s: float) -> np.ndarray:
        """The image at the sample's key instant, its events' sum updated from the previous frame's at
        ``previous_s`` (equal to a single-frame call, to rounding for decayed sums)."""
        self._next_from = float(previous_s)
        try:
            return self.reconstruct(sample)
        finally:
            self._next_from = None


class _EventFilter(StreamsEventSum, Method):
    """Shared parts of the two classical event methods, video included.

    In a video (:meth:`reconstruct_next`) the image is updated from the previous frame's
    (:class:`RunningEventSum`) instead of summing the whole history again: direct integration
    bit for bit as a single-frame call, the high-pass filter to rounding (its float32 image within
    1e-6).
    """

    inputs = frozenset({"events"})

    def __init__(self, name: str | None = None, *, threshold: float | None = None, **params) -> None:
        if threshold is not None:
            threshold = check_positive("threshold", threshold)
        super().__init__(name, threshold=threshold, **params)
        self.last_threshold: float | None = None
        self.last_threshold_source: str | None = None
        self._running = RunningEventSum()

    def _threshold(self, sample: Sample) -> float:
        """The contrast threshold for ``sample``: the method's parameter, the sample's, or the default."""
        value, source = resolve_threshold(sample, self.params["threshold"])
        self.last_threshold, self.last_threshold_source = value, source
        return value

    @staticmethod
    def _events_until_key(sample: Sample) -> EventStream:
        """All events the sample carries (history and window) before the key instant."""
        events = sample.events
        start = min(float(events.t_s[0]), sample.key_time_s) if len(events) else sample.key_time_s
        return events.between(start, sample.key_time_s)

    def _alpha(self) -> float:
        """The decay rate of an event's weight, 1/s (0: none)."""
        return 0.0

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        threshold = self._threshold(sample)
        total = self._running.at(self._events_until_key(sample), time_s=sample.key_time_s, alpha=self._alpha(),
                                 height=sample.height, width=sample.width, previous_s=self._next_from)
        return log_to_image(total * threshold)


class EventIntegration(_EventFilter):
    """``events-integrate``: direct integration of signed thresholds (see the module docstring).

    Parameters
    ----------
    threshold : float or None
        Contrast threshold in log units; ``None`` takes the sample's, else 0.2.
    """


class EventHighPass(_EventFilter):
    """``events-highpass``: Scheerlinck's high-pass filter read out at the key instant.

    Parameters
    ----------
    cutoff_hz : float
        Cutoff frequency in Hz (default 5 Hz; see the module docstring).
    threshold : float or None
        Contrast threshold in log units; ``None`` takes the sample's, else 0.2.
    """

    def __init__(self, name: str | None = None, *, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
                 threshold: float | None = None) -> None:
        super().__init__(name, threshold=threshold, cutoff_hz=check_positive("cutoff_hz", cutoff_hz))

    def _alpha(self) -> float:
        return 2.0 * math.pi * self.params["cutoff_hz"]


def register_methods(register) -> None:
    """Add ``events-integrate`` and ``events-highpass`` to the registry."""
    register("events-integrate", EventIntegration,
             description="direct integration of signed contrast thresholds over history and window")
    register("events-highpass", EventHighPass, params={"cutoff_hz": DEFAULT_CUTOFF_HZ},
             description="Scheerlinck's high-pass filter of the events, 5 Hz cutoff")
