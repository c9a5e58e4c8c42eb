"""Independent check of a free body's plan (:func:`mbplan.verify` of a
:class:`~mbplan.robots.free_body.FreeBody` OCP).

Each interval is replayed from the planned knot ``(R_k, p_k, F_k, v_k)`` under the planned input
``u_k`` by the NumPy LGVI of :mod:`mbplan.simulation.free_body` (eq. 30–35, 60, Newton's method
on SO(3) for eq. 34), which shares no code with the CasADi transcriptions; the replayed knot
``k+1`` must match the planned one within :data:`DEVIATION_TOLERANCE` (rotation angle of
``R``, ``F`` in rad; ``p`` in m, ``v`` in m/s). This checks that the plan solves the discrete
dynamics both formulations impose — the quaternion integrator is the same LGVI — not the
LGVI's discretisation error. Constraints are checked by name at the planned knots, cylinders
(eq. 62, without margin) also on :data:`SUBSTEPS` points of each straight segment
``p_k → p_{k+1}`` (the LGVI's position path), and soft goals at the replayed last knot.
"""

from __future__ import annotations

import numpy as np

from mbplan.errors import InputError
from mbplan.lie import SO3
from mbplan.ocp.problem import OCP
from mbplan.results import PlanResult
from mbplan.robots.free_body import body_state, free_flyer_state
from mbplan.simulation.free_body import lgvi_step
from mbplan.verification.report import (
    Verification,
    constraint_violations,
    goal_errors,
    replay_reasons,
)

DEVIATION_TOLERANCE = 1e-5
SUBSTEPS = 20


def replay(ocp: OCP, result: PlanResult) -> tuple[dict[str, np.ndarray], np.ndarray, str | None]:
    """The replayed knots ``1..N`` (``R, p, F, v``), the per-knot deviation ``(N, 4)`` from
    the plan (``R`` angle, ``p``, ``F`` angle, ``v``) and why a step could not be replayed
    (None if all were): from there on the plan's own knots stand in, at infinite deviation."""
    body, dt = ocp.robot, ocp.dt
    x = body_state(result.q, result.v, dt)
    B, J = body.actuation, body.nonstandard_inertia
    out = {n: np.array(a[1:]) for n, a in x.items()}
    failed, why = ocp.N, None
    for k in range(ocp.N):
        wrench = B @ result.tau[k]
        state = tuple(x[n][k] for n in ("R", "p", "F", "v"))
        try:
            step = lgvi_step(state, wrench[3:], wrench[:3], J, body.mass, body.gravity, dt, k)
        except InputError as err:  # the planned input drives eq. (34) past its roots
            failed, why = k, f"the LGVI replay fails at step {k}: {err}"
            break
        for n, a in zip(("R", "p", "F", "v"), step, strict=True):
            out[n][k] = a
    angle = {
        n: np.linalg.norm(SO3.log(np.swapaxes(x[n][1:], 1, 2) @ out[n]).reshape(-1, 3), axis=1)
        for n in ("R", "F")
    }
    lin = {n: np.max(np.abs(out[n] - x[n][1:]), axis=1) for n in ("p", "v")}
    deviation = np.column_stack([angle["R"], lin["p"], angle["F"], lin["v"]])
    deviation[failed:] = np.inf
    return out, deviation, why


def clearances(ocp: OCP, result: PlanResult) -> dict[str, float]:
    """Smallest clearance (m, without margin) of the segments ``p_k → p_{k+1}`` from every
    obstacle constraint of the OCP, by name."""
    s = np.linspace(0.0, 1.0, SUBSTEPS + 1)[None, :, None]
    p = result.q[:, :3]
    points = (p[:-1, None] + s * (p[1:, None] - p[:-1, None])).reshape(-1, 3)
    return {
        i.name: i.residual.clearance(ocp.robot, ocp.scene, points, None)
        for i in ocp.constraints
        if i.residual.is_obstacle
    }


def final_state(ocp: OCP, result: PlanResult, replayed: dict) -> tuple[np.ndarray, np.ndarray]:
    """``q, v`` with the last knot replaced by its replay (for the soft goals)."""
    last = {n: a[-1:] for n, a in replayed.items()}
    q_end, v_end = free_flyer_state(last["R"], last["p"], last["F"], last["v"], ocp.dt)
    return np.vstack([result.q[:-1], q_end]), np.vstack([result.v[:-1], v_end])


def verify_free_body(ocp: OCP, result: PlanResult) -> Verification:
    """:func:`mbplan.verify` of a free body (module docstring): the joint rows report the
    replay's pose deviation (rad or m), the velocity rows that of ``F`` and ``v``."""
    replayed, deviation, unreplayable = replay(ocp, result)
    tol = DEVIATION_TOLERANCE
    dev_pose = float(np.max(deviation[:, :2]))
    dev_twist = float(np.max(deviation[:, 2:]))
    reasons = [unreplayable] if unreplayable else []
    reasons += [
        f"{name} deviation from the LGVI replay is {dev:.3g} (tolerance {tol:g})"
        for name, dev in (("pose", dev_pose), ("twist", dev_twist))
        if dev > tol
    ]
    violations = constraint_violations(ocp, result.q, result.v, result.tau)
    gaps = clearances(ocp, result)
    goals = goal_errors(ocp, *final_state(ocp, result, replayed))
    reasons += replay_reasons(ocp, violations, gaps, goals)
    limits = [i for i in ocp.constraints if i.residual.input_limits]
    return Verification(
        max_joint_deviation_rad=dev_pose,
        min_obstacle_distance_m=min(gaps.values(), default=np.inf),
        final_goal_error_rad=max(goals.values(), default=float("nan")),
        torque_limit_violation=max((violations[i.name] for i in limits), default=0.0),
        passed=not reasons,
        reasons=reasons,
        max_velocity_deviation=dev_twist,
        joint_deviation_ratio=dev_pose / tol,
        velocity_deviation_ratio=dev_twist / tol,
        violations=violations,
        goal_errors=goals,
        clearances=gaps,
    )
