"""Plug-in for choosing e2vid's warm-up length on validation scenes (training photographs only).

Registers ``e2vid-wK`` and ``firenet-sim-wK``: the shipped networks, stepping through at most the
``K`` most recent fixed-count event windows of a sample (the registered methods use 24).
"""

from baselines.e2vid import E2VID
from baselines.firenet import FireNet

WINDOWS = (4, 6, 8, 12)


def register_methods(register):
    for k in WINDOWS:
        register(f"e2vid-w{k}", E2VID, params={"normalize": True, "max_windows": k}, weights="e2vid.safetensors")
        register(f"firenet-sim-w{k}", FireNet, params={"normalize": True, "max_windows": k},
                 weights="firenet-sim.safetensors")
