"""Joint residuals ``x[joints] - target`` of the positions ``q``, velocities ``v`` and torques ``τ``
(all joints if ``joints`` is None; target zero by default: a regularisation).

In maximal coordinates positions and velocities of revolute and prismatic joints are written on
the relative poses of the joint's bodies (:mod:`mbplan.formulations.maximal_joints`), torques
(forces of prismatic joints) at the knots (interval ``k`` of the OCP is the LGVI's knot ``k+1``,
eq. 29).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from typing import Any, ClassVar

import casadi as cs
import numpy as np

from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import R
from mbplan.residuals.base import (
    Residual,
    ShootingResidual,
    SymbolicContext,
    SymbolicRows,
    vector,
)
from mbplan.transcription.terms import Term

_TORQUE = {
    "cost": (lambda tau, t, w: 0.5 * w * (tau - t) ** 2, [("t", 1), ("w", 1)]),
    "eq": (lambda tau, t: tau - t, [("t", 1)]),
    "limits": (lambda tau, lo, hi: cs.vertcat(tau - hi, lo - tau), [("lo", 1), ("hi", 1)]),
}


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _torque_function(kind: str, jit: bool) -> RiemannianFunction:
    fn, params = _TORQUE[kind]
    return RiemannianFunction(f"torque_{kind}", [("tau", R(1))], fn, params, jit=jit)


def torque_terms(ctx: Any, item: Any, kind: str, bodies: np.ndarray, per: dict) -> list[Term]:
    """Terms of a torque residual ``kind`` (:data:`_TORQUE`) at the LGVI knots ``item.knots +
    1`` of ``bodies`` with per-body parameters ``per``."""
    cost = item.role == "cost"
    mm = ctx.mm
    k, i = (a.ravel() for a in np.meshgrid(item.knots + 1, np.arange(len(bodies)), indexing="ij"))
    params = {n: v[i] for n, v in per.items()} | ({"w": item.weight} if cost else {})
    sense = "cost" if cost else item.residual.sense
    fn = _torque_function(kind, ctx.jit)
    slots = mm.joint_slot[bodies[i]]
    return [Term(item.name, sense, fn, {"tau": ("tau", k * mm.nj + slots)}, params)]


@dataclass(frozen=True, eq=False)
class _JointResidual(Residual):
    """``x[joints] - target`` of one of ``q``, ``v``, ``τ`` (module docstring)."""

    target: np.ndarray | None = None
    joints: tuple[str, ...] | None = None
    variable: ClassVar[str] = "q"

    def indices(self, robot: Any) -> np.ndarray:
        return robot.joint_indices(self.joints)

    def resolve(self, robot: Any, scene: Any) -> Residual:
        n = len(self.indices(robot))
        target = vector(self.target, n, f"{type(self).__name__}.target")
        return replace(
            self, target=target, joints=None if self.joints is None else tuple(self.joints)
        )

    def dim(self, robot: Any, scene: Any) -> int:
        return len(self.indices(robot))

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        key = (type(self), tuple(self.indices(robot).tolist()))
        return SymbolicRows(key, np.asarray(self.target, dtype=float), self._rows)

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        idx = self.indices(ctx.robot).tolist()
        source = ctx.x if self.variable == "tau" else getattr(ctx, self.variable)
        return cs.vertcat(*[source[i] for i in idx]) - ctx.theta

    def row_label(self, robot: Any, scene: Any, row: int) -> str:
        return f"joint {robot.joint_name(self.indices(robot)[row])!r}"

    def shooting(self, ctx: Any, item: Any) -> ShootingResidual:
        """A cost: Crocoddyl's state residual, weighted on the selected joints."""
        if item.role != "cost":
            return ctx.symbolic(item)
        nv, nx = ctx.model.nv, ctx.state.nx
        offset = 0 if self.variable == "q" else nv
        ref = np.zeros(nx)
        ref[offset + self.indices(ctx.ocp.robot)] = self.target
        weights = np.zeros(nx)
        weights[offset + self.indices(ctx.ocp.robot)] = 1.0
        model = ctx.crocoddyl.ResidualModelState(ctx.state, ref, ctx.nu)
        return ShootingResidual(model, np.zeros(nx), np.zeros(nx), 0.0, weights)


@dataclass(frozen=True, eq=False)
class JointPosition(_JointResidual):
    """``q[joints] - target`` (rad or m); ``2 sin((θ - θ_t)/2)`` for a continuous joint (a goal
    modulo 2π, :mod:`mbplan.robots.continuous`)."""

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        error = super()._rows(ctx)
        robot = ctx.robot
        if not robot.continuous:
            return error
        wrapped = set(robot.joint_indices(robot.continuous).tolist())
        idx = self.indices(robot).tolist()
        rows = [2 * cs.sin(error[r] / 2) if i in wrapped else error[r] for r, i in enumerate(idx)]
        return cs.vertcat(*rows)  # continuous: 2 sin(Δθ/2), zero at Δθ ≡ 0 (mod 2π)

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        b = ctx.bodies(item)
        t = np.asarray(self.target, dtype=float)
        R_t = ctx.about_axis(b, t)
        if item.role == "cost":
            w = {"w": item.weight}
            return ctx.joint_terms(item, "position_cost", b, {"R_t": R_t}, {"t": t}, w)
        per = {"R_t": R_t, "a": ctx.mm.axis_child[b]}
        return ctx.joint_terms(item, "position_eq", b, per, {"t": t})


@dataclass(frozen=True, eq=False)
class JointVelocity(_JointResidual):
    """``v[joints] - target`` (rad/s)."""

    variable: ClassVar[str] = "v"

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        b = ctx.bodies(item)
        target = np.asarray(self.target, dtype=float)
        if item.role == "cost":
            if np.any(target != 0.0):
                raise InputError("a velocity cost with a nonzero target is not expressible")
            w = {"w": item.weight / ctx.ocp.dt**2}
            return ctx.joint_terms(item, "velocity_cost", b, {}, {}, w)
        per = {"a": ctx.mm.axis_child[b], "target": target}
        return ctx.joint_terms(item, "velocity_eq", b, per, {"target": target})


@dataclass(frozen=True, eq=False)
class JointTorque(_JointResidual):
    """``τ[joints] - target`` (N m) on the intervals."""

    space: ClassVar[str] = "control"
    variable: ClassVar[str] = "tau"

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        per = {"t": np.asarray(self.target)}
        kind = "cost" if item.role == "cost" else "eq"
        return torque_terms(ctx, item, kind, ctx.bodies(item), per)

    def shooting(self, ctx: Any, item: Any) -> ShootingResidual:
        """Crocoddyl's control residual (weighted on the selected joints as a cost)."""
        idx = self.indices(ctx.ocp.robot)
        ref = np.zeros(ctx.nu)
        ref[idx] = self.target
        model = ctx.crocoddyl.ResidualModelControl(ctx.state, ref)
        weights = np.zeros(ctx.nu)
        weights[idx] = 1.0
        zeros = np.zeros(model.nr)
        return ShootingResidual(model, zeros, zeros, 0.0, weights if item.role == "cost" else None)
