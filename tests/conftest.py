"""Shared test-session setup (kept minimal)."""

import os

# The suite multiplies tiny matrices; multi-threaded OpenBLAS only adds contention on the two
# shared cores (several-fold slowdowns when another job runs). Must precede NumPy's import.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest
from hypothesis import settings

# CI runs property-based tests with a fixed seed so that a landing does not depend on luck;
# locally they explore new examples on every run.
if os.environ.get("CI"):
    settings.register_profile("ci", derandomize=True, deadline=None)
    settings.load_profile("ci")


@pytest.fixture(autouse=True, scope="session")
def _own_disk_cache(tmp_path_factory):
    """The session's structures kept on disk in a folder of its own (the compiled kernels stay
    in the shared cache): the suite's many small problems stay out of the user's cache, and
    every run starts from an empty one."""
    from mbplan.engine import disk_cache

    mp = pytest.MonkeyPatch()
    folder = tmp_path_factory.mktemp("disk_cache")
    mp.setattr(disk_cache, "store_dir", lambda: folder)
    yield
    mp.undo()
