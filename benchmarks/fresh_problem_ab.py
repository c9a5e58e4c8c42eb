"""What a freshly built problem costs the RIPM, this tree against a baseline checkout.

Each round runs, in a fresh process per tree (alternating which goes first), over ``--cases``
drone cases: the binding of a new problem's compiled calls (every term's ``hessian`` and
``value`` calls and their site tables, timed on the problem after its two solves, so with warm
caches; median over the cases), and two solves of each new problem, the first (fresh: as in
``mbplan bench speed``) and a repeat, with the solver's own clock split at its log lines (the
start, then each iteration). Report: per tree the median over cases of the minimum over rounds.

    python benchmarks/fresh_problem_ab.py --baseline /path/to/baseline --cases 40 --rounds 4 \\
        --out benchmarks/results/fresh-problem/drone.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.common import alternating_runs, median_of_min, write_json

SEGMENTS = 3  # the start and the first two iterations
KEYS = (
    "bind_us",
    "fresh_ms_per_iter",
    "repeat_ms_per_iter",
    "fresh_minus_repeat_ms",
    *(f"{w}_{s}_ms" for w in ("fresh", "repeat") for s in range(SEGMENTS)),
)

_CHILD = """
import json, sys, time
import numpy as np
sys.path.insert(0, ".")
from mbplan.tasks.speed import TASKS
from mbplan.solvers.ripm import solve_ripm
task, cases, segments = json.loads(sys.argv[1])
solve_ripm(*TASKS[task](0))
rows = []
for i in range(cases):
    problem, x0, options = TASKS[task](i)
    fresh, repeat = solve_ripm(problem, x0, options), solve_ripm(problem, x0, options)
    t0 = time.perf_counter()
    for kind in ("hessian", "value"):
        problem.bind_calls(kind)
    bind = time.perf_counter() - t0
    row = {"iterations": fresh.iterations, "bind_us": 1e6 * bind,
           "fresh_ms_per_iter": 1e3 * fresh.wall_time_s / fresh.iterations,
           "repeat_ms_per_iter": 1e3 * repeat.wall_time_s / repeat.iterations,
           "fresh_minus_repeat_ms": 1e3 * (fresh.wall_time_s - repeat.wall_time_s)}
    for name, r in (("fresh", fresh), ("repeat", repeat)):
        seg = np.diff(np.r_[0.0, r.history.time_s])
        for s in range(segments):
            row[f"{name}_{s}_ms"] = 1e3 * float(seg[s]) if s < len(seg) else float("nan")
    rows.append(row)
print(json.dumps({task: rows}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="root of the baseline checkout")
    ap.add_argument("--task", default="drone", help="a task of mbplan.tasks.speed")
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if not 1 <= args.cases <= 100 or args.rounds < 1:
        ap.error("--cases must be 1..100 and --rounds at least 1")
    trees = {"baseline": Path(args.baseline), "new": Path(__file__).resolve().parents[1]}
    runs = alternating_runs(trees, _CHILD, [args.task, args.cases, SEGMENTS], args.rounds)
    report = {tag: median_of_min(rs, args.task, KEYS) for tag, rs in runs.items()}
    b, n = report["baseline"], report["new"]
    if b["iterations"] != n["iterations"]:
        print("warning: the trees' iteration counts differ")
    for k in KEYS:
        print(f"{k:24s} {b[k]:9.3f} -> {n[k]:9.3f} ({n[k] / b[k]:.2f}x)")
    if args.out:
        write_json(Path(args.out), {"command": sys.argv, "report": report, "runs": runs})


if __name__ == "__main__":
    main()
