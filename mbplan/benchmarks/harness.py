"""Benchmark harness: run (case, method) jobs, append one JSON line per job, resume, summarise.

Jobs run in a local process pool by default, or on a Dask cluster when a scheduler address is
given (``distributed`` extra). Rows go to a :mod:`mbplan.benchmarks.store`: tagged with the hash
of the run's configuration, appended and fsynced per finished job under a lock, so a killed run
resumes without redoing, losing or mislabelling cases, and a run with another configuration or a
second concurrent run into the same folder is refused.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import threadpoolctl
from tqdm import tqdm

from mbplan.benchmarks.store import Appender, check_config, locked, repair
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


def read_results(path: Path, config: Mapping[str, Any] | None = None) -> list[dict]:
    """The valid rows of a results file made with ``config`` (see :func:`store.repair`)."""
    return repair(path, check_config(path, config or {})) if path.exists() else []


def run_jobs(
    jobs: Sequence[Job],
    results_path: Path,
    *,
    config: Mapping[str, Any] | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    description: str = "benchmark",
) -> list[dict]:
    """Run the jobs not yet in ``results_path``; return all rows (old and new).

    ``config`` (JSON-serialisable) is everything besides (case, method) that changes a row; a
    folder holding rows of another configuration is refused (:func:`store.check_config`)."""
    if workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise InputError("run_jobs: a (case, method) job is given twice")
    results_path.parent.mkdir(parents=True, exist_ok=True)
    with locked(results_path):
        key = check_config(results_path, config or {})
        rows = repair(results_path, key)
        done = {(r["case"], r["method"]) for r in rows}
        todo = [j for j in jobs if j.key not in done]
        if len(todo) < len(jobs):  # rows of an earlier run of this configuration, kept as they are
            print(
                f"{description}: {len(jobs) - len(todo)} of {len(jobs)} jobs already in "
                f"{results_path}, not re-run (delete that file to re-run them with the current code)",
                file=sys.stderr,
            )
        sink = Appender(results_path)
        try:
            with tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc=description) as bar:
                for job, row in _execute(todo, workers, scheduler):
                    row = {"case": job.case, "method": job.method, **row, "config": key}
                    sink.append(row)
                    rows.append(row)
                    bar.update()
        finally:
            sink.close()
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
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("fork") if _LINUX else None,
        initializer=_start_worker,
        initargs=(os.getpid(), worker_threads(workers)),
    )
    try:
        # The workers are forked by the first submit: an interrupt then would be lost in the
        # fork handlers, so it waits (blocked) until the pool stands.
        with _signals_blocked():
            futures = {pool.submit(j.fn, *j.args): j for j in jobs}
        for fut in as_completed(futures):
            yield futures[fut], fut.result()
    except BaseException:
        # Interrupted (Ctrl-C, SIGTERM) or a job failed: stop the workers now instead of
        # waiting for the running jobs; their rows are simply not written.
        _stop_workers(list((getattr(pool, "_processes", None) or {}).values()))
        pool.shutdown(wait=True, cancel_futures=True)  # joins the pool's thread: a quiet exit
        raise
    pool.shutdown()


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_STOP_GRACE = 2.0  # s a terminated worker gets before it is killed
_PR_SET_PDEATHSIG = 1  # prctl option: the signal a process gets when its parent dies
_LINUX = sys.platform.startswith("linux")


def _stop_workers(processes: list) -> None:
    """SIGTERM every worker, then SIGKILL those still alive after :data:`_STOP_GRACE`: a worker
    that cannot take SIGTERM (still blocked, or a child forked while another thread held a lock)
    must not outlive the run holding its parent's pipes."""
    for process in processes:
        process.terminate()
    deadline = time.monotonic() + _STOP_GRACE
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join(_STOP_GRACE)


@contextlib.contextmanager
def _signals_blocked() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP pending for the block; they are delivered after it."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def worker_threads(workers: int) -> int:
    """Threads (BLAS, OpenMP) each of ``workers`` local worker processes may use: the CPUs this
    process may run on, shared out, at least one. Unlimited, every worker's libraries start
    threads for all CPUs and the workers' threads contend for them: two workers on two cores
    plan the UR5 shelf about 1.5 times slower than with one thread each, with either method."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, (cpus or 1) // workers)


_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _start_worker(parent: int, threads: int) -> None:
    """A worker's set-up: its signals (:func:`_worker_signals`) and its thread budget
    (:func:`worker_threads`): the thread pools already loaded are limited now (threadpoolctl),
    the libraries it loads later read the environment."""
    _worker_signals(parent)
    for name in _THREAD_VARIABLES:
        os.environ[name] = str(threads)
    threadpoolctl.threadpool_limits(limits=threads)


def _worker_signals(parent: int) -> None:
    """Workers leave Ctrl-C (sent to the whole process group) to the parent, which stops them
    (SIGTERM: the default, quiet exit, not a handler inherited from the parent); they are
    forked with these signals blocked (:func:`_signals_blocked`). On Linux a worker is killed
    when its parent dies (``PR_SET_PDEATHSIG``), however it dies: a killed run leaves no worker
    behind holding its pipes or its CPU."""
    if _LINUX:  # forked by ``parent`` (the pool's context)
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, ctypes.c_ulong(signal.SIGKILL)) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG) failed")
        if os.getppid() != parent:  # the parent died before the request
            os._exit(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


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
