"""Manipulator planning in maximal coordinates with the RIPM (RIPM paper §VIII.C).

Warm start as in the paper: linear interpolation in joint space, then inverse dynamics in
maximal coordinates for the constraint forces and torques
(:func:`mbplan.simulation.warm_start.maximal_warm_start`).
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin

from mbplan.engine.jit import jit_available
from mbplan.multibody import MaximalModel, joint_positions, maximal_model
from mbplan.results import PlanResult
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.solvers import MLGIPMOptions, RIPMOptions, RIPMResult, RIPMStatus
from mbplan.solvers.dispatch import options_for, solve_with
from mbplan.tasks.obstacle import (
    ObstacleTask,
    joint_interpolation,
    require_eq62,
    robot_description,
    task_collision_pairs,
    validate,
)
from mbplan.transcription.manipulator import ManipulatorOCP, manipulator_problem


def task_ocp(task: ObstacleTask, mm: MaximalModel) -> ManipulatorOCP:
    """The maximal-coordinate form of an :class:`ObstacleTask` (same weights, limits, obstacles)."""
    w = task.weights
    model = mm.model
    return ManipulatorOCP(
        N=task.N,
        dt=task.dt,
        q_target=np.asarray(task.q_target)[mm.idx_q],
        w_q=w.w_q,
        w_v=w.w_v,
        w_tau=w.w_tau,
        terminal_factor=w.terminal_factor,
        torque_limit=np.asarray(task.torque_limit)[mm.idx_v],
        velocity_limit=np.asarray(task.velocity_limit)[mm.idx_v],
        position_limits=(model.lowerPositionLimit[mm.idx_q], model.upperPositionLimit[mm.idx_q]),
        cylinders=tuple((*c.center_xy, c.radius + task.margin) for c in task.cylinders),
        collision_pairs=(
            task_collision_pairs(task)
            if task.obstacle_constraint == "distance" and task.obstacles
            else None
        ),
        collision_margin=task.margin,
    )


def plan_maximal(
    task: ObstacleTask,
    options: RIPMOptions | MLGIPMOptions | None = None,
    jit: bool | None = None,
    method: str = "ripm",
) -> PlanResult:
    """Solve ``task`` on the maximal-coordinate LGVI with the RIPM (or ``method="mlgipm"``);
    return joint-space arrays too."""
    require_eq62(task, method)
    validate(task)
    t0 = time.perf_counter()
    jit = jit_available() if jit is None else jit
    mm = maximal_model(robot_description(task.robot))
    problem = manipulator_problem(mm, task_ocp(task, mm), jit)
    x0 = problem.check_point(maximal_warm_start(mm, joint_interpolation(task), task.dt, jit=jit))
    build = time.perf_counter() - t0
    result = solve_with(method, problem, x0, options or options_for(method, tol=1e-6, max_iter=500))
    return to_plan_result(mm, task, result, build, method)


def to_plan_result(
    mm: MaximalModel,
    task: ObstacleTask,
    result: RIPMResult,
    build_time_s: float,
    method: str = "ripm",
) -> PlanResult:
    """Joint-space view of a maximal solution.

    ``q_k`` from the relative rotations and ``v_k = (q_{k+1} - q_{k-1})/(2Δt)`` (with
    ``q_{N+1}`` from ``R_N F_N``): the LGVI's knot velocity ``(v_{k-½} + v_{k+½})/2`` in joint
    space, the velocity of the planned configuration path. (The velocity of the LGVI's knot
    momentum, by the discrete Legendre transform, differs from it by the LGVI's own
    ``O((Δt ω)²)`` phase error, up to 0.17 rad/s on the iiwa benchmark, and replays worse.)

    The LGVI applies each torque at a knot (eq. 29: ``τ_{k+1}`` enters step ``k``'s dynamics rows,
    the impulse ``Δt τ_k`` split evenly between the intervals beside knot ``k``), i.e. the
    trapezoidal rule of a torque sampled at the knots: ``tau_knots`` holds those samples, to be
    interpolated linearly (first-order hold), and ``tau`` their interval means. Knot 0's torque
    does not enter the LGVI, where the arm rests over the first step as in eq. (61):
    ``tau_knots[0]`` is set so that the mean over ``[t_0, t_1]`` is the torque for which eq.
    (61)'s first step reaches the planned ``v_1`` (it is the gravity torque at ``q_0`` up to the
    Coriolis torque at ``v_1``), which keeps that step an exact explicit-Euler step.
    """
    x, N, dt = result.x, task.N, task.dt
    R = np.concatenate([x["R"], (x["R"][-1] @ x["F"][-1])[None]])
    q = np.empty((N + 2, mm.nq))
    q[0] = joint_positions(mm, R[0], q_ref=task.q0)
    for k in range(1, N + 2):
        q[k] = joint_positions(mm, R[k], q_ref=q[k - 1])
    v = np.zeros((N + 1, mm.nv))
    v[1:] = (q[2:] - q[:-2]) / (2 * dt)
    tau_knots = np.array(x["tau"][:, :, 0])
    # The arm rests over the first step (x_1 = x_0, as q_1 = q_0 in eq. 61): the mean torque over
    # [t_0, t_1] is the one for which eq. (61)'s first step reaches the planned v_1.
    tau_0 = pin.rnea(mm.model, mm.model.createData(), q[0], v[0], (v[1] - v[0]) / dt)
    tau_knots[0] = 2.0 * tau_0 - tau_knots[1]
    tau = 0.5 * (tau_knots[:-1] + tau_knots[1:])
    h = result.history.arrays()
    converged = result.status is RIPMStatus.CONVERGED
    finite = all(np.all(np.isfinite(a)) for a in (q, v, tau_knots))
    return PlanResult(
        method=method,
        status=result.status.name,
        success=converged and finite,
        message=result.message,
        iterations=result.iterations,
        solve_time_s=result.wall_time_s,
        total_time_s=result.wall_time_s + build_time_s,
        time_per_iter_s=result.wall_time_s / max(result.iterations, 1),
        q=q[: N + 1],
        v=v,
        tau=tau,
        dt=dt,
        kkt_history=np.stack([h["inf_pr"], h["inf_du"]], axis=1),
        entered_restoration=bool(np.any(h["restoration"])),
        extra={"kkt_error": result.kkt_error, "n_variables": int(result.y.size)},
        R=x["R"],
        p=x["p"],
        body_names=mm.body_names,
        tau_knots=tau_knots,
    )
