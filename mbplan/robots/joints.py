"""The joints a robot may have, by Pinocchio joint model: revolute (bounded or continuous) and
prismatic, each about a fixed axis, and a free-flyer root joint (a floating base: its body is a
free rigid body); every other kind is refused by name."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mbplan.errors import RobotModelError

# Pinocchio joint model -> (maximal-coordinate joint type, fixed axis in the joint frame or None
# when the joint carries its own axis, continuous i.e. configuration (cos, sin)).
_E = np.eye(3)
_SUPPORTED: dict[str, tuple[str, np.ndarray | None, bool]] = {
    "JointModelRX": ("revolute", _E[0], False),
    "JointModelRY": ("revolute", _E[1], False),
    "JointModelRZ": ("revolute", _E[2], False),
    "JointModelRevoluteUnaligned": ("revolute", None, False),
    "JointModelRUBX": ("revolute", _E[0], True),
    "JointModelRUBY": ("revolute", _E[1], True),
    "JointModelRUBZ": ("revolute", _E[2], True),
    "JointModelRevoluteUnboundedUnaligned": ("revolute", None, True),
    "JointModelPX": ("prismatic", _E[0], False),
    "JointModelPY": ("prismatic", _E[1], False),
    "JointModelPZ": ("prismatic", _E[2], False),
    "JointModelPrismaticUnaligned": ("prismatic", None, False),
    "JointModelFreeFlyer": ("free", np.zeros(3), False),
}
FREE_FLYER = "JointModelFreeFlyer"


def is_floating_root(model: pin.Model, j: int) -> bool:
    """Whether joint ``j`` is a free-flyer joint on the world and the model's first joint (a
    floating base: ``q`` and ``v`` start with its coordinates)."""
    return j == 1 and model.joints[j].shortname() == FREE_FLYER and model.parents[j] == 0


def joint_kind(model: pin.Model, j: int) -> tuple[str, np.ndarray, bool]:
    """(type, unit axis in the joint frame, continuous) of Pinocchio joint ``j``; a free-flyer
    root joint is ``("free", 0, False)``."""
    shortname = model.joints[j].shortname()
    if shortname not in _SUPPORTED or (shortname == FREE_FLYER and not is_floating_root(model, j)):
        raise RobotModelError(
            f"joint {model.names[j]!r} is a {shortname}, which the maximal-coordinate model does "
            "not support (only revolute, continuous and prismatic joints, and a free-flyer "
            "joint on the world as the first joint)"
        )
    jtype, axis, continuous = _SUPPORTED[shortname]
    if axis is None:
        axis = np.array(model.joints[j].extract().axis, dtype=float)
        axis = axis / np.linalg.norm(axis)
    return jtype, axis, continuous
