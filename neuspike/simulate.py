"""``python -m neuspike.simulate``: the simulation's command (and the ``neuspike-simulate`` console script).

The command lives in :mod:`neuspike.simulation.command`, the simulation in :mod:`neuspike.simulation`;
this module is only the documented entry point.
"""

import sys

from neuspike.simulation.command import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
