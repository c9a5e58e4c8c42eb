"""Benchmark harness: resume after a kill without lost or duplicate lines; local pool and Dask."""

import json

import pytest

from mbplan.benchmarks.harness import Job, read_results, run_jobs, summarize
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
