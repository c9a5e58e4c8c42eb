"""The residual library of :class:`mbplan.OCP`: what a cost or constraint measures.

Each residual is plain data; :meth:`resolve` checks it against the robot and scene (names,
shapes, NaN) and returns the same residual with every default filled in (targets, limits), so a
formulation only reads numbers. Costs are ``½ w ‖r‖²``; constraints are ``r = 0`` (``sense =
"eq"``) or ``r ≤ 0`` (``"ineq"``). State residuals live on the knots ``k = 1..N``, control
residuals (torques) on the intervals ``k = 0..N-1``. How each formulation writes them:
:mod:`mbplan.formulations.joint_space` (generalized coordinates) and
:mod:`mbplan.formulations.maximal` (SO(3)×R³ bodies).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.ocp.free_body import FreeBody
from mbplan.ocp.robot import Robot
from mbplan.ocp.scene import Scene
from mbplan.validation import as_array, as_real, as_rotation


@dataclass(frozen=True, eq=False)
class Residual:
    """Base class: ``space`` is ``"state"`` or ``"control"``, ``sense`` the constraint sense,
    ``cost``/``constraint`` whether it can be a cost / a constraint."""

    space: ClassVar[str] = "state"
    sense: ClassVar[str] = "eq"
    cost: ClassVar[bool] = True
    constraint: ClassVar[bool] = True

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        return self

    def dim(self, robot: Robot, scene: Scene) -> int:
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": type(self).__name__}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = value.tolist() if isinstance(value, np.ndarray) else value
        return out

    @staticmethod
    def from_dict(data: dict[str, Any]) -> Residual:
        kind = data.get("kind")
        cls = RESIDUALS.get(kind)  # type: ignore[arg-type]
        if cls is None:
            raise InputError(f"unknown residual kind {kind!r}; known: {sorted(RESIDUALS)}")
        kwargs = {k: v for k, v in data.items() if k != "kind"}
        for k, v in kwargs.items():
            if isinstance(v, list):
                kwargs[k] = tuple(v) if k in ("joints", "objects") else np.array(v, dtype=float)
        return cls(**kwargs)


def _vector(value: ArrayLike | None, n: int, name: str, default: float = 0.0) -> np.ndarray:
    return np.full(n, default) if value is None else as_array(value, (n,), name)


@dataclass(frozen=True, eq=False)
class _JointResidual(Residual):
    """``x[joints] - target`` for one of ``q``, ``v``, ``τ`` (all joints if ``joints`` is None;
    target zero by default: a regularisation)."""

    target: np.ndarray | None = None
    joints: tuple[str, ...] | None = None

    def indices(self, robot: Robot) -> np.ndarray:
        return robot.joint_indices(self.joints)

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        n = len(self.indices(robot))
        target = _vector(self.target, n, f"{type(self).__name__}.target")
        return replace(
            self, target=target, joints=None if self.joints is None else tuple(self.joints)
        )

    def dim(self, robot: Robot, scene: Scene) -> int:
        return len(self.indices(robot))


@dataclass(frozen=True, eq=False)
class JointPosition(_JointResidual):
    """``q[joints] - target`` (rad or m); ``2 sin((θ - θ_t)/2)`` for a continuous joint (a goal
    modulo 2π, :mod:`mbplan.ocp.continuous`)."""


@dataclass(frozen=True, eq=False)
class JointVelocity(_JointResidual):
    """``v[joints] - target`` (rad/s)."""


@dataclass(frozen=True, eq=False)
class JointTorque(_JointResidual):
    """``τ[joints] - target`` (N m) on the intervals."""

    space: ClassVar[str] = "control"


@dataclass(frozen=True, eq=False)
class FrameTranslation(Residual):
    """``p_frame(q) - translation`` (m, world frame)."""

    frame: str = ""
    translation: np.ndarray | None = None

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        _moving_frame(robot, self.frame)
        t = as_array(self.translation, (3,), f"FrameTranslation({self.frame!r}).translation")
        return replace(self, translation=t)

    def dim(self, robot: Robot, scene: Scene) -> int:
        return 3


@dataclass(frozen=True, eq=False)
class FramePlacement(Residual):
    """``(p_frame - p_goal, log(R_goalᵀ R_frame))`` (m, rad): the pose error on SO(3)×R³.

    ``placement`` is a ``pinocchio.SE3`` or a 4x4 homogeneous matrix (world frame)."""

    frame: str = ""
    placement: Any = None

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        _moving_frame(robot, self.frame)
        M = self.placement.homogeneous if isinstance(self.placement, pin.SE3) else self.placement
        M = as_array(M, (4, 4), f"FramePlacement({self.frame!r}).placement")
        as_rotation(M[:3, :3], f"FramePlacement({self.frame!r}).placement rotation")
        return replace(self, placement=M)

    def dim(self, robot: Robot, scene: Scene) -> int:
        return 6

    @property
    def rotation(self) -> np.ndarray:
        return np.asarray(self.placement)[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        return np.asarray(self.placement)[:3, 3]


@dataclass(frozen=True, eq=False)
class Distance(Residual):
    """``margin - d ≤ 0`` for coal's signed distance ``d`` of every collision geometry on a
    moving link and every scene object in ``objects`` (all if None). Constraint only."""

    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    margin: float = 0.0
    objects: tuple[str, ...] | None = None

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        margin = as_real(self.margin, "Distance.margin")
        if robot.collision_model is None or not any(
            g.parentJoint > 0 for g in robot.collision_model.geometryObjects
        ):
            raise InputError(
                f"Distance: robot {robot.name!r} has no collision geometry on a moving link "
                "(pass collision_model= with a pinocchio.Model)"
            )
        names = scene.names if self.objects is None else list(self.objects)
        for n in names:
            scene[n]
        if not names:
            raise InputError("Distance: the scene has no objects")
        return replace(self, margin=margin, objects=tuple(names))

    def dim(self, robot: Robot, scene: Scene) -> int:
        n = sum(g.parentJoint > 0 for g in robot.collision_model.geometryObjects)
        return n * len(self.objects or ())


@dataclass(frozen=True, eq=False)
class ComOutsideCylinder(Residual):
    """Eq. (62): ``(r + margin)² - ‖(x_i, y_i) - c‖² ≤ 0`` for the COM ``p_i`` of every moving
    link and the vertical scene cylinder ``obstacle`` (infinite in z). Constraint only."""

    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    obstacle: str = ""
    margin: float = 0.0

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        o = scene[self.obstacle]
        if o.shape != "cylinder" or not np.allclose(o.pose[:3, 2], [0, 0, 1], atol=1e-9):
            raise InputError(f"ComOutsideCylinder: {o} is not a vertical cylinder")
        return replace(self, margin=as_real(self.margin, "ComOutsideCylinder.margin"))

    def dim(self, robot: Robot, scene: Scene) -> int:
        return 1 if isinstance(robot, FreeBody) else robot.model.njoints - 1

    def circle(self, scene: Scene) -> np.ndarray:
        """``(x_c, y_c, r + margin)``."""
        o = scene[self.obstacle]
        return np.array([*o.pose[:2, 3], o.size[0] + self.margin])


@dataclass(frozen=True, eq=False)
class _Limits(Residual):
    """``(lower - x, x - upper) ≤ 0`` (URDF limits by default). Constraint only."""

    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def _defaults(self, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def resolve(self, robot: Robot, scene: Scene) -> Residual:
        lo, hi = self._defaults(robot)
        name = type(self).__name__
        lower = lo if self.lower is None else as_array(self.lower, (robot.nv,), f"{name}.lower")
        upper = hi if self.upper is None else as_array(self.upper, (robot.nv,), f"{name}.upper")
        free = self._unbounded(robot)
        if not np.all(np.isfinite(lower[~free])) or not np.all(np.isfinite(upper[~free])):
            raise InputError(f"{name}: limits must be finite (URDF without limits?)")
        if np.any((lower >= upper) & ~free):
            j = int(np.argmax((lower >= upper) & ~free))
            raise InputError(
                f"{name}: lower >= upper for joint {robot.model.names[j + 1]!r} "
                f"({lower[j]:g}, {upper[j]:g}; URDF without limits?)"
            )
        return replace(self, lower=np.array(lower), upper=np.array(upper))

    def _unbounded(self, robot: Robot) -> np.ndarray:
        """(nv,) mask of the joints without rows (continuous joints' positions)."""
        return np.zeros(robot.nv, dtype=bool)

    def indices(self, robot: Robot) -> np.ndarray:
        """Velocity indices of the limited joints: rows ``(lower - x, x - upper)[indices]``."""
        return np.flatnonzero(~self._unbounded(robot))

    def dim(self, robot: Robot, scene: Scene) -> int:
        return 2 * len(self.indices(robot))


@dataclass(frozen=True, eq=False)
class JointPositionLimits(_Limits):
    """Position limits of every joint but the continuous ones (no limits, no rows)."""

    def _defaults(self, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
        return robot.model.lowerPositionLimit, robot.model.upperPositionLimit

    def _unbounded(self, robot: Robot) -> np.ndarray:
        free = np.zeros(robot.nv, dtype=bool)
        free[robot.joint_indices(robot.continuous)] = True
        return free


@dataclass(frozen=True, eq=False)
class JointVelocityLimits(_Limits):
    def _defaults(self, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
        return -robot.model.velocityLimit, robot.model.velocityLimit


@dataclass(frozen=True, eq=False)
class JointTorqueLimits(_Limits):
    space: ClassVar[str] = "control"

    def _defaults(self, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
        return -robot.model.effortLimit, robot.model.effortLimit


def _moving_frame(robot: Robot, frame: str) -> int:
    if not isinstance(frame, str):
        raise InputError(f"frame: expected a frame name, got {frame!r}")
    fid = robot.frame_id(frame)
    if robot.model.frames[fid].parentJoint == 0:
        raise InputError(f"frame {frame!r} is fixed to the base: its pose cannot change")
    return fid


RESIDUALS: dict[str, type[Residual]] = {
    cls.__name__: cls
    for cls in (
        JointPosition,
        JointVelocity,
        JointTorque,
        FrameTranslation,
        FramePlacement,
        Distance,
        ComOutsideCylinder,
        JointPositionLimits,
        JointVelocityLimits,
        JointTorqueLimits,
    )
}
