"""Crocoddyl's box-FDDP and mim-solvers' CSQP on the shooting formulation of an OCP (the
``baselines`` extra), ``solve(ocp, q_guess, max_iter, options) -> PlanResult``.

Tolerances are solver-native: FDDP's ``th_stop`` (:data:`FDDP_TOL`) on its expected cost
decrease, CSQP's KKT ``termination_tolerance`` (:data:`CSQP_TOL`) — CSQP's KKT residual stalls
near 1e-3 where an obstacle is active, so IPOPT's 1e-6 is not passed on. ``kkt_history[i]``:
FDDP ``(ffeas, stop)`` (dynamics gaps, stopping criterion), CSQP ``(gap_norm +
constraint_norm, KKT)``, at iterate ``i``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import crocoddyl
import mim_solvers
import numpy as np

from mbplan.formulations.crocoddyl import LIMIT_WEIGHT, OBSTACLE_WEIGHT, ShootingBuilder
from mbplan.ocp.problem import OCP
from mbplan.results import PlanResult

FDDP_TOL = 1e-9
CSQP_TOL = 1e-3


class _History(crocoddyl.CallbackAbstract):
    """Record ``(ffeas, stop)`` of Crocoddyl's solver at every iteration."""

    def __init__(self) -> None:
        crocoddyl.CallbackAbstract.__init__(self)
        self.rows: list[tuple[float, float]] = []

    def __call__(self, solver: crocoddyl.SolverAbstract) -> None:
        self.rows.append((solver.ffeas, solver.stop))


class _CsqpHistory(mim_solvers.CallbackAbstract):
    """Record ``(gap_norm + constraint_norm, KKT)`` of CSQP at every iteration."""

    def __init__(self) -> None:
        mim_solvers.CallbackAbstract.__init__(self)
        self.rows: list[tuple[float, float]] = []

    def __call__(self, solver: mim_solvers.SolverCSQP, solver_type: str = "CSQP") -> None:
        self.rows.append((solver.gap_norm + solver.constraint_norm, solver.KKT))


def _result(
    ocp, method, converged, solver, iterations, max_iter, history, solve_time, start, extra
):
    xs, us = np.array(solver.xs), np.array(solver.us)
    nq = ocp.robot.nq
    if converged:
        status, message = "converged", "converged"
    elif iterations >= max_iter:
        status, message = "max_iter", f"maximum number of iterations ({max_iter}) reached"
    else:
        status = "failed"
        message = (
            f"stopped after {iterations} iterations without converging (regularization at "
            "its maximum or no acceptable step)"
        )
    return PlanResult(
        method=method,
        status=status,
        success=bool(converged),
        message=message,
        iterations=iterations,
        solve_time_s=solve_time,
        total_time_s=time.perf_counter() - start,
        time_per_iter_s=solve_time / max(iterations, 1),
        q=xs[:, :nq],
        v=xs[:, nq:],
        tau=us,
        dt=ocp.dt,
        kkt_history=np.asarray(history, float).reshape(-1, 2),
        entered_restoration=None,
        extra={"objective": float(solver.cost), **extra},
        formulation="shooting",
    )


def _solve(solver, builder, history, q_guess, max_iter, start):
    solver.setCallbacks([history])
    xs, us = builder.warm_start(q_guess)
    build_time = time.perf_counter() - start
    tic = time.perf_counter()
    converged = solver.solve(xs, us, max_iter, False)
    return converged, build_time, time.perf_counter() - tic


def _fddp_final_row(solver: crocoddyl.SolverBoxFDDP) -> tuple[float, float]:
    """``(ffeas, stop)`` at the final iterate: what the next iteration would test."""
    try:
        solver.computeDirection(True)
    except RuntimeError:  # backward pass failed: no stopping criterion there
        return solver.ffeas, float("nan")
    solver.updateExpectedImprovement()
    solver.expectedImprovement()
    return solver.ffeas, solver.stoppingCriteria()


def solve_fddp(
    ocp: OCP, q_guess: np.ndarray, max_iter: int, options: Mapping[str, Any]
) -> PlanResult:
    """Crocoddyl's ``SolverBoxFDDP`` (constraints as penalties, torque limits as control
    bounds; :mod:`mbplan.formulations.crocoddyl`); ``options``: ``th_stop``."""
    start = time.perf_counter()
    builder = ShootingBuilder(ocp, hard=False, method="fddp")
    solver = crocoddyl.SolverBoxFDDP(builder.problem())
    solver.th_stop = float(options.get("th_stop", FDDP_TOL))
    history = _History()
    converged, build, solve_time = _solve(solver, builder, history, q_guess, max_iter, start)
    rows = [*history.rows, _fddp_final_row(solver)]
    extra = {
        "build_time_s": build,
        "obstacle_weight": OBSTACLE_WEIGHT,
        "limit_weight": LIMIT_WEIGHT,
        "kkt_history_columns": ["ffeas", "stop"],
    }
    iterations = len(history.rows)
    return _result(
        ocp,
        "fddp",
        converged,
        solver,
        iterations,
        max_iter,
        rows,
        solve_time,
        start,
        extra,
    )


def solve_csqp(
    ocp: OCP, q_guess: np.ndarray, max_iter: int, options: Mapping[str, Any]
) -> PlanResult:
    """mim-solvers' ``SolverCSQP`` (every constraint hard; ADMM QP with mim-solvers' defaults);
    ``options``: ``termination_tolerance``."""
    start = time.perf_counter()
    builder = ShootingBuilder(ocp, hard=True, method="csqp")
    solver = mim_solvers.SolverCSQP(builder.problem())
    solver.termination_tolerance = float(options.get("termination_tolerance", CSQP_TOL))
    solver.extra_iteration_for_last_kkt = True  # the KKT row of the last iterate
    history = _CsqpHistory()
    converged, build, solve_time = _solve(solver, builder, history, q_guess, max_iter, start)
    iterations = int(solver.iter)
    extra = {
        "build_time_s": build,
        "qp_iterations": int(solver.qp_iters),
        "kkt_history_columns": ["gap_norm + constraint_norm", "KKT"],
    }
    rows = history.rows[: iterations + 1]
    return _result(
        ocp,
        "csqp",
        converged,
        solver,
        iterations,
        max_iter,
        rows,
        solve_time,
        start,
        extra,
    )
