"""One entry point for every planning method on an :class:`ObstacleTask`."""

from __future__ import annotations

from mbplan.errors import InputError
from mbplan.results import PlanResult
from mbplan.solvers.dispatch import options_for
from mbplan.tasks.obstacle import ObstacleTask

METHODS = ("ripm", "mlgipm", "ipopt", "ipopt-no-restoration", "fddp", "csqp")


def plan(
    task: ObstacleTask, method: str = "ripm", tol: float = 1e-6, max_iter: int = 500
) -> PlanResult:
    """Plan ``task`` with ``method``: ``ripm`` (maximal coordinates, RIPM), ``mlgipm``
    (maximal coordinates, MLG-IPM), ``ipopt``
    (generalized coordinates, IPOPT with restoration), ``ipopt-no-restoration``, ``fddp``
    (Crocoddyl BoxFDDP, obstacle as a penalty) or ``csqp`` (mim-solvers, obstacle as a hard
    constraint); the last two need the ``baselines`` extra."""
    if method in ("ripm", "mlgipm"):
        from mbplan.planning.manipulator import plan_maximal

        options = options_for(method, tol=tol, max_iter=max_iter)
        return plan_maximal(task, options, method=method)
    if method in ("ipopt", "ipopt-no-restoration"):
        from mbplan.baselines.generalized_ipopt import solve_generalized_ipopt

        return solve_generalized_ipopt(
            task, max_iter=max_iter, tol=tol, restoration=method == "ipopt"
        )
    if method in ("fddp", "csqp"):
        from mbplan.baselines.crocoddyl_solvers import solve_csqp, solve_fddp

        # Solver-native tolerances (Crocoddyl's stopping criterion, CSQP's KKT 1e-3): CSQP's KKT
        # stalls near 1e-3 where the obstacle is active, so IPOPT's 1e-6 is not passed on.
        return (solve_fddp if method == "fddp" else solve_csqp)(task, max_iter=max_iter)
    raise InputError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
