"""A/B of the reduced step's methods inside whole RIPM solves (default options): this tree
against a baseline checkout, interleaved, each round a fresh process per tree in alternating
order. Inclusive timers on ``Reduction.set_values``, ``Reduction.factorize``,
``Reduction.solve_once`` and ``ReducedKKTSystem``'s entry points, and the whole solve; per task
and timer the minimum over repeats and rounds per case, the median over cases, ms per
iteration, with calls per iteration and the iteration counts (they must agree).

    python benchmarks/reduction_methods_ab.py --baseline /work/base --tasks iiwa-com chain4 \\
        --cases 3 --repeats 3 --rounds 2 --out benchmarks/results/redk/methods-ab.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.common import median_of_min, run_in_tree

_CHILD = r"""
import json, sys, time
from collections import defaultdict
sys.path.insert(0, ".")
from mbplan.tasks.speed import TASKS
from mbplan.solvers import solve_ripm
from mbplan.solvers.reduction import Reduction
from mbplan.solvers.reduced_step import ReducedKKTSystem
tasks, cases, repeats = json.loads(sys.argv[1])
clock, calls = defaultdict(float), defaultdict(int)

def wrap(cls, name):
    fn, label = getattr(cls, name), f"{cls.__name__}.{name}"
    def timed(*a, **kw):
        t0 = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            clock[label] += time.perf_counter() - t0
            calls[label] += 1
    setattr(cls, name, timed)

for name in ("set_values", "factorize", "solve_once"):
    wrap(Reduction, name)
for name in ("set_matrices", "factorize", "solve"):
    wrap(ReducedKKTSystem, name)
out = {}
for task in tasks:
    rows = []
    for case in range(cases):
        problem, x0, opts = TASKS[task](case)
        solve_ripm(problem, x0, opts)
        best = {}
        for _ in range(repeats):
            clock.clear(); calls.clear()
            t0 = time.perf_counter()
            res = solve_ripm(problem, x0, opts)
            clock["whole solve"] = time.perf_counter() - t0
            it = max(res.iterations, 1)
            for k, v in clock.items():
                best[k] = min(best.get(k, 1e9), 1e3 * v / it)
        best["iterations"] = res.iterations
        best["calls"] = {k: v / it for k, v in calls.items()}
        rows.append(best)
    out[task] = rows
print(json.dumps(out))
"""


def summarize(runs: list[dict], task: str) -> dict:
    """Per timer: min over rounds per case, median over cases (ms per iteration)."""
    keys = [k for k in runs[0][task][0] if k not in ("iterations", "calls")]
    out = median_of_min(runs, task, keys)
    out["calls"] = runs[0][task][0]["calls"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--tasks", nargs="+", default=["iiwa-com"])
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    trees = {"base": args.baseline.resolve(), "tree": Path(__file__).resolve().parents[1]}
    runs: dict[str, list[dict]] = {k: [] for k in trees}
    for r in range(args.rounds):
        for k in list(trees) if r % 2 == 0 else list(trees)[::-1]:
            runs[k].append(run_in_tree(trees[k], _CHILD, [args.tasks, args.cases, args.repeats]))
    report = {}
    for task in args.tasks:
        report[task] = {k: summarize(v, task) for k, v in runs.items()}
        b, t = report[task]["base"], report[task]["tree"]
        print(f"{task}: iterations {b['iterations']} / {t['iterations']}")
        for k in sorted(b, key=lambda k: k if k == "whole solve" else "~" + k):
            if k in ("iterations", "calls"):
                continue
            calls = t["calls"].get(k, 1.0)
            print(
                f"  {k:32s} {b[k]:8.3f} -> {t[k]:8.3f} ms/it ({t[k] / b[k]:.2f}x, {calls:.2f}/it)"
            )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"report": report, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
