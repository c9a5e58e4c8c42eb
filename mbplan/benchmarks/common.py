"""Shared helpers of the benchmarks: timing, atomic result files and plots."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.validation import as_int, as_real

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


def alternating_runs(trees: dict[str, Path], code: str, arg: Any, rounds: int) -> dict[str, list]:
    """:func:`run_in_tree` in every tree, ``rounds`` times, the trees' order reversed every other
    round (ABBA: neither tree always runs first); each tree's outputs in round order."""
    runs: dict[str, list] = {tag: [] for tag in trees}
    order = list(trees)
    for r in range(rounds):
        for tag in order if r % 2 == 0 else order[::-1]:
            runs[tag].append(run_in_tree(trees[tag], code, arg))
    return runs


def median_of_min(runs: list[dict], task: str, keys: Iterable[str]) -> dict[str, Any]:
    """Per key of ``runs[round][task][case]``: the minimum over rounds per case, the median over
    cases (the A/B scripts' summary), with the first round's iteration counts."""
    cases = range(len(runs[0][task]))
    out: dict[str, Any] = {
        k: float(np.median([min(r[task][c].get(k, np.nan) for r in runs) for c in cases]))
        for k in keys
    }
    out["iterations"] = [runs[0][task][c]["iterations"] for c in cases]
    return out


MIN_INTERVAL_CASES = 10
"""Fewest cases with a value per method for :func:`median_ratio_interval` to give one."""


def median_ratio_interval(
    num: Mapping[Any, float | None],
    den: Mapping[Any, float | None] | None = None,
    level: float = 0.95,
    draws: int = 2000,
    seed: int = 0,
) -> tuple[float, float] | None:
    """Percentile bootstrap interval of ``median(num) / median(den)`` over paired cases (or of
    ``median(num)`` alone): the cases (the keys; ``None`` or NaN marks a case left out of that
    method's median, e.g. not converged) are drawn with replacement, the same draw for both
    methods, so cases that are slow for every method move both medians together. It shows how
    far the choice of cases moves the statistic within one run, not shifts between runs.
    ``None`` if a method has fewer than :data:`MIN_INTERVAL_CASES` values; draws that leave a
    method without any value are dropped."""
    level = as_real(level, "level", positive=True)
    if not level < 1.0:
        raise InputError(f"median_ratio_interval: level must be in (0, 1), got {level}")
    draws = as_int(draws, "draws", minimum=1, what="number of bootstrap draws")
    cases = sorted(set(num) | set(den or {}), key=str)

    def values(by_case: Mapping[Any, float | None]) -> np.ndarray:
        return np.array([np.nan if by_case.get(c) is None else by_case[c] for c in cases], float)

    columns = [values(num)] + ([] if den is None else [values(den)])
    if any(np.count_nonzero(np.isfinite(v)) < MIN_INTERVAL_CASES for v in columns):
        return None
    pick = np.random.default_rng(seed).integers(0, len(cases), size=(draws, len(cases)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN draw: dropped below
        medians = [np.nanmedian(np.where(np.isfinite(v), v, np.nan)[pick], axis=1) for v in columns]
    with np.errstate(divide="ignore", invalid="ignore"):
        stats = medians[0] if den is None else medians[0] / medians[1]
    stats = stats[np.isfinite(stats)]
    if stats.size == 0:
        return None
    lo, hi = np.percentile(stats, [50 * (1 - level), 50 * (1 + level)])
    return float(lo), float(hi)


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
    shares (status, iterations, times — ``total_time_s`` the wall time of ``plan``, with the
    kernels' ``compile_time_s``, which ``solve_time_s`` leaves out — and the verification), with the result and the :class:`~mbplan.verification.report.Verification`.
    A benchmark passes one ``workspace`` to the cases of a family (:mod:`mbplan.workspace`)."""
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
        "compile_time_s": float(result.compile_time_s),
        "verified": bool(check.passed),
        "verification_reasons": check.reasons,
    }
    if getattr(ocp.robot, "loops", ()):
        row["closure_residual"] = float(check.closure_residual)
    if np.isfinite(check.margin_kept):
        row["margin_kept"] = float(check.margin_kept)
    return row, result, check
