"""Shared test-session setup (kept minimal)."""

import os

# The suite multiplies tiny matrices; multi-threaded OpenBLAS only adds contention on the two
# shared cores (several-fold slowdowns when another job runs). Must precede NumPy's import.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
