"""Where the shared real recordings and published weights live (``../shared`` beside the repository).

``NEUSPIKE_SHARED`` overrides the location; tests that need the folder skip when it is absent.
"""

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("NEUSPIKE_SHARED", REPO.parent / "shared"))
