"""One entry point for every planning method on an :class:`ObstacleTask`."""

from __future__ import annotations

from mbplan.errors import InputError
from mbplan.results import PlanResult
from mbplan.solvers import RIPMOptions
from mbplan.tasks.obstacle import ObstacleTask

METHODS = ("ripm", "ipopt", "ipopt-no-restoration")


def plan(
    task: ObstacleTask, method: str = "ripm", tol: float = 1e-6, max_iter: int = 500
) -> PlanResult:
    """Plan ``task`` with ``method``: ``ripm`` (maximal coordinates, RIPM), ``ipopt``
    (generalized coordinates, IPOPT with restoration) or ``ipopt-no-restoration``."""
    if method == "ripm":
        from mbplan.planning.manipulator import plan_maximal

        return plan_maximal(task, RIPMOptions(tol=tol, max_iter=max_iter))
    if method in ("ipopt", "ipopt-no-restoration"):
        from mbplan.baselines.generalized_ipopt import solve_generalized_ipopt

        return solve_generalized_ipopt(
            task, max_iter=max_iter, tol=tol, restoration=method == "ipopt"
        )
    raise InputError(
        f"unknown method {method!r}; choose from {', '.join(METHODS)} "
        "(Crocoddyl FDDP and mim-solvers CSQP are not implemented yet)"
    )
