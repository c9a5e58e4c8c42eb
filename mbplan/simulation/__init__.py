"""Forward simulation: the maximal-coordinate LGVI and a fine generalized-coordinate reference."""

from mbplan.simulation.maximal import MaximalTrajectory, simulate_maximal
from mbplan.simulation.reference import integrate_aba

__all__ = ["MaximalTrajectory", "integrate_aba", "simulate_maximal"]
