"""NeuSpike-Net behind the method interface: ``neuspike-net`` (spikes + events) and ``neuspike-net-spike``.

It trains as every learned method does (:mod:`neuspike.train`): ``create(name, trained=False)`` builds
the untrained module (:meth:`NeuSpikeNetMethod.build_module`) and :meth:`NeuSpikeNetMethod.encode`
turns a sample into the module's input tensors.

The network is trained on spike windows centred on the key instant; a window that was shifted to stay
inside its recording (a frame near either end) is refused, not reconstructed at the window's centre
(which shows another instant). In a video (:meth:`NeuSpikeNetMethod.reconstruct_next`), the
representations slide (:class:`neuspike.nets.sliding.SlidingRepresentation`): each plane and event
is binned once and every frame's input equals its single-frame input exactly.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch
from torch import nn

from neuspike.errors import FormatError, InputError
from neuspike.methods.learned import LearnedMethod
from neuspike.methods.readout import despeckle, wiener
from neuspike.nets.fusion import FUSIONS
from neuspike.nets.network import HEADS, KEY_ESTIMATES, MOTION_GATES, SUPPORT_CUES, TRANSFORMERS, NeuSpikeNet
from neuspike.nets.representations import (EVENT_REPRESENTATIONS, SPIKE_REPRESENTATIONS, event_representation,
                                           key_representation, spike_gain, spike_quantum, spike_representation)
from neuspike.sample import Sample
from neuspike.methods.weights import read_card
from neuspike.methods.counting import initial_state, level_shift
from neuspike.methods.normalisation import DARK_ESTIMATED, dark_level, spike_counts
from neuspike.nets.sliding import SlidingRepresentation

__all__ = ["ARCHITECTURE_PARAMS", "CARD_DEFAULTS", "LEVELS", "NeuSpikeNetMethod", "count_level"]

#: The parameters that define the module and its inputs (recorded in the weights card and checked).
ARCHITECTURE_PARAMS = ("spike_representation", "event_representation", "fusion", "spike_only", "head", "motion_gate",
                       "transformer", "support_cue", "key_estimates")
#: What an architecture parameter means when a weights card (written before it existed) lacks it.
CARD_DEFAULTS = {"head": "tanh", "motion_gate": "none", "transformer": "fixed", "support_cue": "none",
                 "key_estimates": "none"}
#: Architecture parameters kept out of ``params`` at their defaults (the full network), checked against a card too.
SIZE_DEFAULTS = {"width": 1.0, "head_kernel": 3}
#: How the image's mean level is set (``level``): ``"counts"`` from the window's spike count where the
#: sensor's gain is known (:func:`neuspike.methods.counting.level_shift`), ``"network"`` as the network outputs it.
LEVELS = ("counts", "network")
#: The read-out label of an image whose mean level was counted from the spikes.
COUNTED = "mean level counted from the spikes"


def count_level(sample: Sample) -> float | None:
    """The mean radiance of the window's frame by the linear rule, or None where it cannot be known.

    The rule takes a pixel of radiance ``x`` to fire ``T (gain x + d) - 1/2`` spikes over ``T`` planes
    (``d`` the dark rate, half a spike left in the integrator), so ``(mean rate + 1 / (2 T) - d) / gain``.
    That holds for pixels that fire a few spikes or more; a dim pixel that starts with Algorithm 1's
    random charge fires more than it says (0.18 spikes at zero light), so for a dim frame this is too
    high by up to ``0.68 / (T gain)``. The method's own level does not use it: it shifts its image under
    the sensor model of :mod:`neuspike.methods.counting`. This quick estimate needs the gain (a
    simulation knows it; a real recording rarely does): None otherwise. The dark rate is the stream's,
    or, where the stream does not know it, estimated from the window
    (:func:`neuspike.methods.normalisation.dark_level`).
    """
    spikes = sample.spikes
    if spikes is None:
        return None
    gain, how = spike_gain(sample)
    if how != "known":
        return None
    dark_rate, _ = dark_level(spikes)
    planes = spikes.planes
    rate = np.count_nonzero(planes) / planes.size
    return float((rate + 0.5 / planes.shape[0] - dark_rate) / gain)


def _check_params(params: Mapping[str, Any]) -> dict[str, Any]:
    p = {k: params[k] for k in ARCHITECTURE_PARAMS if k in params}
    missing = [k for k in ARCHITECTURE_PARAMS if k not in p]
    if missing:
        raise InputError(f"neuspike-net: missing parameters {missing}")
    if p["spike_representation"] not in SPIKE_REPRESENTATIONS:
        raise InputError(f"spike_representation: expected one of {SPIKE_REPRESENTATIONS}, got {p['spike_representation']!r}")
    if p["event_representation"] not in EVENT_REPRESENTATIONS:
        raise InputError(f"event_representation: expected one of {EVENT_REPRESENTATIONS}, got {p['event_representation']!r}")
    if p["fusion"] not in FUSIONS:
        raise InputError(f"fusion: expected one of {FUSIONS}, got {p['fusion']!r}")
    if not isinstance(p["spike_only"], bool):
        raise InputError(f"spike_only: expected True or False, got {p['spike_only']!r}")
    if p["head"] not in HEADS:
        raise InputError(f"head: expected one of {HEADS}, got {p['head']!r}")
    if p["motion_gate"] not in MOTION_GATES:
        raise InputError(f"motion_gate: expected one of {MOTION_GATES}, got {p['motion_gate']!r}")
    if p["spike_only"] and p["motion_gate"] != "none":
        raise InputError("motion_gate: the spike-only variant has no motion path to gate; use 'none'")
    if p["transformer"] not in TRANSFORMERS:
        raise InputError(f"transformer: expected one of {TRANSFORMERS}, got {p['transformer']!r}")
    if p["support_cue"] not in SUPPORT_CUES:
        raise InputError(f"support_cue: expected one of {SUPPORT_CUES}, got {p['support_cue']!r}")
    if p["support_cue"] != "none" and p["head"] != "support-count":
        raise InputError(f"support_cue: {p['support_cue']!r} needs the 'support-count' head, got {p['head']!r}")
    if p["key_estimates"] not in KEY_ESTIMATES:
        raise InputError(f"key_estimates: expected one of {tuple(KEY_ESTIMATES)}, got {p['key_estimates']!r}")
    if p["key_estimates"] != "none" and p["head"] != "support-count":
        raise InputError(f"key_estimates: {p['key_estimates']!r} needs the 'support-count' head, got {p['head']!r}")
    return p


def check_centred(sample: Sample, name: str | None) -> None:
    """Refuse a spike window whose centre is more than one plane from the key instant (shifted at a
    recording's end): the network reconstructs its window's centre, so it would show another instant."""
    spikes = sample.spikes
    plane_s = 1.0 / spikes.plane_rate_hz
    centre = spikes.start_s + spikes.num_planes * plane_s / 2.0
    off = sample.key_time_s - centre
    if abs(off) > plane_s * (1 + 1e-6):
        raise InputError(
            f"{name or 'neuspike-net'}: the key instant {sample.key_time_s:.6f} s is {abs(off) * 1e3:.2f} ms "
            f"{'after' if off > 0 else 'before'} the centre of its {spikes.num_planes}-plane spike window (shifted "
            "to stay inside the recording); the network is trained on centred windows only, so this frame is "
            "refused: choose instants at least half a window from either end")


class NeuSpikeNetMethod(LearnedMethod):
    """NeuSpike-Net (:mod:`neuspike.nets`).

    Parameters
    ----------
    spike_representation, event_representation : str
        T_spike and T_event (:mod:`neuspike.nets.representations`).
    fusion : str
        The fusion module F (:mod:`neuspike.nets.fusion`).
    spike_only : bool
        The spike-only variant (texture path and decoders; needs no events).
    event_skip_weight : float
        ``w`` of the input-level skip (1 on simulated data; the paper uses the maximum of the event
        integration on real data).
    head : str
        The prediction head (:data:`neuspike.nets.network.HEADS`): ``"tanh"`` (the paper's),
        ``"support"`` (a per-pixel choice among the spike representation's radiance estimates plus a
        correction, which keeps the absolute scale) or ``"support-count"`` (the same with the
        correction counted in spikes per group; the shipped weights).
    motion_gate : str
        ``"none"`` (the paper's), ``"stats"``: gains on the motion features from the
        representations' statistics (:class:`~neuspike.nets.network.MotionGate`), or ``"stats-local"``:
        those gains times per-pixel maps from the events' local coherence
        (:class:`~neuspike.nets.network.LocalGate`), or ``"stats-noise"``: those gains times per-image
        gains that also read quantiles of per-pixel distributions (:class:`~neuspike.nets.network.NoiseGate`);
        fusion network only.
    transformer : str
        ``"fixed"`` (default; the shipped weights) or ``"learned"``: a learned full-resolution module on
        each representation before its encoder (:class:`~neuspike.nets.network.InputTransformer`).
    support_cue : str
        ``"none"`` (default; the shipped weights) or ``"spread"``: statistics of the group counts
        given to the support head (:class:`~neuspike.nets.network.SupportCue`; ``"support-count"``
        head only).
    key_estimates : str
        ``"none"`` (default; the shipped weights) or ``"isi-sequence"``: the interval sequence around
        the key instant appended to the spike input and weighed by
        :class:`~neuspike.nets.network.KeyRefine` (``"support-count"`` head only).
    width, head_kernel : float, int
        The network's width multiplier and prediction kernel (:class:`~neuspike.nets.network.NeuSpikeNet`):
        1 and 3 (the defaults) are the full network; the compact variants take ``LITE_DESIGN``. Kept out of
        ``params`` at their defaults, so the full networks' parameters read as they always have.
    despeckle : float
        0 (off, the default of the class) or a margin in the image's units: isolated outliers, pixels
        beyond all eight neighbours' range by more than it, are replaced by their 3x3 median after the
        level (:func:`neuspike.methods.readout.despeckle`). The registered networks use
        :data:`neuspike.nets.DESPECKLE`. Kept out of ``params`` when off.
    wiener : float
        0 (off, the default of the class) or the noise variance as a multiple of the square of the noise
        level of the image's least-varying neighbourhoods (:func:`neuspike.methods.readout.noise_level`):
        after despeckling, the local Wiener filter smooths the image where it varies no more than that
        (:func:`neuspike.methods.readout.wiener`). The registered networks use
        :data:`neuspike.nets.WIENER`. Kept out of ``params`` when off.
    level : str
        ``"counts"`` (default): where the sensor's gain is known, the image is shifted so that the
        spikes it predicts, pixel by pixel under the sensor model of how the window began
        (:mod:`neuspike.methods.counting`, with the dark rate known or estimated), add up to the
        spikes the window holds; left as the network made it otherwise. ``"network"``: never
        shifted. The shift removes the offset that instance normalisation leaves to the network's
        guess: under a dark current, which clean windows cannot be told apart from, up to several dB.
    **learned
        :class:`~neuspike.methods.learned.LearnedMethod`'s arguments (weights, device, precision).
    """

    inputs = frozenset({"spikes", "events"})
    #: Shifted spike windows are refused (:func:`check_centred`); the video command keeps to centred ones.
    needs_centred_window = True

    def __init__(self, name: str | None = None, *, spike_representation: str, event_representation: str,
                 fusion: str, spike_only: bool, event_skip_weight: float = 1.0, head: str = "tanh",
                 motion_gate: str = "none", transformer: str = "fixed", support_cue: str = "none",
                 key_estimates: str = "none", level: str = "counts", width: float = 1.0, head_kernel: int = 3,
                 despeckle: float = 0.0, wiener: float = 0.0, **learned: Any) -> None:
        _check_params(dict(spike_representation=spike_representation, event_representation=event_representation,
                           fusion=fusion, spike_only=spike_only, head=head, motion_gate=motion_gate,
                           transformer=transformer, support_cue=support_cue, key_estimates=key_estimates))
        if level not in LEVELS:
            raise InputError(f"level: expected one of {LEVELS}, got {level!r}")
        self.inputs = frozenset({"spikes"}) if spike_only else frozenset({"spikes", "events"})
        if float(width) != 1.0:
            learned["width"] = width
        if head_kernel != 3:
            learned["head_kernel"] = head_kernel
        if isinstance(despeckle, bool) or not isinstance(despeckle, (int, float)) or not 0 <= despeckle < 1:
            raise InputError(f"despeckle: expected a margin in [0, 1) (0 = off), got {despeckle!r}")
        if despeckle:
            learned["despeckle"] = float(despeckle)
        if isinstance(wiener, bool) or not isinstance(wiener, (int, float)) or not 0 <= wiener < 100:
            raise InputError(f"wiener: expected a noise multiple in [0, 100) (0 = off), got {wiener!r}")
        if wiener:
            learned["wiener"] = float(wiener)
        super().__init__(name, spike_representation=spike_representation,
                         event_representation=event_representation, fusion=fusion, spike_only=spike_only,
                         event_skip_weight=float(event_skip_weight), head=head, motion_gate=motion_gate,
                         transformer=transformer, support_cue=support_cue, key_estimates=key_estimates,
                         level=level, **learned)

    # -- LearnedMethod ----------------------------------------------------------------------------

    def build_module(self) -> nn.Module:
        """An untrained module for this variant."""
        p = self.params
        return NeuSpikeNet(fusion=p["fusion"], spike_only=p["spike_only"],
                           event_skip_weight=float(p.get("event_skip_weight", 1.0)), head=p.get("head", "tanh"),
                           motion_gate=p.get("motion_gate", "none"), transformer=p.get("transformer", "fixed"),
                           support_cue=p.get("support_cue", "none"), key_estimates=p.get("key_estimates", "none"),
                           width=p.get("width", 1.0), head_kernel=p.get("head_kernel", 3))

    def encode(self, sample: Sample) -> Sequence[tuple[torch.Tensor, ...]]:
        """One step: (spikes,) or (spikes, events), each float32 (1, 32, H, W), and with the
        ``"support-count"`` head the spike quantum (1, 1, H, W) last. With ``key_estimates`` the spikes
        are (1, 32 + K, H, W), the key estimates after the representation (computed from the window,
        in a video too).

        Raises
        ------
        InputError
            When the sample lacks spikes, or lacks events for the fusion network.
        """
        p = self.params
        if sample.spikes is None:
            raise InputError("neuspike-net: the sample has no spikes")
        check_centred(sample, self.name)
        if not p["spike_only"] and sample.events is None:
            raise InputError("neuspike-net: the sample has no events; the fusion network needs spikes and events "
                             "(neuspike-net-spike takes spikes alone)")
        sliding = getattr(self, "_sliding", None)
        if getattr(self, "_streaming", False) and sliding is not None:
            x_t, x_m = sliding(sample)
        else:
            x_t = spike_representation(sample, p["spike_representation"])
            x_m = None if p["spike_only"] else event_representation(sample, p["event_representation"])
        key = key_representation(sample, p.get("key_estimates", "none"))
        if key is not None:
            x_t = np.concatenate([x_t, key])
        inputs = [torch.from_numpy(x_t)[None]]
        if not p["spike_only"]:
            inputs.append(torch.from_numpy(x_m)[None])
        if p["head"] == "support-count":  # the spike quantum, as a map so that crops and turns keep it
            inputs.append(torch.full((1, 1, *x_t.shape[-2:]), spike_quantum(sample), dtype=torch.float32))
        return [tuple(inputs)]

    # -- streaming (neuspike.video): sliding representations ---------------------------------------

    def reconstruct_next(self, sample: Sample, *, previous_s: float) -> Any:
        """The image at the sample's key instant, its representations assembled from bins shared with
        the previous frames (:class:`~neuspike.nets.sliding.SlidingRepresentation`; equal to
        :meth:`reconstruct`'s input bit for bit, so the image is :meth:`reconstruct`'s)."""
        if getattr(self, "_sliding", None) is None:
            p = self.params
            self._sliding = SlidingRepresentation(p["spike_representation"],
                                                  None if p["spike_only"] else p["event_representation"])
        self._streaming = True
        try:
            return self.reconstruct(sample)
        finally:
            self._streaming = False

    def reset(self) -> None:
        """Start a new sequence; the sliding bins survive only the reset inside a streamed frame's call."""
        super().reset()
        if getattr(self, "_sliding", None) is not None and not getattr(self, "_streaming", False):
            self._sliding.reset()

    def to_image(self, output: torch.Tensor, sample: Sample) -> np.ndarray:
        """The clamped output, shifted so that it predicts the window's spike count (``level="counts"``,
        where the gain is known): :func:`neuspike.methods.counting.level_shift` under the sensor model of
        how the window began; then, with ``despeckle``, its isolated outliers replaced by their 3x3 median
        (:func:`neuspike.methods.readout.despeckle`); then, with ``wiener``, smoothed where it varies no
        more than its noise (:func:`neuspike.methods.readout.wiener`), clamped to [0, 1] again."""
        image = self._leveled(super().to_image(output, sample), sample)
        margin = self.params.get("despeckle", 0.0)
        image = despeckle(image, margin) if margin else image
        scale = self.params.get("wiener", 0.0)
        return np.clip(wiener(image, scale), 0.0, 1.0) if scale else image

    def _leveled(self, image: np.ndarray, sample: Sample) -> np.ndarray:
        self._level = None
        spikes = sample.spikes
        if self.params.get("level", "counts") != "counts" or spikes is None or spike_gain(sample)[1] != "known":
            return image
        counts = spike_counts(spikes.planes)  # one pass, shared with the dark estimate
        dark_rate, self._dark_how = dark_level(spikes, counts)
        shift = level_shift(image, counts, planes=spikes.num_planes, gain=float(spikes.gain), dark_rate=dark_rate,
                            state=initial_state(spikes))
        image = np.clip(image + np.float32(shift), 0.0, 1.0)
        self._level = float(image.mean(dtype=np.float64))
        return image

    def _reconstruct(self, sample: Sample) -> tuple[Any, str]:
        image, label = super()._reconstruct(sample)
        if getattr(self, "_level", None) is not None:
            label = f"{label}; {COUNTED}" + (", dark rate estimated" if self._dark_how == DARK_ESTIMATED else "")
        if spike_gain(sample)[1] == "estimated":  # a real recording: say how its scale was set
            label = f"{label}; gain estimated (99.5th-percentile rate = radiance 1)"
        if self.params.get("despeckle"):
            label = f"{label}; despeckled (margin {self.params['despeckle']:g})"
        if self.params.get("wiener"):
            label = f"{label}; Wiener-smoothed (noise {self.params['wiener']:g}x)"
        return image, label

    def load_weights(self, module: nn.Module, path: Path, *, may_lack: tuple[str, ...] = ()) -> str | None:
        """Our own safetensors, refused when its card says it was trained for another design (unless
        ``may_lack`` names parts a training stage adds to that design: the tensors decide then)."""
        card = read_card(path)
        trained = (card or {}).get("model", {}).get("params")
        if trained is not None and not may_lack:
            ours = {k: self.params[k] for k in ARCHITECTURE_PARAMS}
            theirs = {k: trained.get(k, CARD_DEFAULTS.get(k)) for k in ARCHITECTURE_PARAMS}
            ours.update({k: self.params.get(k, v) for k, v in SIZE_DEFAULTS.items()})
            theirs.update({k: trained.get(k, v) for k, v in SIZE_DEFAULTS.items()})
            if ours != theirs:
                raise FormatError(f"{path}: trained for {theirs}, but this method is {ours}")
        return super().load_weights(module, path, may_lack=may_lack)
