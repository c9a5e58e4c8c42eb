"""Benchmark tasks of the RIPM paper (§VIII) as plain data, with initial guesses and simulators."""

from mbplan.tasks.drone import (
    CostWeights,
    DockingTask,
    QuadrotorParams,
    cluttered_task,
    geodesic_initial_guess,
    rotation_angles,
    sample_docking_cases,
    simulate,
    trajectory_cost,
)

__all__ = [
    "CostWeights",
    "DockingTask",
    "QuadrotorParams",
    "cluttered_task",
    "geodesic_initial_guess",
    "rotation_angles",
    "sample_docking_cases",
    "simulate",
    "trajectory_cost",
]
