"""Shooting formulation on Lie groups: state spaces, discrete dynamics, tracking costs, problems."""

from mbplan.shooting.cost import TrackingCost
from mbplan.shooting.dynamics import DiscreteDynamics
from mbplan.shooting.models import (
    drone_forcing,
    euler_poincare_euler,
    fully_actuated,
    pendulum_forcing,
    quadrotor_lgvi,
    rigid_body_space,
    rotation_lgvi,
)
from mbplan.shooting.problem import ShootingProblem
from mbplan.shooting.space import StateSpace

__all__ = [
    "DiscreteDynamics",
    "ShootingProblem",
    "StateSpace",
    "TrackingCost",
    "drone_forcing",
    "euler_poincare_euler",
    "fully_actuated",
    "pendulum_forcing",
    "quadrotor_lgvi",
    "rigid_body_space",
    "rotation_lgvi",
]
