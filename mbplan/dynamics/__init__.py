"""Discrete dynamics on SO(3)×R³: the Lie group variational integrator and joint constraints."""

from mbplan.dynamics.constraints import axis_constraint, kinematic_chain, pivot_constraint
from mbplan.dynamics.joints import (
    constraint_forces,
    prismatic_constraint,
    prismatic_forces,
    revolute_constraint,
    revolute_forces,
)
from mbplan.dynamics.rigid_body import (
    body_dynamics,
    body_kinematics,
    free_body_step,
    quadrotor_step,
    rotational_dynamics,
    rotational_kinematics,
    translational_dynamics,
    translational_kinematics,
)

__all__ = [
    "axis_constraint",
    "body_dynamics",
    "body_kinematics",
    "constraint_forces",
    "free_body_step",
    "kinematic_chain",
    "pivot_constraint",
    "prismatic_constraint",
    "prismatic_forces",
    "quadrotor_step",
    "revolute_constraint",
    "revolute_forces",
    "rotational_dynamics",
    "rotational_kinematics",
    "translational_dynamics",
    "translational_kinematics",
]
