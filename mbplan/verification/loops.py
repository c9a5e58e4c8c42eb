"""Verification of a plan of a robot with closed loops and passive joints, independent of the
planners: the closures at the planned knots, the replay with constraint dynamics and the passive
joints' torques.

* Closure: :func:`~mbplan.robots.loops.closure_residual` (Pinocchio's forward kinematics) at
  every planned knot; the largest ``|r|`` (``closure_residual``) must be at most
  :data:`CLOSURE_TOLERANCE`.
* Dynamics (:func:`constrained_acceleration`): the tree's equations of motion with the loop
  forces ``λ`` of the imposed rows ``r(q)``,
  ``M(q) a + h(q, v) + D v = τ + J_cᵀλ``, ``J_c a = -J̇_c v - 2α J_c v - α² r`` (Baumgarte,
  ``α = ``:data:`BAUMGARTE` ``/ (N Δt)``: slow against an interval, so that the replay of an
  interval stays the physical motion from the planned velocity, whose ``J_c v_k = O(Δt |v|²)``
  is a transcription's secant velocity; ``α ~ 1/Δt`` would add an ``O(Δt)`` velocity change
  per interval, more than the ``O(Δt²)`` local error). ``J_c`` and ``J̇_c v`` come from
  Pinocchio's frame Jacobians and classical accelerations (:func:`closure_kinematics`), solved
  with ``crba``/``nle`` as one KKT system; RK4 substeps like the tree's replay
  (:mod:`mbplan.verification.multibody`).
* Deviation thresholds: as for a tree, twice the distance of the replay to one step of
  eq. (61), here with loops (:func:`euler_velocity`: the loop forces close ``q_{k+1} +
  Δt v_{k+1}``, as the generalized transcription does). An explicit-Euler step of the
  constrained dynamics instead has another error constant: exact simulations of a four-bar by
  the transcription (0.2 s, Δt = 2.5 ms) then fail with a velocity ratio of 1.24.
* Passive joints: their planned torques (and ``tau_knots``) are zero within
  :data:`~mbplan.residuals.base.TORQUE_TOLERANCE` ``· max(1, |τ|∞)`` (the largest torque of the
  plan: the solver's relative precision).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mbplan.residuals.base import TORQUE_TOLERANCE
from mbplan.robots.loops import Loop, closure_residual, loop_residual
from mbplan.robots.robot import Robot

CLOSURE_TOLERANCE = 1e-6  # m or rad: the largest closure residual at the planned knots
BAUMGARTE = 1.0  # α T (T = N Δt, the horizon) of the constraint stabilisation
EULER_ITERATIONS = 20  # Newton iterations of the reference step (quadratic: 3-5 suffice)


def baumgarte_rate(N: int, dt: float) -> float:
    """``α`` of the constraint stabilisation: :data:`BAUMGARTE` over the horizon ``N Δt``."""
    return BAUMGARTE / (N * dt)


def _hat(w: np.ndarray) -> np.ndarray:
    """``[w]×`` of ``w (..., 3)``, shape ``(..., 3, 3)``."""
    z = np.zeros(w.shape[:-1])
    x, y, s = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [np.stack([z, -s, y], -1), np.stack([s, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def _frame(model: pin.Model, data: pin.Data, joint: str, placement: np.ndarray):
    """World ``(R, p)``, velocity Jacobians ``J_p, J_ω (3, nv)`` (point, angular; world axes)
    and drift accelerations ``(p̈, ω̇)`` at ``a = 0`` of a frame on ``joint``."""
    j = model.getJointId(joint)
    M = pin.SE3(placement)
    oMf = data.oMi[j] * M
    R = oMf.rotation
    J = pin.getFrameJacobian(model, data, j, M, pin.LOCAL)
    vel, acc = M.actInv(data.v[j]), M.actInv(data.a[j])  # frame-local spatial motions
    classical = acc.linear + np.cross(vel.angular, vel.linear)
    return R, oMf.translation, R @ J[:3], R @ J[3:], R @ classical, R @ acc.angular


def closure_kinematics(
    model: pin.Model, loops: tuple[Loop, ...], q: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The imposed rows ``r(q)``, their Jacobian ``J_c (m, nv)`` and drift ``J̇_c v`` at
    ``(q, v)``. Every row is linear in the relative placement ``(R₁ᵀR₂, R₁ᵀ(p₂ - p₁))``
    (:func:`~mbplan.robots.loops.loop_residual` with frame 1 at the identity), so its
    derivatives are the rows of that placement's derivatives."""
    data = model.createData()
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.computeJointJacobians(model, data, q)
    eye, zero = np.eye(3), np.zeros(3)
    r, J, drift = [], [], []
    for loop in loops:
        R1, p1, Jp1, Jw1, a1, dw1 = _frame(model, data, loop.joint1, loop.placement1)
        R2, p2, Jp2, Jw2, a2, dw2 = _frame(model, data, loop.joint2, loop.placement2)
        d, w1 = p2 - p1, Jw1 @ v
        d_dot, w = (Jp2 - Jp1) @ v, (Jw2 - Jw1) @ v
        rel, p_rel = R1.T @ R2, R1.T @ d  # relative placement in frame 1
        Jp_rel = R1.T @ (Jp2 - Jp1 + _hat(d) @ Jw1)  # its velocity: ṗ_rel = J v
        Jw_rel = R1.T @ (Jw2 - Jw1)  # Ṙ_rel = [ω̃]× R_rel, ω̃ = J v
        u = d_dot - np.cross(w1, d)  # R₁ ṗ_rel
        u_dot = a2 - a1 - np.cross(dw1, d) - np.cross(w1, d_dot)
        w_rel = R1.T @ w
        w_rel_dot = R1.T @ (dw2 - dw1 - np.cross(w1, w))
        p_ddot = R1.T @ (u_dot - np.cross(w1, u))
        R_ddot = (_hat(w_rel_dot) + _hat(w_rel) @ _hat(w_rel)) @ rel

        def rows(Rm: np.ndarray, pm: np.ndarray, loop: Loop = loop) -> np.ndarray:
            return loop_residual(loop.kind, eye, zero, Rm, pm)[loop.rows]

        r.append(rows(rel, p_rel))
        dR = _hat(Jw_rel.T) @ rel  # (nv, 3, 3): Ṙ_rel of each unit velocity
        J.append(np.column_stack([rows(dR[i], Jp_rel[:, i]) for i in range(model.nv)]))
        drift.append(rows(R_ddot, p_ddot))
    return np.concatenate(r), np.vstack(J), np.concatenate(drift)


def _mass(model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    """The joint-space inertia ``M(q)`` (Pinocchio's ``crba`` fills its upper triangle)."""
    M = pin.crba(model, data, q)
    return np.triu(M) + np.triu(M, 1).T


def constrained_acceleration(
    robot: Robot, q: np.ndarray, v: np.ndarray, tau: np.ndarray, alpha: float
) -> np.ndarray:
    """``a`` of the loop-constrained dynamics (module docstring) with viscous damping ``D v``;
    NaN if the KKT system is singular or the state not finite."""
    model = robot.model
    data = model.createData()
    with np.errstate(all="ignore"):  # a diverging replay: NaN, reported as divergence
        h = pin.nle(model, data, q, v) + np.asarray(model.damping, dtype=float) * v
        r, J, drift = closure_kinematics(model, robot.loops, q, v)
        m = len(r)
        K = np.block([[_mass(model, data, q), -J.T], [J, np.zeros((m, m))]])
        rhs = np.concatenate([tau - h, -drift - 2.0 * alpha * (J @ v) - alpha**2 * r])
        try:
            return np.linalg.solve(K, rhs)[: model.nv]
        except np.linalg.LinAlgError:
            return np.full(model.nv, np.nan)


def rk4_step(
    robot: Robot,
    q: np.ndarray,
    v: np.ndarray,
    tau: np.ndarray,
    h: float,
    alpha: float,
    tau_end: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One RK4 step of length ``h`` of the constrained dynamics under ``τ`` (ramping linearly
    to ``tau_end`` when given)."""
    tau_end = tau if tau_end is None else tau_end

    def f(s: float, qq: np.ndarray, vv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return vv, constrained_acceleration(robot, qq, vv, tau + s * (tau_end - tau), alpha)

    k1 = f(0.0, q, v)
    k2 = f(0.5, q + 0.5 * h * k1[0], v + 0.5 * h * k1[1])
    k3 = f(0.5, q + 0.5 * h * k2[0], v + 0.5 * h * k2[1])
    k4 = f(1.0, q + h * k3[0], v + h * k3[1])
    return (
        q + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
        v + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
    )


def euler_velocity(
    robot: Robot, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float
) -> np.ndarray:
    """``v_{k+1}`` of one step of eq. (61) with loops from ``(q_k, v_k) = (q, v)`` under ``τ``:
    ``M (v_{k+1} - v)/Δt + h(q, v) + D v_{k+1} = τ + J_c(q)ᵀλ`` with ``q + Δt v + Δt v_{k+1}``
    closed (the secant convention of the generalized transcription), by Newton's method on
    ``(v_{k+1}, λ)`` from ``v`` (NaN if it does not converge)."""
    model = robot.model
    data = model.createData()
    M = _mass(model, data, q)
    D = np.diag(np.asarray(model.damping, dtype=float))
    rhs = tau - pin.nle(model, data, q, v) + M @ v / dt
    J = closure_kinematics(model, robot.loops, q, v)[1]
    nv, m = model.nv, J.shape[0]
    w, lam = np.array(v, dtype=float), np.zeros(m)
    for _ in range(EULER_ITERATIONS):
        r, J_next, _ = closure_kinematics(model, robot.loops, q + dt * (v + w), np.zeros(nv))
        F = np.concatenate([(M / dt + D) @ w - J.T @ lam - rhs, r])
        if np.max(np.abs(F)) < 1e-12 * max(1.0, float(np.max(np.abs(rhs)))):
            return w
        K = np.block([[M / dt + D, -J.T], [dt * J_next, np.zeros((m, m))]])
        try:
            step = np.linalg.solve(K, F)
        except np.linalg.LinAlgError:
            break
        w, lam = w - step[:nv], lam - step[nv:]
    return np.full(nv, np.nan)


def closure_error(robot: Robot, q: np.ndarray) -> float:
    """The largest closure residual ``|r|`` over the knots ``q (K, nq)`` (0 without loops)."""
    gaps = [np.max(np.abs(closure_residual(robot.model, robot.loops, qk)), initial=0.0) for qk in q]
    return float(max(gaps, default=0.0))


def passive_torque(robot: Robot, tau: np.ndarray, tau_knots: np.ndarray | None) -> float:
    """The largest ``|τ|`` of the passive joints in ``tau`` and ``tau_knots`` (0 without)."""
    idx = robot.joint_indices(robot.passive)
    parts = [tau] if tau_knots is None else [tau, tau_knots]
    return float(max(np.max(np.abs(t[:, idx]), initial=0.0) for t in parts))


def closure_reasons(robot: Robot, closure: float) -> list[str]:
    """The reason a plan whose knots close the loops up to ``closure`` fails (if it does)."""
    if closure <= CLOSURE_TOLERANCE:  # NaN fails
        return []
    names = ", ".join(loop.name for loop in robot.loops)
    return [
        f"the planned knots do not close the loops ({names}): closure residual {closure:.3g} "
        f"exceeds {CLOSURE_TOLERANCE:g} (m or rad)"
    ]


def passive_reasons(robot: Robot, passive: float, tau: np.ndarray) -> list[str]:
    """The reason a plan whose passive joints carry torques up to ``passive`` fails (if it
    does; module docstring)."""
    tol = TORQUE_TOLERANCE * max(1.0, float(np.max(np.abs(tau), initial=0.0)))
    if passive <= tol:
        return []
    return [
        f"the passive joints {list(robot.passive)} carry torque up to {passive:.3g} N m "
        f"(tolerance {tol:.3g}): they have no actuator"
    ]
