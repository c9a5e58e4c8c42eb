"""Bitwise fingerprints of RIPM solves: an md5 of every iterate-dependent output (history, x, y,
z, s) with the iteration, evaluation and factorization counts, per case, to compare two trees
(``diff`` the outputs of a baseline checkout and this one).

    python benchmarks/ripm_fingerprint.py > /tmp/new.txt  # from the root of a tree
    (cd <baseline> && PYTHONPATH=. python <this tree>/benchmarks/ripm_fingerprint.py) > /tmp/base.txt
    diff /tmp/base.txt /tmp/new.txt

The cases: drone 0-7, drone-limits 0-7, iiwa-com 0, chain4, the RIPM tests' small problems
(restoration, adaptive μ, Mehrotra probing and corrector) from ``tests/test_ripm.py`` and the
arm sweep's finger_edu tasks (:mod:`mbplan.benchmarks.arm_sweep`).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))  # the tree to fingerprint: the working directory


def fingerprint(res) -> str:
    """md5 of the history, the iterate and the counts of a :class:`RIPMResult`."""
    h = hashlib.md5()
    hist = res.history
    for name in sorted(vars(hist)):
        if name == "time_s":
            continue
        h.update(name.encode())
        h.update(np.asarray(getattr(hist, name), dtype=float).tobytes())
    x = res.x
    parts = [x[k] for k in sorted(x)] if isinstance(x, dict) else [x]
    for a in [*parts, res.y, res.z, res.s]:
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    counts = (res.iterations, res.n_evaluations, res.n_trial_evaluations, res.n_factorizations)
    return (
        f"{res.status.name} it={counts[0]} ev={counts[1]} tr={counts[2]} fa={counts[3]} "
        + (h.hexdigest()[:16])
    )


def _test_cases():
    """The small problems of tests/test_ripm.py with the option sets that exercise the
    restoration phase, the adaptive μ and Mehrotra's probing and corrector."""
    sys.path.insert(0, str(Path.cwd() / "tests"))
    import test_ripm as t

    import mbplan

    assert Path(mbplan.__file__).resolve().parents[1] == Path.cwd().resolve(), mbplan.__file__
    from mbplan.solvers.examples import (
        HS071_X0,
        INFEASIBLE_X0,
        BandedControlNLP,
        hs071,
        infeasible_equality,
        infeasible_inequalities,
    )

    banded = BandedControlNLP(nx=4, nu=2, horizon=20)
    probing = {"mu_strategy": "adaptive", "mu_oracle": "probing"}
    problems = {
        "infeasible-eq": (infeasible_equality, lambda: INFEASIBLE_X0),
        "infeasible-ineq": (infeasible_inequalities, lambda: INFEASIBLE_X0),
        "hs071": (hs071, lambda: HS071_X0),
        "banded": (lambda: banded, banded.initial_guess),
        "disc": (t._outside_disc, lambda: np.array([0.0, 1e-3])),
        "wb": (t._wachter_biegler, lambda: np.array([-2.0, 1.0, 1.0])),
    }
    variants = {
        "default": {},
        "adaptive": {"mu_strategy": "adaptive"},
        "probing": probing,
        "mehrotra": {**probing, "corrector": True, "mu_max_fact": 0.0},
    }
    for pname, (make, x0) in problems.items():
        for vname, opts in variants.items():
            yield f"{pname}/{vname}", make(), x0(), opts


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--drone-cases", type=int, default=8)
    ap.add_argument("--no-large", action="store_true", help="skip iiwa-com 0 and chain4")
    args = ap.parse_args()
    from mbplan.solvers import solve_ripm
    from mbplan.tasks.speed import TASKS

    for name, problem, x0, opts in _test_cases():
        print(name, fingerprint(solve_ripm(problem, x0, **opts)), flush=True)
    tasks = [(t, i) for t in ("drone", "drone-limits") for i in range(args.drone_cases)]
    if not args.no_large:
        tasks += [("iiwa-com", 0), ("chain4", 0)]
    for task, i in tasks:
        problem, x0, options = TASKS[task](i)
        print(f"{task}/{i}", fingerprint(solve_ripm(problem, x0, options)), flush=True)
    for kind, result in _finger_edu().items():
        print(f"finger_edu/{kind}", result, flush=True)


def _finger_edu() -> dict[str, str]:
    """The arm sweep's finger_edu tasks as ``plan(ocp, "ripm", warm_start=rest, max_iter=200)``
    solves them (tests/test_sweep.py): a kept least-squares ``y₀`` and a rank-deficient frame
    goal (a singular KKT matrix)."""
    from mbplan.benchmarks.arm_sweep import sweep_robot, sweep_tasks

    from mbplan.engine.jit import jit_available
    from mbplan.formulations import maximal
    from mbplan.solvers import solve_ripm
    from mbplan.solvers.dispatch import options_for

    results = {}
    for kind, ocp in sweep_tasks(sweep_robot("finger_edu"), seed=len("finger_edu")).items():
        nlp, _ = maximal.build(ocp, jit_available())
        x0 = nlp.initial_point(np.repeat(ocp.q0[None], ocp.N + 1, axis=0))
        options = options_for("ripm", tol=1e-6, max_iter=200)
        results[kind] = fingerprint(solve_ripm(nlp.problem, x0, options))
    return results


if __name__ == "__main__":
    main()
