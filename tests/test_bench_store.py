"""The benchmark store: no row lost, duplicated or mislabelled across configuration changes,
concurrent runs, damaged files and interrupts (tiny fake jobs, so this is fast)."""

import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import mbplan
from mbplan.benchmarks.harness import Job, run_jobs
from mbplan.benchmarks.store import config_hash
from mbplan.errors import InputError

METHODS = ("a", "b")
# Subprocesses import this checkout's mbplan, whatever is installed.
ENV = {"PYTHONPATH": str(Path(mbplan.__file__).parents[1])}


def value(case: int, method: str, seed: int) -> dict:
    return {"success": True, "value": 1000 * seed + 10 * case + METHODS.index(method)}


def _jobs(n: int, seed: int = 0) -> list[Job]:
    return [Job(i, m, value, (i, m, seed)) for i in range(n) for m in METHODS]


def _lines(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def _assert_complete(path, n: int, seed: int) -> None:
    """Every (case, method) exactly once, with the value and configuration of ``seed``."""
    rows = _lines(path)
    keys = [(r["case"], r["method"]) for r in rows]
    assert len(keys) == len(set(keys)), "duplicated rows"
    assert sorted(keys) == sorted((i, m) for i in range(n) for m in METHODS), "lost rows"
    key = config_hash({"seed": seed})
    for r in rows:  # mislabelled: a row of another configuration or another job
        assert r["config"] == key
        assert r["value"] == value(r["case"], r["method"], seed)["value"]


def test_configuration_change_is_refused_and_same_configuration_resumes(tmp_path):
    path = tmp_path / "results.jsonl"
    run_jobs(_jobs(3), path, config={"seed": 0, "warm_start": "linear"})
    before = path.read_text()
    with pytest.raises(InputError, match=r"another configuration \(seed 0 -> 1; warm_start"):
        run_jobs(_jobs(3, seed=1), path, config={"seed": 1, "warm_start": "via"})
    assert path.read_text() == before  # nothing run, nothing relabelled
    calls = []
    rows = run_jobs(
        [Job(9, "a", lambda: calls.append(1) or {"success": True}, ())],
        path,
        config={"seed": 0, "warm_start": "linear"},
    )
    assert len(calls) == 1 and len(rows) == 7  # resumed: only the new job ran


def test_results_without_a_recorded_configuration_are_not_resumed(tmp_path):
    path = tmp_path / "results.jsonl"
    path.write_text('{"case": 0, "method": "a", "success": true}\n')
    with pytest.raises(InputError, match="without a recorded configuration"):
        run_jobs(_jobs(1), path, config={"seed": 0})


def test_corrupt_middle_line_keeps_every_valid_row(tmp_path):
    path = tmp_path / "results.jsonl"
    run_jobs(_jobs(4), path, config={"seed": 0})
    lines = path.read_text().splitlines()
    damaged = lines[2]
    lines[2] = damaged[: len(damaged) // 2]  # a corrupt line in the middle
    lines.insert(5, lines[4])  # and a duplicate
    path.write_text("\n".join(lines) + "\n")
    with pytest.warns(UserWarning, match=r"moved 2 bad line\(s\).*line 3: not valid JSON.*line 6"):
        run_jobs(_jobs(4), path, config={"seed": 0})
    _assert_complete(path, 4, 0)
    rejected = (tmp_path / "results.jsonl.rejected").read_text().splitlines()
    assert rejected[0] == lines[2] and len(rejected) == 2


@pytest.mark.slow
def test_two_concurrent_writers(tmp_path):
    script, procs = _script(tmp_path), []
    for _ in range(2):  # the second starts while the first is writing
        procs.append(
            subprocess.Popen(
                [sys.executable, script, str(tmp_path / "out"), "30", "1", "0"],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=os.environ | ENV,
            )
        )
        assert procs[-1].stdout.readline() == "ready\n"
    (first, _), (second, refused) = [
        (p.wait(timeout=120), p.communicate(timeout=60)[1]) for p in procs
    ]
    assert (first, second) == (0, 2), refused
    assert "another benchmark run" in refused and "Traceback" not in refused
    assert len(refused.strip().splitlines()) == 1
    _assert_complete(tmp_path / "out" / "results.jsonl", 30, 0)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("signum", "workers"),
    [(signal.SIGINT, 1), (signal.SIGTERM, 1), (signal.SIGINT, 2), (signal.SIGTERM, 2)],
    ids=["SIGINT", "SIGTERM", "SIGINT-pool", "SIGTERM-pool"],
)
def test_interrupts_at_random_points(tmp_path, signum, workers):
    script, out, n = _script(tmp_path), tmp_path / "out", 40
    rng = random.Random(signum * 10 + workers)
    codes = []
    for _ in range(3):
        proc = subprocess.Popen(
            [sys.executable, script, str(out), str(n), str(workers), "0"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=os.environ | ENV,
            preexec_fn=_default_sigint,
        )
        assert proc.stdout.readline() == "ready\n"
        time.sleep(rng.uniform(0.0, 1.0))
        proc.send_signal(signum)
        codes.append(proc.wait(timeout=60))
        err = proc.communicate(timeout=60)[1]  # a worker left holding the pipe fails, not hangs
        # 0: it had finished; -signum: the signal came during the interpreter's shutdown
        assert codes[-1] in (0, 128 + signum, -signum), err
        assert "Traceback" not in err, err
        if codes[-1]:
            assert "interrupted" in err.splitlines()[-1]
    assert 128 + signum in codes  # the interrupts did land mid-run
    final = subprocess.run(
        [sys.executable, script, str(out), str(n), str(workers), "0"],
        capture_output=True,
        text=True,
        timeout=120,
        env=os.environ | ENV,
    )
    assert final.returncode == 0, final.stderr
    _assert_complete(out / "results.jsonl", n, 0)
    assert not list(out.glob("*.tmp*"))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_workers_die_with_a_killed_run(tmp_path):
    """SIGKILL gives the run no chance to stop its pool: the workers must still go."""
    script = tmp_path / "sleepers.py"
    script.write_text(
        textwrap.dedent(
            """
            import os, sys, time
            from pathlib import Path
            from mbplan.benchmarks.harness import Job, run_jobs

            def job(case, method, folder):
                Path(folder, str(os.getpid())).touch()
                time.sleep(120)
                return {"success": True}

            folder = sys.argv[1]
            jobs = [Job(i, "a", job, (i, "a", folder)) for i in range(2)]
            run_jobs(jobs, Path(folder) / "out" / "results.jsonl", workers=2)
            """
        )
    )
    pids = tmp_path / "pids"
    pids.mkdir()
    run = subprocess.Popen([sys.executable, str(script), str(pids)], env=os.environ | ENV)
    try:
        deadline = time.monotonic() + 60
        while len([p for p in pids.iterdir() if p.name.isdigit()]) < 2:
            assert time.monotonic() < deadline and run.poll() is None, "the workers did not start"
            time.sleep(0.05)
    finally:
        run.kill()
        run.wait(timeout=30)
    workers = [int(p.name) for p in pids.iterdir() if p.name.isdigit()]
    deadline = time.monotonic() + 20
    alive = workers
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [pid for pid in workers if _running(pid)]
    assert not alive, f"workers {alive} outlived their killed run"


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _default_sigint() -> None:
    """SIGINT's default in the child, so that Python turns it into KeyboardInterrupt even when
    the tests run in a background job (which starts with SIGINT ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _script(tmp_path) -> str:
    path = tmp_path / "bench.py"
    path.write_text(
        textwrap.dedent(
            """
            import random, sys, time
            from pathlib import Path
            from mbplan.benchmarks.harness import Job, run_jobs
            from mbplan.cli.support import run_command

            def job(case, method, seed):
                time.sleep(random.uniform(0.02, 0.06))
                return {"success": True, "value": 1000 * seed + 10 * case + "ab".index(method)}

            out, n, workers, seed = Path(sys.argv[1]), *map(int, sys.argv[2:])
            jobs = [Job(i, m, job, (i, m, seed)) for i in range(n) for m in "ab"]

            def main():
                print("ready", flush=True)
                run_jobs(jobs, out / "results.jsonl", config={"seed": seed}, workers=workers)
                return 0

            sys.exit(run_command(main))
            """
        )
    )
    return str(path)
