"""Transcription of the quadrotor (one rigid body on SO(3)×R³, thrust along body z plus body
torques) into a :class:`TrajectoryProblem` (RIPM paper §VIII.B, eq. 57, 59, 60).

Knots ``k = 0 … N`` carry ``(R_k, p_k, F_k, v_k)``; ``u_k = (u_z, τ)`` for ``k = 0 … N-1``. Step
``k`` imposes ``R_{k+1} = R_k F_k``, ``p_{k+1} = p_k + v_k Δt`` and the forced LGVI (60) between
``(F_k, v_k)`` and ``(F_{k+1}, v_{k+1})``. Knot 0 is the fixed initial state.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics import quadrotor_step
from mbplan.engine import RiemannianFunction
from mbplan.engine.jit import jit_available
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.multibody import nonstandard_inertia
from mbplan.transcription.costs import chordal_cost, quadratic_cost
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block, Point, TrajectoryVariables


@dataclass(frozen=True)
class QuadrotorOCP:
    """Everything that defines one quadrotor trajectory optimization problem."""

    mass: float
    inertia: np.ndarray  # standard inertia I_b about the COM, body frame
    gravity: np.ndarray
    dt: float
    N: int
    R0: np.ndarray
    p0: np.ndarray
    omega0: np.ndarray  # initial body angular velocity (F_0 = exp(ω₀ Δt))
    v0: np.ndarray
    R_goal: np.ndarray
    p_goal: np.ndarray
    w_R: float
    w_p: float
    w_F: float
    w_v: float
    w_u: float
    terminal_factor: float
    u_hover: np.ndarray  # reference input of the input cost
    thrust_limit: float | None = None
    torque_limit: float | None = None
    cylinders: tuple[tuple[float, float, float], ...] = ()  # (x_c, y_c, r)


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


@cache
def _cylinder_function(jit: bool) -> RiemannianFunction:
    def outside(p, c):
        d = p[0:2] - c[0:2]
        return c[2] ** 2 - cs.dot(d, d)

    return RiemannianFunction("cylinder_clearance", [("p", R(3))], outside, [("c", 3)], jit=jit)


def quadrotor_problem(ocp: QuadrotorOCP, jit: bool | None = None) -> TrajectoryProblem:
    """Build the NLP: costs (57) + (59), dynamics (60), optional input limits and cylinders."""
    if ocp.N < 1:
        raise InputError(f"horizon N must be >= 1, got {ocp.N}")
    if not (ocp.dt > 0 and ocp.mass > 0):
        raise InputError(f"dt and mass must be positive, got dt={ocp.dt}, mass={ocp.mass}")
    jit = jit_available() if jit is None else jit
    N = ocp.N
    variables = TrajectoryVariables(
        [Block(name, group, N + 1, fixed=(0,)) for name, group in _vars_state()]
        + [Block("u", R(4), N)]
    )
    step = _step_function(jit)
    bind = {f"{n}{i}": (n, i) for i in (0, 1) for n, _ in _vars_state()} | {"u": ("u", 0)}
    weights = np.tile([ocp.w_R, ocp.w_p, ocp.w_F, ocp.w_v], (N, 1))
    weights[-1] *= ocp.terminal_factor
    terms = [
        Term.at_knots(
            "dynamics",
            "eq",
            step,
            bind,
            range(N),
            {
                "J": nonstandard_inertia(ocp.inertia),
                "mass": ocp.mass,
                "gravity": ocp.gravity,
                "dt": ocp.dt,
            },
        ),
        Term.at_knots(
            "state_cost",
            "cost",
            _state_cost_function(jit),
            {n: (n, 0) for n, _ in _vars_state()},
            range(1, N + 1),
            {"R_d": ocp.R_goal, "p_d": ocp.p_goal, "w": weights},
        ),
        Term.at_knots(
            "input_cost",
            "cost",
            _input_cost_function(jit),
            {"u": ("u", 0)},
            range(N),
            {"u_ref": ocp.u_hover, "w": ocp.w_u},
        ),
    ]
    if ocp.thrust_limit is not None or ocp.torque_limit is not None:
        if ocp.thrust_limit is None or ocp.torque_limit is None:
            raise InputError("input limits need both thrust_limit and torque_limit")
        terms.append(
            Term.at_knots(
                "input_limits",
                "ineq",
                _input_limit_function(jit),
                {"u": ("u", 0)},
                range(N),
                {"u_max": ocp.thrust_limit, "tau_max": ocp.torque_limit},
            )
        )
    for i, c in enumerate(ocp.cylinders):
        terms.append(
            Term.at_knots(
                f"cylinder_{i}",
                "ineq",
                _cylinder_function(jit),
                {"p": ("p", 0)},
                range(1, N + 1),
                {"c": c},
            )
        )
    return TrajectoryProblem(variables, terms)


def geodesic_guess(ocp: QuadrotorOCP) -> Point:
    """Uniform interpolation of the geodesic from the start to the goal pose (§VIII.B).

    ``R_k = R₀ exp(s_k log(R₀ᵀ R_goal))``, ``p_k`` linear, ``F_k = R_kᵀ R_{k+1}``, ``v_k`` the
    finite differences, hover thrust; knot 0 keeps the initial state.
    """
    N = ocp.N
    s = np.linspace(0.0, 1.0, N + 1)
    R0 = SO3.check(ocp.R0)
    xi = SO3.log(R0.T @ SO3.check(ocp.R_goal))
    Rk = R0 @ SO3.exp(s[:, None] * xi)
    pk = (1 - s)[:, None] * ocp.p0 + s[:, None] * ocp.p_goal
    F = np.empty((N + 1, 3, 3))
    F[:N] = np.swapaxes(Rk[:-1], -1, -2) @ Rk[1:]
    F[N] = np.eye(3)
    F[0] = SO3.exp(np.asarray(ocp.omega0, dtype=float) * ocp.dt)
    v = np.zeros((N + 1, 3))
    v[:N] = (pk[1:] - pk[:-1]) / ocp.dt
    v[0] = ocp.v0
    u = np.tile(np.asarray(ocp.u_hover, dtype=float), (N, 1))
    return {"R": Rk, "p": pk, "F": F, "v": v, "u": u}
