"""NeuSpike-Net: the spike + event fusion network and its spike-only variant.

A path written ``61a150f8:reports/neuspike-net/...`` below is a file of the training history, which left
the tree after that commit: ``git show 61a150f8:reports/neuspike-net/README.md`` prints it.

Architecture (REFERENCE §1.1; :mod:`neuspike.nets.network`): two 3-level strided encoders (64, 128,
256), the sum of the deepest features through two residual blocks, three transposed-conv decoders
(128, 64, 32) with concatenated skips, the fusion module F at the two inner skip levels, the
input-level skip ``x_t^0 + w x_m^0``, instance norm before ReLU, and a prediction head; any input
size (padded to multiples of 8, cropped back). The paper's head (a convolution and tanh mapped to
[0, 1], ``head="tanh"``) compressed contrast by about 8 % on bright scenes, since the instance-normalised
features carry no absolute scale; the shipped weights use ``head="support-count"``: a per-pixel
softmax over the spike representation's 32 radiance estimates (the temporal support the motion
allows) plus an additive correction counted in spikes per group and scaled by the data's own spike
quantum (:mod:`neuspike.nets.network`). The shipped fusion weights also have a motion gate (``motion_gate="stats"``): it scales the
motion path at each level by gains computed from the representations' un-normalised statistics, so
that noise-dominated events can be turned down (instance normalisation alone gives them full scale).
``transformer="learned"`` adds a learned full-resolution module on each representation (the paper's
learned T_spike and T_event, whose form is unknown here); against the fixed representations it did
not win on validation (``61a150f8:reports/neuspike-net/README.md``, stage 21), so the shipped weights keep
``"fixed"``.

Designs where the paper is unknown here (:mod:`neuspike.nets.representations`,
:mod:`neuspike.nets.fusion`), chosen by a short measured ablation: each candidate trained from the
same seed for 80 steps (batch 8, 48x48 crops, AdamW 1e-3, ``python -m neuspike.train neuspike-net
--steps 80 --crop 48 --param KEY=VALUE``) on windows simulated from the *training* photographs and
dead-leaves scenes, validated on 24 held-out windows (128x128) of the same distribution; one factor
changed at a time from A (``61a150f8:reports/neuspike-net/ablation.csv``):

====  =================  ==============  =========  ==================  ==================
run   T_spike            T_event         F          fusion PSNR / SSIM  spike-only PSNR
====  =================  ==============  =========  ==================  ==================
A     counts             voxel           gate       22.63 / 0.674       23.01
B     counts_interval    voxel           gate       23.35 / 0.721       23.95
C     counts             contrast        gate       23.24 / 0.693       23.13
D     counts             voxel           attention  21.98 / 0.650       22.53
====  =================  ==============  =========  ==================  ==================

Chosen (:data:`DEFAULT_DESIGN`): T_spike ``counts_interval`` (+0.7 dB over counts), T_event
``contrast`` (+0.6 dB over the normalised voxel grid: the per-bin log-contrast keeps a physical
scale that normalisation removes), F ``gate`` (+0.65 dB over channel attention). The runs are short
and single-seed, so differences below about 0.5 dB would not be decisive; these are not.

Registered methods (:func:`register_methods`, the ``neuspike.methods`` entry point):
``neuspike-net`` (spikes + events) and ``neuspike-net-spike`` (spikes only), with weights shipped in
``neuspike/trained/``.
"""

from __future__ import annotations

from typing import Any, Callable

from neuspike.nets.fusion import FUSIONS, AttentionFusion, GateFusion, make_fusion
from neuspike.nets.method import ARCHITECTURE_PARAMS, NeuSpikeNetMethod
from neuspike.nets.network import PAPER_PARAMETERS, NeuSpikeNet, pad_to_multiple
from neuspike.nets.representations import (EVENT_REPRESENTATIONS, SPIKE_REPRESENTATIONS, event_representation,
                                           spike_representation)

__all__ = [
    "ARCHITECTURE_PARAMS", "DEFAULT_DESIGN", "DESPECKLE", "EVENT_REPRESENTATIONS", "FUSIONS", "PAPER_PARAMETERS",
    "SPIKE_REPRESENTATIONS", "AttentionFusion", "GateFusion", "NeuSpikeNet", "NeuSpikeNetMethod",
    "WIENER", "event_representation", "make_fusion", "pad_to_multiple", "register_methods", "spike_representation",
]

#: The design the ablation chose (T_spike, T_event, F).
DEFAULT_DESIGN: dict[str, Any] = {"spike_representation": "counts_interval", "event_representation": "contrast",
                                  "fusion": "gate", "head": "support-count"}

#: What the shipped weights add to it (from stage 25 on; both files are stage 43's,
#: ``61a150f8:reports/neuspike-net/README.md``): the interval sequence at the key instant, weighed by
#: :class:`~neuspike.nets.network.KeyRefine`.
SHIPPED_DESIGN: dict[str, Any] = {"key_estimates": "isi-sequence"}

#: The compact variants (``neuspike-net-lite`` and ``neuspike-net-spike-lite`` once trained): the shipped design
#: at 0.45 of every encoder and decoder width with a 1x1 prediction layer, the representations, head and
#: level unchanged. At 400x250: 6.6 of the fusion network's 30.6 GFLOP and 4.4 of the spike-only
#: network's 20.2 (torch's FLOP counter; ``tests/neuspike/nets/test_lite.py``).
LITE_DESIGN: dict[str, Any] = {"width": 0.45, "head_kernel": 1}


#: The registered networks' read-out margin for isolated outliers (:func:`neuspike.methods.readout.despeckle`):
#: a pixel beyond all eight neighbours' range by more than 0.1 of the range is replaced by its 3x3
#: median, pass after pass until none remains. Chosen on the 48 validation windows of the training
#: photographs (2-core AMD EPYC Genoa, shipped weights; mean PSNR / SSIM / specks per mille of the
#: fusion network, one pass): off 35.90 / 0.881 / 1.69, 0.2: 36.05 / 0.889 / 0.85, 0.1: 35.97 / 0.892 / 0.06,
#: 0.05: 35.72 / 0.893 / 0.11: the smallest margin whose PSNR stays above the read-out without it, and the
#: fewest specks; repeated passes: 35.96 / 0.892 / 0.00 (the spike-only network 34.19 / 0.862 / 1.88 off,
#: 34.32 / 0.874 / 0.00).
DESPECKLE = 0.1

#: The registered networks' smoothing of the grain they leave (:func:`neuspike.methods.readout.wiener`, after
#: despeckling): the local Wiener filter over 7x7 boxes, the noise variance 5 times the square of the noise level
#: of the image's least-varying neighbourhoods (the 5th percentile of the 7x7 mean absolute Laplacian). Chosen on
#: windows of the training photographs only (2-core AMD EPYC with AVX-512 BF16, the weights shipped on 2026-12-07 in
#: bfloat16, 400x250, L = 1/32, 1/8, 1/2 at every noise level, seed 0): eight scenes with flat regions (still and pan over
#: page, cell, rocket, hubble_deep_field, brick, coffee) and eight of texture (grass, astronaut, cat,
#: immunohistochemistry, coffee, brick), 192 cells. Among estimates of the noise (percentiles of the local variance,
#: the median and percentiles of the absolute Laplacian), boxes 3-9 and multiples 0.5-6, the rule: the highest mean
#: SSIM of the candidates that lower no point of either set for either network by more than 0.05 dB or 0.001
#: SSIM. Mean PSNR / SSIM, off -> on: fusion, flat scenes 35.96 / 0.879 -> 36.70 / 0.929, texture 33.28 / 0.876 ->
#: 33.28 / 0.876 (at most -0.011 dB / -0.0004 at a point); spike-only 35.56 / 0.874 -> 36.31 / 0.926 and 32.90 /
#: 0.871 -> 32.89 / 0.871. The gain is largest where the noise is (flat scenes at L = 1/32 under high noise +1.9 dB
#: / +0.23 SSIM). The percentile of the local variance (the first estimate tried) gained as much on the flat scenes
#: but took up to 0.7 dB off the textured ones, where smooth shading and texture fill even the flattest boxes.
WIENER = 5.0


def register_methods(register: Callable[..., Any]) -> None:
    """Register ``neuspike-net`` and ``neuspike-net-spike`` (the ``neuspike.methods`` entry point)."""
    register("neuspike-net", NeuSpikeNetMethod,
             params={**DEFAULT_DESIGN, **SHIPPED_DESIGN, "spike_only": False, "motion_gate": "stats",
                     "despeckle": DESPECKLE, "wiener": WIENER},
             inputs={"spikes", "events"}, weights="neuspike-net.safetensors",
             description="NeuSpike-Net: spike + event fusion U-Net (trained here on the simulator)")
    register("neuspike-net-spike", NeuSpikeNetMethod,
             params={**DEFAULT_DESIGN, **SHIPPED_DESIGN, "spike_only": True, "despeckle": DESPECKLE, "wiener": WIENER},
             inputs={"spikes"}, weights="neuspike-net-spike.safetensors",
             description="NeuSpike-Net, spike-only variant: texture path and decoders")
