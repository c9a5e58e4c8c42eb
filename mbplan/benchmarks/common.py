"""Shared helpers of the benchmarks: timing, atomic result files and plots."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as cs
import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def median_time(fn: Callable[[], Any], min_repeats: int = 5, min_seconds: float = 0.2) -> float:
    """Median wall time of ``fn()`` over at least ``min_repeats`` calls and ``min_seconds``."""
    fn()  # warm-up (mapping, caches)
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < min_repeats or time.perf_counter() - start < min_seconds:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run_in_tree(tree: Path, code: str, arg: Any) -> Any:
    """Run ``code`` by ``python -c`` in the checkout ``tree`` (so that it imports that tree's
    mbplan: A/B runs against a baseline checkout) with ``json.dumps(arg)`` as its argument;
    returns its last line of output, parsed as JSON."""
    done = subprocess.run(
        [sys.executable, "-c", code, json.dumps(arg)],
        cwd=tree,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def machine_info() -> dict[str, Any]:
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "casadi": cs.__version__,
        "numpy": np.__version__,
    }


@contextmanager
def _replacing(path: Path) -> Iterator[Path]:
    """A temporary file next to ``path`` that replaces ``path`` when the block succeeds (and is
    removed if it fails), so no half-written result is left."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file."""
    with _replacing(path) as tmp:
        tmp.write_text(text)


def write_json(path: Path, data: Any) -> None:
    write_atomic(path, json.dumps(data, indent=2) + "\n")


def save_plot(fig: Figure, path: Path, dpi: int) -> None:
    """Save a matplotlib figure to ``path`` (format from the suffix) via a temporary file, then
    close it."""
    import matplotlib.pyplot as plt

    try:
        with _replacing(path) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)


def plan_row(ocp: Any, method: str, **plan_options: Any) -> tuple[dict[str, Any], Any, Any]:
    """``mbplan.plan(ocp, method, **plan_options)`` verified, as the JSON row every benchmark
    shares (status, iterations, times — ``total_time_s`` the wall time of ``plan`` — and the
    verification), with the result and the :class:`~mbplan.verification.Verification`."""
    from mbplan.planning.solve import plan
    from mbplan.verification import verify

    t0 = time.perf_counter()
    result = plan(ocp, method, **plan_options)
    wall = time.perf_counter() - t0
    check = verify(ocp, result)
    row = {
        "success": bool(result.success),
        "status": result.status,
        "iterations": int(result.iterations),
        "solve_time_s": float(result.solve_time_s),
        "total_time_s": float(wall),
        "time_per_iter_s": float(result.time_per_iter_s),
        "verified": bool(check.passed),
        "verification_reasons": check.reasons,
    }
    return row, result, check
