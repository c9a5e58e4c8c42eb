"""Transcription of a fixed-base manipulator in maximal coordinates (RIPM paper §VIII.C).

The multi-body LGVI of :mod:`mbplan.transcription.multibody` plus: tracking costs pulling every
body to its pose at the target configuration (chordal (57) on ``R``, quadratic (59) on ``p``),
velocity costs (``F → I``, ``v → 0``), torque regularisation, torque limits as inequalities and
vertical-cylinder obstacles on each body's COM (eq. 62).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as cs
import numpy as np

from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel, body_poses
from mbplan.transcription.costs import chordal_cost, quadratic_cost
from mbplan.transcription.multibody import multibody_layout
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import TrajectoryVariables


@dataclass(frozen=True)
class ManipulatorOCP:
    """Weights are per body (pose, velocity) and per joint (torque)."""

    N: int
    dt: float
    q_target: np.ndarray
    w_R: float = 1.0
    w_p: float = 10.0
    w_F: float = 1.0
    w_v: float = 0.1
    w_tau: float = 1e-3
    terminal_factor: float = 50.0
    torque_limit: np.ndarray | None = None  # (nb,) symmetric bounds
    cylinders: tuple[tuple[float, float, float], ...] = ()  # (x_c, y_c, r) on every body COM


def _pose_cost(R, p, F, v, R_d, p_d, w):
    I3 = cs.DM.eye(3)
    return (
        chordal_cost(R, R_d, w[0] * I3)
        + quadratic_cost(p, p_d, w[1] * I3)
        + chordal_cost(F, I3, w[2] * I3)
        + quadratic_cost(v, cs.DM.zeros(3), w[3] * I3)
    )


@cache
def _pose_cost_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "body_pose_cost",
        [("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3))],
        _pose_cost,
        [("R_d", (3, 3)), ("p_d", 3), ("w", 4)],
        jit=jit,
    )


@cache
def _torque_cost_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "torque_cost", [("tau", R(1))], lambda tau, w: 0.5 * w * tau**2, [("w", 1)], jit=jit
    )


@cache
def _torque_limit_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "torque_limits",
        [("tau", R(1))],
        lambda tau, lim: cs.vertcat(tau - lim, -tau - lim),
        [("lim", 1)],
        jit=jit,
    )


@cache
def _com_cylinder_function(jit: bool) -> RiemannianFunction:
    def outside(p, c):
        d = p[0:2] - c[0:2]
        return c[2] ** 2 - cs.dot(d, d)

    return RiemannianFunction("com_cylinder_clearance", [("p", R(3))], outside, [("c", 3)], jit=jit)


def manipulator_problem(mm: MaximalModel, ocp: ManipulatorOCP, jit: bool) -> TrajectoryProblem:
    """The NLP of a point-to-point motion with obstacles (eq. 27–28, 57, 59, 62)."""
    N, nb = ocp.N, mm.nb
    layout = multibody_layout(mm, N, ocp.dt, jit=jit)
    terms = list(layout.terms)
    R_t, p_t = body_poses(mm, ocp.q_target)
    k, b = (a.ravel() for a in np.meshgrid(np.arange(1, N + 1), np.arange(nb), indexing="ij"))
    sites = k * nb + b
    w = np.tile([ocp.w_R, ocp.w_p, ocp.w_F, ocp.w_v], (len(sites), 1))
    w[k == N] *= ocp.terminal_factor
    bind = {n: (n, sites) for n in ("R", "p", "F", "v")}
    terms.append(
        Term(
            "pose_cost",
            "cost",
            _pose_cost_function(jit),
            bind,
            {"R_d": R_t[b], "p_d": p_t[b], "w": w},
        )
    )
    terms.append(
        Term(
            "torque_cost",
            "cost",
            _torque_cost_function(jit),
            {"tau": ("tau", sites)},
            {"w": ocp.w_tau},
        )
    )
    if ocp.torque_limit is not None:
        lim = np.asarray(ocp.torque_limit, dtype=float)[b]
        terms.append(
            Term(
                "torque_limits",
                "ineq",
                _torque_limit_function(jit),
                {"tau": ("tau", sites)},
                {"lim": lim},
            )
        )
    for i, c in enumerate(ocp.cylinders):
        terms.append(
            Term(
                f"com_cylinder_{i}",
                "ineq",
                _com_cylinder_function(jit),
                {"p": ("p", sites)},
                {"c": c},
            )
        )
    return TrajectoryProblem(TrajectoryVariables(layout.blocks), terms)
