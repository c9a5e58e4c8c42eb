"""Residuals in joint coordinates: the context of their joint-space translation
(:meth:`mbplan.residuals.Residual.joint_space`), for the generalized formulation, the verifier,
the start check and the warm starts.

Per knot, a residual's :class:`~mbplan.residuals.base.SymbolicRows` are a CasADi function of
``x = (q, v)`` (state) or ``x = τ`` (control) built on a symbolic forward kinematics of the chain
of 1-dof joints and a floating base (Pinocchio's pip wheel has no CasADi bindings; the
kinematics of revolute/prismatic chains is a product of joint placements and ``exp(θ a)``, a free
flyer's the rotation of its unit quaternion), so derivatives of every order are exact. Rows with their own derivatives (coal distances) are evaluated directly.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as cs
import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.formulations.free_body import evaluate_body
from mbplan.formulations.free_flyer import quaternion_matrix
from mbplan.lie import SO3
from mbplan.ocp.scene import Scene
from mbplan.residuals.base import Residual, SymbolicContext, SymbolicRows
from mbplan.robots.free_body import FreeBody
from mbplan.robots.joints import FREE_FLYER
from mbplan.robots.robot import Robot


def joint_axes(model: pin.Model) -> list[tuple[str, np.ndarray]]:
    """``(kind, unit axis in the joint frame)`` of joints ``1..njoints-1`` (a free flyer:
    ``("free", 0)``)."""
    out = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.shortname() == FREE_FLYER:
            out.append(("free", np.zeros(3)))
            continue
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
        if kind == "free":
            i = model.joints[j].idx_q
            p = p + cs.mtimes(R, q[i : i + 3])
            R = cs.mtimes(R, quaternion_matrix(q[i + 3 : i + 7]))
        elif kind == "revolute":
            R = cs.mtimes(R, SO3.exp(qj * cs.DM(axis)))
        else:
            p = p + cs.mtimes(R, cs.DM(axis)) * qj
        out.append((R, p))
    return out


# process-wide cache, result-neutral: symbols of the (unmodified) robot's kinematics alone
@lru_cache(maxsize=16)
def _state_symbols(robot: Robot) -> tuple[cs.SX, list[tuple[cs.SX, cs.SX]]]:
    """A knot state ``x = (q, v)`` and the joints' :func:`symbolic_placements` at its ``q``, built
    once per robot (the slow part of a state residual's graph; every state residual's function
    takes this ``x``)."""
    x = cs.SX.sym("x", robot.nq + robot.nv)
    return x, symbolic_placements(robot.model, x[: robot.nq])


def symbolic_rows(robot: Robot, scene: Scene, residual: Residual) -> SymbolicRows:
    """The residual's :class:`SymbolicRows` (an :class:`InputError` if it has none)."""
    form = residual.joint_space(robot, scene)
    if not isinstance(form, SymbolicRows):
        raise residual.inexpressible("CasADi joint coordinates")
    return form


# process-wide cache, result-neutral: CasADi function of the robot and residual structure
@lru_cache(maxsize=256)
def _parametric(robot: Robot, form: SymbolicRows, space: str, name: str) -> cs.Function:
    """``r(x, θ)`` at one knot of the rows ``form``: built once per robot and rows of one
    structure (``form.key``), whatever the parameters ``θ``."""
    x = _state_symbols(robot)[0] if space == "state" else cs.SX.sym("x", robot.nv)
    theta = cs.SX.sym("theta", form.parameters.size)
    return cs.Function(name, [x, theta], [_rows(robot, form, x, theta)])


def _rows(robot: Robot, form: SymbolicRows, x: cs.SX, theta: cs.SX) -> cs.SX:
    """The rows of ``form`` at the symbols ``x``, ``θ`` on the robot's symbolic kinematics."""
    return form.rows(SymbolicContext(robot, x, theta, lambda: _state_symbols(robot)[1]))


def _parametric_of(
    robot: Robot, scene: Scene, residual: Residual
) -> tuple[cs.Function, np.ndarray]:
    """The residual's :func:`_parametric` function and its parameter values."""
    form = symbolic_rows(robot, scene, residual)
    fn = _parametric(robot, form, residual.space, type(residual).__name__)
    return fn, form.parameters


# process-wide cache, result-neutral: CasADi function of the robot, scene and residual
@lru_cache(maxsize=256)
def knot_function(robot: Robot, scene: Scene, residual: Residual) -> cs.Function:
    """``r(x)`` at one knot (``x = (q, v)`` or ``τ``), an SX function (cached per residual)."""
    fn, theta = _parametric_of(robot, scene, residual)
    x = cs.SX.sym("x", fn.size1_in(0))
    return cs.Function(type(residual).__name__, [x], [fn(x, cs.DM(theta))])


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
    control residuals (a free body's: :func:`mbplan.formulations.free_body.evaluate_body`, with
    ``dt``)."""
    if isinstance(robot, FreeBody):
        return evaluate_body(robot, scene, residual, q, v, tau, dt)
    form = residual.joint_space(robot, scene)
    if not isinstance(form, SymbolicRows):
        return form.values(np.asarray(q))
    x = np.hstack([q, v]) if residual.space == "state" else np.asarray(tau)
    fn = _parametric(robot, form, residual.space, type(residual).__name__)
    return np.array(_mapped(fn, len(x))(x.T, form.parameters)).T.reshape(len(x), -1)


# process-wide cache, result-neutral: a CasADi map of the function and knot count alone
@lru_cache(maxsize=256)
def _mapped(fn: cs.Function, knots: int) -> cs.Function:
    """``fn`` over ``knots`` knots (its parameters shared)."""
    return fn.map(knots)


class SymbolicConfigurationRows:
    """A state residual's CasADi rows that read ``q`` alone, with their own derivatives in ``q``
    (the interface of :class:`~mbplan.residuals.distance.DistanceRows`), so that a formulation
    can evaluate them at configurations other than its knots."""

    def __init__(self, robot: Robot, scene: Scene, residual: Residual):
        fn = knot_function(robot, scene, residual)
        x = cs.SX.sym("x", fn.size1_in(0))
        if residual.space != "state" or cs.depends_on(fn(x), x[robot.nv :]):
            raise InputError(
                f"{type(residual).__name__}: rows between knots need a state residual of q alone"
            )
        q = cs.SX.sym("q", robot.nv)
        r = fn(cs.vertcat(q, cs.SX.zeros(robot.nv)))
        mu = cs.SX.sym("mu", r.numel())
        jac = cs.jacobian(r, q)
        self.size = r.numel()
        self._support = np.array(cs.DM(jac.sparsity(), 1).full(), dtype=bool)
        self._value = cs.Function("r", [q], [r])
        self._jac = cs.Function("j", [q], [cs.densify(jac)])
        self._hess = cs.Function("h", [q, mu], [cs.densify(cs.hessian(cs.dot(mu, r), q)[0])])

    def values(self, q: np.ndarray) -> np.ndarray:
        """The rows ``(K, P)`` at ``q (K, nv)``."""
        return np.array(_mapped(self._value, len(q))(q.T)).T.reshape(len(q), self.size)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """``∂r/∂q`` ``(K, P, nv)``."""
        J = np.array(_mapped(self._jac, len(q))(q.T))  # (P, K·nv), one block per knot
        return J.reshape(self.size, len(q), -1).transpose(1, 0, 2)

    def jacobian_support(self) -> np.ndarray:
        """``(P, nv)`` bool: the structural nonzeros of the Jacobian."""
        return self._support

    def hessian(self, q: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """``Σ_p μ_kp ∇²r_p`` ``(K, nv, nv)``."""
        H = np.array(_mapped(self._hess, len(q))(q.T, np.asarray(mu).T))
        return H.reshape(q.shape[1], len(q), -1).transpose(1, 0, 2)


def configuration_rows(robot: Robot, scene: Scene, residual: Residual) -> Any:
    """The residual's rows with their own derivatives in ``q``: its own (coal distances) or its
    CasADi rows as :class:`SymbolicConfigurationRows`."""
    form = residual.joint_space(robot, scene)
    return (
        SymbolicConfigurationRows(robot, scene, residual)
        if isinstance(form, SymbolicRows)
        else form
    )
