"""Closed-loop mechanisms: the RIPM (maximal coordinates) against IPOPT (generalized coordinates).

Per mechanism of :mod:`mbplan.tasks.mechanisms` (``fourbar``, ``delta``, ``two_arm_carry``):
case 0 is the example task, cases ``1..n-1`` its seeded randomizations, every method planning
from the same warm start (:data:`~mbplan.tasks.mechanisms.WARM_START`) with the mechanisms'
tolerance; the tables add the largest loop-closure residual at the knots (``mbplan.verify``).
A :class:`~mbplan.benchmarks.families.Suite` run by :func:`mbplan.benchmarks.families.run`.

Regenerate: ``mbplan bench loops --n 10 --seed 0 --out benchmarks/results/loops``.
"""

from __future__ import annotations

from functools import partial

from mbplan.benchmarks.families import Family, Suite
from mbplan.tasks.mechanisms import DT, MECHANISMS, TOL, WARM_START, N, mechanism_case

ABOUT = {
    "fourbar": "The planar four-bar (one point closure) turns its rocker to a goal angle.",
    "delta": "The delta robot carries its platform over a box (three point closures, capsule "
    "tool).",
    "two_arm_carry": "Two arms carry a bar welded to both grippers to a goal pose (a weld "
    "closure).",
}

SUITE = Suite(
    name="loops",
    title="Closed-loop mechanisms: RIPM (maximal) vs IPOPT (generalized)",
    families={m: Family(m, partial(mechanism_case, m), WARM_START, ABOUT[m]) for m in MECHANISMS},
    intro="Per mechanism, case 0 is the example task (`examples/tasks/`) and the other cases "
    "draw its goal (`mbplan.tasks.mechanisms`, seed {seed}); every task runs "
    f"N = {N} steps of {DT} s from rest to its goal at rest. *closure residual*: the largest "
    "loop-closure residual at the knots (`mbplan.verify`), median over the converged runs.",
    tol=TOL,
    n=10,
    extra_columns=("closure_residual",),
    family_flag="mechanisms",
    family_noun="mechanism",
)
