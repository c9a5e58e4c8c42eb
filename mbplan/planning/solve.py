"""One entry point for every planning method on an :class:`ObstacleTask`."""

from __future__ import annotations

from mbplan.errors import InputError
from mbplan.resources import check_plan_memory
from mbplan.results import PlanResult
from mbplan.solvers import RIPMOptions
from mbplan.tasks.obstacle import ObstacleTask, robot_description
from mbplan.validation import as_int, as_real

METHODS = ("ripm", "ipopt", "ipopt-no-restoration", "fddp", "csqp")


def plan(
    task: ObstacleTask, method: str = "ripm", tol: float = 1e-6, max_iter: int = 500
) -> PlanResult:
    """Plan ``task`` with ``method``: ``ripm`` (maximal coordinates, RIPM), ``ipopt``
    (generalized coordinates, IPOPT with restoration), ``ipopt-no-restoration``, ``fddp``
    (Crocoddyl BoxFDDP, obstacle as a penalty) or ``csqp`` (mim-solvers, obstacle as a hard
    constraint); the last two need the ``baselines`` extra. Arguments and the memory the
    horizon needs are checked before anything is built."""
    check_plan_request(task, method, tol, max_iter)
    if method == "ripm":
        from mbplan.planning.manipulator import plan_maximal
        from mbplan.solvers.linear_solver import compile_kernels_in_background

        compile_kernels_in_background()  # first run: numba compiles while the C compiler runs

        return plan_maximal(task, RIPMOptions(tol=tol, max_iter=max_iter))
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
    raise AssertionError(method)  # unreachable: check_plan_request knows METHODS


def check_plan_request(task: ObstacleTask, method: str, tol: float, max_iter: int) -> None:
    """:class:`InputError` for an unknown method, a bad ``tol``/``max_iter`` or a horizon whose
    estimated memory exceeds what is available (:mod:`mbplan.resources`)."""
    if not isinstance(task, ObstacleTask):
        raise InputError(f"plan: expected an ObstacleTask, got {type(task).__name__}")
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    as_real(tol, "tol", positive=True)
    as_int(max_iter, "max_iter", minimum=0, what="iteration limit")
    bodies = robot_description(task.robot).model.nv
    check_plan_memory("maximal" if method == "ripm" else "generalized", bodies, task.N)
