"""Crocoddyl's own quadruped and biped gaits solved by its FDDP: the timing anchor of
``mbplan bench locomotion`` (the ``baselines`` extra).

The same robot, gait, Δt, step and support knots as :func:`mbplan.locomotion.quadruped_gait`
(:func:`~mbplan.locomotion.biped_gait`), but Crocoddyl's problem:
``crocoddyl.utils.quadruped.SimpleQuadrupedalGaitProblem`` (``.biped.SimpleBipedGaitProblem``:
6-D sole contacts; forward contact dynamics with Baumgarte stabilization, impulse models at
touchdown, explicit Euler, the friction (wrench) cone as a penalty cost, its own weights), from
its own start (the standing state repeated, quasi-static controls), at most :data:`MAX_ITER`
iterations. Its plans are not put
through :func:`mbplan.verify` (their contact forces live in Crocoddyl's data, their cones are
soft); the numbers are Crocoddyl's iterations and solve time on the machine that ran the
benchmark, and the largest violation of the hard cones of :mod:`mbplan.dynamics.friction` by
its contact forces (:func:`cone_violations`: the friction cone for points, the contact wrench
cone of Crocoddyl's own 0.1 m × 0.05 m box for soles), which its penalty lets them leave.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from mbplan.dynamics.friction import cone_violation, wrench_cone_violation
from mbplan.robots.robot import load_robot

MAX_ITER = 100
FRICTION = 0.7  # Crocoddyl's gait examples
SOLE = (0.1, 0.05)  # Crocoddyl's biped WrenchCone box (length, width)
CREATE = {"walk": "Walking", "trot": "Trotting", "pace": "Pacing", "bound": "Bounding"}


def fddp_gait(
    robot: str,
    feet: tuple[str, ...],
    gait: str,
    step_length: float,
    step_height: float,
    dt: float,
    step_knots: int,
    support_knots: int,
    repeats: int = 3,
) -> dict[str, Any]:
    """Crocoddyl's FDDP on its gait problem (module docstring; ``feet``: a quadruped's four
    or a biped's ``(left, right)``): iterations, whether it converged, the median solve time
    over ``repeats`` solves (s)."""
    import crocoddyl
    from crocoddyl.utils.biped import SimpleBipedGaitProblem
    from crocoddyl.utils.quadruped import SimpleQuadrupedalGaitProblem

    model = load_robot(robot)
    biped = len(feet) == 2
    q0 = model.configuration("half_sitting" if biped else "standing")
    x0 = np.concatenate([q0, np.zeros(model.nv)])
    if biped:
        builder = SimpleBipedGaitProblem(model.model, feet[1], feet[0])
    else:
        builder = SimpleQuadrupedalGaitProblem(model.model, *feet)
    if biped and gait == "walk":
        problem = builder.createWalkingProblem(
            x0, step_length, step_height, dt, step_knots, support_knots
        )
    elif gait == "jump":
        length = np.array([step_length, 0.0, 0.0])
        problem = builder.createJumpingProblem(
            x0, step_height, length, dt, support_knots, step_knots
        )
    else:
        create = getattr(builder, f"create{CREATE[gait]}Problem")
        problem = create(x0, step_length, step_height, dt, step_knots, support_knots)
    times, iterations, converged = [], 0, False
    for _ in range(repeats):
        solver = crocoddyl.SolverFDDP(problem)
        xs = [x0] * (problem.T + 1)
        us = problem.quasiStatic([x0] * problem.T)
        start = time.perf_counter()
        converged = bool(solver.solve(xs, us, MAX_ITER, False))
        times.append(time.perf_counter() - start)
        iterations = int(solver.iter)
    return {
        "iterations": iterations,
        "converged": converged,
        "solve_time_s": float(np.median(times)),
        "knots": int(problem.T),
        "max_cone_violation": cone_violations(solver),
    }


def cone_violations(solver: Any) -> float:
    """The largest violation (N; N m for a sole's torque rows) of the cones by the contact
    forces of a solved Crocoddyl problem's running models (world-aligned, as its gait builders
    define their contacts; a 6-D contact's wrench about the sole in its ``WrenchCone``)."""
    worst = 0.0
    for data in solver.problem.runningDatas:
        if not hasattr(data, "differential"):  # an impulse model
            continue
        contacts = data.differential.multibody.contacts.contacts.todict()
        for contact in contacts.values():
            f = contact.f
            if len(contact.Jc) == 3:
                violation = cone_violation(f.linear, FRICTION)
            else:
                wrench = np.concatenate([f.linear, f.angular])
                violation = wrench_cone_violation(wrench, FRICTION, *SOLE)
            worst = max(worst, float(violation))
    return worst
