"""Residuals of :mod:`mbplan.ocp.residuals` in joint coordinates: the generalized formulation's
translation, also what the verifier, the start check and the warm starts evaluate.

Per knot, a residual is a CasADi function of ``x = (q, v)`` (state) or ``x = τ`` (control)
built on a symbolic forward kinematics of the chain of 1-dof joints (Pinocchio's pip wheel has no
CasADi bindings; the kinematics of revolute/prismatic chains is a product of joint placements and
``exp(θ a)``), so derivatives of every order are exact. :class:`~mbplan.ocp.residuals.Distance`
is coal's, through the one coal path of :mod:`mbplan.multibody.collision`.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as cs
import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.lie import SO3
from mbplan.multibody.collision import (
    CollisionPairs,
    chain_kinematics,
    collision_pairs,
    joint_space_contacts,
)
from mbplan.ocp import body_residuals
from mbplan.ocp.free_body import FreeBody
from mbplan.ocp.residuals import (
    ComOutsideCylinder,
    Distance,
    FramePlacement,
    FrameTranslation,
    JointPosition,
    JointTorque,
    JointVelocity,
    Residual,
    _Limits,
)
from mbplan.ocp.robot import Robot
from mbplan.ocp.scene import Scene
from mbplan.transcription.constraints import cylinder_clearance


def joint_axes(model: pin.Model) -> list[tuple[str, np.ndarray]]:
    """``(kind, unit axis in the joint frame)`` of joints ``1..njoints-1``."""
    out = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        data = joint.createData()
        joint.calc(data, np.zeros(1))
        S = np.array(data.S).ravel()
        if np.linalg.norm(S[3:]) > 0.5:
            out.append(("revolute", S[3:] / np.linalg.norm(S[3:])))
        else:
            out.append(("prismatic", S[:3] / np.linalg.norm(S[:3])))
    return out


def symbolic_placements(model: pin.Model, q: cs.SX) -> list[tuple[cs.SX, cs.SX]]:
    """World placements ``(R, p)`` of joints ``0..njoints-1`` at the symbolic ``q``."""
    out: list[tuple[cs.SX, cs.SX]] = [(cs.SX.eye(3), cs.SX.zeros(3))]
    for j, (kind, axis) in enumerate(joint_axes(model), start=1):
        Rp, pp = out[model.parents[j]]
        M = model.jointPlacements[j]
        R = cs.mtimes(Rp, cs.DM(M.rotation))
        p = pp + cs.mtimes(Rp, cs.DM(M.translation))
        qj = q[model.joints[j].idx_q]
        if kind == "revolute":
            R = cs.mtimes(R, SO3.exp(qj * cs.DM(axis)))
        else:
            p = p + cs.mtimes(R, cs.DM(axis)) * qj
        out.append((R, p))
    return out


def frame_error(R, p, p_goal, R_goal=None):
    """Frame residual of a frame pose ``(R, p)``: ``p - p_goal``, and with ``R_goal`` also
    ``log(R_goalᵀ R)`` (the one definition, used by both formulations)."""
    if R_goal is None:
        return p - p_goal
    return cs.vertcat(p - p_goal, SO3.log(cs.mtimes(R_goal.T, R)))


@lru_cache(maxsize=16)
def _state_symbols(robot: Robot) -> tuple[cs.SX, list[tuple[cs.SX, cs.SX]]]:
    """A knot state ``x = (q, v)`` and the joints' :func:`symbolic_placements` at its ``q``, built
    once per robot (the slow part of a state residual's graph; every state residual's function
    takes this ``x``)."""
    x = cs.SX.sym("x", 2 * robot.nv)
    return x, symbolic_placements(robot.model, x[: robot.nv])


def _symbolic(robot: Robot, scene: Scene, residual: Residual) -> tuple[cs.SX, cs.SX]:
    """The knot's symbol ``x`` and ``r(x)``: a state residual's ``x`` is the robot's
    :func:`_state_symbols`, the one its placements are built on."""
    x = _state_symbols(robot)[0] if residual.space == "state" else cs.SX.sym("x", robot.nv)
    return x, _rows(robot, scene, residual, x)


def _rows(robot: Robot, scene: Scene, residual: Residual, x: cs.SX) -> cs.SX:
    model, nv = robot.model, robot.nv
    q, v = x[:nv], x[nv:] if residual.space == "state" else None
    if isinstance(residual, (JointPosition, JointVelocity, JointTorque)):
        idx = robot.joint_indices(residual.joints).tolist()
        source = {JointPosition: q, JointVelocity: v, JointTorque: x}[type(residual)]
        error = cs.vertcat(*[source[i] for i in idx]) - cs.DM(residual.target)
        if isinstance(residual, JointPosition) and robot.continuous:
            wrapped = set(robot.joint_indices(robot.continuous).tolist())
            rows = [
                2 * cs.sin(error[r] / 2) if i in wrapped else error[r] for r, i in enumerate(idx)
            ]
            error = cs.vertcat(*rows)  # continuous: 2 sin(Δθ/2), zero at Δθ ≡ 0 (mod 2π)
        return error
    if isinstance(residual, _Limits):
        var = {"JointPositionLimits": q, "JointVelocityLimits": v}.get(type(residual).__name__, x)
        keep = residual.indices(robot).tolist()
        var = cs.vertcat(*[var[i] for i in keep])
        lo, hi = (cs.DM(np.asarray(b)[keep]) for b in (residual.lower, residual.upper))
        return cs.vertcat(lo - var, var - hi)
    placements = _state_symbols(robot)[1]
    if isinstance(residual, (FrameTranslation, FramePlacement)):
        frame = model.frames[robot.frame_id(residual.frame)]
        Rj, pj = placements[frame.parentJoint]
        R = cs.mtimes(Rj, cs.DM(frame.placement.rotation))
        p = pj + cs.mtimes(Rj, cs.DM(frame.placement.translation))
        R_goal = cs.DM(residual.rotation) if isinstance(residual, FramePlacement) else None
        return frame_error(R, p, cs.DM(residual.translation), R_goal)
    if isinstance(residual, ComOutsideCylinder):
        c = cs.DM(residual.circle(scene))
        rows = []
        for j in range(1, model.njoints):
            Rj, pj = placements[j]
            rows.append(cylinder_clearance(pj + cs.mtimes(Rj, cs.DM(model.inertias[j].lever)), c))
        return cs.vertcat(*rows)
    raise InputError(f"{type(residual).__name__} has no joint-space CasADi form")


@lru_cache(maxsize=256)
def knot_function(robot: Robot, scene: Scene, residual: Residual) -> cs.Function:
    """``r(x)`` at one knot (``x = (q, v)`` or ``τ``), an SX function (cached per residual)."""
    x, rows = _symbolic(robot, scene, residual)
    return cs.Function(type(residual).__name__, [x], [rows])


@lru_cache(maxsize=64)
def distance_pairs(robot: Robot, scene: Scene, objects: tuple[str, ...]) -> CollisionPairs:
    """The (moving collision geometry, scene object) pairs of a distance residual."""
    solids = [(scene[n].geometry(), scene[n].pose) for n in objects]
    return collision_pairs(robot.collision_model, solids)


def distance_values(
    robot: Robot, scene: Scene, residual: Distance, q: np.ndarray, order: int = 0
) -> tuple[np.ndarray, ...]:
    """``margin - d`` ``(K, P)`` at ``q (K, nq)``; with ``order >= 1`` also the Jacobian
    ``(K, P, nv)`` ``nᵀ J₁`` (and the kinematics and contacts for second order)."""
    pairs = distance_pairs(robot, scene, residual.objects)
    kin = chain_kinematics(robot.model, robot.model.createData(), np.atleast_2d(q))
    contacts, J = joint_space_contacts(pairs, kin)
    value = residual.margin - contacts.distance
    if order == 0:
        return (value,)
    grad = np.einsum("kpa,kpja->kpj", contacts.normal, J)
    return value, grad, kin, contacts, J


def evaluate(
    robot: Robot,
    scene: Scene,
    residual: Residual,
    q: np.ndarray | None,
    v: np.ndarray | None,
    tau: np.ndarray | None,
    dt: float | None = None,
) -> np.ndarray:
    """The residual ``(K, m)`` at ``K`` knots: ``q, v (K, nv)`` for state residuals, ``tau`` for
    control residuals (a free body's: :func:`mbplan.ocp.body_residuals.evaluate`, with ``dt``)."""
    if isinstance(robot, FreeBody):
        return body_residuals.evaluate(robot, scene, residual, q, v, tau, dt)
    if isinstance(residual, Distance):
        return distance_values(robot, scene, residual, np.asarray(q))[0]
    x = np.hstack([q, v]) if residual.space == "state" else np.asarray(tau)
    fn = knot_function(robot, scene, residual)
    return np.array(fn.map(len(x))(x.T)).T.reshape(len(x), -1)


def row_label(robot: Robot, scene: Scene, residual: Residual, row: int) -> str:
    """What row ``row`` of a residual measures (for messages)."""
    if isinstance(robot, FreeBody):
        return f"row {row} of {type(residual).__name__} on the free body {robot.name!r}"
    names = list(robot.model.names[1:])
    if isinstance(residual, Distance):
        pairs = distance_pairs(robot, scene, residual.objects)
        geometry = pairs.names[row].split("/")[0]
        obj = residual.objects[int(pairs.obstacle[row])]
        return f"geometry {geometry!r} and scene object {obj!r}"
    if isinstance(residual, ComOutsideCylinder):
        return f"the COM of the link of joint {names[row]!r} near cylinder {residual.obstacle!r}"
    if isinstance(residual, _Limits):
        keep = residual.indices(robot)
        side = "lower" if row < len(keep) else "upper"
        return f"the {side} limit of joint {names[int(keep[row % len(keep)])]!r}"
    if isinstance(residual, (JointPosition, JointVelocity, JointTorque)):
        idx = robot.joint_indices(residual.joints)
        return f"joint {names[int(idx[row])]!r}"
    return f"row {row}"
