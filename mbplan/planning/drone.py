"""Drone docking with the RIPM on SO(3)×R³ (RIPM paper §VIII.B)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mbplan.errors import InputError
from mbplan.solvers import MLGIPMOptions, RIPMOptions, RIPMResult, RIPMStatus
from mbplan.solvers.dispatch import solve_with
from mbplan.tasks.drone import DockingTask, geodesic_initial_guess, simulate
from mbplan.transcription.quadrotor import quadrotor_problem


@dataclass(frozen=True)
class DockingSolution:
    """The RIPM's result and an independent replay of its inputs through the LGVI simulator."""

    result: RIPMResult
    build_time_s: float
    replay_deviation_m: float  # max |p_replay - p_planned| over the knots

    @property
    def converged(self) -> bool:
        """Strict success: the solver reached ``tol`` (not just the acceptable level)."""
        return self.result.status is RIPMStatus.CONVERGED


def plan_docking(
    task: DockingTask,
    options: RIPMOptions | MLGIPMOptions | None = None,
    jit: bool | None = None,
    method: str = "ripm",
) -> DockingSolution:
    """Solve one docking task (``method`` ``"ripm"`` or ``"mlgipm"``, with that solver's
    options) from the geodesic initial guess and replay the inputs."""
    t0 = time.perf_counter()
    problem = quadrotor_problem(task, jit=jit)
    x0 = problem.check_point(geodesic_initial_guess(task))
    build = time.perf_counter() - t0
    result = solve_with(method, problem, x0, options)
    try:
        replay = simulate(task, result.x["u"])
        deviation = float(np.max(np.abs(replay["p"] - result.x["p"])))
    except InputError:  # inputs of a failed solve the LGVI cannot replay
        deviation = float("inf")
    return DockingSolution(result, build, deviation)
