"""Test-suite settings shared by every test file.

Hypothesis runs derandomised (the same examples on every run, so a failure reproduces) and
without per-example deadlines (CI machines are shared and their timing is noisy).
"""

from hypothesis import settings

settings.register_profile("neuspike", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("neuspike")
