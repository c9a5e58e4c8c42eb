"""Forward simulation: the maximal-coordinate LGVI and a fine generalized-coordinate reference."""

from mbplan.simulation.maximal import MaximalTrajectory, discrete_energy, simulate_maximal
from mbplan.simulation.reference import integrate_aba

__all__ = ["MaximalTrajectory", "discrete_energy", "integrate_aba", "simulate_maximal"]
