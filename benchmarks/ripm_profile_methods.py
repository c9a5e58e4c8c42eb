"""The RIPM's own per-iteration cost, method by method: exclusive time of every driver method
(main phase, restoration and line search), of ``KKTSystem``'s entry points and of the
problem's ``evaluate`` / ``values`` / ``retract``, in µs per iteration.

Each method is wrapped by a timer that subtracts the time of the wrapped methods it calls
(about 0.3-0.5 µs of timer overhead per call is included in every row). Per case the minimum
over ``--repeats`` solves (after a warm-up solve), with the calls per iteration of the first.

    python benchmarks/ripm_profile_methods.py --task drone --cases 3 --repeats 10
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.transcription.problem import TrajectoryProblem

from mbplan.solvers import linear_solver, ripm
from mbplan.tasks.speed import TASKS

_SKIP = {"run", "kkt", "iter"}


class _Clock:
    """Exclusive times and call counts of the wrapped methods."""

    def __init__(self) -> None:
        self.time: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._inner: list[float] = []

    def wrap(self, cls: type, name: str) -> None:
        fn: Callable = getattr(cls, name)
        label = f"{cls.__name__.strip('_')}.{name}"

        def timed(*args: Any, **kw: Any) -> Any:
            t0 = time.perf_counter()
            self._inner.append(0.0)
            try:
                return fn(*args, **kw)
            finally:
                dt = time.perf_counter() - t0
                self.time[label] += dt - self._inner.pop()
                self.calls[label] += 1
                if self._inner:
                    self._inner[-1] += dt

        setattr(cls, name, timed)

    def reset(self) -> None:
        self.time.clear()
        self.calls.clear()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default="drone", choices=sorted(TASKS))
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=10)
    args = ap.parse_args()
    clock = _Clock()
    for name in dir(ripm._RIPM):
        attr = getattr(ripm._RIPM, name)
        if name.startswith("_") and not name.startswith("__") and callable(attr):
            if not isinstance(attr, property) and name not in _SKIP:
                clock.wrap(ripm._RIPM, name)
    for name in ("__init__", "set_matrices", "factorize", "solve"):
        clock.wrap(linear_solver.KKTSystem, name)
    for name in ("evaluate", "values", "retract"):
        clock.wrap(TrajectoryProblem, name)
    cases = [TASKS[args.task](i) for i in range(args.cases)]
    rows, calls, iterations = [], None, []
    for problem, x0, options in cases:
        ripm.solve_ripm(problem, x0, options)
        best: dict[str, float] = {}
        for _ in range(args.repeats):
            clock.reset()
            t0 = time.perf_counter()
            res = ripm.solve_ripm(problem, x0, options)
            best["whole solve"] = min(best.get("whole solve", 1e9), time.perf_counter() - t0)
            for k, v in clock.time.items():
                best[k] = min(best.get(k, 1e9), v)
        it = max(res.iterations, 1)
        iterations.append(res.iterations)
        rows.append({k: 1e6 * v / it for k, v in best.items()})
        calls = calls or {k: v / it for k, v in clock.calls.items()}
    keys = sorted(rows[0], key=lambda k: -rows[0][k])
    print(f"{args.task}: iterations {iterations}; µs per iteration (case by case), calls per iter")
    for k in keys:
        values = " ".join(f"{r.get(k, 0.0):8.1f}" for r in rows)
        print(f"  {k:34s} {values}   {calls.get(k, 0.0):5.2f}")


if __name__ == "__main__":
    main()
