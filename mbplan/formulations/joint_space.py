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


# process-wide cache, result-neutral: symbols of the (unmodified) robot's kinematics alone
@lru_cache(maxsize=16)
def _state_symbols(robot: Robot) -> tuple[cs.SX, list[tuple[cs.SX, cs.SX]]]:
    """A knot state ``x = (q, v)`` and the joints' :func:`symbolic_placements` at its ``q``, built
    once per robot (the slow part of a state residual's graph; every state residual's function
    takes this ``x``)."""
    x = cs.SX.sym("x", 2 * robot.nv)
    return x, symbolic_placements(robot.model, x[: robot.nv])


def _structure(robot: Robot, residual: Residual) -> tuple:
    """What a residual's rows depend on besides its :func:`_parameters`: equal structures of
    one robot share one :func:`_parametric` function."""
    if isinstance(residual, (JointPosition, JointVelocity, JointTorque)):
        return type(residual), tuple(robot.joint_indices(residual.joints).tolist())
    if isinstance(residual, _Limits):
        return type(residual), tuple(residual.indices(robot).tolist())
    if isinstance(residual, (FrameTranslation, FramePlacement)):
        return type(residual), residual.frame
    if isinstance(residual, ComOutsideCylinder):
        return (type(residual),)
    raise InputError(f"{type(residual).__name__} has no joint-space CasADi form")


def _parameters(robot: Robot, scene: Scene, residual: Residual) -> np.ndarray:
    """The residual's numbers, the second input of its :func:`_parametric` function: a joint
    residual's target, the limits ``(lower, upper)`` of the limited joints, a frame goal's
    translation (after its rotation, column-major), a cylinder's ``(x_c, y_c, r + margin)``."""
    if isinstance(residual, (JointPosition, JointVelocity, JointTorque)):
        return np.asarray(residual.target, dtype=float)
    if isinstance(residual, _Limits):
        keep = residual.indices(robot)
        lower, upper = (np.asarray(b, dtype=float)[keep] for b in (residual.lower, residual.upper))
        return np.concatenate([lower, upper])
    if isinstance(residual, FramePlacement):
        return np.concatenate([residual.rotation.ravel(order="F"), residual.translation])
    if isinstance(residual, FrameTranslation):
        return np.asarray(residual.translation, dtype=float)
    return residual.circle(scene)


# process-wide cache, result-neutral: CasADi function of the robot and residual structure
@lru_cache(maxsize=256)
def _parametric(robot: Robot, structure: tuple, n_parameters: int) -> cs.Function:
    """``r(x, θ)`` at one knot for residuals of ``structure`` (:func:`_structure`), ``θ`` their
    :func:`_parameters`: built once per robot and structure, whatever the targets."""
    kind = structure[0]
    x = _state_symbols(robot)[0] if kind.space == "state" else cs.SX.sym("x", robot.nv)
    theta = cs.SX.sym("theta", n_parameters)
    return cs.Function(kind.__name__, [x, theta], [_rows(robot, structure, x, theta)])


def _rows(robot: Robot, structure: tuple, x: cs.SX, theta: cs.SX) -> cs.SX:
    model, nv = robot.model, robot.nv
    kind = structure[0]
    q, v = x[:nv], x[nv:] if kind.space == "state" else None
    if kind in (JointPosition, JointVelocity, JointTorque):
        idx = list(structure[1])
        source = {JointPosition: q, JointVelocity: v, JointTorque: x}[kind]
        error = cs.vertcat(*[source[i] for i in idx]) - theta
        if kind is JointPosition and robot.continuous:
            wrapped = set(robot.joint_indices(robot.continuous).tolist())
            rows = [
                2 * cs.sin(error[r] / 2) if i in wrapped else error[r] for r, i in enumerate(idx)
            ]
            error = cs.vertcat(*rows)  # continuous: 2 sin(Δθ/2), zero at Δθ ≡ 0 (mod 2π)
        return error
    if issubclass(kind, _Limits):
        var = {"JointPositionLimits": q, "JointVelocityLimits": v}.get(kind.__name__, x)
        keep = list(structure[1])
        var = cs.vertcat(*[var[i] for i in keep])
        return cs.vertcat(theta[: len(keep)] - var, var - theta[len(keep) :])
    placements = _state_symbols(robot)[1]
    if kind in (FrameTranslation, FramePlacement):
        frame = model.frames[robot.frame_id(structure[1])]
        Rj, pj = placements[frame.parentJoint]
        R = cs.mtimes(Rj, cs.DM(frame.placement.rotation))
        p = pj + cs.mtimes(Rj, cs.DM(frame.placement.translation))
        if kind is FrameTranslation:
            return frame_error(R, p, theta)
        return frame_error(R, p, theta[9:], cs.reshape(theta[:9], 3, 3))
    rows = []  # ComOutsideCylinder
    for j in range(1, model.njoints):
        Rj, pj = placements[j]
        rows.append(cylinder_clearance(pj + cs.mtimes(Rj, cs.DM(model.inertias[j].lever)), theta))
    return cs.vertcat(*rows)


def _parametric_of(
    robot: Robot, scene: Scene, residual: Residual
) -> tuple[cs.Function, np.ndarray]:
    """The residual's :func:`_parametric` function and its parameter values."""
    theta = _parameters(robot, scene, residual)
    return _parametric(robot, _structure(robot, residual), theta.size), theta


# process-wide cache, result-neutral: CasADi function of the robot, scene and residual
@lru_cache(maxsize=256)
def knot_function(robot: Robot, scene: Scene, residual: Residual) -> cs.Function:
    """``r(x)`` at one knot (``x = (q, v)`` or ``τ``), an SX function (cached per residual)."""
    fn, theta = _parametric_of(robot, scene, residual)
    x = cs.SX.sym("x", fn.size1_in(0))
    return cs.Function(type(residual).__name__, [x], [fn(x, cs.DM(theta))])


# process-wide cache, result-neutral: geometry pairs of the robot, scene and object names
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
    fn, theta = _parametric_of(robot, scene, residual)
    return np.array(_mapped(fn, len(x))(x.T, theta)).T.reshape(len(x), -1)


# process-wide cache, result-neutral: a CasADi map of the function and knot count alone
@lru_cache(maxsize=256)
def _mapped(fn: cs.Function, knots: int) -> cs.Function:
    """``fn`` over ``knots`` knots (its parameters shared)."""
    return fn.map(knots)


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
