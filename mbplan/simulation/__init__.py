"""Forward simulation: the maximal-coordinate LGVI and a fine generalized-coordinate reference."""

from mbplan.simulation.maximal import (
    MaximalTrajectory,
    discrete_energy,
    discrete_momentum,
    simulate_maximal,
)
from mbplan.simulation.reference import integrate_aba

__all__ = [
    "MaximalTrajectory",
    "discrete_energy",
    "discrete_momentum",
    "integrate_aba",
    "simulate_maximal",
]
