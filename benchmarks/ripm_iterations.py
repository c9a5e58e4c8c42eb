"""Status, iterations, factorizations (through the reduction / in all) and objective of RIPM
solves with the default options, one JSON line per solve; run it from the root of two trees
and compare the outputs (the iteration counts must agree).

    python benchmarks/ripm_iterations.py --tasks iiwa-com:12 chain4 chain8 chain16 > tree.jsonl
    (cd <baseline> && PYTHONPATH=. python <this tree>/benchmarks/ripm_iterations.py ...) > base.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))  # the tree to run: the working directory

from mbplan.solvers import reduced_step, solve_ripm
from mbplan.tasks.speed import TASKS


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="+", default=["iiwa-com:12", "chain4", "chain8", "chain16"])
    args = ap.parse_args()
    systems = []
    init = reduced_step.ReducedKKTSystem.__init__

    def spy(self, *a, **kw):
        init(self, *a, **kw)
        systems.append(self)

    reduced_step.ReducedKKTSystem.__init__ = spy
    for spec in args.tasks:
        task, _, cases = spec.partition(":")
        for case in range(int(cases or 1)):
            problem, x0, opts = TASKS[task](case)
            systems.clear()
            t0 = time.perf_counter()
            res = solve_ripm(problem, x0, opts)
            row = {
                "task": task,
                "case": case,
                "status": res.status.name,
                "iterations": res.iterations,
                "factorizations": res.n_factorizations,
                "reduced": sum(s.n_reduced for s in systems),
                "objective": res.objective,
                "ms": 1e3 * (time.perf_counter() - t0),
            }
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
