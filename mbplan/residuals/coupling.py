"""Joint couplings ``q_f - m q_l - o``: a follower joint driven by a leader (a URDF ``<mimic>``).

:class:`~mbplan.OCP` adds one equality constraint per coupling of its robot
(:attr:`mbplan.robots.robot.Robot.mimic`) at every state knot. Both joints keep their own actuation:
the coupling is a kinematic constraint the planned torques satisfy, not a transmission, so the
follower's torque is planned, limited and verified like any other joint's.

In maximal coordinates a revolute joint's angle is read from its bodies' relative rotation as
``θ_mid + atan2`` about the axis, relative to the middle ``θ_mid`` of its range (zero for a
continuous joint): exact while the joint stays within π of ``θ_mid`` (always, for a revolute
range below 2π); a prismatic joint's displacement is
:func:`~mbplan.dynamics.joints.prismatic_displacement`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from typing import Any, ClassVar

import casadi as cs
import numpy as np

from mbplan.dynamics.joints import prismatic_displacement, revolute_increment
from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.residuals.base import Residual, SymbolicContext, SymbolicRows
from mbplan.robots.joints import joint_kind
from mbplan.transcription.terms import Term
from mbplan.validation import as_array


@dataclass(frozen=True, eq=False)
class JointCoupling(Residual):
    """``q[follower] - multiplier · q[leader] - offset`` (rad or m) of two revolute (or
    continuous) or two prismatic joints. Constraint only (module docstring)."""

    cost: ClassVar[bool] = False
    follower: str = ""
    leader: str = ""
    multiplier: float = 1.0
    offset: float = 0.0

    @property
    def joints(self) -> tuple[str, str]:
        """``(leader, follower)``: the joints the rows read."""
        return self.leader, self.follower

    def resolve(self, robot: Any, scene: Any) -> Residual:
        if self.follower == self.leader:
            raise InputError(f"JointCoupling: joint {self.follower!r} cannot follow itself")
        robot.joint_indices(self.joints)  # InputError naming an unknown joint
        kinds = [joint_kind(robot.model, robot.model.getJointId(j))[0] for j in self.joints]
        if kinds[0] != kinds[1]:
            raise InputError(
                f"JointCoupling: joint {self.follower!r} ({kinds[1]}) cannot follow joint "
                f"{self.leader!r} ({kinds[0]}): both must be revolute or both prismatic"
            )
        m, o = as_array((self.multiplier, self.offset), (2,), "JointCoupling (multiplier, offset)")
        return replace(self, multiplier=float(m), offset=float(o))

    def dim(self, robot: Any, scene: Any) -> int:
        return 1

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        """Parameters ``(multiplier, offset)``."""
        key = (type(self), tuple(robot.joint_indices(self.joints).tolist()))
        return SymbolicRows(key, np.array([self.multiplier, self.offset]), self._rows)

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        lead, follow = ctx.robot.joint_indices(self.joints).tolist()
        return ctx.q[follow] - ctx.theta[0] * ctx.q[lead] - ctx.theta[1]

    def row_label(self, robot: Any, scene: Any, row: int) -> str:
        return (
            f"the coupling q[{self.follower!r}] = {self.multiplier:g} q[{self.leader!r}] "
            f"+ {self.offset:g}"
        )

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        """One row per knot on the (distinct) bodies of both joints and their parents."""
        mm = ctx.mm
        lead, follow = (int(b) for b in ctx.bodies(item))
        roles = (mm.parent[lead], lead, mm.parent[follow], follow)
        bodies = sorted({int(b) for b in roles if b >= 0})
        slots = tuple(bodies.index(b) if b >= 0 else -1 for b in roles)
        jtype = mm.joint_types[lead]
        names = ("R",) if jtype == "revolute" else ("R", "p")
        bind = {f"{n}{s}": (n, item.knots * mm.nb + b) for s, b in enumerate(bodies) for n in names}
        m = float(self.multiplier)
        if jtype == "revolute":
            mid = np.zeros(2)
            for i, b in enumerate((lead, follow)):
                if not mm.continuous[b]:
                    mid[i] = 0.5 * (mm.lower_position_limit[b] + mm.upper_position_limit[b])
            R_mid = ctx.about_axis(np.array([lead, follow]), mid)
            axis = mm.axis_child[[lead, follow]]
            params = {"R_l": R_mid[0], "a_l": axis[0], "R_f": R_mid[1], "a_f": axis[1]}
            params |= {"m": m, "c": float(self.offset) + m * mid[0] - mid[1]}
        else:
            params = {"m": m, "c": float(self.offset)}
            for tag, b in (("l", lead), ("f", follow)):
                params |= {
                    f"r_p{tag}": mm.r_parent[b],
                    f"r_c{tag}": mm.r_child[b],
                    f"axis_{tag}": mm.axis_parent[b],
                }
        fn = _coupling_function(jtype, slots, len(bodies), ctx.jit)
        return [Term(item.name, "eq", fn, bind, params)]


_GEOMETRY = {
    "revolute": [("R_l", (3, 3)), ("a_l", 3), ("R_f", (3, 3)), ("a_f", 3)],
    "prismatic": [(f"{n}{t}", 3) for t in "lf" for n in ("r_p", "r_c", "axis_")],
}


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _coupling_function(jtype: str, slots: tuple[int, ...], n: int, jit: bool) -> RiemannianFunction:
    """``q_f - m q_l - c`` on ``n`` bodies; ``slots``: the body of the leader's parent, the
    leader, the follower's parent and the follower (-1: the world)."""
    prismatic = jtype == "prismatic"
    variables = [(f"R{s}", SO3) for s in range(n)]
    variables += [(f"p{s}", R(3)) for s in range(n)] if prismatic else []

    def pose(x: dict, s: int) -> tuple:
        if s < 0:
            return cs.DM.eye(3), cs.DM.zeros(3)
        return x[f"R{s}"], x.get(f"p{s}", cs.DM.zeros(3))

    def coordinate(x: dict, parent: int, child: int, tag: str) -> cs.SX:
        pose_p, pose_c = pose(x, parent), pose(x, child)
        now = (*pose_p, *pose_c)
        if prismatic:
            return prismatic_displacement(now, x[f"r_p{tag}"], x[f"r_c{tag}"], x[f"axis_{tag}"])
        middle = (cs.DM.eye(3), cs.DM.zeros(3), x[f"R_{tag}"], cs.DM.zeros(3))
        return revolute_increment(middle, now, x[f"a_{tag}"])

    def rows(**x: Any) -> cs.SX:
        parent_l, lead, parent_f, follow = slots
        ql = coordinate(x, parent_l, lead, "l")
        return coordinate(x, parent_f, follow, "f") - x["m"] * ql - x["c"]

    params = _GEOMETRY[jtype] + [("m", 1), ("c", 1)]
    return RiemannianFunction(f"{jtype}_coupling", variables, rows, params, jit=jit)
