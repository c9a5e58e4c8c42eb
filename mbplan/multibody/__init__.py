"""Maximal-coordinate multi-body models (one rigid body on SO(3) x R^3 per joint)."""

from mbplan.multibody.model import MaximalModel, maximal_model, nonstandard_inertia
from mbplan.multibody.state_maps import (
    body_poses,
    body_velocities,
    joint_constraint_residuals,
    joint_positions,
    joint_velocities,
)

__all__ = [
    "MaximalModel",
    "body_poses",
    "body_velocities",
    "joint_constraint_residuals",
    "joint_positions",
    "joint_velocities",
    "maximal_model",
    "nonstandard_inertia",
]
