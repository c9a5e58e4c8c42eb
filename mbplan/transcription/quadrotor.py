"""Transcription of the quadrotor (one rigid body on SO(3)×R³, thrust along body z plus body
torques) into a :class:`TrajectoryProblem` (RIPM paper §VIII.B, eq. 57, 59, 60).

Knots ``k = 0 … N`` carry ``(R_k, p_k, F_k, v_k)``; ``u_k = (u_z, τ)`` for ``k = 0 … N-1``. Step
``k`` imposes ``R_{k+1} = R_k F_k``, ``p_{k+1} = p_k + v_k Δt`` and the forced LGVI (60) between
``(F_k, v_k)`` and ``(F_{k+1}, v_{k+1})``. Knot 0 is the fixed initial state.
"""

from __future__ import annotations

from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics import quadrotor_step
from mbplan.engine import RiemannianFunction
from mbplan.engine.jit import jit_available
from mbplan.lie import SO3, R
from mbplan.tasks.drone import DockingTask
from mbplan.transcription.constraints import cylinder_clearance_function
from mbplan.transcription.costs import chordal_cost, quadratic_cost
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block, TrajectoryVariables


def _vars_state() -> list:
    return [("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3))]


@cache
def _step_function(jit: bool) -> RiemannianFunction:
    variables = [(f"{n}{i}", g) for i in (0, 1) for n, g in _vars_state()] + [("u", R(4))]
    return RiemannianFunction(
        "quadrotor_step",
        variables,
        quadrotor_step,
        [("J", (3, 3)), ("mass", 1), ("gravity", 3), ("dt", 1)],
        jit=jit,
    )


def _state_cost(R, p, F, v, R_d, p_d, w):
    I3 = cs.DM.eye(3)
    return (
        chordal_cost(R, R_d, w[0] * I3)
        + quadratic_cost(p, p_d, w[1] * I3)
        + chordal_cost(F, I3, w[2] * I3)
        + quadratic_cost(v, cs.DM.zeros(3), w[3] * I3)
    )


@cache
def _state_cost_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "quadrotor_state_cost",
        _vars_state(),
        _state_cost,
        [("R_d", (3, 3)), ("p_d", 3), ("w", 4)],
        jit=jit,
    )


@cache
def _input_cost_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "quadrotor_input_cost",
        [("u", R(4))],
        lambda u, u_ref, w: quadratic_cost(u, u_ref, w * cs.DM.eye(4)),
        [("u_ref", 4), ("w", 1)],
        jit=jit,
    )


@cache
def _input_limit_function(jit: bool) -> RiemannianFunction:
    def limits(u, u_max, tau_max):
        return cs.vertcat(-u[0], u[0] - u_max, u[1:4] - tau_max, -u[1:4] - tau_max)

    return RiemannianFunction(
        "quadrotor_input_limits", [("u", R(4))], limits, [("u_max", 1), ("tau_max", 1)], jit=jit
    )


def quadrotor_problem(task: DockingTask, jit: bool | None = None) -> TrajectoryProblem:
    """Build the NLP: costs (57) + (59), dynamics (60), optional input limits and cylinders."""
    jit = jit_available() if jit is None else jit
    N, prm, wt = task.N, task.params, task.weights
    variables = TrajectoryVariables(
        [Block(name, group, N + 1, fixed=(0,)) for name, group in _vars_state()]
        + [Block("u", R(4), N)]
    )
    bind = {f"{n}{i}": (n, i) for i in (0, 1) for n, _ in _vars_state()} | {"u": ("u", 0)}
    weights = np.tile([wt.w_R, wt.w_p, wt.w_F, wt.w_v], (N, 1))
    weights[-1] *= wt.terminal_factor
    dynamics = {
        "J": prm.nonstandard_inertia,
        "mass": prm.mass,
        "gravity": prm.gravity,
        "dt": task.dt,
    }
    terms = [
        Term.at_knots("dynamics", "eq", _step_function(jit), bind, range(N), dynamics),
        Term.at_knots(
            "state_cost",
            "cost",
            _state_cost_function(jit),
            {n: (n, 0) for n, _ in _vars_state()},
            range(1, N + 1),
            {"R_d": task.R_goal, "p_d": task.p_goal, "w": weights},
        ),
        Term.at_knots(
            "input_cost",
            "cost",
            _input_cost_function(jit),
            {"u": ("u", 0)},
            range(N),
            {"u_ref": prm.hover_input, "w": wt.w_u},
        ),
    ]
    if task.with_input_limits:
        limits = {"u_max": prm.thrust_limit, "tau_max": prm.torque_limit}
        terms.append(
            Term.at_knots(
                "input_limits",
                "ineq",
                _input_limit_function(jit),
                {"u": ("u", 0)},
                range(N),
                limits,
            )
        )
    for i, c in enumerate(task.obstacles):
        terms.append(
            Term.at_knots(
                f"cylinder_{i}",
                "ineq",
                cylinder_clearance_function(jit),
                {"p": ("p", 0)},
                range(1, N + 1),
                {"c": c},
            )
        )
    return TrajectoryProblem(variables, terms)
