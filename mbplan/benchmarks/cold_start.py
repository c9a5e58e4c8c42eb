"""A plan in a new process beside the same plan warm, for the speed benchmark's ``cold`` section.

Every ``mbplan plan`` is a new process: it imports the package, loads the compiled kernels
(numba's and the CasADi functions' shared objects) and the structures kept on disk
(:mod:`mbplan.engine.disk_cache`), then plans. :func:`cold_starts` runs one plan per task and
method in a subprocess (``python -m mbplan.benchmarks.cold_start TASK METHOD``) after a first,
discarded run of the same subprocess, so the disk caches are warm as after ``mbplan warmup``;
the subprocess then plans the same task again (warm: everything in memory) and reports both.
"""

from __future__ import annotations

import gc
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

from mbplan.tasks.speed import chain_task, drone_task, iiwa_task

COLD_TASKS: dict[str, tuple[str, Callable[[], Any]]] = {
    "iiwa-com": ("via", lambda: iiwa_task(0)),
    "iiwa-distance": ("via", lambda: iiwa_task(0, constraint="distance")),
    "drone": ("via", lambda: drone_task(0)),
    "chain8": ("linear", lambda: chain_task(8)),
}
"""Task name → (warm start, its OCP's builder): the speed benchmark's first case of each."""

COLD_METHODS = ("ripm", "ipopt")


def cold_starts(
    tasks: Sequence[str] = tuple(COLD_TASKS),
    methods: Sequence[str] = COLD_METHODS,
    repeats: int = 3,
) -> dict[str, dict[str, dict[str, float]]]:
    """task → method → the medians over ``repeats`` new processes (after one discarded) of
    :func:`measure`'s numbers, of ``process_s``, the subprocess's wall time, and of
    ``startup_s``, what it spends besides the two plans (interpreter, imports, exit)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for task in tasks:
        for method in methods:
            runs = [_subprocess(task, method) for _ in range(repeats + 1)][1:]
            out.setdefault(task, {})[method] = {
                key: statistics.median(r[key] for r in runs) for key in runs[0]
            }
    return out


def _subprocess(task: str, method: str) -> dict[str, float]:
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "mbplan.benchmarks.cold_start", task, method],
        capture_output=True,
        text=True,
        check=True,
        env={k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"},
    )
    wall = time.perf_counter() - start
    numbers = json.loads(proc.stdout.strip().splitlines()[-1])
    startup = wall - numbers["cold_plan_s"] - numbers["warm_plan_s"]
    return {"process_s": wall, "startup_s": startup, **numbers}


def measure(task: str, method: str) -> dict[str, float]:
    """The plan of ``task`` with ``method`` in this process (cold, in a new one), then again
    (warm); seconds."""
    from mbplan.planning.solve import plan

    warm_start, build = COLD_TASKS[task]
    numbers: dict[str, float] = {}
    for when in ("cold", "warm"):
        t0 = time.perf_counter()
        result = plan(build(), method, warm_start=warm_start)
        numbers |= {
            f"{when}_plan_s": time.perf_counter() - t0,
            f"{when}_solve_s": result.solve_time_s,
            f"{when}_compile_s": result.compile_time_s,
            f"{when}_iterations": result.iterations,
        }
    return numbers


if __name__ == "__main__":
    gc.freeze()  # as the `mbplan` program does (mbplan.cli.main.console)
    print(json.dumps(measure(sys.argv[1], sys.argv[2])), flush=True)
    gc.freeze()
