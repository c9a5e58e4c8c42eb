"""Discrete dynamics on SO(3)×R³: the Lie group variational integrator and joint constraints."""

from mbplan.dynamics.constraints import axis_constraint, kinematic_chain, pivot_constraint
from mbplan.dynamics.rigid_body import (
    nonstandard_inertia,
    quadrotor_step,
    rotational_dynamics,
    rotational_kinematics,
    translational_dynamics,
    translational_kinematics,
)

__all__ = [
    "axis_constraint",
    "kinematic_chain",
    "nonstandard_inertia",
    "pivot_constraint",
    "quadrotor_step",
    "rotational_dynamics",
    "rotational_kinematics",
    "translational_dynamics",
    "translational_kinematics",
]
