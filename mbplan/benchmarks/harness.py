"""Benchmark harness: run (case, method) jobs, append one JSON line per job, resume, summarise.

Jobs run in a local process pool by default, or on a Dask cluster when a scheduler address is
given (``distributed`` extra). ``results.jsonl`` is appended and flushed per finished job, so a
killed run resumes without redoing or losing cases: jobs already in the file are skipped, and a
partially written last line (a kill mid-write) is dropped before appending.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from mbplan.errors import InputError


@dataclass(frozen=True)
class Job:
    """One solve: ``fn(*args)`` must return a JSON-serialisable dict."""

    case: int
    method: str
    fn: Callable[..., dict]
    args: tuple

    @property
    def key(self) -> tuple[int, str]:
        return (self.case, self.method)


def read_results(path: Path) -> list[dict]:
    """Complete lines of a results file; a truncated last line is removed from the file."""
    if not path.exists():
        return []
    text = path.read_text()
    lines = text.split("\n")
    complete, rows = [], []
    for line in lines:
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
            complete.append(line)
        except json.JSONDecodeError:
            break  # a line cut by a kill: everything after it is dropped
    if len(complete) != len([ln for ln in lines if ln.strip()]):
        path.write_text("".join(f"{ln}\n" for ln in complete))
    return rows


def run_jobs(
    jobs: Sequence[Job],
    results_path: Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    description: str = "benchmark",
) -> list[dict]:
    """Run the jobs not yet in ``results_path``; return all rows (old and new)."""
    results_path.parent.mkdir(parents=True, exist_ok=True)
    rows = read_results(results_path)
    done = {(r["case"], r["method"]) for r in rows}
    todo = [j for j in jobs if j.key not in done]
    if workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    with (
        results_path.open("a") as sink,
        tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc=description) as bar,
    ):

        def record(job: Job, row: dict) -> None:
            row = {"case": job.case, "method": job.method, **row}
            sink.write(json.dumps(row) + "\n")
            sink.flush()
            os.fsync(sink.fileno())
            rows.append(row)
            bar.update()

        for job, row in _execute(todo, workers, scheduler):
            record(job, row)
    return rows


def _execute(
    jobs: Sequence[Job], workers: int, scheduler: str | None
) -> Iterable[tuple[Job, dict]]:
    if not jobs:
        return
    if scheduler is not None:
        try:
            from distributed import Client
            from distributed import as_completed as dask_completed
        except ImportError as exc:
            raise InputError(
                "--scheduler needs the 'distributed' package: pip install mbplan[distributed]"
            ) from exc
        with Client(scheduler) as client:
            futures = {client.submit(j.fn, *j.args, pure=False): j for j in jobs}
            for fut in dask_completed(futures):
                yield futures[fut], fut.result()
        return
    if workers == 1:
        for j in jobs:
            yield j, j.fn(*j.args)
        return
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(j.fn, *j.args): j for j in jobs}
        for fut in as_completed(futures):
            yield futures[fut], fut.result()


def summarize(rows: Sequence[dict], task: str, tol: float) -> dict[str, Any]:
    """Per-method statistics in the schema of ``summary.json``.

    Iteration and time statistics are over converged runs (NaN-free; ``null`` when none).
    """
    methods: dict[str, Any] = {}
    for name in sorted({r["method"] for r in rows}):
        rs = [r for r in rows if r["method"] == name]
        ok = [r for r in rs if r["success"]]
        entry: dict[str, Any] = {
            "n": len(rs),
            "converged": len(ok),
            "tol": tol,
            "median_iters": _stat(np.median, [r["iterations"] for r in ok]),
            "mean_iters": _stat(np.mean, [r["iterations"] for r in ok]),
            "median_time_per_iter_s": _stat(np.median, [r["time_per_iter_s"] for r in ok]),
            "median_solve_time_s": _stat(np.median, [r["solve_time_s"] for r in ok]),
        }
        if any("verified" in r for r in rs):
            entry["verified"] = sum(bool(r.get("verified")) and r["success"] for r in rs)
            entry["median_total_time_s"] = _stat(np.median, [r["total_time_s"] for r in ok])
        methods[name] = entry
    return {"task": task, "methods": methods}


def _stat(fn: Callable, values: list[float]) -> float | None:
    return float(fn(values)) if values else None
