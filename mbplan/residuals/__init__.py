"""The residual library of :class:`mbplan.OCP`: what a cost or constraint measures.

One class per residual kind, each owning its translations (:mod:`mbplan.residuals.base`):
joint residuals (:mod:`.joint`), joint limits (:mod:`.limits`), mimic couplings
(:mod:`.coupling`), frame goals and heights (:mod:`.frame`), coal distances (:mod:`.distance`), the centre of mass, eq. (62)
(:mod:`.com`) and a free body's residuals (:mod:`.body`). A new kind is a subclass of :class:`Residual` implementing the translations it
supports; :data:`RESIDUALS` lists every kind.
"""

from mbplan.residuals.base import RESIDUALS, Residual
from mbplan.residuals.body import (
    BodyInput,
    BodyInputLimits,
    BodyOrientation,
    BodyPosition,
    BodyRotationStep,
    BodyVelocity,
)
from mbplan.residuals.com import ComOutsideCylinder, ComPosition
from mbplan.residuals.coupling import JointCoupling
from mbplan.residuals.distance import Distance
from mbplan.residuals.frame import FrameHeight, FramePlacement, FrameTranslation
from mbplan.residuals.joint import JointPosition, JointTorque, JointVelocity
from mbplan.residuals.limits import JointPositionLimits, JointTorqueLimits, JointVelocityLimits

__all__ = [
    "RESIDUALS",
    "BodyInput",
    "BodyInputLimits",
    "BodyOrientation",
    "BodyPosition",
    "BodyRotationStep",
    "BodyVelocity",
    "ComOutsideCylinder",
    "ComPosition",
    "Distance",
    "FrameHeight",
    "FramePlacement",
    "FrameTranslation",
    "JointCoupling",
    "JointPosition",
    "JointPositionLimits",
    "JointTorque",
    "JointTorqueLimits",
    "JointVelocity",
    "JointVelocityLimits",
    "Residual",
]
