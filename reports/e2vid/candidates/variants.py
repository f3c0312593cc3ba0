"""Plug-in for choosing between trained ``e2vid`` weights on validation scenes (training photographs only).

Registers ``e2vid-stage2`` and ``e2vid-stage3``: the ``e2vid`` network with the weights files
``e2vid-stage2.safetensors`` and ``e2vid-stage3.safetensors``, looked up in the sweep's
``--weights`` folder (the candidates are not shipped; see README.md beside this file).
"""

from baselines.e2vid import E2VID

CANDIDATES = ("stage2", "stage3")


def register_methods(register):
    for name in CANDIDATES:
        register(f"e2vid-{name}", E2VID, params={"normalize": True}, weights=f"e2vid-{name}.safetensors")
