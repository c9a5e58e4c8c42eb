"""The residual library of :class:`mbplan.OCP` (defined in :mod:`mbplan.ocp.residuals`)."""

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
