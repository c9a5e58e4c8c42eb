"""Statuses and iterations of the RIPM on the speed tasks with a given ``dual_step_cap``.

    python screen.py TASK N [START] [CAP]    # one JSON line: cases START .. START+N-1

``CAP`` defaults to the option's default; 0 is IPOPT's rule (``z`` always takes its own
step). ``screen.sh`` runs every task of this directory's tables."""

import collections
import json
import sys
import time

from mbplan.solvers.ripm import solve_ripm
from mbplan.tasks.speed import TASKS

task, n = sys.argv[1], int(sys.argv[2])
start = int(sys.argv[3]) if len(sys.argv) > 3 else 0
statuses, per = collections.Counter(), []
t0 = time.perf_counter()
for i in range(start, start + n):
    problem, x0, options = TASKS[task](i)
    if len(sys.argv) > 4:
        options = options.replace(dual_step_cap=float(sys.argv[4]))
    res = solve_ripm(problem, x0, options)
    statuses[res.status.name] += 1
    per.append((i, res.status.name, res.iterations))
its = sum(p[2] for p in per)
print(
    json.dumps(
        dict(
            task=task,
            cap=options.dual_step_cap,
            start=start,
            n=n,
            status=dict(statuses),
            iterations=its,
            mean=its / n,
            time_s=round(time.perf_counter() - t0, 1),
            cases=per,
        )
    )
)
