"""A/B of the RIPM's per-iteration profile with ``kkt_method="reduced"``: this tree (variants
``joints``: the maximal formulation's plan without the joint-wrench blocks, ``joints+wrench``:
with them, the default for trees at most ``WRENCH_MAX_DEPTH`` deep) against a baseline
checkout (its default plan), interleaved, each round a fresh process per variant in
alternating order.

Per task and component: the minimum over rounds per case, the median over cases (ms per
iteration), with the iteration counts (they must agree). Only these side-by-side ratios mean
anything on a shared machine.

    python benchmarks/reduced_ab.py --baseline /work/base --tasks iiwa-com chain4 chain8 \\
        --cases 3 --rounds 3 --out benchmarks/results/reduced-step/ab.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.common import median_of_min, run_in_tree

KEYS = ("evaluate", "values", "retract", "assembly", "factorize", "solve", "python")

_CHILD = """
import json, sys
sys.path.insert(0, ".")
from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.tasks.speed import TASKS
tasks, cases, forces = json.loads(sys.argv[1])
if forces is not None:
    from mbplan.formulations.maximal_layout import JointEliminationPlans
out = {}
for name in tasks:
    rows = []
    for i in range(cases):
        problem, x0, opts = TASKS[name](i)
        if forces is not None:
            problem.elimination_plan = JointEliminationPlans(problem, forces)
        row = profile_solve(problem, x0, opts.replace(kkt_method="reduced"))
        rows.append({k: v for k, v in row.items() if k.endswith("_ms") or k == "iterations"})
    out[name] = rows
print(json.dumps(out))
"""


def summarize(runs: list[dict], task: str) -> dict:
    """Per component: min over rounds per case, median over cases (ms per iteration); ``sum``:
    the whole iteration."""
    out = median_of_min(runs, task, [f"{k}_ms" for k in KEYS] + ["per_iter_ms"])
    out.update({k: out.pop(f"{k}_ms") for k in KEYS})
    out["sum"] = out.pop("per_iter_ms")
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", required=True)
    ap.add_argument("--tasks", nargs="+", default=["iiwa-com"])
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    here = Path(__file__).resolve().parents[1]
    variants = {
        "base": (Path(args.baseline), None),
        "joints": (here, False),
        "joints+wrench": (here, True),
    }
    runs: dict[str, list] = {v: [] for v in variants}
    for rnd in range(args.rounds):
        order = list(variants) if rnd % 2 == 0 else list(reversed(variants))
        for v in order:
            tree, forces = variants[v]
            runs[v].append(run_in_tree(tree, _CHILD, [args.tasks, args.cases, forces]))
            print(f"round {rnd} {v} done", flush=True)
    report = {}
    for task in args.tasks:
        report[task] = {v: summarize(runs[v], task) for v in variants}
        for v in variants:
            s = report[task][v]
            parts = " ".join(f"{k} {s[k]:.2f}" for k in KEYS)
            print(f"{task:9s} {v:14s} per-iter {s['sum']:.2f} ms ({parts}) it {s['iterations']}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"report": report, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
