"""Why the joint-eliminated Newton step keeps one choice of replaced rows and dependent columns
per KKT pattern (and so depends on the process's solve history), measured on the iiwa's first
KKT matrices (the RIPM's warm start of each case).

Every case shares one memo key (plan and patterns: checked). For each case: the choice QR
pivoting makes on that case's own values (distinct choices are counted), the time of the
symbolic phase that builds a choice (:class:`Reduction`), and which choices picked on other
values take the case's values (no breakdown): every case's own choice (the smallest number of
cases any one choice takes), the first case's (what the memo keeps after a first solve), and
choices picked on reference values made from the pattern alone (seeded normal values on every
stored entry of ``A_E``, or only on the first case's nonzero entries).

    python benchmarks/reduction_picks.py --cases 30 --constraint com \\
        --out benchmarks/results/reduction-picks/iiwa-com.json
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.paper import iiwa_obstacle, iiwa_obstacle_starts
from mbplan.solvers.reduction import Reduction, _key

from mbplan.benchmarks.common import write_json
from mbplan.tasks.speed import maximal_ripm_problem

SEEDS = 3


def first_matrices(cases: int, constraint: str) -> list[tuple]:
    """``(plan, H, A_E, A_I)`` at each case's warm start (the pattern of every Newton step)."""
    out = []
    for q0 in iiwa_obstacle_starts(cases, 0, constraint)[:cases]:
        problem, x0 = maximal_ripm_problem(iiwa_obstacle(q0, N=40, constraint=constraint), "via")
        ev = problem.evaluate(x0)
        plan = problem.elimination_plan(ev.eq_jacobian)
        out.append((plan, ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian))
    return out


def choice(red: Reduction) -> str:
    return hashlib.md5(b"".join(red.dep_key)).hexdigest()[:12]


def takes(red: Reduction, matrices: list[tuple]) -> int:
    """How many of the cases' matrices the choice ``red`` reduces without a breakdown."""
    return sum(bool(red.fresh().set_values(h, ae, ai)) for _, h, ae, ai in matrices)


def reference(ae, seed: int, nonzero_only: bool):
    ref = ae.copy()
    values = np.random.default_rng(seed).standard_normal(len(ae.data))
    ref.data = np.where(ae.data != 0, values, 0.0) if nonzero_only else values
    return ref


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--constraint", default="com")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    matrices = first_matrices(args.cases, args.constraint)
    keys = {_key(plan, h, ae, ai, "amd", 0.0) for plan, h, ae, ai in matrices}
    assert len(keys) == 1, "the cases do not share one KKT pattern and plan"
    reductions, build_s = [], []
    for plan, h, ae, ai in matrices:
        t = time.perf_counter()
        reductions.append(Reduction(plan, h, ae, ai, "amd", 0.0))
        build_s.append(time.perf_counter() - t)
    picks = [choice(red) for red in reductions]
    plan, h, ae, ai = matrices[0]
    first = reductions[0]
    references = {
        f"{kind}_seed{seed}": takes(
            Reduction(plan, h, reference(ae, seed, kind == "nonzero"), ai, "amd", 0.0), matrices
        )
        for kind in ("all", "nonzero")
        for seed in range(SEEDS)
    }
    data = {
        "command": "python benchmarks/reduction_picks.py " + " ".join(sys.argv[1:]),
        "cases": args.cases,
        "constraint": args.constraint,
        "distinct_own_choices": len(set(picks)),
        "symbolic_phase_s_median": float(np.median(build_s)),
        "first_case_choice_takes": takes(first, matrices),
        "fewest_cases_any_own_choice_takes": min(takes(red, matrices) for red in reductions),
        "reference_choice_takes": references,
        "other_cases_with_the_first_cases_nonzeros_of_A_E": sum(
            np.array_equal(m[2].data != 0, ae.data != 0) for m in matrices[1:]
        ),
    }
    print(data)
    write_json(args.out, data)


if __name__ == "__main__":
    main()
