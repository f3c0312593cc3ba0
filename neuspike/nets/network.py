"""The NeuSpike-Net module: two encoder paths, fused skips, residual blocks, decoders (REFERENCE §1.1).

Shapes (B batch; H, W any size, padded inside to multiples of 8 and cropped back):

* texture path (spikes) and motion path (events): x^0 (B, 32, H, W) -> three strided 3x3
  conv + instance norm + ReLU layers -> x^1 (B, 64, H/2, W/2), x^2 (B, 128, H/4, W/4),
  x^3 (B, 256, H/8, W/8);
* r^0 = x_t^3 + x_m^3, then two residual blocks (3x3, 256, instance norm before ReLU);
* three decoders, each a 3x3 transposed convolution (stride 2) + instance norm + ReLU, to 128, 64
  and 32 channels; after each, the skip of that level is concatenated: F(x_t^2, x_m^2),
  F(x_t^1, x_m^1), and at the input level x_t^0 + w * x_m^0;
* prediction (``head``):

  - ``"tanh"`` (the paper's): 3x3 convolution of the 64 channels to 1, then ``(tanh + 1) / 2`` in
    [0, 1]. Instance normalisation removes each feature map's scale, so the absolute intensity
    reaches the output only through the input-level skip; networks with this head compress contrast
    (a gain error).
  - ``"support"``: 3x3 convolution of the 64 channels to ``1 + in_channels``: a per-pixel softmax
    over the spike representation's channels (each a radiance estimate: rates over 16-plane groups
    and interval estimates at their centres) chooses the temporal support, and the first channel
    adds a correction: ``sum_i softmax(a)_i x_t,i^0 + c``. The weighted sum is a convex combination
    of unbiased estimates, so the absolute scale is the data's and is kept at any light; with the
    convolution's weights at zero the network is the mean of all channels (TFP and TFI over the
    window). The output is not bounded: the method clamps it to [0, 1], and training scores it
    unclamped.
  - ``"support-count"``: as ``"support"``, but the correction is counted in spikes per 16-plane
    group: ``sum_i softmax(a)_i x_t,i^0 + c * q`` with ``q = 1 / (16 * gain)``, the radiance of one
    spike in a group, given as a last input (a (B, 1, H, W) map or (B, 1, 1, 1)). The biases the
    correction removes are counts (the integrator's start loses half a spike per window on
    average; a dark current adds spikes at a rate that does not depend on the light), while the
    instance-normalised features carry no absolute scale. With ``"support"`` the network had to
    infer the light level from the image to turn a count into radiance, and got a scene-dependent
    offset; here the scale comes with the data.

Motion gate (``motion_gate``):

* ``"none"`` (the paper's): the motion features enter as they are. Instance normalisation gives
  every motion feature map unit scale whatever the events carry, so events that are mostly noise
  (a high shot-noise rate) reach the decoders as strongly as events that trace edges.
* ``"stats"``: four gains ``g = 2 sigmoid(mlp(s))`` in (0, 2), one per level, scale the motion
  features before they are fused (x_m^3 at r^0, x_m^2 and x_m^1 before F, x_m^0 in the input-level
  skip). ``s`` are statistics of the two representations taken before any normalisation, per
  channel over the image (128 numbers): for the spikes log(eps + mean |x|) and log(eps + std x), for
  the events log(eps + rms x) and log(eps + rms box3(x)), box3 the 3x3 mean. Noise events are
  spatially incoherent: the 3x3 mean spreads an isolated event over nine pixels (rms / 3), a line
  of events over three (rms / sqrt 3), a region hardly at all. So the gate sees how dense and how
  coherent the events are beside the spikes. The MLP's last layer starts at zero, so
  ``g = 1`` and a network built from weights without the gate computes exactly what they computed.
* ``"stats-local"``: the four gains of ``"stats"`` times four per-pixel maps ``p = 2 sigmoid(conv1x1(
  relu(conv3x3(c))))`` in (0, 2) (:class:`LocalGate`, 188 parameters), one per level, each averaged
  over the pixels of its level (x_m^0 full resolution, x_m^1 2x2 blocks, ...). ``c`` is the local
  coherence of the events: the 3x3 mean of the channel-mean energy ``E = box3(mean_c x^2)`` and
  ``log(eps + box3(mean_c box3(x)^2)) - log(eps + E)``, near log(1/9) where the events are isolated
  (noise), near log(1/3) along an edge, near 0 over a region that changes as a whole. A per-image
  gain scales the noise in flat regions and the edges' events alike; the map can shut the one and
  keep the other. Its last layer starts at zero (``p = 1``), so ``"stats"`` weights load
  (``STARTS_AS_IDENTITY``) and compute exactly what they computed.

* ``"stats-noise"``: the four gains of ``"stats"`` times four more from :class:`NoiseGate`, which
  reads the same 128 statistics and 20 quantiles of per-pixel distributions (on every 4th row and
  column): log(eps + mean_c x^2) of the events, the same of box3(x), their difference (each pixel's
  coherence), and log(eps + mean_c (s - box3 s)^2) of the spikes (each pixel's fine detail, where
  the spike fixed-pattern noise shows), each at the 10, 25, 50, 75 and 90 % quantiles. Averages over
  the image mix a few strong edges with the flat background; the quantiles see the background,
  where sensor noise is. On stage 38's training windows a 32-unit MLP tells the high noise level
  from the others on 97.3 % of held-out windows with both sets, 91.7 % with the 128 statistics
  alone (``61a150f8:reports/neuspike-net/gate_probe.py --separability``). Its last layer starts at zero (gains
  1), so ``"stats"`` weights load and compute exactly what they computed; it is the part that the
  trainer's ``gate_targets`` supervise where present.

Input transformers (``transformer``; the paper's T_spike and T_event are learned modules of unknown form):

* ``"fixed"`` (default): the representations enter the encoders and the input-level skip as computed
  (:mod:`neuspike.nets.representations`).
* ``"learned"``: each path first passes its representation through a learned full-resolution module,
  ``x + conv1x1(relu(conv3x3(x)))`` (32 -> 32 -> 32 channels, 10,304 parameters a path), and the
  result enters the encoder and the input-level skip. The strided first encoder layer means that,
  without it, nothing non-linear runs at full resolution before the prediction layer. The
  ``"support"`` heads still weigh the fixed spike representation (their basis of radiance
  estimates), and the motion gate still sees the fixed statistics. The 1x1 layer starts at zero,
  so the module is the identity at construction: weights trained with ``"fixed"`` load into a
  ``"learned"`` network and compute exactly what they computed (``STARTS_AS_IDENTITY``).

Support cue (``support_cue``; the ``"support-count"`` head only):

* ``"none"`` (default): the softmax that chooses the temporal support comes from the decoder
  features alone. Instance normalisation has removed their scale, and nothing in them says how fast
  a pixel's radiance changes within the window: on fast pans the support does not narrow with speed
  (``61a150f8:reports/neuspike-net/fast_motion_probe.py``).
* ``"spread"``: two full-resolution statistics of the 16 group rates, counted in spikes (``n_g =
  rate_g / q``; ``"support-count"`` only, which has the quantum ``q``): the dispersion
  ``log1p(var_g n / (mean_g n + 1))`` (near 0 where the radiance is constant, since an
  integrate-and-fire pixel's group counts differ by about one spike; large where an edge passes
  within the window) and the change between the window's halves ``log1p(|mean n_8..15 - mean n_0..7|
  / sqrt(mean n + 1))``. A small module ``conv1x1(relu(conv3x3(cue)))`` (2 -> 16 -> 33 channels, 865
  parameters) adds its output to the prediction layer's logits and correction. Its last layer starts
  at zero, so weights trained without it load and compute exactly what they computed
  (``STARTS_AS_IDENTITY``).

Key estimates (``key_estimates``; the ``"support-count"`` head only):

* ``"none"`` (default): the head weighs the 32 channels, whose finest estimates are 16-plane group
  rates and one interval at each group's centre. On a fast pan an edge crosses about 11 pixels within
  one group at 16x the sweeps' speed, and none of the estimates is taken at the key instant itself.
* ``"isi-sequence"``: the spike input carries 5 more channels after the 32, the radiance estimates
  ``1 / (ISI * gain)`` of the inter-spike interval that holds the key instant and of the two before
  and the two after it (:func:`neuspike.nets.representations.key_intervals`); the encoders, the
  input-level skip, the support softmax and the cues see the 32 channels only. A small module
  (:class:`KeyRefine`) reads the decoder's last features and the estimates, counted in spikes and
  standardised against the support (``z_k = (n_k - n) / sqrt(n + 1)``, ``n = convex / q``, and
  ``log1p(n_k)``), and gives per-pixel weights ``a_k``: the image is ``convex + sum_k a_k (e_k -
  convex) + correction``. Its last layer starts at zero, so weights trained without it load and
  compute exactly what they computed (``STARTS_AS_IDENTITY``), and ``a_k`` moves the estimate
  towards the key instant where the image calls for it (up to replacing it, ``a_k = 1``).

The spike-only variant (``spike_only=True``) has the texture path and the decoders: no motion
path and no fusion modules, r^0 = x_t^3, skips x_t^2, x_t^1, x_t^0. Every fusion candidate reduces
to ``F(t, 0) = t``, so the spike-only network is exactly the full one with the motion path silent,
and its tensors are a subset of the full network's (same names).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from neuspike.errors import InputError
from neuspike.nets.fusion import make_fusion
from neuspike.nets.representations import KEY_CHANNELS
from neuspike.nn.blocks import ConvNormReLU, NormResidualBlock, UpConvNormReLU

__all__ = ["HEADS", "InputTransformer", "LocalGate", "MOTION_GATES", "MotionGate", "NeuSpikeNet", "NoiseGate",
           "PAPER_PARAMETERS",
           "KEY_ESTIMATES", "KeyRefine", "SUPPORT_CUES", "SupportCue", "TRANSFORMERS", "pad_to_multiple"]

#: The supplement's parameter count of the fusion network.
PAPER_PARAMETERS = 5_985_000
ENCODER_CHANNELS = (64, 128, 256)
DECODER_CHANNELS = (128, 64, 32)
MULTIPLE = 8
#: The prediction heads (module docstring).
HEADS = ("tanh", "support", "support-count")
#: The motion gates (module docstring).
MOTION_GATES = ("none", "stats", "stats-local", "stats-noise")
#: The input transformers (module docstring).
TRANSFORMERS = ("fixed", "learned")
#: The support head's cues (module docstring).
SUPPORT_CUES = ("none", "spread")
#: Extra spike estimates at the key instant and the channels each adds to the spike input (module docstring).
KEY_ESTIMATES = KEY_CHANNELS


def pad_to_multiple(x: torch.Tensor, multiple: int = MULTIPLE) -> torch.Tensor:
    """Zero-pad (B, C, H, W) at the bottom and right to multiples of ``multiple`` (250 -> 256 rows).

    Sides are padded to at least ``2 * multiple`` so that the deepest features have more than one
    pixel (instance normalisation needs two).
    """
    h, w = x.shape[-2:]
    ph, pw = max((-h) % multiple, 2 * multiple - h), max((-w) % multiple, 2 * multiple - w)
    return F.pad(x, (0, pw, 0, ph)) if ph or pw else x


def scaled_channels(channels: tuple[int, ...], width: float) -> tuple[int, ...]:
    """``channels`` times ``width`` (at least 8 each, rounded to a multiple of 4); ``width`` 1 keeps them."""
    return tuple(channels) if width == 1.0 else tuple(max(8, 4 * round(c * width / 4)) for c in channels)


class _Encoder(nn.Module):
    def __init__(self, in_channels: int, channels: tuple[int, ...] = ENCODER_CHANNELS) -> None:
        super().__init__()
        chans = (in_channels, *channels)
        self.layers = nn.ModuleList(ConvNormReLU(a, b, stride=2) for a, b in zip(chans[:-1], chans[1:]))

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        feats = [x]
        for layer in self.layers:
            feats.append(layer(feats[-1]))
        return feats


class MotionGate(nn.Module):
    """Four gains in (0, 2) for the motion features, from the representations' statistics.

    (spikes, events), each (B, C, H, W) before padding -> (B, 4): the gains of x_m^3, x_m^2, x_m^1
    and x_m^0. Exactly 1 at construction (the last layer is zero).
    """

    LEVELS = 4
    #: Keeps the logarithm of an empty channel finite.
    EPS = 1e-3

    def __init__(self, in_channels: int, hidden: int = 32) -> None:
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(4 * in_channels, hidden), nn.ReLU(), nn.Linear(hidden, self.LEVELS))
        nn.init.zeros_(self.mlp[2].weight)
        nn.init.zeros_(self.mlp[2].bias)

    @classmethod
    def statistics(cls, spikes: torch.Tensor, events: torch.Tensor, boxed: torch.Tensor | None = None
                   ) -> torch.Tensor:
        """(B, C, H, W) x2 -> (B, 4C): per channel, log(eps + mean |spikes|), log(eps + std spikes),
        log(eps + rms events), log(eps + rms box3(events)). ``boxed``: ``box3(events)`` in float32
        where the caller has it already."""
        spikes, events = spikes.float(), events.float()
        boxed = cls.box3(events) if boxed is None else boxed
        mean = spikes.mean(dim=(2, 3), keepdim=True)
        spread = (spikes - mean).square().mean(dim=(2, 3)).sqrt()  # torch's std: 2.4x slower on the CPU
        parts = [spikes.abs().mean(dim=(2, 3)), spread,
                 events.square().mean(dim=(2, 3)).sqrt(), boxed.square().mean(dim=(2, 3)).sqrt()]
        return torch.log(cls.EPS + torch.cat(parts, dim=1))

    @staticmethod
    def box3(x: torch.Tensor) -> torch.Tensor:
        """The 3x3 mean over the pixels inside the image ((B, C, H, W) -> same; 2 or 3 neighbours per
        axis at the borders): ``avg_pool2d(x, 3, 1, 1, count_include_pad=False)``, computed as a
        row sum and a column sum (the counts factor the same way), 2.3x faster on the CPU."""
        p = F.pad(x, (1, 1, 1, 1))
        rows = p[..., :-2, :] + p[..., 1:-1, :] + p[..., 2:, :]
        total = rows[..., :-2] + rows[..., 1:-1] + rows[..., 2:]
        h, w = x.shape[-2:]

        def count(n: int) -> torch.Tensor:  # neighbours inside the image along one axis
            i = torch.arange(n, device=x.device)
            return 3.0 - (i == 0).float() - (i == n - 1).float()

        return total / (count(h)[:, None] * count(w)[None, :])

    def forward(self, spikes: torch.Tensor, events: torch.Tensor, boxed: torch.Tensor | None = None) -> torch.Tensor:
        return 2.0 * torch.sigmoid(self.mlp(self.statistics(spikes, events, boxed)))


class LocalGate(nn.Module):
    """The ``"stats-local"`` maps (module docstring): events (B, C, H, W) before padding -> logits
    (B, 4, H, W), one channel per level (x_m^0 first); the gains are ``2 sigmoid`` of them. Zero
    logits at construction (the last layer is zero), so every gain is exactly 1."""

    LEVELS = 4
    HIDDEN = 8
    #: Keeps the logarithm of an empty neighbourhood finite.
    EPS = 1e-3

    def __init__(self) -> None:
        super().__init__()
        self.mix = nn.Conv2d(2, self.HIDDEN, 3, padding=1)
        self.out = nn.Conv2d(self.HIDDEN, self.LEVELS, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    @classmethod
    def statistics(cls, events: torch.Tensor, boxed: torch.Tensor | None = None) -> torch.Tensor:
        """(B, C, H, W) -> (B, 2, H, W): ``log(eps + E)`` and ``log(eps + box3(mean_c box3(x)^2)) -
        log(eps + E)``, ``E = box3(mean_c x^2)`` (module docstring). ``boxed``: ``box3(events)`` in
        float32 where the caller has it already."""
        events = events.float()
        boxed = MotionGate.box3(events) if boxed is None else boxed
        energy = torch.log(cls.EPS + MotionGate.box3(events.square().mean(dim=1, keepdim=True)))
        coherent = torch.log(cls.EPS + MotionGate.box3(boxed.square().mean(dim=1, keepdim=True)))
        return torch.cat([energy, coherent - energy], dim=1)

    def forward(self, events: torch.Tensor, boxed: torch.Tensor | None = None) -> torch.Tensor:
        c = self.statistics(events, boxed).to(self.mix.weight.dtype)
        return self.out(torch.relu(self.mix(c)))

    @classmethod
    def level_gains(cls, logits: torch.Tensor, size: tuple[int, int]) -> list[torch.Tensor]:
        """Logits (B, 4, H, W) -> the gains of x_m^0 .. x_m^3 on the padded grid ``size`` (the logits
        padded with 0, a gain of 1, then averaged over each level's 2^l x 2^l blocks)."""
        h, w = logits.shape[-2:]
        gains = 2.0 * torch.sigmoid(F.pad(logits.float(), (0, size[1] - w, 0, size[0] - h)))
        return [gains[:, 0:1]] + [F.avg_pool2d(gains[:, level:level + 1], 2 ** level)
                                  for level in range(1, cls.LEVELS)]


class NoiseGate(nn.Module):
    """The ``"stats-noise"`` gains (module docstring): (spikes, events) (B, C, H, W) before padding ->
    (B, 4) in (0, 2), in :class:`MotionGate`'s order (x_m^3 first). Exactly 1 at construction."""

    LEVELS = 4
    #: The quantiles of each per-pixel distribution.
    QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)
    #: The distributions are read on every STRIDE-th row and column.
    STRIDE = 4
    EPS = 1e-3

    def __init__(self, in_channels: int, hidden: int = 32) -> None:
        super().__init__()
        inputs = 4 * in_channels + 4 * len(self.QUANTILES)
        self.mlp = nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, self.LEVELS))
        nn.init.zeros_(self.mlp[2].weight)
        nn.init.zeros_(self.mlp[2].bias)

    @classmethod
    def statistics(cls, spikes: torch.Tensor, events: torch.Tensor, boxed: torch.Tensor | None = None
                   ) -> torch.Tensor:
        """(B, C, H, W) x2 -> (B, 4C + 20): :meth:`MotionGate.statistics`, then the quantiles of the
        events' energy, of their 3x3 mean's energy, of the difference of the two logarithms, and of
        the spikes' detail energy (module docstring). ``boxed``: ``box3(events)`` in float32."""
        spikes, events = spikes.float(), events.float()
        boxed = MotionGate.box3(events) if boxed is None else boxed
        base = MotionGate.statistics(spikes, events, boxed)
        s = cls.STRIDE

        def log_energy(x: torch.Tensor) -> torch.Tensor:  # (B, H', W') -> (B, H' W')
            return torch.log(cls.EPS + x).flatten(1)

        energy = log_energy(events[..., ::s, ::s].square().mean(dim=1))
        coherent = log_energy(boxed[..., ::s, ::s].square().mean(dim=1))
        detail = log_energy((spikes[..., ::s, ::s] - cls.strided_box3(spikes)).square().mean(dim=1))
        q = torch.tensor(cls.QUANTILES, device=events.device)
        parts = [torch.quantile(v, q, dim=1).T for v in (energy, coherent, coherent - energy, detail)]
        return torch.cat([base, *parts], dim=1)

    @classmethod
    def strided_box3(cls, x: torch.Tensor) -> torch.Tensor:
        """:meth:`MotionGate.box3` of ``x`` (B, C, H, W) at every STRIDE-th row and column only
        (B, C, ceil(H / STRIDE), ceil(W / STRIDE)): nine strided views of the zero-padded input summed,
        over the number of neighbours inside the image."""
        s = cls.STRIDE
        h, w = x.shape[-2:]
        p = F.pad(x, (1, 1, 1, 1))
        total = sum(p[..., di:di + h:s, dj:dj + w:s] for di in range(3) for dj in range(3))

        def count(n: int) -> torch.Tensor:  # neighbours inside the image along one axis, at 0, s, 2s, ...
            i = torch.arange(0, n, s, device=x.device)
            return 3.0 - (i == 0).float() - (i == n - 1).float()

        return total / (count(h)[:, None] * count(w)[None, :])

    def forward(self, spikes: torch.Tensor, events: torch.Tensor, boxed: torch.Tensor | None = None) -> torch.Tensor:
        return 2.0 * torch.sigmoid(self.mlp(self.statistics(spikes, events, boxed)))


class InputTransformer(nn.Module):
    """A learned T: (B, C, H, W) -> (B, C, H, W), ``x + conv1x1(relu(conv3x3(x)))``; the identity at
    construction (the 1x1 layer is zero)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.mix = nn.Conv2d(channels, channels, 3, padding=1)
        self.out = nn.Conv2d(channels, channels, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.out(torch.relu(self.mix(x)))


class SupportCue(nn.Module):
    """The ``"spread"`` cue (module docstring): (rates (B, 16, H, W), quantum (B, 1, H|1, W|1)) ->
    logits (B, outputs, H, W) added to the prediction layer's; zero at construction."""

    CHANNELS = 2
    HIDDEN = 16
    GROUPS = 16

    def __init__(self, outputs: int) -> None:
        super().__init__()
        self.mix = nn.Conv2d(self.CHANNELS, self.HIDDEN, 3, padding=1)
        self.out = nn.Conv2d(self.HIDDEN, outputs, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    @classmethod
    def statistics(cls, rates: torch.Tensor, quantum: torch.Tensor) -> torch.Tensor:
        """The dispersion and the half-window change of the group counts (module docstring), (B, 2, H, W)."""
        n = rates.float() / quantum.float()
        mean = n.mean(dim=1, keepdim=True)
        dispersion = torch.log1p((n - mean).square().mean(dim=1, keepdim=True) / (mean + 1.0))
        half = cls.GROUPS // 2
        change = (n[:, half:].mean(dim=1, keepdim=True) - n[:, :half].mean(dim=1, keepdim=True)).abs()
        return torch.cat([dispersion, torch.log1p(change / torch.sqrt(mean + 1.0))], dim=1)

    def forward(self, rates: torch.Tensor, quantum: torch.Tensor) -> torch.Tensor:
        cue = self.statistics(rates, quantum).to(self.mix.weight.dtype)
        return self.out(torch.relu(self.mix(cue)))


class KeyRefine(nn.Module):
    """The ``"isi-sequence"`` refinement (module docstring): (features (B, 32, H, W), estimates (B, K, H, W),
    convex (B, 1, H, W), quantum (B, 1, H|1, W|1)) -> ``sum_k a_k (e_k - convex)`` (B, 1, H, W); zero at
    construction."""

    HIDDEN = 16

    def __init__(self, features: int, estimates: int) -> None:
        super().__init__()
        self.mix = nn.Conv2d(features + 2 * estimates, self.HIDDEN, 3, padding=1)
        self.out = nn.Conv2d(self.HIDDEN, estimates, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    @staticmethod
    def statistics(estimates: torch.Tensor, convex: torch.Tensor, quantum: torch.Tensor) -> torch.Tensor:
        """``z_k = (n_k - n) / sqrt(n + 1)`` and ``log1p(n_k)``, counts in the quantum's unit: (B, 2K, H, W)."""
        q = quantum.float()
        n_k, n = estimates.float() / q, (convex.float() / q).clamp(min=0.0)
        return torch.cat([(n_k - n) / torch.sqrt(n + 1.0), torch.log1p(n_k)], dim=1)

    def forward(self, features: torch.Tensor, estimates: torch.Tensor, convex: torch.Tensor,
                quantum: torch.Tensor) -> torch.Tensor:
        stats = self.statistics(estimates, convex, quantum).to(self.mix.weight.dtype)
        a = self.out(torch.relu(self.mix(torch.cat([features.to(stats.dtype), stats], dim=1))))
        return (a.float() * (estimates.float() - convex)).sum(dim=1, keepdim=True)


class NeuSpikeNet(nn.Module):
    """NeuSpike-Net (module docstring).

    Parameters
    ----------
    in_channels : int
        Channels of each representation (32).
    fusion : str
        The fusion module F (:data:`neuspike.nets.fusion.FUSIONS`).
    spike_only : bool
        The texture path and decoders only.
    event_skip_weight : float
        ``w`` of the input-level skip ``x_t^0 + w * x_m^0`` (1 on simulated data).
    head : str
        The prediction head, one of :data:`HEADS`.
    motion_gate : str
        ``"none"``, ``"stats"``, ``"stats-local"`` or ``"stats-noise"`` (:data:`MOTION_GATES`, module docstring); the
        spike-only network has no motion path and takes ``"none"`` only.
    transformer : str
        ``"fixed"`` or ``"learned"`` (:data:`TRANSFORMERS`, module docstring): a learned
        full-resolution module on each representation before its encoder.
    support_cue : str
        ``"none"`` or ``"spread"`` (:data:`SUPPORT_CUES`, module docstring): statistics of the group
        counts that tell the support head where the radiance changes within the window
        (``"support-count"`` head only).
    key_estimates : str
        ``"none"`` or ``"isi-sequence"`` (:data:`KEY_ESTIMATES`, module docstring): the spike input's
        extra channels at the key instant and the module that weighs them (``"support-count"`` head only).
    width : float
        Multiplies every encoder and decoder width (:func:`scaled_channels`); 1 (the default) is the
        paper's network. The compact variants (``LITE_DESIGN``) take 0.45 with ``head_kernel`` 1.
    head_kernel : int
        Kernel of the prediction layer (3, the default; or 1). At full resolution over the decoder's
        features and the 32 representation channels of the input skip, the 3x3 layer is 3.9 of the
        spike-only network's 20.2 GFLOP at 400x250 and 2.9 of 7.7 at width 0.5; as 1x1 it is a ninth
        of that, the full-resolution transposed convolution before it still seeing each pixel's
        neighbours.
    """

    #: Parts that compute the identity as constructed: weights trained without them start the same network.
    STARTS_AS_IDENTITY = ("motion_gate.", "local_gate.", "noise_gate.", "spike_transformer.", "event_transformer.", "support_cue.", "key_refine.")

    def __init__(self, in_channels: int = 32, *, fusion: str = "gate", spike_only: bool = False,
                 event_skip_weight: float = 1.0, head: str = "tanh", motion_gate: str = "none",
                 transformer: str = "fixed", support_cue: str = "none", key_estimates: str = "none",
                 width: float = 1.0, head_kernel: int = 3) -> None:
        super().__init__()
        if isinstance(width, bool) or not isinstance(width, (int, float)) or not 0.1 <= float(width) <= 2.0:
            raise InputError(f"NeuSpikeNet: width must be a number in [0.1, 2], got {width!r}")
        self.width = float(width)
        if head_kernel not in (1, 3):
            raise InputError(f"NeuSpikeNet: head_kernel must be 1 or 3, got {head_kernel!r}")
        enc, dec = scaled_channels(ENCODER_CHANNELS, self.width), scaled_channels(DECODER_CHANNELS, self.width)
        if key_estimates not in KEY_ESTIMATES:
            raise InputError(f"NeuSpikeNet: key_estimates must be one of {tuple(KEY_ESTIMATES)}, got {key_estimates!r}")
        if key_estimates != "none" and head != "support-count":
            raise InputError(f"NeuSpikeNet: key_estimates {key_estimates!r} counts spikes with the quantum, which "
                             f"only the 'support-count' head takes (head {head!r})")
        if support_cue not in SUPPORT_CUES:
            raise InputError(f"NeuSpikeNet: support_cue must be one of {SUPPORT_CUES}, got {support_cue!r}")
        if support_cue != "none" and head != "support-count":
            raise InputError(f"NeuSpikeNet: support_cue {support_cue!r} counts spikes with the quantum, which "
                             f"only the 'support-count' head takes (head {head!r})")
        if transformer not in TRANSFORMERS:
            raise InputError(f"NeuSpikeNet: transformer must be one of {TRANSFORMERS}, got {transformer!r}")
        if head not in HEADS:
            raise InputError(f"NeuSpikeNet: head must be one of {HEADS}, got {head!r}")
        if motion_gate not in MOTION_GATES:
            raise InputError(f"NeuSpikeNet: motion_gate must be one of {MOTION_GATES}, got {motion_gate!r}")
        if spike_only and motion_gate != "none":
            raise InputError("NeuSpikeNet: the spike-only network has no motion path to gate (motion_gate='none')")
        self.in_channels = in_channels
        self.key_channels = KEY_ESTIMATES[key_estimates]
        self.spike_only = spike_only
        self.head = head
        self.event_skip_weight = float(event_skip_weight)
        if transformer == "learned":
            self.spike_transformer = InputTransformer(in_channels)
        self.texture = _Encoder(in_channels, enc)
        if not spike_only:
            if transformer == "learned":
                self.event_transformer = InputTransformer(in_channels)
            self.motion = _Encoder(in_channels, enc)
            self.fuse1 = make_fusion(fusion, enc[0])
            self.fuse2 = make_fusion(fusion, enc[1])
            if motion_gate != "none":
                self.motion_gate = MotionGate(in_channels)
            if motion_gate == "stats-local":
                self.local_gate = LocalGate()
            if motion_gate == "stats-noise":
                self.noise_gate = NoiseGate(in_channels)
        self.residual = nn.Sequential(NormResidualBlock(enc[2]), NormResidualBlock(enc[2]))
        self.up1 = UpConvNormReLU(enc[2], dec[0])
        self.up2 = UpConvNormReLU(dec[0] + enc[1], dec[1])
        self.up3 = UpConvNormReLU(dec[1] + enc[0], dec[2])
        outputs = 1 if head == "tanh" else 1 + in_channels
        self.predict = nn.Conv2d(dec[2] + in_channels, outputs, head_kernel, padding=head_kernel // 2)
        if head != "tanh":  # start as the mean of every estimate, no correction
            nn.init.zeros_(self.predict.weight)
            nn.init.zeros_(self.predict.bias)
        if support_cue == "spread":
            self.support_cue = SupportCue(outputs)
        if self.key_channels:
            self.key_refine = KeyRefine(dec[2], self.key_channels)

    @property
    def takes_quantum(self) -> bool:
        """Whether the inputs end with the spike quantum ``q`` (the ``"support-count"`` head)."""
        return self.head == "support-count"

    def forward(self, spikes: torch.Tensor, *rest: torch.Tensor | None, parts: bool = False
                ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """(spikes[, events][, quantum]) -> image (B, 1, H, W) (in [0, 1] for the ``"tanh"`` head).

        spikes and events are (B, 32, H, W) (spikes (B, 32 + K, H, W) with ``key_estimates``, the K key
        estimates last); ``events`` must be given to the full network and
        omitted for the spike-only one; ``quantum`` (the radiance of one spike in a 16-plane group,
        (B, 1, H, W) or (B, 1, 1, 1)) comes last, for the ``"support-count"`` head only.
        ``parts=True`` (the ``"support"`` heads only) returns ``(image, convex)``, ``convex`` the
        head's convex combination of the spike estimates before the correction is added
        (``image = convex + correction``, plus the key refinement with ``key_estimates``), so a loss
        can score the chosen temporal support itself.
        """
        rest = list(rest)
        quantum = rest.pop() if self.takes_quantum and rest and (self.spike_only or len(rest) == 2) else None
        events = rest[0] if rest else None
        if len(rest) > 1:
            raise InputError(f"NeuSpikeNet: {len(rest) + 1 + (quantum is not None)} inputs given, expected at most "
                             f"{1 + (not self.spike_only) + self.takes_quantum}")
        self._check_inputs(spikes, quantum, parts)
        spikes, key = self._split(spikes)
        if self.spike_only and events is not None:
            raise InputError("NeuSpikeNet: the spike-only network takes no events")
        if not self.spike_only:
            if events is None:
                raise InputError("NeuSpikeNet: the fusion network needs the event representation")
            if events.shape != spikes.shape:
                raise InputError(f"NeuSpikeNet: events {tuple(events.shape)} and spikes {tuple(spikes.shape)} differ")
        h, w = spikes.shape[-2:]
        t = self.texture(pad_to_multiple(self._transform("spike_transformer", spikes)))
        if self.spike_only:
            return self._decode(t[3], t[2], t[1], t[0], spikes, quantum, (h, w), parts, key)
        m = self.motion(pad_to_multiple(self._transform("event_transformer", events)))
        if hasattr(self, "motion_gate"):
            shared = hasattr(self, "local_gate") or hasattr(self, "noise_gate")
            boxed = MotionGate.box3(events.float()) if shared else None
            g = (self.motion_gate(spikes, events) if boxed is None else self.motion_gate(spikes, events, boxed))
            if hasattr(self, "noise_gate"):
                g = g * self.noise_gate(spikes, events, boxed)
            g = g.to(m[3].dtype)[:, :, None, None]
            m = [g[:, 3:4] * m[0], g[:, 2:3] * m[1], g[:, 1:2] * m[2], g[:, 0:1] * m[3]]
            if hasattr(self, "local_gate"):
                local = LocalGate.level_gains(self.local_gate(events, boxed), m[0].shape[-2:])
                m = [p.to(x.dtype) * x for p, x in zip(local, m)]
        return self._decode(t[3] + m[3], self.fuse2(t[2], m[2]), self.fuse1(t[1], m[1]),
                            t[0] + self.event_skip_weight * m[0], spikes, quantum, (h, w), parts, key)

    def forward_texture_only(self, spikes: torch.Tensor, quantum: torch.Tensor | None = None, *,
                             parts: bool = False) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """The spike-only network inside this one: the motion path silenced (``F(t, 0) = t``).

        spikes: (B, 32, H, W) [, quantum] -> (B, 1, H, W); equals the spike-only module holding the
        same texture-path, residual and decoder weights. ``parts`` as in :meth:`forward`.
        """
        self._check_inputs(spikes, quantum, parts)
        spikes, key = self._split(spikes)
        h, w = spikes.shape[-2:]
        t = self.texture(pad_to_multiple(self._transform("spike_transformer", spikes)))
        return self._decode(t[3], t[2], t[1], t[0], spikes, quantum, (h, w), parts, key)

    def _split(self, spikes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The 32 representation channels and the key estimates after them (None without them). The 32
        are copied to a contiguous tensor, so every layer computes on the layout of a network without
        the estimates, and weights trained without them give the same images bit for bit."""
        if not self.key_channels:
            return spikes, None
        return spikes[:, : self.in_channels].contiguous(), spikes[:, self.in_channels:]

    def _transform(self, name: str, x: torch.Tensor) -> torch.Tensor:
        """The learned input transformer ``name`` applied to ``x``, or ``x`` (``"fixed"``)."""
        module = getattr(self, name, None)
        return x if module is None else module(x)

    def _check_inputs(self, spikes: torch.Tensor, quantum: torch.Tensor | None, parts: bool = False) -> None:
        if parts and self.head == "tanh":
            raise InputError("NeuSpikeNet: parts=True needs a 'support' head; the 'tanh' head has no convex part")
        channels = self.in_channels + self.key_channels
        if spikes.ndim != 4 or spikes.shape[1] != channels:
            extra = f" ({self.in_channels} + {self.key_channels} key estimates)" if self.key_channels else ""
            raise InputError(f"NeuSpikeNet: spikes must be (B, {channels}, H, W){extra}, got {tuple(spikes.shape)}")
        if self.takes_quantum:
            if quantum is None:
                raise InputError("NeuSpikeNet: the support-count head needs the spike quantum as its last input")
            if quantum.ndim != 4 or quantum.shape[:2] != (spikes.shape[0], 1) or \
                    quantum.shape[-2:] not in ((1, 1), tuple(spikes.shape[-2:])):
                raise InputError(f"NeuSpikeNet: quantum must be (B, 1, H, W) or (B, 1, 1, 1) for spikes "
                                 f"{tuple(spikes.shape)}, got {tuple(quantum.shape)}")
        elif quantum is not None:
            raise InputError(f"NeuSpikeNet: the {self.head!r} head takes no quantum")

    def _decode(self, r: torch.Tensor, s2: torch.Tensor, s1: torch.Tensor, s0: torch.Tensor,
                spikes: torch.Tensor, quantum: torch.Tensor | None, size: tuple[int, int], parts: bool = False,
                key: torch.Tensor | None = None) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        h, w = size
        d = self.up1(self.residual(r))
        d = self.up2(torch.cat([d, s2], dim=1))
        d = self.up3(torch.cat([d, s1], dim=1))
        y = self.predict(torch.cat([d, s0.to(d.dtype)], dim=1))[..., :h, :w]
        if hasattr(self, "support_cue"):
            y = y + self.support_cue(spikes[:, : SupportCue.GROUPS, :h, :w], quantum).to(y.dtype)
        if self.head == "tanh":
            return 0.5 * (torch.tanh(y) + 1.0)
        weights = torch.softmax(y[:, 1:].float(), dim=1)
        support = (weights * spikes[..., :h, :w].float()).sum(dim=1, keepdim=True)
        correction = y[:, :1].float()
        if quantum is not None:
            correction = correction * quantum.float()
        image = support + correction
        if key is not None:
            image = image + self.key_refine(d[..., :h, :w], key[..., :h, :w], support, quantum)
        return (image, support) if parts else image
