"""How spike-rate estimates become images in [0, 1].

Two documented paths, and every method says which one it took (the label goes into each result row):

``"gain"``
    The stream's gain (expected spikes per plane per unit radiance) is known, as for simulated data:
    radiance = (rate - dark rate) / gain. Radiance above 1 (brighter than reference white, HDR)
    saturates at 1, which is the output contract of every method; nothing else is altered.
``"robust-p99"``
    The gain is unknown (real recordings): the dark-corrected estimate is divided by its 99th
    percentile over the image (ignoring non-finite values), so 1 % of pixels saturate and the image's
    scale no longer depends on the light level. An all-zero estimate stays zero.

The dark level
--------------
A spike pixel fires in darkness too (dark current: about one spike per 180 planes on a Vidar,
REFERENCE.md §1.2); every counted rate carries that floor, which at weak light is half of all spikes.
The floor is the stream's dark rate (mean spikes per plane in darkness) and is subtracted before the
gain divides. :func:`dark_level` says where it came from:

``"known"``
    The stream carries it (every simulation records it, 0.0 without a dark-current stage; a user may
    give a real sensor's calibration). A non-zero known rate adds ``", dark rate subtracted"`` to the
    label; a zero rate leaves the label as it was.
``"estimated"``
    The stream does not (a real recording): :func:`estimate_dark_rate` takes the rate of the darkest
    8x8 blocks of the window (their 1st percentile) as darkness, at most :data:`DARK_RATE_CAP`. That
    assumes the view holds some black; in a view without any, the estimate is the darkest content's
    rate (up to the cap) and the image comes out darker than the truth, by at most
    ``DARK_RATE_CAP / gain``. The label says ``", dark rate estimated"``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from neuspike.streams import SpikeStream

GAIN = "gain"
ROBUST = "robust-p99"
ROBUST_PERCENTILE = 99.0
#: Side of the square pixel blocks whose mean rates :func:`estimate_dark_rate` compares.
DARK_BLOCK_PX = 8
#: The percentile of those block rates taken as darkness.
DARK_PERCENTILE = 1.0
#: The most an estimate may take as darkness, spikes per plane: twice a Vidar's measured dark rate
#: (one spike per 180 planes, REFERENCE.md §1.2). A view whose darkest blocks fire faster holds no
#: black, and their rate is the light of its darkest content, not the sensor's floor.
DARK_RATE_CAP = 1.0 / 90.0
#: Where a stream's dark rate came from (:func:`dark_level`).
DARK_KNOWN, DARK_ESTIMATED = "known", "estimated"


def spike_counts(planes: np.ndarray) -> np.ndarray:
    """Each pixel's spike count over the planes: (H, W) unsigned integers, equal to
    ``np.count_nonzero(planes, axis=0)`` (a byte sum into 16-bit counters where the window allows, about
    five times faster on a 256-plane window)."""
    planes = np.asarray(planes)
    u8 = planes.view(np.uint8) if planes.dtype in (np.bool_, np.uint8) else (planes != 0).view(np.uint8)
    if planes.dtype == np.uint8 and u8.size and int(u8.max()) > 1:  # counts must not weigh a byte's value
        u8 = (u8 != 0).view(np.uint8)
    return u8.sum(axis=0, dtype=np.uint16 if planes.shape[0] < 2**16 else np.uint32)


def robust_scale(estimate: np.ndarray, *, percentile: float = ROBUST_PERCENTILE) -> float:
    """The ``percentile``-th value of ``estimate`` (> 0), or 1.0 when that value is not positive."""
    finite = estimate[np.isfinite(estimate)]
    if finite.size == 0:
        return 1.0
    scale = float(np.percentile(finite, percentile))
    return scale if scale > 0 else 1.0


def estimate_dark_rate(planes: np.ndarray, *, block_px: int = DARK_BLOCK_PX,
                       percentile: float = DARK_PERCENTILE, cap: float = DARK_RATE_CAP,
                       counts: np.ndarray | None = None) -> float:
    """The dark rate of a spike window estimated from its planes alone.

    The window's per-pixel rate is averaged over ``block_px`` x ``block_px`` blocks (a block of 64
    pixels holds enough spikes for its mean to be steady where one pixel's count is not), and the
    ``percentile``-th block rate is taken as the rate of darkness.

    Parameters
    ----------
    planes : ndarray, shape (T, H, W), bool or 0/1
        The spike planes of the window.
    block_px : int
        Block side in pixels (a view smaller than a block is one block).
    percentile : float
        Which block rate counts as dark, in [0, 100].
    cap : float
        The largest rate returned (module docstring).
    counts : ndarray (H, W), optional
        :func:`spike_counts` of the planes where the caller has it already (the same estimate, one
        pass over the planes fewer).

    Returns
    -------
    float
        Spikes per plane, in [0, cap]. Close to the truth where at least that share of the view is
        black (a little below it, the spread of the block means); above it, up to the cap, where the
        view holds no black (it includes the light of the darkest content).
    """
    planes = np.asarray(planes)
    if planes.ndim != 3 or planes.shape[0] == 0:
        raise ValueError(f"planes: expected shape (T, H, W) with T >= 1, got {planes.shape}")
    t, h, w = planes.shape
    if counts is None:
        counts = spike_counts(planes)
    elif np.shape(counts) != (h, w):
        raise ValueError(f"counts: expected shape {(h, w)}, got {np.shape(counts)}")
    rate = np.asarray(counts).astype(np.float64) / t
    bh, bw = min(block_px, h), min(block_px, w)
    rows, cols = h // bh, w // bw
    blocks = rate[:rows * bh, :cols * bw].reshape(rows, bh, cols, bw).mean(axis=(1, 3))
    return min(float(cap), max(0.0, float(np.percentile(blocks, percentile))))


def dark_level(stream: "SpikeStream", counts: np.ndarray | None = None) -> tuple[float, str]:
    """``(dark rate, how)``: the stream's own (``"known"``) or :func:`estimate_dark_rate` of its planes
    (``counts``: their per-pixel spike counts, where the caller has them)."""
    if stream.dark_rate is not None:
        return float(stream.dark_rate), DARK_KNOWN
    return estimate_dark_rate(stream.planes, counts=counts), DARK_ESTIMATED


def dark_note(dark_rate: float, how: str) -> str:
    """The label suffix that says how the dark level was handled (empty for a known zero rate)."""
    if how == DARK_ESTIMATED:
        return ", dark rate estimated"
    return ", dark rate subtracted" if dark_rate > 0 else ""


def rate_to_image(rate: np.ndarray, gain: float | None, *, dark_rate: float,
                  dark_how: str = DARK_KNOWN) -> tuple[np.ndarray, str]:
    """Turn a rate estimate (spikes per plane, (H, W)) into a float32 image in [0, 1].

    Parameters
    ----------
    rate : ndarray (H, W)
        Non-negative rate estimate in spikes per plane (NaN/inf treated as 0).
    gain : float or None
        Expected spikes per plane per unit radiance, or ``None`` when unknown.
    dark_rate : float
        Spikes per plane in darkness (>= 0), subtracted from ``rate`` first (module docstring).
    dark_how : {"known", "estimated"}
        Where ``dark_rate`` came from; it is said in the label.

    Returns
    -------
    image : float32 (H, W) in [0, 1]
    label : ``"gain"`` or ``"robust-p99"``, with :func:`dark_note`'s suffix
    """
    rate = np.asarray(rate)
    if not np.isfinite(rate).all():
        rate = np.nan_to_num(rate.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    dark_rate = float(dark_rate)
    if not (np.isfinite(dark_rate) and dark_rate >= 0):
        raise ValueError(f"dark_rate: expected a finite number >= 0, got {dark_rate!r}")
    if dark_rate > 0:
        rate = np.subtract(rate, dark_rate, dtype=np.float64)
    if gain is not None:
        scale, label = float(gain), GAIN
    else:
        scale, label = robust_scale(rate), ROBUST
    # divide in float64, then clip the float32 image in place (one allocation each)
    image = np.divide(rate, scale, dtype=np.float64).astype(np.float32)
    return np.clip(image, 0.0, 1.0, out=image), label + dark_note(dark_rate, dark_how)


def stream_rate_to_image(rate: np.ndarray, stream: "SpikeStream") -> tuple[np.ndarray, str]:
    """:func:`rate_to_image` with the stream's gain and its dark level (:func:`dark_level`)."""
    dark_rate, how = dark_level(stream)
    return rate_to_image(rate, stream.gain, dark_rate=dark_rate, dark_how=how)
