"""Shared test-session setup (kept minimal)."""

import os

# The suite multiplies tiny matrices; multi-threaded OpenBLAS only adds contention on the two
# shared cores (several-fold slowdowns when another job runs). Must precede NumPy's import.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from hypothesis import settings

# CI runs property-based tests with a fixed seed so that a landing does not depend on luck;
# locally they explore new examples on every run.
if os.environ.get("CI"):
    settings.register_profile("ci", derandomize=True, deadline=None)
    settings.load_profile("ci")
