"""Warm starts for any :class:`~mbplan.OCP`: a joint path ``q (N+1, nq)`` with ``q_1 = q_0``.

* ``"linear"``: linear joint interpolation from ``q0`` to the goal configuration over knots
  ``1..N`` (§VIII.C);
* ``"via"``: the same if every knot keeps clear of the OCP's obstacle constraints; otherwise the
  shortest collision-free two-segment path ``q0 → q_via → q_goal`` among :data:`VIA_CANDIDATES`
  seeded random via points (falls back to linear if none is collision-free at the knots).

The goal configuration is the target of a terminal :class:`~mbplan.residuals.JointPosition`
(constraint or cost), else the inverse kinematics of a terminal frame goal
(:func:`inverse_kinematics`, which reports an unreachable goal before any solve; not for a
floating-base robot, whose base would have to be placed too), else ``q0``.
A robot with loop closures heads for ``q0`` with the joints of a terminal partial joint goal at
their targets, the loops closed around them, and every knot of its path closes the loops
(:func:`closed_path`: the actuated joints kept where possible, the passive ones continued from
the previous knot, so the path stays on one assembly branch).
A free body's warm start is the geodesic of :func:`geodesic_path`; a floating-base robot's is
Pinocchio's interpolation (the joints linear, the base along its geodesic) for both kinds.
Continuous joints interpolate in angle (to the target as given, not modulo 2π); via points and
IK starts sample them within ``± π`` of the midpoint / the IK's start.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from mbplan.errors import InfeasibleRequestError, InputError, WarmStartWarning
from mbplan.formulations.joint_space import evaluate
from mbplan.lie import SO3
from mbplan.ocp.problem import OCP
from mbplan.residuals import (
    BodyOrientation,
    BodyPosition,
    ComOutsideCylinder,
    Distance,
    FramePlacement,
    FrameTranslation,
    JointPosition,
)
from mbplan.robots.continuous import joint_ranges
from mbplan.robots.free_body import FreeBody, quaternions, rotations
from mbplan.robots.loops import CLOSE_TOLERANCE, close_loops, closure_residual, loop_jacobian
from mbplan.robots.robot import Robot

VIA_CANDIDATES = 256  # random via points tried by the "via" warm start
IK_STARTS = 32  # random restarts of the inverse kinematics
IK_TOLERANCE = 1e-8  # ‖error‖ (m, rad) at which the IK stops
COARSE_STRIDE = 4  # a loop robot's candidate paths: every 4th knot judged first


def path_clearance(ocp: OCP, path: np.ndarray) -> float:
    """Largest obstacle-constraint residual (``≤ 0``: clear, with the margins) over the knots
    ``path (K, nq)``; ``-inf`` if the OCP has no obstacle constraint, NaN if a residual is."""
    return float(path_clearances(ocp, np.asarray(path, dtype=float)[None])[0])


def path_clearances(ocp: OCP, paths: np.ndarray) -> np.ndarray:
    """:func:`path_clearance` of every path of ``paths (P, K, nq)``: each obstacle constraint
    evaluated once at all ``P K`` knots."""
    P, K = paths.shape[:2]
    knots = paths.reshape(P * K, -1)
    worst = np.full(P, -np.inf)
    for item in ocp.constraints:
        if isinstance(item.residual, (Distance, ComOutsideCylinder)):
            r = evaluate(ocp.robot, ocp.scene, item.residual, knots, np.zeros_like(knots), None)
            worst = np.maximum(worst, r.reshape(P, -1).max(axis=1))
    return worst


def inverse_kinematics(
    robot: Robot,
    goal: FramePlacement | FrameTranslation,
    q_init: np.ndarray,
    accept=None,
    seed: int = 0,
) -> np.ndarray:
    """A configuration within the joint limits that reaches ``goal`` (damped least squares from
    ``q_init``, then from :data:`IK_STARTS` seeded random configurations), closes the robot's
    loops (their residuals as further rows) and that ``accept(q)`` (e.g. collision-free), if
    given. :class:`InfeasibleRequestError` naming the frame and the best
    error if none does: the goal is outside the workspace (or blocked)."""
    model, data = robot.model, robot.model.createData()
    fid = robot.frame_id(goal.frame)
    lo, hi = joint_ranges(robot, np.asarray(q_init, float))

    def error(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The goal's (and the loops') residual and its Jacobian at ``q``."""
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[fid]
        e = M.translation - goal.translation
        J6 = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        J = M.rotation @ J6[:3]
        if isinstance(goal, FramePlacement):
            e = np.concatenate([e, pin.log3(goal.rotation.T @ M.rotation)])
            J = np.vstack([J, pin.Jlog3(goal.rotation.T @ M.rotation) @ J6[3:]])
        if robot.loops:  # the closures as further rows: a closed configuration
            e = np.concatenate([e, closure_residual(model, robot.loops, q)])
            J = np.vstack([J, loop_jacobian(model, robot.loops, q)])
        return e, J

    rng = np.random.default_rng(seed)
    best_err, rejected = np.inf, 0
    for start in range(IK_STARTS + 1):
        q = np.array(q_init, float) if start == 0 else rng.uniform(lo, hi)
        err = np.inf
        for _ in range(200):
            e, J = error(q)
            err = float(np.linalg.norm(e))
            if err < IK_TOLERANCE:
                break
            dq = -J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(len(e)), e)
            q = np.clip(q + dq, lo, hi)
        if err >= 1e-6:  # clipped steps stall where the solution lies on a limit: bounded LSQ
            q, err = _bounded_least_squares(error, q, lo, hi)
        best_err = min(best_err, err)
        if err < 1e-6:
            if accept is None or accept(q):
                return q
            rejected += 1
    detail = f"; {rejected} solutions collide with the scene" if rejected else ""
    raise InfeasibleRequestError(
        f"frame goal for {goal.frame!r} at {np.round(goal.translation, 4).tolist()} is out of "
        f"reach: best inverse-kinematics error {best_err:.3g} after {IK_STARTS + 1} starts within "
        f"the joint limits{detail} (is the goal inside the workspace?)"
    )


def _bounded_least_squares(
    error: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    q: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
) -> tuple[np.ndarray, float]:
    """``min ½‖e(q)‖²`` within ``[lo, hi]`` from ``q`` (scipy's trust-region reflective
    method): the configuration and its error norm."""
    free = hi > lo  # a joint without range keeps its value
    if not free.any():
        return q, float(np.linalg.norm(error(q)[0]))

    def full(x: np.ndarray) -> np.ndarray:
        out = q.copy()
        out[free] = x
        return out

    fit = least_squares(
        lambda x: error(full(x))[0],
        np.clip(q[free], lo[free], hi[free]),
        jac=lambda x: error(full(x))[1][:, free],
        bounds=(lo[free], hi[free]),
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
        max_nfev=200,
    )
    q = full(fit.x)
    return q, float(np.linalg.norm(error(q)[0]))


def goal_configuration(ocp: OCP) -> np.ndarray:
    """The configuration the warm start heads for (module docstring)."""
    terminal = [i for i in ocp.items if i.residual.space == "state" and ocp.N in i.knots]
    terminal.sort(key=lambda i: i.role != "constraint")
    for item in terminal:
        r = item.residual
        if isinstance(r, JointPosition) and r.joints is None:
            q = np.array(ocp.q0, dtype=float)
            q[ocp.robot.q_of_v[ocp.robot.joint_indices(None)]] = r.target
            return q
    loops = getattr(ocp.robot, "loops", ())
    for item in terminal:
        r = item.residual
        if loops and isinstance(r, JointPosition):
            idx = ocp.robot.joint_indices(r.joints)
            q = np.array(ocp.q0, dtype=float)
            q[idx] = r.target
            closed, gap = close_loops(ocp.robot.model, loops, q, fixed=idx)
            if gap <= CLOSE_TOLERANCE:
                return closed
            message = (
                f"warm start: the loops do not close with the joints of {item.name!r} at their "
                f"targets near q0 (residual {gap:.3g}); the warm start stays at q0"
            )
            warnings.warn(WarmStartWarning(message), stacklevel=2)
            return np.array(ocp.q0)
    for item in terminal:
        r = item.residual
        if isinstance(r, (FramePlacement, FrameTranslation)) and not ocp.robot.floating:
            return inverse_kinematics(
                ocp.robot, r, ocp.q0, accept=lambda q: path_clearance(ocp, q[None]) <= 0.0
            )
    return np.array(ocp.q0)


def initial_path(ocp: OCP, kind: str = "linear") -> np.ndarray:
    """The warm start ``q (N+1, nq)`` of kind ``"linear"`` or ``"via"`` (module docstring)."""
    if kind not in ("linear", "via"):
        raise InputError(f"warm_start: expected 'linear', 'via' or an array, got {kind!r}")
    if isinstance(ocp.robot, FreeBody):
        return geodesic_path(ocp)
    return _path(ocp, kind)


def closed_path(robot: Robot, path: np.ndarray) -> np.ndarray:
    """``path (K, nq)`` with every knot projected onto the robot's loop closures
    (:func:`~mbplan.robots.loops.close_loops`): the actuated joints kept, the passive ones
    started from the previous knot's (else every joint free). Knots that cannot be closed are
    left as they are (the planner's closure constraints then pull them)."""
    return _close_path(robot, path)[0]


def _close_path(robot: Robot, path: np.ndarray) -> tuple[np.ndarray, bool]:
    """:func:`closed_path` and whether every knot closes."""
    model, loops = robot.model, robot.loops
    passive = robot.joint_indices(robot.passive)
    actuated = np.setdiff1d(np.arange(robot.nq), passive)
    out = np.array(path, dtype=float)
    closed = True
    for k in range(len(out)):
        start = out[k].copy()
        if k:
            start[passive] = out[k - 1, passive]
        q, gap = close_loops(model, loops, start, fixed=actuated)
        if gap > CLOSE_TOLERANCE:
            q, gap = close_loops(model, loops, start)
        if gap <= CLOSE_TOLERANCE:
            out[k] = q
        closed &= gap <= CLOSE_TOLERANCE
    return out, closed


def _path(ocp: OCP, kind: str) -> np.ndarray:
    """:func:`initial_path` of a robot (with loops, every candidate path closed)."""
    robot = ocp.robot
    q0, q_goal = ocp.q0, goal_configuration(ocp)
    s = np.concatenate([[0.0], np.linspace(0.0, 1.0, ocp.N)])
    if robot.floating:  # the base's quaternion interpolates on the sphere; no via points
        return np.array([pin.interpolate(robot.model, q0, q_goal, t) for t in s])
    linear = q0 + s[:, None] * (q_goal - q0)
    if kind == "linear":
        return closed_path(robot, linear) if robot.loops else linear
    clear = _first_clear(ocp, linear[None])
    if clear is not None:
        return clear
    rng = np.random.default_rng(0)
    mid = 0.5 * (q0 + q_goal)
    lo, hi = joint_ranges(ocp.robot, mid)
    # within half a turn of the middle: a via farther round is a pose reached the long way
    reach = np.minimum(0.5 * (hi - lo), np.pi)
    vias = np.clip(mid + rng.uniform(-1.0, 1.0, (VIA_CANDIDATES, *mid.shape)) * reach, lo, hi)
    lengths = np.linalg.norm(vias - q0, axis=1) + np.linalg.norm(q_goal - vias, axis=1)
    first = np.minimum(2 * s, 1.0)[:, None]
    second = np.maximum(2 * s - 1.0, 0.0)[:, None]
    vias = vias[np.argsort(lengths, kind="stable")]
    start, size = 0, 1
    while start < len(vias):  # the shortest clear one, in batches of 1, 2, 4, ... candidates
        via = vias[start : start + size, None]
        clear = _first_clear(ocp, q0 + first * (via - q0) + second * (q_goal - via))
        if clear is not None:
            return clear
        start, size = start + size, 2 * size
    warnings.warn(WarmStartWarning(VIA_FALLBACK), stacklevel=2)
    return closed_path(robot, linear) if robot.loops else linear


def _first_clear(ocp: OCP, paths: np.ndarray) -> np.ndarray | None:
    """The first of ``paths (P, K, nq)`` that keeps clear of the obstacle constraints at its
    knots, or ``None``. With loops each candidate is closed (:func:`closed_path`) and must close
    at every knot; its every :data:`COARSE_STRIDE`-th knot is closed and judged first, where
    most candidates already collide."""
    robot = ocp.robot
    if not robot.loops:
        clear = np.flatnonzero(path_clearances(ocp, paths) <= 0.0)
        return paths[clear[0]].copy() if clear.size else None
    for path in paths:
        for knots in (slice(None, None, COARSE_STRIDE), slice(None)):
            closed, ok = _close_path(robot, path[knots])
            if not ok or path_clearance(ocp, closed) > 0.0:
                break
        else:
            return closed
    return None


VIA_FALLBACK = (
    f'warm start "via": none of {VIA_CANDIDATES} via points gives a collision-free path at the '
    "knots; using the linear warm start (make this an error with "
    'warnings.simplefilter("error", mbplan.errors.WarmStartWarning) or --strict-warm-start)'
)


def geodesic_path(ocp: OCP) -> np.ndarray:
    """A free body's warm start (both kinds; no via-point search): the uniform geodesic
    ``R_k = R_0 exp(t_k log(R_0ᵀ R_g))``, ``p_k = p_0 + t_k (p_g - p_0)``, ``t_k = k/N``
    (§VIII.B) to the targets of the terminal :class:`~mbplan.residuals.BodyOrientation`
    and :class:`~mbplan.residuals.BodyPosition` items (the start if there are none)."""
    start = rotations(ocp.q0[3:][None])[0]
    R_goal, p_goal = start, ocp.q0[:3]
    for item in ocp.items:
        if item.knots[-1] == ocp.N and isinstance(item.residual, BodyOrientation):
            R_goal = item.residual.rotation
        if item.knots[-1] == ocp.N and isinstance(item.residual, BodyPosition):
            p_goal = item.residual.translation
    t = np.arange(ocp.N + 1) / ocp.N
    R = start @ SO3.exp(t[:, None] * SO3.log(start.T @ R_goal))
    R[-1] = R_goal
    return np.hstack([ocp.q0[:3] + t[:, None] * (p_goal - ocp.q0[:3]), quaternions(R)])
