"""Frame residuals: the translation ``p_f - p_g`` or the pose error ``(p_f - p_g, log(R_gᵀ R_f))``
on SO(3)×R³ of a frame on a moving link (world frame), or its height above a level. Joint space writes them on the symbolic
forward kinematics, maximal coordinates on the pose ``(R_b R_jf, p_b + R_b c)`` of the frame's
body ``(R_b, p_b)``."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from typing import Any, ClassVar

import casadi as cs
import numpy as np
import pinocchio as pin

from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.residuals.base import Residual, SymbolicContext, SymbolicRows
from mbplan.transcription.terms import Term
from mbplan.validation import as_array, as_rotation


def frame_error(R, p, p_goal, R_goal=None):
    """Frame residual of a frame pose ``(R, p)``: ``p - p_goal``, and with ``R_goal`` also
    ``log(R_goalᵀ R)`` (the one definition, used by every formulation)."""
    if R_goal is None:
        return p - p_goal
    return cs.vertcat(p - p_goal, SO3.log(cs.mtimes(R_goal.T, R)))


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _frame_function(kind: str, cost: bool, jit: bool) -> RiemannianFunction:
    """Frame translation or placement error of the frame at ``(R_b R_jf, p_b + R_b c)`` on body
    ``(R_b, p_b)``; as a cost ``½ w ‖r‖²``."""
    goal = [("R_g", (3, 3)), ("p_g", 3)] if kind == "placement" else [("p_g", 3)]

    def fn(Rb, pb, R_jf, c, p_g, R_g=None, w=None):
        Rf, pf = cs.mtimes(Rb, R_jf), pb + cs.mtimes(Rb, c)
        r = p_g[2] - pf[2] if kind == "height" else frame_error(Rf, pf, p_g, R_g)
        return 0.5 * w * cs.sumsqr(r) if cost else r

    params = [("R_jf", (3, 3)), ("c", 3), *goal] + ([("w", 1)] if cost else [])
    name = f"frame_{kind}_{'cost' if cost else 'eq'}"
    return RiemannianFunction(name, [("Rb", SO3), ("pb", R(3))], fn, params, jit=jit)


def _moving_frame(robot: Any, frame: str) -> int:
    if not isinstance(frame, str):
        raise InputError(f"frame: expected a frame name, got {frame!r}")
    fid = robot.frame_id(frame)
    if robot.model.frames[fid].parentJoint == 0:
        raise InputError(f"frame {frame!r} is fixed to the base: its pose cannot change")
    return fid


@dataclass(frozen=True, eq=False)
class _FrameResidual(Residual):
    """A residual of the pose of ``frame``; ``kind`` names its :func:`_frame_function`."""

    frame: str = ""

    kind: ClassVar[str] = "translation"

    def goal(self) -> dict[str, np.ndarray]:
        """The goal's parameters ``p_g`` (and ``R_g``)."""
        raise NotImplementedError

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        """Parameters: the goal's rotation (column-major, a placement's) and translation."""
        goal = self.goal()
        theta = [goal["R_g"].ravel(order="F")] if "R_g" in goal else []
        theta.append(np.asarray(goal["p_g"], dtype=float))
        return SymbolicRows((type(self), self.frame), np.concatenate(theta), self._rows)

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        robot, theta = ctx.robot, ctx.theta
        frame = robot.model.frames[robot.frame_id(self.frame)]
        Rj, pj = ctx.placements()[frame.parentJoint]
        Rf = cs.mtimes(Rj, cs.DM(frame.placement.rotation))
        pf = pj + cs.mtimes(Rj, cs.DM(frame.placement.translation))
        if self.kind == "height":
            return theta[2] - pf[2]
        if self.kind == "translation":
            return frame_error(Rf, pf, theta)
        return frame_error(Rf, pf, theta[9:], cs.reshape(theta[:9], 3, 3))

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        robot, cost = ctx.ocp.robot, item.role == "cost"
        frame = robot.model.frames[robot.frame_id(self.frame)]
        b = ctx.body_of_joint[int(frame.parentJoint)]
        params = {
            "R_jf": frame.placement.rotation,
            "c": frame.placement.translation - ctx.mm.com_in_joint[b],
            "p_g": np.asarray(self.goal()["p_g"]),
        } | {k: v for k, v in self.goal().items() if k == "R_g"}
        if cost:
            params["w"] = item.weight
        sites = item.knots * ctx.mm.nb + b
        fn = _frame_function(self.kind, cost, ctx.jit)
        sense = "cost" if cost else self.sense
        return [Term(item.name, sense, fn, {"Rb": ("R", sites), "pb": ("p", sites)}, params)]


@dataclass(frozen=True, eq=False)
class FrameTranslation(_FrameResidual):
    """``p_frame(q) - translation`` (m, world frame)."""

    translation: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        _moving_frame(robot, self.frame)
        t = as_array(self.translation, (3,), f"FrameTranslation({self.frame!r}).translation")
        return replace(self, translation=t)

    def dim(self, robot: Any, scene: Any) -> int:
        return 3

    def goal(self) -> dict[str, np.ndarray]:
        return {"p_g": np.asarray(self.translation, dtype=float)}


@dataclass(frozen=True, eq=False)
class FramePlacement(_FrameResidual):
    """``(p_frame - p_goal, log(R_goalᵀ R_frame))`` (m, rad): the pose error on SO(3)×R³.

    ``placement`` is a ``pinocchio.SE3`` or a 4x4 homogeneous matrix (world frame)."""

    placement: Any = None

    kind: ClassVar[str] = "placement"

    def resolve(self, robot: Any, scene: Any) -> Residual:
        _moving_frame(robot, self.frame)
        M = self.placement.homogeneous if isinstance(self.placement, pin.SE3) else self.placement
        M = as_array(M, (4, 4), f"FramePlacement({self.frame!r}).placement")
        as_rotation(M[:3, :3], f"FramePlacement({self.frame!r}).placement rotation")
        return replace(self, placement=M)

    def dim(self, robot: Any, scene: Any) -> int:
        return 6

    @property
    def rotation(self) -> np.ndarray:
        return np.asarray(self.placement)[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        return np.asarray(self.placement)[:3, 3]

    def goal(self) -> dict[str, np.ndarray]:
        return {"R_g": self.rotation, "p_g": np.asarray(self.translation, dtype=float)}


@dataclass(frozen=True, eq=False)
class FrameHeight(_FrameResidual):
    """``height - z_frame ≤ 0`` (m): the frame's origin at or above ``height`` (world ``z``; a
    swing foot above the ground). Constraint only."""

    height: float = 0.0

    kind: ClassVar[str] = "height"
    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False

    def resolve(self, robot: Any, scene: Any) -> Residual:
        _moving_frame(robot, self.frame)
        height = as_array(self.height, (), f"FrameHeight({self.frame!r}).height")
        return replace(self, height=float(height))

    def dim(self, robot: Any, scene: Any) -> int:
        return 1

    def goal(self) -> dict[str, np.ndarray]:
        return {"p_g": np.array([0.0, 0.0, self.height])}
