"""One entry point for every planning method: :func:`plan` (``mbplan.plan``).

A method is a registry entry (:data:`METHODS`): its formulation and an adapter
``solve(ocp, q_guess, settings) -> PlanResult`` (:mod:`mbplan.planning.methods`). Adding a
method is one line, e.g. ``METHODS["mlg-ipm"] = Method("maximal", solve_mlg_ipm)``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mbplan.engine.compile_clock import CompileClock
from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.formulations.free_body_shooting import check_shooting_ocp
from mbplan.formulations.joint_space import evaluate
from mbplan.ocp.problem import OCP
from mbplan.planning import methods as m
from mbplan.planning.initial_guess import initial_path
from mbplan.resources import check_plan_memory
from mbplan.results import PlanResult
from mbplan.robots.free_body import FreeBody
from mbplan.robots.loops import refuse_loops
from mbplan.validation import as_array, as_int, as_real
from mbplan.workspace import Workspace


@dataclass(frozen=True)
class Method:
    """A planning method: the formulation it solves and its adapter."""

    formulation: str
    solve: Callable[[OCP, np.ndarray, m.Settings], PlanResult]
    check: Callable[[OCP, str], None] | None = None
    """Refuses, before any solve, an OCP the method cannot plan (``check(ocp, method)``)."""


def _fixed_base(ocp: OCP, method: str) -> None:
    """:class:`InputError` if the robot of ``ocp`` has a floating base: Crocoddyl's shooting
    problems are built here for fixed-base robots (a free flyer's state needs its own)."""
    if getattr(ocp.robot, "floating", False):
        raise InputError(
            f"method {method!r} does not plan floating-base robots ({ocp.robot.name!r}): its "
            "shooting problem is built for fixed-base robots; plan with 'ripm' (maximal "
            "coordinates: the base is a free rigid body) or 'ipopt'"
        )


def _open_chain(ocp: OCP, method: str) -> None:
    """:class:`InputError` if the robot of ``ocp`` has loops (Crocoddyl's dynamics have none), a
    floating base (:func:`_fixed_base`) or the OCP has contacts (its shooting problem has none)."""
    refuse_loops(ocp.robot, method)
    _fixed_base(ocp, method)
    if ocp.contacts:
        raise InputError(
            f"method {method!r} does not plan contacts ({', '.join(ocp.contact_names)}): its "
            "shooting problem has no contact model; plan with 'ripm' or 'ipopt'"
        )


METHODS: dict[str, Method] = {
    "ripm": Method("maximal", m.solve_ripm_maximal),
    "mlgipm": Method("maximal", m.solve_mlgipm_maximal),
    "ipopt": Method("generalized", m.solve_ipopt_generalized),
    "ipopt-no-restoration": Method("generalized", m.solve_ipopt_no_restoration),
    "ms-ilqr": Method("shooting", m.solve_ms_ilqr, check_shooting_ocp),
    "ss-ilqr": Method("shooting", m.solve_ss_ilqr, check_shooting_ocp),
}


def _crocoddyl(name: str) -> Callable[[OCP, np.ndarray, m.Settings], PlanResult]:
    """The solver ``name`` of :mod:`mbplan.baselines.crocoddyl`, imported when called
    (Crocoddyl and mim-solvers are the optional ``baselines`` extra)."""

    def solve(ocp: OCP, q_guess: np.ndarray, settings: m.Settings) -> PlanResult:
        from mbplan.baselines import crocoddyl

        return getattr(crocoddyl, name)(ocp, q_guess, settings.max_iter, settings.options)

    return solve


METHODS["fddp"] = Method("shooting", _crocoddyl("solve_fddp"), _open_chain)
METHODS["csqp"] = Method("shooting", _crocoddyl("solve_csqp"), _open_chain)


def plan(
    ocp: Any,
    method: str = "ripm",
    *,
    warm_start: str | ArrayLike = "via",
    tol: float = 1e-6,
    max_iter: int = 500,
    options: Mapping[str, Any] | None = None,
    jit: bool | None = None,
    workspace: Workspace | None = None,
) -> PlanResult:
    """Plan ``ocp`` with ``method`` (:data:`METHODS`) from ``warm_start`` (``"linear"``,
    ``"via"`` or a joint path ``(N+1, nq)``, :mod:`mbplan.planning.initial_guess`).
    ``workspace``: where the maximal formulation and the RIPM keep their structures, patterns,
    analyses and reductions; pass one to the plans of one problem family to build them once
    (``None``: this plan's own; the result is the same).

    Every input is checked and the start checked against the constraints before any solve.
    ``success`` means: the solver converged, the trajectory is finite and every hard constraint
    holds at the planned knots (``result.violations``); soft goals report ``goal_errors``.
    """
    settings = check_plan_request(ocp, method, tol, max_iter, options, jit)
    settings = dataclasses.replace(settings, workspace=workspace)
    formulation = METHODS[method].formulation
    with CompileClock() as guessing:  # the start's check builds the coal pass on first use
        check_start(ocp)
        if formulation == "maximal":
            from mbplan.solvers.kkt.system import compile_kernels_in_background

            compile_kernels_in_background()  # first run: numba compiles while the C compiler runs
        q_guess = warm_start_path(ocp, warm_start)
    result = METHODS[method].solve(ocp, q_guess, settings)
    return finish(ocp, result, guessing.elapsed(), guessing.compile_s)


def warm_start_path(ocp: OCP, warm_start: str | ArrayLike) -> np.ndarray:
    """The joint path ``(N+1, nq)`` a plan starts from (:func:`plan`'s ``warm_start``)."""
    if isinstance(warm_start, str):
        return initial_path(ocp, warm_start)
    q_guess = as_array(warm_start, (ocp.N + 1, ocp.robot.nq), "warm_start")
    if isinstance(ocp.robot, FreeBody) or getattr(ocp.robot, "floating", False):
        norm = np.linalg.norm(q_guess[:, 3:7], axis=1)
        zero = np.flatnonzero(norm < 1e-9)
        if zero.size:
            raise InputError(
                f"warm_start: knot {zero[0]} has a zero quaternion (columns 3:7, x y z w)"
            )
        if not isinstance(ocp.robot, FreeBody):  # a floating base's poses: unit quaternions
            q_guess = np.array(q_guess)
            q_guess[:, 3:7] /= norm[:, None]
    return q_guess


def check_start(ocp: OCP) -> None:
    """Raise before any solve if the start violates a state inequality constraint at knot 1
    (at rest knot 1 equals knot 0: an obstacle overlapping the start, a limit violated)."""
    for item in ocp.constraints:
        r = item.residual
        if r.space != "state" or r.sense != "ineq" or 1 not in item.knots:
            continue
        value = evaluate(ocp.robot, ocp.scene, r, ocp.q0[None], ocp.v0[None], None, ocp.dt)[0]
        i = int(np.argmax(value)) if value.size else 0
        if value.size and value[i] > 1e-9:
            what = r.start_violation(ocp.robot, ocp.scene, i, float(value[i]))
            raise InfeasibleRequestError(f"the start q0 violates constraint {item.name!r}: {what}")


def check_plan_request(
    ocp: Any,
    method: str,
    tol: float = 1e-6,
    max_iter: int = 500,
    options: Mapping[str, Any] | None = None,
    jit: bool | None = None,
) -> m.Settings:
    """The :class:`~mbplan.planning.methods.Settings` of a request; :class:`InputError` for a
    non-OCP, an unknown method, a bad ``tol``/``max_iter`` or a horizon whose estimated memory
    exceeds what is available (:mod:`mbplan.resources`)."""
    if not isinstance(ocp, OCP):
        raise InputError(f"plan: expected an OCP, got {type(ocp).__name__}")
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    settings = m.Settings(
        tol=as_real(tol, "tol", positive=True),
        max_iter=as_int(max_iter, "max_iter", minimum=0, what="iteration limit"),
        options=dict(options or {}),
        jit=jit,
    )
    if METHODS[method].check is not None:
        METHODS[method].check(ocp, method)
    formulation = "maximal" if METHODS[method].formulation == "maximal" else "generalized"
    check_plan_memory(formulation, ocp.robot.nv, ocp.N)
    return settings


def finish(
    ocp: OCP, result: PlanResult, guess_time: float = 0.0, guess_compile_time: float = 0.0
) -> PlanResult:
    """Attach ``ocp``, the constraint violations and goal errors (and the loops' closure
    residual, ``extra["closure_residual"]``); set ``success`` (one meaning); add the warm start's
    time (``guess_time``, and the kernels it compiled, ``guess_compile_time``) to the plan's."""
    from mbplan.verification.contacts import contact_reasons, contact_violations
    from mbplan.verification.loops import closure_error, closure_reasons
    from mbplan.verification.report import constraint_violations, goal_errors, hard_constraints_met

    finite = all(np.all(np.isfinite(a)) for a in (result.q, result.v, result.tau))
    violations = goal = {}
    unmet: list[str] = []
    extra = {**result.extra, "warm_start_time_s": guess_time}
    if finite:
        violations = constraint_violations(ocp, result.q, result.v, result.tau, result.tau_knots)
        goal = goal_errors(ocp, result.q, result.v)
        violations |= contact_violations(ocp, result.q, result.contact_forces)
        unmet = hard_constraints_met(ocp, violations)
        unmet += contact_reasons(ocp, violations, result.contact_forces)
        if getattr(ocp.robot, "loops", ()):
            extra["closure_residual"] = closure_error(ocp.robot, result.q)
            unmet += closure_reasons(ocp.robot, extra["closure_residual"])
    message = result.message
    if not finite:
        message = f"{message}; the solution contains NaN or inf"
    elif result.success and unmet:
        message = f"{message}, but {unmet[0]}"
    return dataclasses.replace(
        result,
        success=bool(result.success and finite and not unmet),
        message=message,
        total_time_s=result.total_time_s + guess_time + guess_compile_time,
        compile_time_s=result.compile_time_s + guess_compile_time,
        violations=violations,
        goal_errors=goal,
        ocp=ocp,
        extra=extra,
    )
