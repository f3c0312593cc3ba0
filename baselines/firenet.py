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

The weights come from the user: a folder passed as ``weights_dir`` (the commands' ``--weights``,
or their ``NEUSPIKE_WEIGHTS`` variable), declared in the registry entry (its :class:`~neuspike.methods.WeightsConfig`, sub-folder
``firenet``) and resolved by :func:`neuspike.methods.weights.resolve_weights`: the file is looked up as
``<dir>/firenet/<file>`` and then ``<dir>/<file>``, so either the weights root or the FireNet folder itself may be named. When no
folder is given or the file is not there, creating the method (:func:`neuspike.methods.create`) raises
:class:`~neuspike.methods.weights.WeightsNotFound` (a :class:`~neuspike.methods.MethodUnavailable`) naming
every path tried; the harness records the reason and skips the method.

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

Precision follows the shared rule of :mod:`neuspike.methods.learned`: ``"auto"`` (default) picks bfloat16
where the device computes it natively and float32 elsewhere (emulated bfloat16 is slower than
float32); the choice is recorded in ``params["precision"]``. In bfloat16 the convolutions run under
autocast while the recurrent states and their update stay float32. The cost in accuracy is
negligible: after 24 windows of simulated pans the two outputs differ by 0.001-0.002 on average
(SSIM between them 0.999 and above), and their SSIM to the ground truth differs by less than 0.001.

Speed: the update and reset gates of each GRU run as one convolution (:class:`ConvGRU`), and the
residual blocks work in place. Torch's threads are left as the caller set them; on a machine whose
cores are busy with other work, one thread is far faster than two (a second thread waiting for a
busy core stalls every small operation).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from neuspike.utils.checks import check_positive, check_positive_int
from neuspike.errors import FormatError, InputError
from neuspike.methods.learned import LearnedMethod
from neuspike.methods import WeightsConfig
from neuspike.nn import ConvGRU, ResidualBlock
from neuspike.methods.representations import event_windows, voxel_grid
from neuspike.sample import Sample
from neuspike.streams import EventStream
from neuspike.methods.weights import load_state_strict, load_torch_state

__all__ = [
    "NUM_BINS",
    "FireNetModule",
    "map_state_dict",
    "load_firenet",
    "FireNet",
    "register_methods",
]

#: Temporal bins of the voxel grid the network expects.
NUM_BINS = 5
#: Channels of every hidden layer.
CHANNELS = 16


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
    mapped, layout = map_state_dict(load_torch_state(path))
    module = FireNetModule()
    load_state_strict(module, mapped, f"{path} ({layout} layout)")
    return module.eval(), layout


class FireNet(LearnedMethod):
    """``firenet`` / ``firenet-plus``: FireNet on 5-bin voxel grids, warmed up on the sample's history.

    Parameters
    ----------
    normalize : bool
        Normalise the non-zero voxels to mean 0, std 1 (as ``firenet.pt`` was trained; not
        ``firenet_plus.pt``).
    events_per_pixel : float
        Events per window per pixel (default 0.35).
    max_windows : int
        Most recent windows used for warm-up and output (default 24).
    read_out : {"key", "window"}
        What a streamed frame (:meth:`reconstruct_next`) shows. ``"key"`` (default): the scene at the
        frame's key instant; the events after the last full window are stepped as a partial window
        without committing it, which costs one network step a frame beyond the full windows.
        ``"window"``: the output of the last full window, which may end before the key instant (by
        at most one window's duration; the label says by how much); a frame steps only the windows
        completed since the previous one, and a frame that completes none repeats the last image
        at no network cost. A fresh reconstruction is the same either way (its last window ends at
        the key instant).
    device, precision, compiled
        As for every :class:`~neuspike.methods.learned.LearnedMethod`. The module is untrained until
        :meth:`load_file` loads ``firenet.pt`` or ``firenet_plus.pt`` (published, ``.pt``) or our own
        ``.safetensors`` into it: :func:`neuspike.methods.create` does, from the registry entry.
    """

    inputs = frozenset({"events"})
    recurrent = True

    #: The values of ``read_out`` (class docstring).
    READ_OUTS = ("key", "window")

    def __init__(self, name: str | None = None, *, normalize: bool, events_per_pixel: float = 0.35,
                 max_windows: int = 24, read_out: str = "key", **learned: Any) -> None:
        if not isinstance(normalize, bool):
            raise InputError(f"normalize: expected True or False, got {normalize!r}")
        if read_out not in self.READ_OUTS:
            raise InputError(f"read_out: expected one of {self.READ_OUTS}, got {read_out!r}")
        super().__init__(
            name,
            normalize=normalize,
            events_per_pixel=check_positive("events_per_pixel", events_per_pixel),
            max_windows=check_positive_int("max_windows", max_windows),
            read_out=read_out,
            **learned,
        )
        self.module = self.module.to(memory_format=torch.channels_last)

    def build_module(self) -> nn.Module:
        return FireNetModule()

    def load_weights(self, module: nn.Module, path: Path, *, may_lack: tuple[str, ...] = ()) -> str:
        """Our own safetensors (``"safetensors"``), or a published ``.pt`` in either layout (``"legacy"``, ``"plus"``)."""
        if path.suffix == ".safetensors":  # our own (firenet-sim), in the module's own names
            return super().load_weights(module, path, may_lack=may_lack)
        mapped, layout = map_state_dict(load_torch_state(path))
        load_state_strict(module, mapped, f"{path} ({layout} layout)")
        return layout

    @property
    def layout(self) -> str | None:
        """The layout the weights were read in (``"safetensors"``, ``"legacy"``, ``"plus"``; ``None`` untrained)."""
        return self.weights_layout

    @property
    def windows_used(self) -> int | None:
        """The event windows the last call stepped through (``last_steps``)."""
        return self.last_steps

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
        if self._state is not None and self._state_hw() != tuple(grid.shape[1:]):
            raise InputError(
                f"FireNet.step: grid size {grid.shape[1:]} differs from the sequence's {self._state_hw()}; "
                "call reset() between sequences"
            )
        out = self.run_step(self._grid_tensor(grid))
        image = out[0, 0].float().clamp(0.0, 1.0)
        return np.ascontiguousarray(image.cpu().numpy(), dtype=np.float32)

    def _state_hw(self) -> tuple[int, int]:
        """(H, W) of the sequence the recurrent state belongs to."""
        return tuple(self._state[0].shape[2:])

    def windows(self, sample: Sample) -> list[tuple[int, int, float, float]]:
        """The fixed-count windows :meth:`encode` steps through, as :func:`event_windows` gives them."""
        h, w = sample.height, sample.width
        events = sample.events
        start = min(float(events.t_s[0]), sample.key_time_s) if len(events) else sample.key_time_s
        events = events.between(start, sample.key_time_s)
        per_window = max(1, int(round(self.params["events_per_pixel"] * h * w)))
        return event_windows(events.t_s, events_per_window=per_window, end_s=sample.key_time_s,
                             max_windows=self.params["max_windows"])

    @staticmethod
    def _grid_tensor(grid: np.ndarray) -> tuple[torch.Tensor]:
        return (torch.from_numpy(np.ascontiguousarray(grid))[None].contiguous(memory_format=torch.channels_last),)

    # -- streaming (neuspike.video): carry the state from frame to frame -------------------------

    def reconstruct_next(self, sample: Sample, *, previous_s: float) -> np.ndarray:
        """The image at the sample's key instant, continuing the state of the previous frame.

        The state is committed only at the ends of full windows: the events after the last commit
        (the previous fresh reconstruction ends on one, at its key instant) are cut into windows of
        ``events_per_pixel * H * W`` events counted forward, each stepped and committed; the
        remaining events up to the key instant are stepped on the committed state without committing
        it, and give the output. A frame thus costs its full windows plus at most one step, whatever
        the frame rate. With ``read_out="window"`` the remaining events wait for the next frame and
        the output is the last full window's (the previous image when none completed). The frame
        warms up afresh (as :meth:`reconstruct`) when time went back, when more than ``max_windows``
        windows are pending, or after :meth:`reset`. Events must reach back to the previous frame
        (the video stream's event history does).
        """
        self._next_from = previous_s
        try:
            return self.reconstruct(sample)
        finally:
            self._next_from = None

    def _reconstruct(self, sample: Sample) -> tuple[np.ndarray, str]:
        carried = getattr(self, "_carried", None)
        if getattr(self, "_next_from", None) is not None and carried is not None and carried[0] is self._state:
            seen = self.windows_seen
            image = self._continue(sample, *carried)
            if image is not None:
                self.windows_seen = seen + self._committed
                label = self._warm_up_label()
                if self.params["read_out"] == "window":
                    label += f"; read out at the last full window, {1e3 * self._lag_s:.3g} ms before the key instant"
                return image, label
        image, label = super()._reconstruct(sample)
        self._carried = (self._state, sample.key_time_s, image)
        self.windows_seen = self.last_steps
        return image, self._warm_up_label(label)

    #: Windows the current state has stepped through since its reset (``max_windows`` or more: fully warmed up).
    windows_seen: int = 0

    def _warm_up_label(self, label: str | None = None) -> str:
        """The read-out's label, saying so when the state rests on fewer than ``max_windows`` windows
        (a frame near the start of the events, whose history is short)."""
        label = self.output_label if label is None else label
        most = self.params["max_windows"]
        if self.windows_seen < most:
            label = f"{label}; short history: warmed up on {self.windows_seen} of {most} windows"
        return label

    def _continue(self, sample: Sample, state: Any, t0: float, image: np.ndarray) -> np.ndarray | None:
        key, ev, h, w = sample.key_time_s, sample.events, sample.height, sample.width
        if key < t0:
            return None
        i0, i1 = (int(i) for i in np.searchsorted(ev.t_s, [t0, key], side="left"))
        per = max(1, int(round(self.params["events_per_pixel"] * h * w)))
        full = (i1 - i0) // per
        if full > self.params["max_windows"]:
            return None

        def step(a: int, b: int, start: float, end: float) -> np.ndarray:
            end = max(end, float(np.nextafter(start, np.inf)))
            chunk = EventStream.trusted(ev.t_s[a:b], ev.x[a:b], ev.y[a:b], ev.p[a:b], w, h)
            grid = voxel_grid(chunk, bins=NUM_BINS, t0_s=start, t1_s=end, height=h, width=w,
                              normalize=self.params["normalize"])
            return self.to_image(self.run_step(self._grid_tensor(grid)), sample)

        for j in range(full):
            a, b = i0 + j * per, i0 + (j + 1) * per
            t1 = float(ev.t_s[b]) if b < i1 else key
            image, t0 = step(a, b, t0, t1), t1
        self._carried = (self._state, t0, image)
        self._committed = full
        self.last_steps = full
        self._lag_s = key - t0
        if self.params["read_out"] == "window":  # the rest waits for the next frame
            return image
        if i0 + full * per < i1:  # the partial window: stepped, not committed
            committed = self._state
            image = step(i0 + full * per, i1, t0, key)
            self._state = committed
            self.last_steps = full + 1
        return image

    def encode(self, sample: Sample) -> list[tuple[torch.Tensor]]:
        """One voxel grid per fixed-count event window up to the key instant (an empty grid without events)."""
        h, w = sample.height, sample.width
        events = sample.events
        start = min(float(events.t_s[0]), sample.key_time_s) if len(events) else sample.key_time_s
        events = events.between(start, sample.key_time_s)
        per_window = max(1, int(round(self.params["events_per_pixel"] * h * w)))
        windows = event_windows(events.t_s, events_per_window=per_window, end_s=sample.key_time_s,
                                max_windows=self.params["max_windows"])
        if not windows:
            return [self._grid_tensor(np.zeros((NUM_BINS, h, w), dtype=np.float32))]
        steps = []
        for i0, i1, t0, t1 in windows:
            # slices of a validated stream keep its invariants
            chunk = EventStream.trusted(events.t_s[i0:i1], events.x[i0:i1], events.y[i0:i1], events.p[i0:i1], w, h)
            grid = voxel_grid(chunk, bins=NUM_BINS, t0_s=t0, t1_s=t1, height=h, width=w,
                              normalize=self.params["normalize"])
            steps.append(self._grid_tensor(grid))
        return steps


def register_methods(register) -> None:
    """Add ``firenet``, ``firenet-plus`` and ``firenet-sim`` to the registry."""
    register("firenet", FireNet, params={"normalize": True}, weights=WeightsConfig("firenet.pt", subdirs=("firenet",)),
             description="FireNet (published weights), normalised 5-bin voxel grids, 0.35 events/pixel windows")
    register("firenet-plus", FireNet, params={"normalize": False},
             weights=WeightsConfig("firenet_plus.pt", subdirs=("firenet",)),
             description="FireNet+ (published weights), raw 5-bin voxel grids, 0.35 events/pixel windows")
    register("firenet-sim", FireNet, params={"normalize": True},
             weights=WeightsConfig("firenet-sim.safetensors", subdirs=("firenet",)),
             description="FireNet trained here on the simulator (python -m neuspike.train firenet-sim), "
                         "normalised 5-bin voxel grids, 0.35 events/pixel windows")
