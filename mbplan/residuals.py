"""The residual library of :class:`mbplan.OCP` (defined in :mod:`mbplan.ocp.residuals`)."""

from mbplan.ocp.body_residuals import (
    BodyInput,
    BodyInputLimits,
    BodyOrientation,
    BodyPosition,
    BodyRotationStep,
    BodyVelocity,
)
from mbplan.ocp.residuals import (
    ComOutsideCylinder,
    Distance,
    FramePlacement,
    FrameTranslation,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    JointVelocityLimits,
    Residual,
)

__all__ = [
    "BodyInput",
    "BodyInputLimits",
    "BodyOrientation",
    "BodyPosition",
    "BodyRotationStep",
    "BodyVelocity",
    "ComOutsideCylinder",
    "Distance",
    "FramePlacement",
    "FrameTranslation",
    "JointPosition",
    "JointPositionLimits",
    "JointTorque",
    "JointTorqueLimits",
    "JointVelocity",
    "JointVelocityLimits",
    "Residual",
]
