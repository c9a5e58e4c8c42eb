"""Time per iteration of whole RIPM solves with ``kkt_method="full"`` and ``"reduced"`` (the
formulation's default elimination plan), the minimum over ``--repeats`` solves after a warm-up
one, for the choice of ``kkt_method="auto"`` (reduced whenever a plan exists); one JSON line
per task. Run it from the root of each tree to compare.

    python benchmarks/kkt_method_breakeven.py --tasks chain16 chain32 chain64 --repeats 1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))  # the tree to run: the working directory

from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="+", default=["chain16", "chain32"])
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    for task in args.tasks:
        problem, x0, opts = TASKS[task](0)
        row = {"task": task}
        for method in ("full", "reduced"):
            options = opts.replace(kkt_method=method)
            solve_ripm(problem, x0, options)
            best = float("inf")
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                res = solve_ripm(problem, x0, options)
                best = min(best, time.perf_counter() - t0)
            row[method] = {"iterations": res.iterations, "ms_per_iter": 1e3 * best / res.iterations}
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
