"""Plug-in for choosing between trained ``e2vid`` weights on validation scenes (training photographs,
and from stage 13 two held-out dead-leaves pictures made by ``leaves.py``; never the test photographs).

Registers ``e2vid-<name>`` for every candidate name: the ``e2vid`` network with the weights file
``e2vid-<name>.safetensors``, looked up in the sweep's ``--weights`` folder (the candidates are not
shipped; see README.md beside this file). The names are ``E2VID_CANDIDATES`` (comma-separated) when
that variable is set (``none``: no e2vid candidate), otherwise the stages compared so far. ``E2VID_PRECISION`` (float32 or bfloat16),
when set, fixes the candidates' precision (otherwise the ``auto`` choice of the machine).

``FIRENET_SIM_CANDIDATES`` (comma-separated; otherwise the ones scored so far) registers ``firenet-sim-<name>`` the
same way: the FireNet module trained here (``firenet-sim``) with ``firenet-sim-<name>.safetensors``.
"""

import os

from baselines.e2vid import E2VID
from baselines.firenet import FireNet

CANDIDATES = ("stage2", "stage3", "s5-00150", "s5-00300", "s6-00200", "s6-00400", "s6-00600", "s7-00100", "s7-00200",
              "s7-00300", "s7-00400", "s7-00500", "s7-00600", "s8-00250", "s8-00500", "s8-00750", "s9-00100",
              "s9-00200", "s9-00300", "s9-00400", "s9-00500", "s9-00600", "s10-00100", "s10-00200", "s10-00300",
              "s11-00100", "s11-00200", "s12-00300", "s12-00750", "s12-00900",
              "s13-00300", "s13-00400", "s13-00500", "s14-00400", "s14-00500", "s14-00600", "s15-00200", "s15-00300",
              "s16-00150", "s16-00200")
#: The firenet-sim candidates scored so far (FIRENET_SIM_CANDIDATES picks among them and others).
FIRENET_SIM_SCORED = ("fs1-shipped", "fs2-00500", "fs2-00750", "fs2-01000", "fs2-01250", "fs2-01500", "fs2-01750",
                      "fs2-02000", "fs3-00200", "fs3-00400", "fs3-00600")


def register_methods(register):
    names = [n.strip() for n in os.environ.get("E2VID_CANDIDATES", "").split(",") if n.strip()] or CANDIDATES
    names = [n for n in names if n != "none"]
    precision = os.environ.get("E2VID_PRECISION")
    params = {"normalize": True, **({"precision": precision} if precision else {})}
    for name in names:
        register(f"e2vid-{name}", E2VID, params=params, weights=f"e2vid-{name}.safetensors")
    firenet = [n.strip() for n in os.environ.get("FIRENET_SIM_CANDIDATES", "").split(",") if n.strip()]
    for name in [n for n in firenet or FIRENET_SIM_SCORED if n != "none"]:
        register(f"firenet-sim-{name}", FireNet, params=params, weights=f"firenet-sim-{name}.safetensors")
