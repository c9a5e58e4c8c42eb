"""Joint limits ``(lower - x, x - upper) ≤ 0`` of the positions, velocities and torques (URDF
limits by default). Constraints only: bounds on the decision variables of the generalized
NLP, node bounds or penalties in Crocoddyl, the cosine forms of
:mod:`mbplan.formulations.maximal_joints` in maximal coordinates."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, ClassVar

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.residuals.base import (
    TORQUE_TOLERANCE,
    Residual,
    ShootingResidual,
    SymbolicContext,
    SymbolicRows,
)
from mbplan.residuals.joint import torque_terms
from mbplan.transcription.terms import Term
from mbplan.validation import as_array


def _given(value: Any, default: np.ndarray, free: np.ndarray, name: str) -> np.ndarray:
    """A given bound ``(nv,)`` (``default`` if None): finite, but for the entries without rows
    (``free``), which keep their defaults (a floating base's, a continuous joint's: ±inf)."""
    if value is None:
        return default
    if np.shape(value) != free.shape:
        raise InputError(f"{name}: expected shape {free.shape}, got {np.shape(value)}")
    finite = np.where(free, 0.0, np.asarray(value, dtype=float))
    return np.where(free, default, as_array(finite, free.shape, name))


@dataclass(frozen=True, eq=False)
class _Limits(Residual):
    """``(lower - x, x - upper) ≤ 0`` (URDF limits by default). Constraint only."""

    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    variable: ClassVar[str] = "q"
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def _defaults(self, robot: Any) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def resolve(self, robot: Any, scene: Any) -> Residual:
        lo, hi = self._defaults(robot)
        name = type(self).__name__
        free = self._unbounded(robot)
        lower = _given(self.lower, lo, free, f"{name}.lower")
        upper = _given(self.upper, hi, free, f"{name}.upper")
        if not np.all(np.isfinite(lower[~free])) or not np.all(np.isfinite(upper[~free])):
            raise InputError(f"{name}: limits must be finite (URDF without limits?)")
        if np.any((lower >= upper) & ~free):
            j = int(np.argmax((lower >= upper) & ~free))
            raise InputError(
                f"{name}: lower >= upper for joint {robot.joint_name(j)!r} "
                f"({lower[j]:g}, {upper[j]:g}; URDF without limits?)"
            )
        return replace(self, lower=np.array(lower), upper=np.array(upper))

    def _unbounded(self, robot: Any) -> np.ndarray:
        """(nv,) mask of the entries without rows (a floating base's; continuous joints'
        positions)."""
        return robot.q_of_v < 0

    def indices(self, robot: Any) -> np.ndarray:
        """Velocity indices of the limited joints: rows ``(lower - x, x - upper)[indices]``."""
        return np.flatnonzero(~self._unbounded(robot))

    def dim(self, robot: Any, scene: Any) -> int:
        return 2 * len(self.indices(robot))

    def variable_bounds(self, robot: Any) -> tuple[str, np.ndarray, np.ndarray]:
        return self.variable, self.lower, self.upper

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        """Parameters: the limits ``(lower, upper)`` of the limited joints."""
        keep = self.indices(robot)
        lower, upper = (np.asarray(b, dtype=float)[keep] for b in (self.lower, self.upper))
        key = (type(self), tuple(keep.tolist()))
        return SymbolicRows(key, np.concatenate([lower, upper]), self._rows)

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        keep = self.indices(ctx.robot).tolist()
        source = ctx.x if self.variable == "tau" else getattr(ctx, self.variable)
        var = cs.vertcat(*[source[i] for i in keep])
        return cs.vertcat(ctx.theta[: len(keep)] - var, var - ctx.theta[len(keep) :])

    def row_label(self, robot: Any, scene: Any, row: int) -> str:
        keep = self.indices(robot)
        side = "lower" if row < len(keep) else "upper"
        return f"the {side} limit of joint {robot.joint_name(keep[row % len(keep)])!r}"

    def shooting(self, ctx: Any, item: Any) -> ShootingResidual:
        """Bounds on Crocoddyl's state residual (FDDP: a penalty of the limits' weight)."""
        nv, nx = ctx.model.nv, ctx.state.nx
        lo, hi = np.full(nx, -np.inf), np.full(nx, np.inf)
        part = slice(0, nv) if self.variable == "q" else slice(nv, 2 * nv)
        lo[part], hi[part] = self.lower, self.upper
        model = ctx.crocoddyl.ResidualModelState(ctx.state, np.zeros(nx), ctx.nu)
        return ShootingResidual(model, lo, hi, ctx.limit_weight)


TURN_ROUNDING = 1e-3
"""How far below 2π a range still counts as a turn (URDFs round π: the so100's ±3.14158)."""


@dataclass(frozen=True, eq=False)
class JointPositionLimits(_Limits):
    """Position limits of every joint but the continuous ones (no limits, no rows)."""

    def _defaults(self, robot: Any) -> tuple[np.ndarray, np.ndarray]:
        """The URDF limits by velocity index (a floating base's entries unbounded)."""
        iq = robot.q_of_v
        joint = iq >= 0
        lower, upper = np.full(robot.nv, -np.inf), np.full(robot.nv, np.inf)
        lower[joint] = robot.model.lowerPositionLimit[iq[joint]]
        upper[joint] = robot.model.upperPositionLimit[iq[joint]]
        return lower, upper

    def _unbounded(self, robot: Any) -> np.ndarray:
        free = super()._unbounded(robot)
        free[robot.joint_indices(robot.continuous)] = True
        return free

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        """``cos(θ - mid) ≥ cos(half)`` per revolute joint of a range below a turn (exact); the
        angle counted in turns from a reference for a range of a turn or more; no rows for
        continuous joints.

        A rotation forgets the turns, so a range of 2π or more (less :data:`TURN_ROUNDING`; UR
        elbows' ±π, the UR5's and xarm7's ±2π, the so100's wrist roll) bounds
        ``θ = θ_ref + Δ`` with ``Δ`` the signed angle of ``R_rel`` from ``R_rel0 exp(θ_ref a)``:
        ``θ_ref`` per knot is the start's angle until a solve sets it to the warm start's and
        moves it along the iterates (:mod:`mbplan.formulations.maximal_turns`), so the rows count
        the turns the plan makes, as its reported angles (unwrapped from knot to knot) do."""
        mm = ctx.mm
        lo, hi = np.asarray(self.lower)[mm.idx_v], np.asarray(self.upper)[mm.idx_v]
        limited = np.isin(mm.idx_v, self.indices(ctx.ocp.robot))
        arc = limited & (~mm.revolute | (hi - lo < 2 * np.pi - TURN_ROUNDING))
        terms = []
        b = np.flatnonzero(arc)
        if b.size:
            half = 0.5 * (hi[b] - lo[b])
            per = {"R_mid": ctx.about_axis(b, 0.5 * (lo[b] + hi[b])), "cos_half": np.cos(half)}
            terms += ctx.joint_terms(item, "position_limits", b, per, {"lo": lo[b], "hi": hi[b]})
        b = np.flatnonzero(limited & ~arc)
        if b.size:
            start = np.asarray(ctx.ocp.q0, dtype=float)[mm.idx_q[b]]
            per = {
                "R_ref": ctx.about_axis(b, start),
                "theta_ref": start,
                "a": mm.axis_child[b],
                "lo": lo[b],
                "hi": hi[b],
            }
            winding = ctx.joint_terms(item, "position_winding", b, per, {})
            terms += [replace(t, name=f"{t.name}/turns") for t in winding]
        return terms


@dataclass(frozen=True, eq=False)
class JointVelocityLimits(_Limits):
    variable: ClassVar[str] = "v"

    def _defaults(self, robot: Any) -> tuple[np.ndarray, np.ndarray]:
        return -robot.model.velocityLimit, robot.model.velocityLimit

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        mm = ctx.mm
        lo, hi = np.asarray(self.lower)[mm.idx_v], np.asarray(self.upper)[mm.idx_v]
        if not np.allclose(lo[mm.revolute], -hi[mm.revolute]):
            raise InputError("asymmetric velocity limits of revolute joints are not expressible")
        b = mm.jointed
        lo, hi = lo[b], hi[b]
        per = {"cos_step": np.cos(np.minimum(hi * ctx.ocp.dt, np.pi))}
        return ctx.joint_terms(item, "velocity_limits", b, per, {"lo": lo, "hi": hi})


@dataclass(frozen=True, eq=False)
class JointTorqueLimits(_Limits):
    """Torque limits, checked by the verifier on the applied torques within
    :data:`~mbplan.residuals.base.TORQUE_TOLERANCE` ``· max(1, limit)``."""

    space: ClassVar[str] = "control"
    variable: ClassVar[str] = "tau"
    input_limits: ClassVar[bool] = True

    def _defaults(self, robot: Any) -> tuple[np.ndarray, np.ndarray]:
        return -robot.model.effortLimit, robot.model.effortLimit

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        mm = ctx.mm
        iv = mm.idx_v[mm.jointed]
        per = {"lo": np.asarray(self.lower)[iv], "hi": np.asarray(self.upper)[iv]}
        return torque_terms(ctx, item, "limits", mm.jointed, per)

    def shooting(self, ctx: Any, item: Any) -> ShootingResidual:
        """Crocoddyl's control residual in ``[lower, upper]`` (CSQP); FDDP imposes the limits
        as the nodes' control bounds (:meth:`variable_bounds`)."""
        model = ctx.crocoddyl.ResidualModelControl(ctx.state, ctx.nu)
        return ShootingResidual(model, self.lower, self.upper, None)

    def violation_tolerance(self, tolerance: float | None) -> float:
        return TORQUE_TOLERANCE * max(1.0, float(np.max(np.abs(self.upper))))

    def violation_reason(self, name: str, violation: float, tolerance: float) -> str:
        return f"torques exceed the limits ({name!r}) by up to {violation:.3g} N m"
