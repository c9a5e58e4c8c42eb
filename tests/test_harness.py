"""Benchmark harness: resume after a kill without lost or duplicate lines; local pool and Dask."""

import json
import os

import numpy as np
import pytest
import threadpoolctl

from mbplan.benchmarks.harness import Job, read_results, run_jobs, summarize, worker_threads
from mbplan.errors import InputError


def square(x: int) -> dict:
    return {
        "success": x % 3 != 0,
        "status": "ok" if x % 3 else "fail",
        "iterations": x,
        "solve_time_s": 0.1 * x,
        "time_per_iter_s": 0.1,
    }


def _jobs(n: int) -> list[Job]:
    return [Job(i, m, square, (i,)) for i in range(n) for m in ("a", "b")]


def test_resume_after_interrupted_run(tmp_path, capsys):
    path = tmp_path / "results.jsonl"
    run_jobs(_jobs(3), path)
    assert "already in" not in capsys.readouterr().err
    # A kill mid-write leaves a truncated last line.
    with path.open("a") as f:
        f.write('{"case": 3, "method": "a", "succ')
    with pytest.warns(UserWarning, match="line 7: not valid JSON"):
        rows = run_jobs(_jobs(5), path)
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    keys = [(r["case"], r["method"]) for r in lines]
    assert len(keys) == len(set(keys)) == 10  # nothing lost, nothing twice
    assert sorted(keys) == sorted((i, m) for i in range(5) for m in ("a", "b"))
    assert len(rows) == 10
    assert "benchmark: 6 of 10 jobs already in" in capsys.readouterr().err  # says what it kept
    # A third run has nothing left to do and leaves the file unchanged.
    before = path.read_text()
    run_jobs(_jobs(5), path)
    assert path.read_text() == before
    assert "benchmark: 10 of 10 jobs already in" in capsys.readouterr().err


def test_process_pool_matches_serial(tmp_path):
    serial = run_jobs(_jobs(4), tmp_path / "s.jsonl")
    pooled = run_jobs(_jobs(4), tmp_path / "p.jsonl", workers=2)
    key = lambda r: (r["case"], r["method"])  # noqa: E731
    assert sorted(serial, key=key) == sorted(pooled, key=key)


def thread_budget(x: int) -> dict:
    """What a worker may use: the largest thread count of its loaded thread pools (NumPy's
    BLAS at least) and what libraries it loads later read."""
    np.ones((2, 2)) @ np.ones((2, 2))
    pools = threadpoolctl.threadpool_info()
    return {
        **square(x),
        "pools": len(pools),
        "threads": max(p["num_threads"] for p in pools),
        "environment": os.environ.get("OMP_NUM_THREADS"),
    }


def test_pool_workers_share_out_the_cpus(tmp_path):
    """Two workers on n CPUs use n // 2 threads each (at least one), not n each."""
    budget = worker_threads(2)
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert budget == max(1, cpus // 2)
    before = threadpoolctl.threadpool_info()
    environment = os.environ.get("OMP_NUM_THREADS")
    rows = run_jobs(
        [Job(i, "a", thread_budget, (i,)) for i in range(4)], tmp_path / "t.jsonl", workers=2
    )
    assert all(r["pools"] >= 1 and r["threads"] == budget for r in rows)
    assert all(r["environment"] == str(budget) for r in rows)
    assert threadpoolctl.threadpool_info() == before  # the run's own process keeps its pools
    assert os.environ.get("OMP_NUM_THREADS") == environment


def test_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        rows = run_jobs(_jobs(3), tmp_path / "d.jsonl", scheduler=cluster.scheduler_address)
    assert sorted((r["case"], r["method"]) for r in rows) == sorted(
        (i, m) for i in range(3) for m in ("a", "b")
    )
    assert all(r["iterations"] == r["case"] for r in rows)


def test_summary_counts_only_successes():
    rows = [square(i) | {"case": i, "method": "a"} for i in range(6)]
    s = summarize(rows, "t", 1e-6)["methods"]["a"]
    assert (s["n"], s["converged"]) == (6, 4)
    assert s["median_iters"] == 3.0  # successes 1, 2, 4, 5


def test_bad_worker_count(tmp_path):
    with pytest.raises(InputError, match="workers"):
        run_jobs(_jobs(1), tmp_path / "x.jsonl", workers=0)


def test_read_results_missing_file(tmp_path):
    assert read_results(tmp_path / "none.jsonl") == []
