"""``python -m neuspike.video``: see :mod:`neuspike.video.cli`."""

import sys

from neuspike.video.cli import main

sys.exit(main())
