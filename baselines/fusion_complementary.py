"""``fusion-complementary``: Scheerlinck's complementary filter with the frame taken from spikes.

The complementary filter (Scheerlinck, Barnes and Mahony, ACCV 2018, eq. 8) fuses a frame-based
estimate ``L_F`` of the log intensity, accurate at low temporal frequencies, with events, which
carry the high frequencies. Per pixel and per event i (time t_i, contribution ``c_i = p_i * theta``)::

    L <- beta_i * L + (1 - beta_i) * L_F + c_i,      beta_i = exp(-alpha * (t_i - t_{i-1}))

and before output a last decay towards ``L_F`` at the output instant t. Here ``L_F`` comes from the
spike camera and is constant over the window, and the filter starts at ``L(t_0) = L_F``, so the
recursion has the closed form::

    L(t) = L_F + sum over the pixel's events of c_i * exp(-alpha * (t - t_i))

(the ``(L(t_0) - L_F) * exp(-alpha * (t - t_0))`` term vanishes): ``L_F`` plus the events' high-pass
filter (:func:`baselines.event_integration.highpass_events`), one weighted ``bincount`` for all
pixels. Its transfer function is ``H_F(f) + 1 - 1 / (1 + j f / f_c)``: the frame's low-pass
response ``H_F`` plus the events' high-pass response, which sum to one (an exact reconstruction of
the log intensity) when ``H_F`` is the complementary low-pass ``1 / (1 + j f / f_c)``.

The frame: a causal spike rate
------------------------------
``L_F = log(max(r, r_min))`` with ``r`` the mean spike rate (spikes per plane) of the planes up to
the key instant: every plane of the spike window whose centre is at or before the key instant
(the newest ``spike_planes`` of them when that parameter is given; at least plane 0). Planes after
the key instant are not used, and neither are events after it (see below): a causal average of
the spikes is a low-pass estimate with a known lag, which the events' high-pass branch makes up
for, whereas the window-centred TFP average (symmetric blur) would need the events after the key
instant to be undone. A box average over a span ``D`` before the key instant has the response
``exp(-j pi f D) sinc(f D) = 1 - j pi f D + O(f^2)``; the exponential low-pass has
``1 - j f / f_c + O(f^2)``. They agree to first order when ``f_c = 1 / (pi D)``, that is when the
filter's time constant ``1 / alpha`` equals the mean age of the averaged planes (``D / 2``). So the
crossover is *matched to the spike planes* by default (``cutoff_hz=None``):
``alpha = 1 / mean age``. For the suite's simulated windows (256 planes at 20 kHz, the key instant
at the start of plane 128) the 128 planes before the key instant have a mean age of 3.2 ms:
``alpha = 312.5 / s``, ``f_c = 49.7 Hz``. The events then remove the lag (motion blur) of the spike
average over the last few milliseconds, while the spikes anchor the absolute level and events
older than a few time constants fade (their weight is ``exp(-alpha * age)``, 4 % after 10 ms), so
threshold mismatch and noise events cannot accumulate as in direct integration. The mean age is
floored at half a plane period (a key instant at the centre of plane 0 would otherwise give an
infinite crossover).

Dark floor: a pixel without a spike in the ``n`` averaged planes has ``r = 0``, whose log does not
exist; its rate is taken as ``r_min = 0.5 / n`` (half a spike in the averaged planes), the
estimate's own resolution; where the gain is known and that floor would map above white
(``r_min > gain``: a very dark scene), it is ``gain / 256`` instead (one 8-bit step), so a dark
pixel is not drawn white. The choice is deterministic and recorded (``last_planes``). The sensor's
dark rate (:func:`neuspike.methods.normalisation.dark_level`) is subtracted from ``r`` first, so the
dark current's spikes are not taken for light.

Events: every event the sample carries up to the key instant (``t_i < t``), its history included;
the filter runs from the first of them (``t_0``). Events after the key instant show a later scene
and are not used, as for the event-only methods. ``theta`` is the method's ``threshold`` parameter,
else the sample's ``event_threshold``, else 0.2 (:func:`baselines.event_integration.resolve_threshold`).

Output: ``exp(L)`` is a rate in spikes per plane. With the stream's gain known it is divided by the
gain and saturates at 1 (label ``"gain"``, as :func:`neuspike.methods.normalisation.rate_to_image`);
computed as ``r * exp(min(h, log(gain / r)))`` (``h`` the events' term, the cap only where the
pixel saturates anyway), so no overflow can occur and with no events the result is exactly the
spike estimate's image. Without a gain, the log image is divided by its 99th percentile in the log
domain (label ``"robust-p99"``, :func:`baselines.event_integration.log_to_image`).
"""

from __future__ import annotations

import math

import numpy as np

from baselines.event_integration import RunningEventSum, StreamsEventSum, highpass_events, log_to_image, resolve_threshold
from neuspike.methods.normalisation import dark_level, dark_note, rate_to_image
from neuspike.utils.checks import check_positive, check_positive_int
from neuspike.errors import InputError
from neuspike.methods import Method
from neuspike.methods.representations import spike_count
from neuspike.sample import Sample
from neuspike.streams import EventStream

__all__ = [
    "DARK_FLOOR_SPIKES",
    "causal_planes",
    "causal_spike_rate",
    "matched_cutoff_hz",
    "complementary_filter",
    "ComplementaryFusion",
    "register_methods",
]

#: Spikes assumed in the averaged planes of a pixel that did not fire (the dark floor).
DARK_FLOOR_SPIKES = 0.5

# Key instants within this many planes of a plane centre count as on it (float rounding).
_PLANE_TOLERANCE = 1e-6


def causal_planes(num_planes: int, plane_rate_hz: float, start_s: float, time_s: float,
                  max_planes: int | None = None) -> tuple[int, int]:
    """The planes ``[start, stop)`` whose centres are at or before ``time_s``.

    Plane j of a stream starting at ``start_s`` has its centre at ``start_s + (j + 0.5) / rate``.

    Parameters
    ----------
    num_planes : int
        T, the planes in the stream (>= 1).
    plane_rate_hz : float
        Planes per second.
    start_s : float
        Start of plane 0, in seconds.
    time_s : float
        The key instant, in seconds.
    max_planes : int or None
        Keep only the newest ``max_planes`` planes; ``None`` keeps all.

    Returns
    -------
    start, stop : int
        ``0 <= start < stop <= T``. When no plane centre precedes ``time_s``, plane 0 alone
        (``(0, 1)``).
    """
    num_planes = check_positive_int("num_planes", num_planes)
    rate = check_positive("plane_rate_hz", plane_rate_hz)
    offset = (float(time_s) - float(start_s)) * rate
    if not math.isfinite(offset):
        raise InputError(f"time_s: expected a finite time, got {time_s!r} (start {start_s!r})")
    stop = min(max(int(math.floor(offset + 0.5 + _PLANE_TOLERANCE)), 1), num_planes)
    start = 0 if max_planes is None else max(0, stop - check_positive_int("spike_planes", max_planes))
    return start, stop


def causal_spike_rate(planes: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Mean spike rate of planes ``[start, stop)``.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
    start, stop : int
        ``0 <= start < stop <= T``.

    Returns
    -------
    ndarray float64 (H, W) in [0, 1]: spikes per plane.
    """
    if not isinstance(planes, np.ndarray) or planes.ndim != 3 or planes.dtype != np.bool_:
        raise InputError(f"planes: expected a bool array (T, H, W), got {getattr(planes, 'dtype', type(planes))} "
                         f"{getattr(planes, 'shape', '')}")
    if not 0 <= start < stop <= planes.shape[0]:
        raise InputError(f"planes [{start}, {stop}): expected 0 <= start < stop <= {planes.shape[0]}")
    return spike_count(planes[start:stop]) * (1.0 / (stop - start))


def matched_cutoff_hz(plane_rate_hz: float, start_s: float, time_s: float, start: int, stop: int) -> float:
    """The crossover frequency that matches an average of planes ``[start, stop)`` read at ``time_s``.

    ``f_c = 1 / (2 pi a)`` with ``a`` the mean age of the planes' centres at ``time_s``, floored at
    half a plane period: the exponential low-pass with time constant ``a`` has the same lag as the
    box average (module docstring).

    Returns
    -------
    float, Hz (> 0).
    """
    rate = check_positive("plane_rate_hz", plane_rate_hz)
    mean_centre_s = float(start_s) + (0.5 * (start + stop - 1) + 0.5) / rate
    age_s = max(float(time_s) - mean_centre_s, 0.5 / rate)
    return 1.0 / (2.0 * math.pi * age_s)


def complementary_filter(
    events: EventStream,
    *,
    frame_log: np.ndarray,
    threshold: float,
    cutoff_hz: float,
    time_s: float,
) -> np.ndarray:
    """Scheerlinck's complementary filter with a constant frame, read out at ``time_s``.

    ``L(t) = L_F + sum_i c_i * exp(-alpha * (t - t_i))``, ``alpha = 2 pi cutoff_hz``, ``c_i = p_i *
    threshold``: the exact value of the per-event recursion ``L <- beta L + (1 - beta) L_F + c_i``
    (``beta = exp(-alpha * dt)``) started at ``L = L_F`` and decayed towards ``L_F`` up to ``time_s``.

    Parameters
    ----------
    events : EventStream
        Events with ``t_i <= time_s``, of the frame's size.
    frame_log : ndarray float (H, W), finite
        The frame-based log intensity ``L_F``.
    threshold : float
        Contrast threshold in log units (> 0).
    cutoff_hz : float
        Crossover frequency in Hz (> 0).
    time_s : float
        Output time in seconds.

    Returns
    -------
    ndarray, float64, shape (H, W): the fused log intensity.

    Raises
    ------
    InputError
        On a frame that is not a finite 2-D array of the events' size, events after ``time_s``,
        or invalid parameters.
    """
    frame_log = np.asarray(frame_log, dtype=np.float64)
    if frame_log.ndim != 2:
        raise InputError(f"frame_log: expected shape (H, W), got {frame_log.shape}")
    if not np.isfinite(frame_log).all():
        raise InputError("frame_log: expected finite values, found NaN or infinity")
    height, width = frame_log.shape
    return frame_log + highpass_events(events, threshold=threshold, cutoff_hz=cutoff_hz, time_s=time_s,
                                       height=height, width=width)


def _rate_image(frame_rate: np.ndarray, event_log: np.ndarray, gain: float | None) -> tuple[np.ndarray, str]:
    """``frame_rate * exp(event_log)`` as an image (module docstring, "Output")."""
    if gain is None:
        return log_to_image(np.log(frame_rate) + event_log)
    cap = np.maximum(np.log(gain) - np.log(frame_rate), 0.0)  # beyond it the pixel saturates at 1
    return rate_to_image(frame_rate * np.exp(np.minimum(event_log, cap)), gain, dark_rate=0.0)


class ComplementaryFusion(StreamsEventSum, Method):
    """``fusion-complementary``: complementary filter of events around a causal spike rate.

    Parameters
    ----------
    cutoff_hz : float or None
        Crossover frequency in Hz; ``None`` (default) matches it to the averaged spike planes
        (:func:`matched_cutoff_hz`; 49.7 Hz for the suite's 256-plane windows).
    spike_planes : int or None
        Average only the newest this-many planes before the key instant; ``None`` (default) all
        planes of the window up to the key instant.
    threshold : float or None
        Contrast threshold in log units; ``None`` takes the sample's, else 0.2.

    Attributes
    ----------
    last_planes : (int, int) or None
        Planes ``[start, stop)`` the last reconstruction averaged.
    last_cutoff_hz : float or None
        Crossover frequency it used.
    last_threshold, last_threshold_source
        The contrast threshold it used and where it came from.
    """

    inputs = frozenset({"spikes", "events"})

    def __init__(self, name: str | None = None, *, cutoff_hz: float | None = None,
                 spike_planes: int | None = None, threshold: float | None = None) -> None:
        if cutoff_hz is not None:
            cutoff_hz = check_positive("cutoff_hz", cutoff_hz)
        if spike_planes is not None:
            spike_planes = check_positive_int("spike_planes", spike_planes)
        if threshold is not None:
            threshold = check_positive("threshold", threshold)
        super().__init__(name, cutoff_hz=cutoff_hz, spike_planes=spike_planes, threshold=threshold)
        self.last_planes: tuple[int, int] | None = None
        self.last_cutoff_hz: float | None = None
        self.last_threshold: float | None = None
        self.last_threshold_source: str | None = None
        self._running = RunningEventSum()

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        stream = sample.spikes
        time_s = sample.key_time_s
        start, stop = causal_planes(stream.num_planes, stream.plane_rate_hz, stream.start_s, time_s,
                                    self.params["spike_planes"])
        rate = causal_spike_rate(stream.planes, start, stop)
        dark_rate, dark_how = dark_level(stream)  # the sensor's floor comes off before the floor of no spikes
        floor = DARK_FLOOR_SPIKES / (stop - start)
        if stream.gain is not None and floor > stream.gain:  # the floor would map above white: one 8-bit step
            floor = stream.gain / 256.0
        frame_rate = np.maximum(rate - dark_rate if dark_rate > 0 else rate, floor)
        cutoff_hz = self.params["cutoff_hz"]
        if cutoff_hz is None:
            cutoff_hz = matched_cutoff_hz(stream.plane_rate_hz, stream.start_s, time_s, start, stop)
        threshold, source = resolve_threshold(sample, self.params["threshold"])
        events = sample.events
        first = min(float(events.t_s[0]), time_s) if len(events) else time_s
        events = events.between(first, time_s)
        event_log = threshold * self._running.at(events, time_s=time_s, alpha=2.0 * math.pi * cutoff_hz,
                                                 height=sample.height, width=sample.width, previous_s=self._next_from)
        self.last_planes, self.last_cutoff_hz = (start, stop), cutoff_hz
        self.last_threshold, self.last_threshold_source = threshold, source
        image, label = _rate_image(frame_rate, event_log, stream.gain)
        return image, label + dark_note(dark_rate, dark_how)


def register_methods(register) -> None:
    """Add ``fusion-complementary`` to the registry."""
    register("fusion-complementary", ComplementaryFusion,
             params={"cutoff_hz": None, "spike_planes": None},
             description="complementary filter: causal spike rate (low-pass) + high-passed events, "
                         "crossover matched to the spike planes")
