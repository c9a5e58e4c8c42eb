"""Maximal-coordinate model of a fixed-base robot: one rigid body on SO(3) x R^3 per joint.

Each Pinocchio joint ``j`` (revolute, continuous or prismatic) moves one rigid body: the links
rigidly attached to its child link are already merged into ``model.inertias[j]`` by Pinocchio.
The body frame has its origin at the body's centre of mass and the orientation of the joint frame,
so a body pose ``(R, p)`` is the world orientation of joint frame ``j`` and the world position of
the body COM.  Joints become holonomic constraints between a parent body (or the fixed world,
pose ``R = I, p = 0``) and the child body (paper §VI.B):

* pivot: ``R_p r_parent + p_p = R_c r_child + p_c``;
* axis:  ``(R_p perp_parent[i])^T (R_c axis_child) = 0`` for ``i = 0, 1``.

A prismatic joint keeps ``R_p^T R_c = R_rel0`` and lets the pivot points separate along the axis.
A free-flyer joint on the world (a floating base) is no constraint at all: its body is a free
rigid body, moved by the forces of its children's joints alone (no actuation, no multipliers).
A robot's loop closures are constraints between two bodies (:mod:`mbplan.multibody.loops`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from mbplan.errors import RobotModelError
from mbplan.multibody.loops import MaximalLoop, maximal_loops
from mbplan.robots import Robot, RobotSpec, load
from mbplan.robots.joints import joint_kind
from mbplan.robots.loops import Loop


@dataclass(frozen=True, eq=False)
class MaximalModel:
    """Bodies and joints of a robot in maximal coordinates (read-only NumPy arrays).

    Index ``i`` runs over the ``nb`` bodies; body ``i`` is moved by joint ``i`` (Pinocchio joint
    ``pin_joint[i]``) that connects it to body ``parent[i]`` (``-1``: the fixed world).  Vectors
    ``*_parent`` are expressed in the parent body frame (world frame for a world parent) and
    ``*_child`` in the child body frame.
    """

    name: str
    model: pin.Model  # the source model (not copied)
    gravity: np.ndarray  # (3,) world gravity acceleration
    # bodies
    body_names: tuple[str, ...]
    mass: np.ndarray  # (nb,)
    inertia: np.ndarray  # (nb, 3, 3) standard inertia I_b about the COM, body frame
    inertia_nonstandard: np.ndarray  # (nb, 3, 3) J = tr(I_b)/2 I - I_b (eq. 33)
    com_in_joint: np.ndarray  # (nb, 3) COM in the joint frame
    parent: np.ndarray  # (nb,) int, -1 = world
    # joints
    joint_names: tuple[str, ...]
    joint_types: tuple[str, ...]  # "revolute", "prismatic" or "free" (a floating base)
    continuous: np.ndarray  # (nb,) bool: revolute without limits, q = (cos, sin)
    pin_joint: np.ndarray  # (nb,) int, Pinocchio joint index
    idx_q: np.ndarray  # (nb,) int, first index in Pinocchio's q
    idx_v: np.ndarray  # (nb,) int, index in Pinocchio's v
    r_parent: np.ndarray  # (nb, 3) pivot from parent COM (world: anchor point)
    r_child: np.ndarray  # (nb, 3) pivot from child COM
    axis_parent: np.ndarray  # (nb, 3) unit joint axis
    axis_child: np.ndarray  # (nb, 3) unit joint axis
    perp_parent: np.ndarray  # (nb, 2, 3) orthonormal, orthogonal to axis_parent
    R_rel0: np.ndarray  # (nb, 3, 3) R_parent^T R_child at zero joint position
    lower_position_limit: np.ndarray  # (nb,) rad or m; -inf for continuous joints
    upper_position_limit: np.ndarray  # (nb,)
    velocity_limit: np.ndarray  # (nb,)
    effort_limit: np.ndarray  # (nb,)
    damping: np.ndarray  # (nb,)
    loops: tuple[MaximalLoop, ...] = ()  # closures between bodies

    @property
    def nb(self) -> int:
        """Number of rigid bodies (= number of joints)."""
        return len(self.body_names)

    @property
    def nq(self) -> int:
        """Size of Pinocchio's configuration vector."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Size of Pinocchio's velocity vector."""
        return self.model.nv

    @property
    def free(self) -> np.ndarray:
        """(nb,) bool mask of the free bodies (a floating base: no joint constraint)."""
        return np.array([t == "free" for t in self.joint_types], dtype=bool)

    @property
    def jointed(self) -> np.ndarray:
        """The bodies held by a joint constraint (every body but a floating base), in order:
        joint slot ``s`` (the multipliers and actuation of a plan) is body ``jointed[s]``."""
        return np.flatnonzero(~self.free)

    @property
    def nj(self) -> int:
        """Number of joint constraints (revolute and prismatic joints)."""
        return int(np.count_nonzero(~self.free))

    @property
    def joint_slot(self) -> np.ndarray:
        """(nb,) each body's joint slot (index in :attr:`jointed`), ``-1`` for a free body."""
        slot = -np.ones(self.nb, np.int64)
        slot[self.jointed] = np.arange(self.nj)
        return slot

    @property
    def revolute(self) -> np.ndarray:
        """(nb,) bool mask of revolute (incl. continuous) joints."""
        return np.array([t == "revolute" for t in self.joint_types], dtype=bool)

    @property
    def prismatic(self) -> np.ndarray:
        """(nb,) bool mask of prismatic joints."""
        return np.array([t == "prismatic" for t in self.joint_types], dtype=bool)


def nonstandard_inertia(inertia: np.ndarray) -> np.ndarray:
    """Paper's non-standard inertia ``J = tr(I_b)/2 I3 - I_b``, inverse of ``I_b = tr(J) I3 - J``
    (eq. 33); works on stacks ``(..., 3, 3)``."""
    trace = np.trace(inertia, axis1=-2, axis2=-1)[..., None, None]
    return 0.5 * trace * np.eye(3) - inertia


# dtype of each per-joint MaximalModel array collected by maximal_model
_ARRAY_FIELDS: dict[str, type] = {
    "mass": float,
    "inertia": float,
    "com_in_joint": float,
    "parent": int,
    "continuous": bool,
    "pin_joint": int,
    "idx_q": int,
    "idx_v": int,
    "r_parent": float,
    "r_child": float,
    "axis_parent": float,
    "axis_child": float,
    "perp_parent": float,
    "R_rel0": float,
    "lower_position_limit": float,
    "upper_position_limit": float,
    "velocity_limit": float,
    "effort_limit": float,
    "damping": float,
}


def maximal_model(robot: RobotSpec | Robot, loops: Sequence[Loop] | None = None) -> MaximalModel:
    """Maximal-coordinate model of ``robot`` (a :class:`~mbplan.robots.Robot`, whose loops it
    takes, or anything :func:`mbplan.robots.load` accepts) with the loop closures ``loops``
    (default: the robot's; resolved ones, :func:`mbplan.multibody.loops.maximal_loops`).

    Raises :class:`RobotModelError` for a joint that is not revolute, continuous or prismatic, or
    a free-flyer joint on the world (spherical, planar, a free flyer deeper in the tree, mimic,
    helical, universal, composite, ...) and for a body whose
    mass or inertia (after merging fixed links) is not positive.
    """
    if isinstance(robot, Robot):
        model, loops = robot.model, robot.loops if loops is None else loops
    else:
        model = load(robot, geometry=False).model
    if model.njoints == 1:
        raise RobotModelError(f"robot {model.name!r} has no moving joint")
    body_names = _body_names(model)

    cols: dict[str, list] = {k: [] for k in _ARRAY_FIELDS}
    joint_types: list[str] = []
    for j in range(1, model.njoints):
        jtype, axis, continuous = joint_kind(model, j)
        inertia = model.inertias[j]
        _check_body(body_names[j - 1], model.names[j], inertia)
        parent = model.parents[j]
        placement = model.jointPlacements[j]
        com_parent = model.inertias[parent].lever if parent > 0 else np.zeros(3)
        axis_parent = placement.rotation @ axis
        free = jtype == "free"
        lo, hi = (
            (-np.inf, np.inf)
            if continuous or free
            else (
                model.lowerPositionLimit[model.idx_qs[j]],
                model.upperPositionLimit[model.idx_qs[j]],
            )
        )
        iv = model.idx_vs[j]
        velocity, effort = (
            (np.inf, 0.0) if free else (model.upperVelocityLimit[iv], model.upperEffortLimit[iv])
        )
        joint_types.append(jtype)
        for key, value in (
            ("mass", inertia.mass),
            ("inertia", inertia.inertia),
            ("com_in_joint", inertia.lever),
            ("parent", parent - 1),
            ("continuous", continuous),
            ("pin_joint", j),
            ("idx_q", model.idx_qs[j]),
            ("idx_v", iv),
            ("r_parent", placement.translation - com_parent),
            ("r_child", -inertia.lever),
            ("axis_parent", axis_parent),
            ("axis_child", axis),
            ("perp_parent", np.zeros((2, 3)) if free else _orthonormal_complement(axis_parent)),
            ("R_rel0", placement.rotation),
            ("lower_position_limit", lo),
            ("upper_position_limit", hi),
            ("velocity_limit", velocity),
            ("effort_limit", effort),
            ("damping", 0.0 if free else model.damping[iv]),
        ):
            cols[key].append(value)

    arrays = {k: _readonly(np.array(v, dtype=_ARRAY_FIELDS[k])) for k, v in cols.items()}
    closures = maximal_loops(model, loops or (), arrays["pin_joint"], arrays["com_in_joint"])
    return MaximalModel(
        name=model.name,
        model=model,
        gravity=_readonly(np.array(model.gravity.linear, dtype=float)),
        body_names=tuple(body_names),
        inertia_nonstandard=_readonly(nonstandard_inertia(arrays["inertia"])),
        joint_names=tuple(model.names[1:]),
        joint_types=tuple(joint_types),
        loops=closures,
        **arrays,
    )


def _check_body(body: str, joint: str, inertia: pin.Inertia) -> None:
    moments = np.linalg.eigvalsh(inertia.inertia)
    if not inertia.mass > 0.0 or not moments[0] > 0.0:
        raise RobotModelError(
            f"body {body!r} (moved by joint {joint!r}) has mass {inertia.mass} and principal "
            f"moments of inertia {moments}: a rigid body needs a positive mass and a "
            "positive-definite inertia"
        )


def _body_names(model: pin.Model) -> list[str]:
    """Name of the child link of each joint (first body frame on it), else the joint name."""
    names = list(model.names[1:])
    named = set()
    for frame in model.frames:
        j = frame.parentJoint
        if frame.type == pin.FrameType.BODY and j > 0 and j not in named:
            names[j - 1] = frame.name
            named.add(j)
    return names


def _orthonormal_complement(axis: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal vectors orthogonal to the unit vector ``axis``."""
    helper = np.eye(3)[np.argmin(np.abs(axis))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(axis, u)])


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a
