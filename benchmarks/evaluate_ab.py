"""A/B of derivative evaluation, trial values and retraction: this tree against a baseline.

Each round runs, in a fresh process per tree (baseline first, then this tree), for every task
and case: the RIPM profile (``profile_solve``: evaluate / values / retract in ms per iteration,
iteration count) and micro-timings of one ``evaluate`` (with and without the Hessian), one
``values`` and one ``retract`` at the warm start (min over ``--micro`` repeats, µs), and an
md5 digest of all their outputs at the warm start and at a retracted point with random
multipliers (equal digests: bit-identical results). Report: per task, component and tree the
minimum over rounds per case, then the median over cases.

    python benchmarks/evaluate_ab.py --baseline /tmp/base --tasks drone drone-limits iiwa-com \\
        --cases 3 --rounds 3 --out benchmarks/results/evaluate/small.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.common import median_of_min, run_in_tree

PROFILE = ("evaluate", "values", "retract")
MICRO = ("evaluate_us", "jacobian_us", "values_us", "retract_us")

_CHILD = """
import hashlib, json, sys, time
import numpy as np
sys.path.insert(0, ".")
from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.tasks.speed import TASKS
tasks, cases, micro = json.loads(sys.argv[1])

def best(fn, k):
    fn()
    times = []
    for _ in range(k):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * min(times)

def digest(problem, x0):
    rng = np.random.default_rng(0)
    y, z = rng.standard_normal(problem.n_eq), rng.random(problem.n_ineq)
    x1 = problem.retract(x0, 1e-2 * rng.standard_normal(problem.n))
    h = hashlib.md5()
    for x in (x0, x1):
        for ev in (problem.evaluate(x, 0.7, y, z), problem.evaluate(x, hessian=False)):
            for a in (ev.gradient, ev.eq, ev.ineq, np.array([ev.objective])):
                h.update(np.ascontiguousarray(a).tobytes())
            for m in (ev.eq_jacobian, ev.ineq_jacobian, ev.hessian_lower):
                if m is not None:
                    for a in (m.data, m.indices, m.indptr):
                        h.update(np.ascontiguousarray(a).tobytes())
        f, eq, ineq = problem.values(x)
        h.update(np.array([f]).tobytes() + eq.tobytes() + ineq.tobytes())
        for name in sorted(x1):
            h.update(np.ascontiguousarray(x1[name]).tobytes())
    return h.hexdigest()

out = {}
for name in tasks:
    rows = []
    for i in range(cases):
        problem, x0, options = TASKS[name](i)
        r = profile_solve(problem, x0, options)
        row = {k: r[k + "_ms"] for k in ("evaluate", "values", "retract")}
        row["iterations"] = r["iterations"]
        rng = np.random.default_rng(1)
        y, z = rng.standard_normal(problem.n_eq), rng.random(problem.n_ineq)
        dx = 1e-3 * rng.standard_normal(problem.n)
        k = micro if problem.n < 5000 else max(3, micro // 20)
        row["evaluate_us"] = best(lambda: problem.evaluate(x0, 1.0, y, z), k)
        row["jacobian_us"] = best(lambda: problem.evaluate(x0, hessian=False), k)
        row["values_us"] = best(lambda: problem.values(x0), k)
        row["retract_us"] = best(lambda: problem.retract(x0, dx), k)
        row["digest"] = digest(problem, x0)
        rows.append(row)
    out[name] = rows
print(json.dumps(out))
"""


def summarize(runs: list[dict], task: str) -> dict:
    """Per component: min over rounds per case, median over cases."""
    out = median_of_min(runs, task, (*PROFILE, *MICRO))
    cases = range(len(runs[0][task]))
    out["digests"] = sorted({r[task][c]["digest"] for r in runs for c in cases})
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", required=True, help="root of the baseline checkout")
    ap.add_argument("--tasks", nargs="+", default=["drone", "drone-limits", "iiwa-com"])
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--micro", type=int, default=200, help="repeats of each micro-timing")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    here = Path(__file__).resolve().parents[1]
    runs: dict[str, list[dict]] = {"baseline": [], "new": []}
    for _ in range(args.rounds):
        for tag, tree in (("baseline", Path(args.baseline)), ("new", here)):
            runs[tag].append(run_in_tree(tree, _CHILD, [args.tasks, args.cases, args.micro]))
    report = {}
    for task in args.tasks:
        report[task] = {tag: summarize(r, task) for tag, r in runs.items()}
        b, n = report[task]["baseline"], report[task]["new"]
        same = "bit-identical" if b["digests"] == n["digests"] else "DIFFERENT outputs"
        print(f"{task}: iterations {b['iterations']} / {n['iterations']}, {same}")
        for k in (*PROFILE, *MICRO):
            unit = "us" if k.endswith("_us") else "ms/iter"
            print(f"  {k:12s} {b[k]:9.3f} -> {n[k]:9.3f} {unit} ({n[k] / b[k]:.2f}x)")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"report": report, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
