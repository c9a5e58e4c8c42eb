"""Solve iiwa-distance cases 0..n-1 in order in one process (as ``mbplan bench speed`` does: the
reduction's memoized choices make a case depend on the cases solved before it), writing each
case's RIPM log and a status JSON.

    PYTHONPATH=. python benchmarks/results/distls/status_logs.py 100 /tmp/logs  # tree's root
"""

import contextlib
import io
import json
import os
import sys
import warnings

sys.path.insert(0, os.getcwd())
from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS


def main() -> None:
    warnings.simplefilter("ignore")
    n, outdir = int(sys.argv[1]), sys.argv[2]
    task = sys.argv[3] if len(sys.argv) > 3 else "iiwa-distance"
    os.makedirs(outdir, exist_ok=True)
    res = {}
    for i in range(n):
        problem, x0, options = TASKS[task](i)
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            r = solve_ripm(problem, x0, options, print_level=1)
        with open(f"{outdir}/{task}-{i}.log", "w") as f:
            f.write(buf.getvalue())
        res[i] = (r.status.name, r.iterations, float(r.objective), float(r.kkt_error), r.message)
    with open(f"{outdir}/{task}-status.json", "w") as f:
        json.dump(res, f, indent=0)


if __name__ == "__main__":
    main()
