"""FireNet: a small recurrent network that reconstructs intensity from event voxel grids.

The network (Scheerlinck et al., WACV 2020) works at full resolution with 16 channels::

    encoder   3x3 conv 5 -> 16, ReLU
    gru1      convolutional GRU, 16 hidden channels (three 3x3 convs 32 -> 16, two of them fused)
    res1      residual block: 3x3 conv, ReLU, 3x3 conv, + input, ReLU
    gru2      convolutional GRU like gru1
    res2      residual block like res1
    readout   1x1 conv 16 -> 1, no activation; clamped to [0, 1] to read it as an image

With the input x and the previous state s (zeros at the start of a sequence), a GRU computes
``z = sigmoid(update([x, s]))``, ``r = sigmoid(reset([x, s]))``, ``o = tanh(candidate([x, s * r]))``
and the new state ``s * (1 - z) + o * z``, which is also its output. 37,777 parameters.

Weights. Two published checkpoints are supported, each a ``{"arch", "model", "state_dict"}``
dictionary opened with ``torch.load(path, weights_only=True)``:

* ``firenet.pt`` (FireNet, trained on voxel grids whose non-zero entries were normalised to mean 0,
  std 1), in the older parameter layout (``net.head.conv.conv2d.*``, ``net.head.recurrent_block.*``,
  ``net.resblocks.0.conv.*``, ``net.resblocks.0.recurrent_block.*``, ``net.resblocks.1.*``,
  ``net.pred.conv2d.*``) — method ``firenet``;
* ``firenet_plus.pt`` (FireNet+, trained without that normalisation), in the newer layout
  (``head.conv2d.*``, ``G1.*``, ``R1.*``, ``G2.*``, ``R2.*``, ``pred.conv2d.*``) — method
  ``firenet-plus``.

:func:`load_firenet` maps either layout onto this module's own names and loads strictly: every
tensor in the file is used, none of the module's is missing, and all shapes agree; anything else is
a :class:`~neuspike.errors.FormatError` naming the offending keys.

The weights' folder comes from the user: the ``weights_dir`` argument (the CLI's ``--weights``), or
else the environment variable ``NEUSPIKE_WEIGHTS``. The file is looked up as
``<dir>/firenet/<file>`` and then ``<dir>/<file>``, so either the weights root or the FireNet folder
itself may be named. When no folder is given or the file is not there, constructing the method
raises :class:`~neuspike.methods.MethodUnavailable` with the reason (the harness records it and
skips the method).

Event windows. The network is recurrent and needs several windows of warm-up. A reconstruction
resets the state, then feeds the sample's events (history and window) up to the key instant as a
sequence of voxel grids of 5 bins. The windows hold a fixed number of events,
``N = round(events_per_pixel * H * W)`` with ``events_per_pixel = 0.35`` (the E2VID reference
setting): fixed-count windows keep the input's event density in the range the network was trained
on whatever the speed of the scene, which fixed-duration windows do not. They are counted backwards
from the key instant, so the last window ends exactly at the key instant; the oldest may hold fewer
events. Only the most recent ``max_windows`` windows (default 24) are used, which bounds the cost
of one reconstruction. Window k spans ``[t of its first event, t of the next window's first event)``
(the last: up to the key instant), so the windows tile time without gaps.

Why end at the key instant rather than at the window's end: the network's output shows the scene as
it is at the end of its last window; the ground truth is taken at the key instant, and events after
it would show a later scene. Spike methods see the whole window, symmetric about the key instant, so
their estimate is also centred on it.

Output: the readout clamped to [0, 1] (label ``"clamp"``), as FireNet's authors read it; no other
normalisation.

Precision: ``precision="auto"`` (default) picks ``"bfloat16"`` when the CPU has native bfloat16
arithmetic (AVX512-BF16 or AMX, as torch reports it) and ``"float32"`` otherwise; the choice made is
recorded in the method's ``params["precision"]``. ``precision="bfloat16"`` runs the convolutions in bfloat16 under CPU autocast;
the recurrent states and their update stay float32. ``precision="float32"`` runs everything in
float32. On this machine class (a CPU with AMX and AVX512-BF16 units), measured on a quiet machine,
one step at 400x250 (voxel grid included) took 23-26 ms in bfloat16 against about 40 ms in float32
with two threads (44 ms against 69 ms with one), which is what makes the 30 ms target reachable:
the float32 convolutions already run near the cores' float32 peak (7.5 GFLOP per step). The cost in accuracy is negligible: after 24 windows of
simulated pans the two outputs differ by 0.001-0.002 on average (SSIM between them 0.999 and
above), and their SSIM to the ground truth differs by less than 0.001. On CPUs without bfloat16
units bfloat16 is emulated and slower than float32, which is why ``"auto"`` falls back to float32.

Speed: the update and reset gates of each GRU run as one convolution (:class:`ConvGRU`), and the
residual blocks work in place. Torch's threads are left as the caller set them; on a machine whose
cores are busy with other work, one thread is far faster than two (a second thread waiting for a
busy core stalls every small operation).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from neuspike.checks import check_positive, check_positive_int
from neuspike.errors import FormatError, InputError
from neuspike.methods import Method, MethodUnavailable
from neuspike.representations import voxel_grid
from neuspike.sample import Sample
from neuspike.streams import EventStream

__all__ = [
    "WEIGHTS_ENV",
    "NUM_BINS",
    "ConvGRU",
    "ResidualBlock",
    "FireNetModule",
    "map_state_dict",
    "load_firenet",
    "find_weights",
    "event_windows",
    "FireNet",
    "register_methods",
]

#: Environment variable naming the weights folder.
WEIGHTS_ENV = "NEUSPIKE_WEIGHTS"
#: Temporal bins of the voxel grid the network expects.
NUM_BINS = 5
#: Channels of every hidden layer.
CHANNELS = 16
#: Label of the output scale: the network's readout clamped to [0, 1].
CLAMP = "clamp"


class ConvGRU(nn.Module):
    """Convolutional GRU cell with 3x3 gates.

    The update and reset gates read the same ``[x, s]``, so they run as one convolution with
    ``2C`` output channels (their weights concatenated along the output channels), which computes
    each output channel exactly as the two separate convolutions do. Without autograd the
    concatenated input is built once: after the gates, its state half is overwritten in place with
    ``s * r`` for the candidate convolution.

    Parameters
    ----------
    channels : int
        Channels of the input and of the hidden state (C).
    """

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.update = nn.Conv2d(2 * channels, channels, 3, padding=1)
        self.reset = nn.Conv2d(2 * channels, channels, 3, padding=1)
        self.candidate = nn.Conv2d(2 * channels, channels, 3, padding=1)

    def gate_weights(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The update and reset gates as one convolution: weight (2C, 2C, 3, 3), bias (2C,)."""
        return (torch.cat([self.update.weight, self.reset.weight]), torch.cat([self.update.bias, self.reset.bias]))

    def forward(self, x: torch.Tensor, state: torch.Tensor,
                gates: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
        """x, state: (B, C, H, W) -> new state (B, C, H, W), of the state's dtype.

        ``gates`` may pass :meth:`gate_weights` computed once in advance.
        """
        c = x.shape[1]
        weight, bias = self.gate_weights() if gates is None else gates
        xs = torch.cat([x, state.to(x.dtype)], dim=1)
        zr = torch.sigmoid(F.conv2d(xs, weight.to(xs.dtype), bias.to(xs.dtype), padding=1))
        z, r = zr[:, :c], zr[:, c:]
        if torch.is_grad_enabled() and (xs.requires_grad or r.requires_grad):
            xs = torch.cat([x, state.to(x.dtype) * r], dim=1)  # autograd still needs the old xs
        else:
            torch.mul(xs[:, c:], r, out=xs[:, c:])  # [x, s * r] in place
        o = torch.tanh(self.candidate(xs))
        return torch.addcmul(state, o.to(state.dtype) - state, z.to(state.dtype))


class ResidualBlock(nn.Module):
    """3x3 conv, ReLU, 3x3 conv, + input, ReLU; channels unchanged."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv_a = nn.Conv2d(channels, channels, 3, padding=1)
        self.conv_b = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: (B, C, H, W) -> (B, C, H, W)."""
        y = self.conv_b(F.relu_(self.conv_a(x)))
        return F.relu_(y.add_(x))


class FireNetModule(nn.Module):
    """The FireNet network; one call advances the recurrent states by one voxel grid.

    Forward
    -------
    grid : Tensor (B, 5, H, W)
        Event voxel grid.
    states : tuple of two Tensors (B, 16, H, W) or None
        The states of ``gru1`` and ``gru2``; ``None`` starts from zeros.

    Returns
    -------
    image : Tensor (B, 1, H, W), unbounded (clamp to [0, 1] to read it as an image)
    states : the new states
    """

    def __init__(self, bins: int = NUM_BINS, channels: int = CHANNELS) -> None:
        super().__init__()
        self.encoder = nn.Conv2d(bins, channels, 3, padding=1)
        self.gru1 = ConvGRU(channels)
        self.res1 = ResidualBlock(channels)
        self.gru2 = ConvGRU(channels)
        self.res2 = ResidualBlock(channels)
        self.readout = nn.Conv2d(channels, 1, 1)

    def forward(
        self, grid: torch.Tensor, states: tuple[torch.Tensor, torch.Tensor] | None = None
    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        x = F.relu(self.encoder(grid))
        if states is None:
            zeros = torch.zeros(
                (x.shape[0], self.gru1.update.out_channels, *x.shape[2:]),
                dtype=torch.float32, device=x.device,
            ).contiguous(memory_format=torch.channels_last)
            states = (zeros, zeros)
        s1 = self.gru1(x, states[0])
        x = self.res1(s1.to(x.dtype))
        s2 = self.gru2(x, states[1])
        x = self.res2(s2.to(x.dtype))
        return self.readout(x), (s1, s2)


# Source-prefix -> our-prefix, per layout; the suffix (".weight"/".bias") carries over.
def _gru_map(src: str, dst: str) -> list[tuple[str, str]]:
    return [(f"{src}.update_gate.", f"{dst}.update."), (f"{src}.reset_gate.", f"{dst}.reset."),
            (f"{src}.out_gate.", f"{dst}.candidate.")]


def _res_map(src: str, dst: str) -> list[tuple[str, str]]:
    return [(f"{src}.conv1.", f"{dst}.conv_a."), (f"{src}.conv2.", f"{dst}.conv_b.")]


LAYOUTS: Mapping[str, list[tuple[str, str]]] = {
    # The older E2VID-style layout of firenet.pt.
    "legacy": [("net.head.conv.conv2d.", "encoder."), *_gru_map("net.head.recurrent_block", "gru1"),
               *_res_map("net.resblocks.0.conv", "res1"), *_gru_map("net.resblocks.0.recurrent_block", "gru2"),
               *_res_map("net.resblocks.1", "res2"), ("net.pred.conv2d.", "readout.")],
    # The layout of firenet_plus.pt.
    "plus": [("head.conv2d.", "encoder."), *_gru_map("G1", "gru1"), *_res_map("R1", "res1"),
             *_gru_map("G2", "gru2"), *_res_map("R2", "res2"), ("pred.conv2d.", "readout.")],
}


def map_state_dict(state_dict: Mapping[str, torch.Tensor]) -> tuple[dict[str, torch.Tensor], str]:
    """Rename a published FireNet state dict onto :class:`FireNetModule`'s names.

    Parameters
    ----------
    state_dict : mapping of str to Tensor
        In either published layout (see the module docstring).

    Returns
    -------
    mapped : dict of our parameter names to tensors
    layout : ``"legacy"`` or ``"plus"``

    Raises
    ------
    FormatError
        When a key fits neither layout, or two keys map to the same name.
    """
    keys = list(state_dict)
    layout = "legacy" if any(k.startswith("net.") for k in keys) else "plus"
    table = LAYOUTS[layout]
    mapped: dict[str, torch.Tensor] = {}
    unknown = []
    for key in keys:
        for src, dst in table:
            if key.startswith(src):
                name = dst + key[len(src):]
                if name in mapped:
                    raise FormatError(f"FireNet weights ({layout} layout): two tensors map onto {name!r}")
                mapped[name] = state_dict[key]
                break
        else:
            unknown.append(key)
    if unknown:
        raise FormatError(f"FireNet weights ({layout} layout): tensors that fit no part of the network: {unknown}")
    return mapped, layout


def load_firenet(path: str | os.PathLike) -> tuple[FireNetModule, str]:
    """Build a :class:`FireNetModule` and load a published checkpoint into it, strictly.

    Parameters
    ----------
    path : path to a ``.pt`` file holding ``{"state_dict": {...}, ...}`` (or a bare state dict).

    Returns
    -------
    module : FireNetModule in eval mode, float32, on the CPU
    layout : the layout the file used (``"legacy"`` or ``"plus"``)

    Raises
    ------
    FormatError
        When the file is not a FireNet checkpoint, a tensor is unused or missing, or a shape differs.
    """
    try:
        checkpoint = torch.load(Path(path), map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as exc:
        raise FormatError(f"{path}: cannot be read as a weights-only torch file ({type(exc).__name__}: {exc})") from exc
    state_dict = checkpoint.get("state_dict", checkpoint) if isinstance(checkpoint, dict) else None
    if not isinstance(state_dict, dict) or not all(isinstance(v, torch.Tensor) for v in state_dict.values()):
        raise FormatError(f"{path}: expected a dictionary of tensors (optionally under 'state_dict')")
    mapped, layout = map_state_dict(state_dict)
    module = FireNetModule()
    own = module.state_dict()
    missing = sorted(set(own) - set(mapped))
    unused = sorted(set(mapped) - set(own))
    if missing or unused:
        raise FormatError(f"{path} ({layout} layout): missing tensors {missing}, unused tensors {unused}")
    wrong = [f"{k}: file {tuple(mapped[k].shape)}, network {tuple(own[k].shape)}"
             for k in own if mapped[k].shape != own[k].shape]
    if wrong:
        raise FormatError(f"{path} ({layout} layout): shapes differ: {wrong}")
    module.load_state_dict({k: v.to(torch.float32) for k, v in mapped.items()}, strict=True)
    return module.eval(), layout


def find_weights(file_name: str, weights_dir: str | os.PathLike | None) -> Path:
    """Locate a weights file: ``weights_dir`` or ``$NEUSPIKE_WEIGHTS``, then ``firenet/`` or the folder itself.

    Raises
    ------
    MethodUnavailable
        When no folder is given or the file is in neither place; the message says which.
    """
    if weights_dir is None:
        weights_dir = os.environ.get(WEIGHTS_ENV) or None
        origin = f"${WEIGHTS_ENV}"
    else:
        origin = "weights_dir"
    if weights_dir is None:
        raise MethodUnavailable(
            f"FireNet weights not given: pass weights_dir (CLI --weights) or set ${WEIGHTS_ENV} "
            f"to the folder holding {file_name}"
        )
    root = Path(weights_dir)
    candidates = [root / "firenet" / file_name, root / file_name]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise MethodUnavailable(
        f"FireNet weights {file_name} not found: looked in {', '.join(str(c) for c in candidates)} "
        f"({origin} = {str(root)!r})"
    )


def event_windows(t_s: np.ndarray, *, events_per_window: int, end_s: float,
                  max_windows: int) -> list[tuple[int, int, float, float]]:
    """Split sorted event times into fixed-count windows counted back from ``end_s``.

    Parameters
    ----------
    t_s : ndarray float64 (N,)
        Sorted event times, all ``< end_s``.
    events_per_window : int
        Events per window (the oldest window may hold fewer).
    end_s : float
        End of the last window, in seconds.
    max_windows : int
        Keep only the most recent windows.

    Returns
    -------
    list of ``(i0, i1, t0_s, t1_s)``, oldest first: events ``i0:i1`` fall in ``[t0_s, t1_s]``, with
    ``t0_s`` the first event's time and ``t1_s`` the next window's first event time (``end_s`` for
    the last). An empty input gives an empty list. When all of a window's events and its end share
    one timestamp, ``t1_s`` is the next representable float after ``t0_s``.
    """
    n = int(t_s.shape[0])
    if n == 0:
        return []
    ends = list(range(n, 0, -events_per_window))[:max_windows]
    windows = []
    next_start = float(end_s)
    for i1 in ends:
        i0 = max(0, i1 - events_per_window)
        t0 = float(t_s[i0])
        t1 = next_start if next_start > t0 else float(np.nextafter(t0, np.inf))
        windows.append((i0, i1, t0, t1))
        next_start = t0
    return windows[::-1]


def native_bfloat16() -> bool:
    """Whether this CPU computes bfloat16 natively (AVX512-BF16 or AMX), as torch reports it."""
    cpu = getattr(torch, "cpu", None)
    for probe in ("_is_avx512_bf16_supported", "_is_amx_tile_supported"):
        check = getattr(cpu, probe, None)
        try:
            if check is not None and check():
                return True
        except Exception:  # a private probe that changed shape: assume no native support
            continue
    return False


class FireNet(Method):
    """``firenet`` / ``firenet-plus``: FireNet on 5-bin voxel grids, warmed up on the sample's history.

    Parameters
    ----------
    weights_file : str
        File name of the checkpoint (``"firenet.pt"`` or ``"firenet_plus.pt"``).
    normalize : bool
        Normalise the non-zero voxels to mean 0, std 1 (as ``firenet.pt`` was trained; not
        ``firenet_plus.pt``).
    weights_dir : str or path or None
        Folder of the weights; ``None`` reads ``$NEUSPIKE_WEIGHTS``.
    events_per_pixel : float
        Events per window per pixel (default 0.35).
    max_windows : int
        Most recent windows used for warm-up and output (default 24).
    precision : ``"auto"`` (default), ``"bfloat16"`` or ``"float32"``
        Arithmetic of the convolutions (see the module docstring).

    Raises
    ------
    MethodUnavailable
        When the weights cannot be found.
    """

    inputs = frozenset({"events"})
    recurrent = True

    def __init__(
        self,
        name: str | None = None,
        *,
        weights_file: str,
        normalize: bool,
        weights_dir: str | os.PathLike | None = None,
        events_per_pixel: float = 0.35,
        max_windows: int = 24,
        precision: str = "auto",
    ) -> None:
        if precision not in ("auto", "float32", "bfloat16"):
            raise InputError(f"precision: expected 'auto', 'float32' or 'bfloat16', got {precision!r}")
        if precision == "auto":
            precision = "bfloat16" if native_bfloat16() else "float32"
        if not isinstance(normalize, bool):
            raise InputError(f"normalize: expected True or False, got {normalize!r}")
        super().__init__(
            name,
            weights_file=str(weights_file),
            normalize=normalize,
            events_per_pixel=check_positive("events_per_pixel", events_per_pixel),
            max_windows=check_positive_int("max_windows", max_windows),
            precision=precision,
        )
        self.weights_path = find_weights(str(weights_file), weights_dir)
        module, self.layout = load_firenet(self.weights_path)
        self.module = module.to(memory_format=torch.channels_last)
        self._states: tuple[torch.Tensor, torch.Tensor] | None = None
        self.windows_used = 0

    def reset(self) -> None:
        """Forget the recurrent states (start of a new sequence)."""
        self._states = None

    def parameter_count(self) -> int:
        return sum(p.numel() for p in self.module.parameters())

    def step(self, grid: np.ndarray) -> np.ndarray:
        """Advance the network by one voxel grid and return its output.

        Parameters
        ----------
        grid : ndarray float32 (5, H, W)
            A voxel grid (normalised or not, as the weights expect).

        Returns
        -------
        ndarray float32 (H, W): the readout clamped to [0, 1].
        """
        grid = np.asarray(grid, dtype=np.float32)
        if grid.ndim != 3 or grid.shape[0] != NUM_BINS:
            raise InputError(f"FireNet.step: expected a voxel grid of shape ({NUM_BINS}, H, W), got {grid.shape}")
        x = torch.from_numpy(np.ascontiguousarray(grid))[None].contiguous(memory_format=torch.channels_last)
        if self._states is not None and tuple(self._states[0].shape[2:]) != tuple(grid.shape[1:]):
            raise InputError(
                f"FireNet.step: grid size {grid.shape[1:]} differs from the sequence's {tuple(self._states[0].shape[2:])}; "
                "call reset() between sequences"
            )
        with torch.inference_mode():
            if self.params["precision"] == "bfloat16":
                with torch.autocast("cpu", dtype=torch.bfloat16):
                    out, self._states = self.module(x, self._states)
            else:
                out, self._states = self.module(x, self._states)
            image = out[0, 0].float().clamp_(0.0, 1.0)
        return np.ascontiguousarray(image.numpy(), dtype=np.float32)

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        self.reset()
        h, w = sample.height, sample.width
        events = sample.events
        start = min(float(events.t_s[0]), sample.key_time_s) if len(events) else sample.key_time_s
        events = events.between(start, sample.key_time_s)
        per_window = max(1, int(round(self.params["events_per_pixel"] * h * w)))
        windows = event_windows(events.t_s, events_per_window=per_window, end_s=sample.key_time_s,
                                max_windows=self.params["max_windows"])
        if not windows:
            image = self.step(np.zeros((NUM_BINS, h, w), dtype=np.float32))
            self.windows_used = 1
            return image, CLAMP
        for i0, i1, t0, t1 in windows:
            # slices of a validated stream keep its invariants
            chunk = EventStream.trusted(events.t_s[i0:i1], events.x[i0:i1], events.y[i0:i1], events.p[i0:i1], w, h)
            grid = voxel_grid(chunk, bins=NUM_BINS, t0_s=t0, t1_s=t1, height=h, width=w,
                              normalize=self.params["normalize"])
            image = self.step(grid)
        self.windows_used = len(windows)
        return image, CLAMP


def register_methods(register) -> None:
    """Add ``firenet`` and ``firenet-plus`` to the registry."""
    register("firenet", FireNet, params={"weights_file": "firenet.pt", "normalize": True},
             description="FireNet (published weights), normalised 5-bin voxel grids, 0.35 events/pixel windows")
    register("firenet-plus", FireNet, params={"weights_file": "firenet_plus.pt", "normalize": False},
             description="FireNet+ (published weights), raw 5-bin voxel grids, 0.35 events/pixel windows")
