"""Solver adapters: one function per method, ``solve(ocp, q_guess, settings) -> PlanResult``.

An adapter builds its formulation's NLP from the OCP, runs its solver from the joint path
``q_guess (N+1, nq)``, and returns the joint-space trajectory with the solver's statistics;
:func:`mbplan.plan` then attaches the OCP and decides ``success`` (one meaning for all).
"""

from __future__ import annotations

import os
import re
import tempfile
from dataclasses import dataclass, field, fields
from typing import Any

import casadi as cs
import numpy as np

from mbplan.baselines.ipopt import IpoptStats, base_options
from mbplan.engine.compile_clock import CompileClock
from mbplan.engine.jit import jit_available
from mbplan.errors import InputError
from mbplan.formulations import free_body, maximal
from mbplan.formulations.casadi_nlp import callbacks
from mbplan.formulations.free_body import FreeBodyNLP
from mbplan.formulations.free_body_shooting import FreeBodyShooting
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.maximal import MaximalNLP
from mbplan.formulations.maximal_turns import FOLLOW, center_turns
from mbplan.formulations.maximal_velocity_limits import ROUNDS, tighten_velocity_limits
from mbplan.formulations.quaternion import QuaternionNLP
from mbplan.ocp.problem import OCP
from mbplan.results import PlanResult
from mbplan.robots.free_body import FreeBody
from mbplan.solvers import RIPMStatus
from mbplan.solvers.dispatch import options_for, solve_with
from mbplan.solvers.ilqr import ALOptions, ILQROptions, solve_ilqr, solve_ilqr_bounded
from mbplan.workspace import Workspace

LGVI_RIPM_OPTIONS: dict[str, Any] = {"constr_mult_init_max": 0.0}
"""The RIPM's defaults on the LGVI (maximal and free-body formulations), under
``Settings.options``: ``y₀ = 0``, no least-squares multipliers. The LGVI rows' least-squares
multipliers are forces and momenta, above ``RIPMOptions.constr_mult_init_max`` = 1 (and so
discarded) on every benchmark task, at the cost of one KKT factorization and solve per solve;
where kept (IPOPT's 10³) they cost the drone iterations."""

_ITERATION_LINE = re.compile(r"^\s*\d+(r?)\s+[-+]?\d\.\d+e[-+]\d+\s")


@dataclass(frozen=True)
class Settings:
    """What every adapter gets: tolerance, iteration limit, method-specific ``options``
    (``RIPMOptions`` or ``MLGIPMOptions`` fields for the RIPM or MLG-IPM, IPOPT option names
    for IPOPT), ``jit`` and the caller's ``workspace`` (the maximal formulation's and the
    RIPM's structures; ``None``: the solve's own)."""

    tol: float = 1e-6
    max_iter: int = 500
    options: dict[str, Any] = field(default_factory=dict)
    jit: bool | None = None
    workspace: Workspace | None = None


def solve_ripm_maximal(ocp: OCP, q_guess: np.ndarray, settings: Settings) -> PlanResult:
    """The RIPM on the maximal-coordinate LGVI (success: ``CONVERGED``)."""
    return _solve_maximal("ripm", ocp, q_guess, settings)


def solve_mlgipm_maximal(ocp: OCP, q_guess: np.ndarray, settings: Settings) -> PlanResult:
    """MLG-IPM (Santos et al.) on the maximal-coordinate LGVI (success: ``CONVERGED``);
    ``settings.options`` are ``MLGIPMOptions`` fields."""
    return _solve_maximal("mlgipm", ocp, q_guess, settings)


def maximal_start(
    ocp: OCP, q_guess: np.ndarray, jit: bool, workspace: Workspace | None = None
) -> tuple[MaximalNLP | FreeBodyNLP, np.ndarray]:
    """The LGVI NLP of ``ocp`` (the free-body formulation for a
    :class:`~mbplan.robots.free_body.FreeBody`, else the maximal one, its turn references centred
    on ``q_guess``) and its initial point from the joint path ``q_guess (N+1, nq)``; structures
    kept in ``workspace``."""
    if isinstance(ocp.robot, FreeBody):
        nlp, _ = free_body.build(ocp, jit, workspace)
    else:
        nlp, _ = maximal.build(ocp, jit, workspace)
        center_turns(nlp, q_guess)
    return nlp, nlp.initial_point(q_guess)


def _solve_maximal(solver: str, ocp: OCP, q_guess: np.ndarray, settings: Settings) -> PlanResult:
    """``solver`` (:mod:`mbplan.solvers.dispatch`) on the maximal-coordinate LGVI of ``ocp``;
    a converged plan solves again (at most ``ROUNDS`` times, all iterations counted) while a
    joint's reported angles left the references of its turn-counting limit rows
    (:mod:`~mbplan.formulations.maximal_turns`) or,
    with contacts, a reported knot velocity exceeds its limit
    (:func:`~mbplan.formulations.maximal_velocity_limits.tighten_velocity_limits`)."""
    jit = jit_available() if settings.jit is None else settings.jit
    with CompileClock() as building:
        nlp, x0 = maximal_start(ocp, q_guess, jit, settings.workspace)
    build = building.elapsed()
    defaults = LGVI_RIPM_OPTIONS if solver == "ripm" else {}
    options = options_for(solver, tol=settings.tol, max_iter=settings.max_iter, **defaults)
    options = options.replace(**settings.options)
    runs = [solve_with(solver, nlp.problem, x0, options, settings.workspace)]
    traj = nlp.trajectory(runs[-1].x)
    if not isinstance(ocp.robot, FreeBody):  # limits held where the rows see only part of them
        for _ in range(ROUNDS):
            used = sum(r.iterations for r in runs)
            if runs[-1].status is not RIPMStatus.CONVERGED or used >= options.max_iter:
                break
            turned = center_turns(nlp, traj["q"], beyond=FOLLOW)
            if not (ocp.contacts and tighten_velocity_limits(nlp, traj["v"])) and not turned:
                break
            again = options.replace(max_iter=options.max_iter - used)
            runs.append(solve_with(solver, nlp.problem, runs[-1].x, again, settings.workspace))
            traj = nlp.trajectory(runs[-1].x)
    result = runs[-1]
    h = [r.history.arrays() for r in runs]
    iterations = sum(r.iterations for r in runs)
    wall = sum(r.wall_time_s for r in runs)
    compile_s = sum(r.compile_time_s for r in runs)
    return PlanResult(
        method=solver,
        status=result.status.name,
        success=result.status is RIPMStatus.CONVERGED,
        message=result.message,
        iterations=iterations,
        solve_time_s=wall,
        total_time_s=building.wall() + wall + compile_s,
        time_per_iter_s=wall / max(iterations, 1),
        dt=ocp.dt,
        compile_time_s=building.compile_s + compile_s,
        kkt_history=np.concatenate([np.stack([a["inf_pr"], a["inf_du"]], axis=1) for a in h]),
        entered_restoration=any(bool(np.any(a["restoration"])) for a in h),
        extra={
            "objective": result.objective,
            "kkt_error": result.kkt_error,
            "n_variables": int(result.y.size),
            "build_time_s": build,
            "solves": len(runs),
        },
        formulation="maximal",
        **traj,
    )


def _restoration_iterations(log: str) -> int:
    """Number of iteration lines of IPOPT's log marked ``r`` (restoration phase)."""
    marks = (_ITERATION_LINE.match(line) for line in log.splitlines())
    return sum(1 for mark in marks if mark is not None and mark.group(1) == "r")


def solve_ipopt_generalized(
    ocp: OCP, q_guess: np.ndarray, settings: Settings, restoration: bool = True
) -> PlanResult:
    """IPOPT (exact Hessian, MUMPS) on the generalized formulation (success:
    ``Solve_Succeeded``). IPOPT also writes its log to a temporary file to count the
    restoration iterations (marked ``r``); ``restoration=False`` sets ``max_resto_iter = 0``:
    IPOPT then stops at the first restoration iteration (the "w/o restoration" column of
    Table III). A robot with loops adds the loop forces ``λ (N, nc)`` per interval,
    ``extra["loop_forces"]``."""
    clock = CompileClock().start()
    try:
        return _solve_ipopt(ocp, q_guess, settings, restoration, clock)
    finally:
        clock.stop()


def _solve_ipopt(
    ocp: OCP, q_guess: np.ndarray, settings: Settings, restoration: bool, clock: CompileClock
) -> PlanResult:
    """:func:`solve_ipopt_generalized`, timed by ``clock`` (started)."""
    options = base_options(settings.max_iter, settings.tol)
    reserved = {"output_file", "file_print_level"} & set(settings.options)
    if reserved:
        raise InputError(f"ipopt options: {sorted(reserved)} are used to detect restoration")
    nlp: GeneralizedNLP | QuaternionNLP
    if isinstance(ocp.robot, FreeBody):  # unit quaternions in R⁴, CasADi's exact derivatives
        nlp = QuaternionNLP(ocp)
        problem, derivatives = nlp.problem, {}
    else:
        nlp = GeneralizedNLP(ocp)
        g_fn, jac_fn, hess_fn = callbacks(nlp, "generalized")
        z = cs.MX.sym("z", nlp.n)
        problem = {"x": z, "f": nlp.symbolic_objective(z), "g": g_fn(z)}
        derivatives = {"jac_g": jac_fn, "hess_lag": hess_fn, "no_nlp_grad": True}
    fd, log_path = tempfile.mkstemp(prefix="ipopt_", suffix=".log")
    os.close(fd)
    options |= {"output_file": log_path, "file_print_level": 5}
    if not restoration:
        options["max_resto_iter"] = 0
    options.update(settings.options)
    try:
        solver = cs.nlpsol(
            "generalized_ipopt",
            "ipopt",
            problem,
            {
                **derivatives,
                "print_time": False,
                "record_time": True,
                "ipopt": options,
            },
        )
        build_time = clock.elapsed()
        sol = solver(
            x0=nlp.initial_guess(q_guess), lbx=nlp.lbz, ubx=nlp.ubz, lbg=nlp.lbg, ubg=nlp.ubg
        )
        stats = IpoptStats.of(solver.stats())
        with open(log_path, encoding="utf-8", errors="replace") as fh:
            resto = _restoration_iterations(fh.read())
    finally:
        os.unlink(log_path)
    z_opt = np.asarray(sol["x"]).ravel()
    loops = {}
    if isinstance(nlp, QuaternionNLP):
        traj = nlp.trajectory(z_opt)
    else:
        traj = dict(zip(("q", "v", "tau"), nlp.unpack(z_opt), strict=True))
        if nlp.nc:
            loops = {"loop_forces": nlp.loop_forces(z_opt).tolist()}
        if ocp.contacts:
            traj |= {
                "contact_forces": nlp.force_columns.forces(z_opt),
                "contact_frames": ocp.contact_frames,
            }
    message = stats.status.replace("_", " ")
    if not restoration and resto:
        message = "stopped on entering the restoration phase, which is disabled (max_resto_iter=0)"
    return PlanResult(
        method="ipopt" if restoration else "ipopt-no-restoration",
        status=stats.status,
        success=stats.status == "Solve_Succeeded",
        message=message,
        iterations=stats.iterations,
        solve_time_s=stats.solve_time,
        total_time_s=clock.wall(),
        time_per_iter_s=stats.time_per_iteration,
        dt=ocp.dt,
        compile_time_s=clock.compile_s,
        kkt_history=np.column_stack([stats.inf_pr, stats.inf_du]).reshape(-1, 2),
        entered_restoration=resto > 0,
        extra={
            "objective": float(sol["f"]),
            "restoration_iterations": resto,
            "eval_time_s": stats.eval_time,
            "build_time_s": build_time,
            "solver_time_per_iter_s": stats.solver_time_per_iteration,
            "n_variables": nlp.n,
            "n_constraints": nlp.m,
            **loops,
        },
        formulation="generalized",
        **traj,
    )


def solve_ipopt_no_restoration(ocp: OCP, q_guess: np.ndarray, settings: Settings) -> PlanResult:
    return solve_ipopt_generalized(ocp, q_guess, settings, restoration=False)


def solve_ms_ilqr(ocp: OCP, q_guess: np.ndarray, settings: Settings) -> PlanResult:
    """MS-iLQR (thesis Alg. 2) on a free body's shooting problem (success: ``CONVERGED``)."""
    return _solve_ilqr(ocp, q_guess, settings, multiple_shooting=True)


def solve_ss_ilqr(ocp: OCP, q_guess: np.ndarray, settings: Settings) -> PlanResult:
    """SS-iLQR (thesis Alg. 1) on a free body's shooting problem (success: ``CONVERGED``)."""
    return _solve_ilqr(ocp, q_guess, settings, multiple_shooting=False)


def _solve_ilqr(
    ocp: OCP, q_guess: np.ndarray, settings: Settings, multiple_shooting: bool
) -> PlanResult:
    """SS-/MS-iLQR on :class:`~mbplan.formulations.free_body_shooting.FreeBodyShooting`, with the input
    limits by the AL outer loop (thesis Alg. 3) when the OCP has any. ``settings.tol`` bounds
    the mean gradient norm, the defect norm and the bound violation; ``settings.options`` are
    :class:`~mbplan.solvers.ilqr.ILQROptions` or :class:`~mbplan.solvers.ilqr.ALOptions` fields
    (default: with line search). MS-iLQR starts from the warm start's states and their inverse
    LGVI inputs, SS-iLQR from the rollout of the hover input."""
    method = "ms-ilqr" if multiple_shooting else "ss-ilqr"
    known = {f.name for f in fields(ILQROptions)}, {f.name for f in fields(ALOptions)}
    unknown = set(settings.options) - known[0] - known[1]
    if unknown:
        raise InputError(
            f"{method} options: unknown {sorted(unknown)}; known: {sorted(known[0] | known[1])}"
        )
    tol = settings.tol
    options = ILQROptions(
        **{"line_search": True, "tol": tol, "defect_tol": tol, "max_iter": settings.max_iter}
        | {k: v for k, v in settings.options.items() if k in known[0]},
        multiple_shooting=multiple_shooting,
    )
    al = ALOptions(
        **{"constraint_tol": tol} | {k: v for k, v in settings.options.items() if k in known[1]}
    )
    jit = jit_available() if settings.jit is None else settings.jit
    with CompileClock() as building:
        problem = FreeBodyShooting(ocp, q_guess, method, jit)
    x_init, u_init = problem.x_ref, problem.u_guess
    if not multiple_shooting:  # open loop, the warm start's inputs drift off its path
        x_init, u_init = None, np.tile(ocp.robot.hover_input, (ocp.N, 1))
    with CompileClock() as solving:  # the solver's wall time includes its kernels' compilation
        if np.all(np.isinf(problem.lower)) and np.all(np.isinf(problem.upper)):
            result = solve_ilqr(problem, options, x_init=x_init, u_init=u_init)
        else:
            result = solve_ilqr_bounded(
                problem,
                problem.lower,
                problem.upper,
                options,
                al,
                x_init=x_init,
                u_init=u_init,
            )
    build = building.elapsed()
    solve_time = max(result.wall_time_s - solving.compile_s, 0.0)
    h = result.history
    return PlanResult(
        method=method,
        status=result.status.name,
        success=result.success,
        message=result.message,
        iterations=result.iterations,
        solve_time_s=solve_time,
        total_time_s=building.wall() + result.wall_time_s,
        time_per_iter_s=solve_time / max(result.iterations, 1),
        dt=ocp.dt,
        compile_time_s=building.compile_s + solving.compile_s,
        kkt_history=np.column_stack([h.defect_norm, h.grad_norm]).reshape(-1, 2),
        entered_restoration=None,
        extra={
            "objective": result.objective,
            "grad_norm": result.grad_norm,
            "defect_norm": result.defect_norm,
            "group_violation": result.group_violation,
            "build_time_s": build,
            "kkt_history_columns": ["defect_norm", "grad_norm"],
        },
        formulation="shooting",
        **problem.trajectory(result.x, result.u),
    )
