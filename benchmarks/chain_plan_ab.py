"""Whole RIPM solves of the speed tasks with different joint elimination plans (and KKT options),
interleaved in one process: the per-iteration profile (``profile_solve``: a warm-up solve, then
a timed one) of every variant in turn, ``--rounds`` times with the order alternating; the
report is the minimum over rounds of each component (ms per iteration) with the iteration
counts (they must agree for a fair comparison).

Variants (``--variants``): ``rule`` is the tree's default (``JointEliminationPlans(problem)``
under ``kkt_method="auto"``); ``full`` the full factorization; ``<path>[<segment>]`` a plan of
:func:`~mbplan.formulations.maximal_layout.joint_elimination_plan` (``joints`` or ``wrench``,
``segment`` bodies per segment, none: one segment) always taken (``kkt_method="reduced"``);
a suffix ``+metis`` adds ``kkt_ordering="auto", kkt_pivot_threshold=1e-10``.

    python benchmarks/chain_plan_ab.py --tasks chain16 chain32 --variants rule joints8 \
        --rounds 2 --out benchmarks/results/chain-s7/plan-ab.json
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.formulations.maximal_layout import JointEliminationPlans
from mbplan.tasks.speed import TASKS

ONE_SEGMENT = 10**6
METIS = {"kkt_ordering": "auto", "kkt_pivot_threshold": 1e-10}


def configure(problem: Any, options: Any, variant: str) -> Any:
    """Set ``problem.elimination_plan`` for ``variant`` and return its options."""
    base, _, extra = variant.partition("+")
    over = dict(METIS) if extra == "metis" else {}
    if extra not in ("", "metis"):
        raise SystemExit(f"unknown variant {variant!r}")
    inner = problem.elimination_plan.problem
    if base == "rule":
        problem.elimination_plan = JointEliminationPlans(inner)
    elif base == "full":
        over["kkt_method"] = "full"
    else:
        m = re.fullmatch(r"(joints|wrench)(\d*)", base)
        if m is None:
            raise SystemExit(f"unknown variant {variant!r}")
        segment = int(m[2]) if m[2] else ONE_SEGMENT
        problem.elimination_plan = JointEliminationPlans(inner, m[1] == "wrench", segment)
        over["kkt_method"] = "reduced"
    return options.replace(**over)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="+", default=["chain16", "chain32"], choices=list(TASKS))
    ap.add_argument("--variants", nargs="+", default=["rule", "joints8"])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    results: dict[str, dict[str, list[dict]]] = {}
    for task in args.tasks:
        problem, x0, options = TASKS[task](0)
        runs: dict[str, list[dict]] = {v: [] for v in args.variants}
        for r in range(args.rounds):
            for v in args.variants if r % 2 == 0 else args.variants[::-1]:
                row = profile_solve(problem, x0, configure(problem, options, v))
                runs[v].append(row)
                keep = ("iterations", "restoration_iterations", "per_iter_ms", "assembly_ms",
                        "factorize_ms", "solve_ms", "status")  # fmt: skip
                print(task, v, json.dumps({k: row[k] for k in keep}), flush=True)
        results[task] = runs
        for v, rows in runs.items():
            best = {k: min(x[k] for x in rows) for k in rows[0] if k.endswith("_ms")}
            its = sorted({x["iterations"] for x in rows})
            parts = " ".join(
                f"{k[:-3]} {best[k]:.1f}" for k in ("assembly_ms", "factorize_ms", "solve_ms")
            )
            print(f"{task:18s} {v:14s} iters {its} per_iter {best['per_iter_ms']:.1f} {parts}")
        if args.out:
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.out).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
