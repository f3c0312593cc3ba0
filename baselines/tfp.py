"""TFP, texture from playback: the spike rate in a window of planes around the key plane.

The estimate of a pixel's rate (spikes per plane) is its spike count in a window of planes divided by
the number of planes in that window; the radiance is (rate - dark rate) / gain, where the gain is the
expected number of spikes per plane per unit radiance (``L / threshold`` for simulated data) and the
dark rate the sensor's spikes per plane in darkness (known, or estimated from the window:
:func:`neuspike.methods.normalisation.dark_level`). When the gain is
unknown (real recordings) the rate goes through the robust normalisation of
:mod:`neuspike.methods.normalisation` instead, and the method says so in its normalisation label.

Which planes
------------
``window=None`` (the ``tfp`` entry) uses every plane of the sample's spike window. A window of ``w``
planes (``tfp-w8`` ... ``tfp-w64``) is the planes ``[k - w // 2, k - w // 2 + w)`` around the key plane
``k``:

* odd ``w``: ``(w - 1) / 2`` planes on each side of the key plane, centred on the key plane's centre;
* even ``w``: ``w / 2`` planes before the key plane and ``w / 2`` from it on (the key plane included),
  centred on the key plane's *start*. For simulated samples the key instant is the start of the
  centre plane (``T / 2`` of an even ``T``), so even windows are centred on the key instant exactly.

When the stream has fewer than ``w`` planes, the whole stream is used (``T`` planes); when it has
enough planes but the window would spill over one end (a key plane near an edge), the window is
shifted inward so that it keeps its ``w`` planes. Neither is silent: :func:`tfp_window` returns the
planes used, and :class:`TFP` records them in ``last_window`` (``(start, stop)``) after every call.

Quantisation: over ``n`` planes the count of an ideal integrate-and-fire pixel with constant input is
``floor(n * a)`` or ``ceil(n * a)`` (``a`` its rate), so the radiance error is below ``1 / (n * gain)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from neuspike.utils.checks import check_int, check_positive_int, check_spike_window
from neuspike.errors import InputError
from neuspike.methods.normalisation import stream_rate_to_image
from neuspike.methods.representations import spike_count
from neuspike.methods import Method
from neuspike.sample import Sample

#: The fixed-size variants registered besides ``tfp`` (planes per window).
VARIANT_WINDOWS_PLANES = (8, 16, 32, 64)

def _check_window(window: Any) -> int | None:
    if window is None:
        return None
    return check_int("window", window, minimum=1, what="None (the whole stream) or a whole number of planes")


def tfp_window(num_planes: int, key_plane: int, window: int | None) -> tuple[int, int]:
    """The planes ``[start, stop)`` that TFP counts.

    Parameters
    ----------
    num_planes : int
        T, the number of planes in the stream (>= 1).
    key_plane : int
        Index of the key plane, in [0, T).
    window : int or None
        Requested planes per window; ``None`` for the whole stream.

    Returns
    -------
    start, stop : int
        ``stop - start = min(window, T)`` planes (``T`` when ``window`` is ``None``); see the module
        docstring for the placement of even windows and the shift at the stream's ends.
    """
    num_planes = check_positive_int("num_planes", num_planes)
    key_plane = check_int("key_plane", key_plane, what="an integer plane index")
    if not 0 <= key_plane < num_planes:
        raise InputError(f"key_plane: expected an index in [0, {num_planes}), got {key_plane}")
    window = _check_window(window)
    num_planes, key_plane = int(num_planes), int(key_plane)
    if window is None or window >= num_planes:
        return 0, num_planes
    start = min(max(key_plane - window // 2, 0), num_planes - window)
    return start, start + window


def tfp_rate(planes: np.ndarray, key_plane: int, window: int | None) -> np.ndarray:
    """Spike rate around the key plane: the count in the TFP window divided by its planes.

    Parameters
    ----------
    planes : ndarray of bool, shape (T, H, W)
        The spike window.
    key_plane : int
        Index of the key plane, in [0, T).
    window : int or None
        Planes per window (see :func:`tfp_window`), ``None`` for all T planes.

    Returns
    -------
    ndarray float64 (H, W) in [0, 1]
        Spikes per plane.
    """
    planes, key_plane = check_spike_window(planes, key_plane)
    start, stop = tfp_window(planes.shape[0], key_plane, window)
    return _window_rate(planes, start, stop)


def _window_rate(planes: np.ndarray, start: int, stop: int) -> np.ndarray:
    # count * (1 / n) rather than count / n: a multiplication is twice as fast as a division here,
    # and the two differ by at most 2 units in the last place.
    return spike_count(planes[start:stop]) * (1.0 / (stop - start))


class TFP(Method):
    """Texture from playback (see the module docstring).

    Parameters
    ----------
    name : str, optional
        Registry name.
    window : int or None
        Planes per window centred on the key plane; ``None`` uses the whole spike window.

    Attributes
    ----------
    last_window : tuple of int or None
        The planes ``(start, stop)`` of the last reconstruction's window, indices into its stream.
    """

    inputs = frozenset({"spikes"})

    def __init__(self, name: str | None = None, *, window: int | None = None) -> None:
        window = _check_window(window)
        super().__init__(name, window=window)
        self.window = window
        self.last_window: tuple[int, int] | None = None

    def reset(self) -> None:
        """Forget the previous frame's count (streaming)."""
        self._previous = None

    def reconstruct_next(self, sample: Sample, *, previous_s: float) -> np.ndarray:
        """Streaming (:mod:`neuspike.video`): the previous frame's count, plus the planes that entered
        the window, minus those that left it. Counts are integers, so the image is the one
        :meth:`reconstruct` gives; a window that does not overlap the previous one going forward, or
        moved by more than half its length, is counted afresh. The previous sample's planes must be
        unchanged (the video stream hands out read-only views).
        """
        self._sliding = True
        try:
            return self.reconstruct(sample)
        finally:
            self._sliding = False

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        stream = sample.spikes
        start, stop = tfp_window(stream.num_planes, sample.key_plane, self.window)
        base = round(stream.start_s * stream.plane_rate_hz)  # recording plane of stream.planes[0]
        a0, a1 = base + start, base + stop
        prev = getattr(self, "_previous", None) if getattr(self, "_sliding", False) else None
        if (prev is not None and prev[4] == stream.plane_rate_hz and prev[0].shape[1:] == stream.planes.shape[1:]
                and prev[2] <= a0 < prev[3] <= a1 and 2 * ((a0 - prev[2]) + (a1 - prev[3])) < a1 - a0):
            planes0, base0, p0, p1, _, count = prev
            count = count.astype(np.int32)
            count -= spike_count(planes0[p0 - base0:a0 - base0])
            count += spike_count(stream.planes[p1 - base:a1 - base])
        else:
            count = spike_count(stream.planes[start:stop])
        self._previous = (stream.planes, base, a0, a1, stream.plane_rate_hz, count)
        rate = count * (1.0 / (stop - start))  # as _window_rate computes it
        self.last_window = (start, stop)
        return stream_rate_to_image(rate, stream)


def register_methods(register) -> None:
    """Register ``tfp`` (whole window) and ``tfp-w8``, ``tfp-w16``, ``tfp-w32``, ``tfp-w64``."""
    register(
        "tfp",
        TFP,
        params={"window": None},
        description="texture from playback: spike rate over the whole spike window, divided by the gain",
    )
    for planes in VARIANT_WINDOWS_PLANES:
        register(
            f"tfp-w{planes}",
            TFP,
            params={"window": planes},
            description=f"texture from playback: spike rate over {planes} planes centred on the key plane",
        )
