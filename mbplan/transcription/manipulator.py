"""Transcription of a fixed-base manipulator task in maximal coordinates (RIPM paper §VIII.C).

The multi-body LGVI of :mod:`mbplan.transcription.multibody` plus the terms of the task, written
on relative rotations ``R_rel = R_pᵀR_c = R_rel0 exp(θ a)`` of each revolute joint so that they
match the generalized-coordinate transcription term by term:

* joint tracking: the chordal distance (57) ``‖R_rel R_targetᵀ - I‖²`` weighted ``w_q/2``, which
  is ``w_q (1 - cos Δθ) ≈ ½ w_q Δθ²``;
* joint velocity: the chordal distance of ``R_rel`` at knots ``k`` and ``k+1``
  (``R_rel,k+1 = F_pᵀ R_rel,k F_c``) weighted ``w_v/(2Δt²)`` ``≈ ½ w_v ((θ_{k+1} - θ_k)/Δt)²``;
* torque regularisation ``½ w_τ τ²`` and torque limits ``|τ| ≤ τ_max``;
* joint limits ``cos(θ - θ_mid) ≥ cos(θ_half)`` and velocity limits
  ``cos(θ_{k+1} - θ_k) ≥ cos(v_max Δt)`` (exact for ranges below 2π);
* each body's COM outside vertical cylinders (eq. 62), and/or coal signed distances between the
  bodies' collision geometry and obstacles at least a margin (:mod:`mbplan.transcription.distance`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as cs
import numpy as np

from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.multibody.collision import CollisionPairs
from mbplan.transcription.constraints import cylinder_clearance_function
from mbplan.transcription.costs import chordal_cost
from mbplan.transcription.distance import distance_constraint_function, pair_bodies
from mbplan.transcription.multibody import multibody_layout
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import TrajectoryVariables


@dataclass(frozen=True)
class ManipulatorOCP:
    """Joint-space task data; weights as in :mod:`mbplan.tasks.obstacle`'s cost."""

    N: int
    dt: float
    q_target: np.ndarray  # (nb,) joint angles
    w_q: float = 1.0
    w_v: float = 0.1
    w_tau: float = 1e-4
    terminal_factor: float = 50.0
    torque_limit: np.ndarray | None = None  # (nb,) symmetric bounds
    velocity_limit: np.ndarray | None = None  # (nb,)
    position_limits: tuple[np.ndarray, np.ndarray] | None = None  # (lower (nb,), upper (nb,))
    cylinders: tuple[tuple[float, float, float], ...] = ()  # (x_c, y_c, r) on every body COM
    collision_pairs: CollisionPairs | None = None  # coal distance >= collision_margin, knots 1..N
    collision_margin: float = 0.0


def _relative(Rp, Fp, Rc, Fc):
    """``R_rel`` at knot k and k+1 from the bodies' orientations and pose changes."""
    rel = cs.mtimes(Rp.T, Rc)
    return rel, cs.mtimes([Fp.T, rel, Fc])


def _cos_angle(A, B):
    """``cos`` of the rotation angle of ``AᵀB``: ``(tr(AᵀB) - 1)/2``."""
    return 0.5 * (cs.trace(cs.mtimes(A.T, B)) - 1.0)


def _joint_cost(Rp, Fp, Rc, Fc, R_t, w):
    rel, rel_next = _relative(Rp, Fp, Rc, Fc)
    I3 = cs.DM.eye(3)
    return chordal_cost(rel, R_t, w[0] * I3) + chordal_cost(rel_next, rel, w[1] * I3)


def _joint_limits(Rp, Fp, Rc, Fc, R_mid, cos_half, cos_step):
    rel, rel_next = _relative(Rp, Fp, Rc, Fc)
    return cs.vertcat(cos_half - _cos_angle(R_mid, rel), cos_step - _cos_angle(rel, rel_next))


def _world_variant(fn):
    """The same function with a fixed parent (``R_p = F_p = I``, the world)."""

    def world(Rc, Fc, **params):
        return fn(cs.DM.eye(3), cs.DM.eye(3), Rc, Fc, **params)

    return world


_JOINT_VARS = [("Rp", SO3), ("Fp", SO3), ("Rc", SO3), ("Fc", SO3)]


@cache
def _joint_function(kind: str, jit: bool, world: bool) -> RiemannianFunction:
    fn, params = {
        "cost": (_joint_cost, [("R_t", (3, 3)), ("w", 2)]),
        "limits": (_joint_limits, [("R_mid", (3, 3)), ("cos_half", 1), ("cos_step", 1)]),
    }[kind]
    variables = _JOINT_VARS[2:] if world else _JOINT_VARS
    name = f"joint_{kind}{'_world' if world else ''}"
    return RiemannianFunction(name, variables, _world_variant(fn) if world else fn, params, jit=jit)


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


def _about_axis(mm: MaximalModel, angles: np.ndarray) -> np.ndarray:
    """``R_rel0 exp(θ a_c)`` per joint: the relative rotation at joint angles ``θ``."""
    return mm.R_rel0 @ SO3.exp(angles[:, None] * mm.axis_child)


def manipulator_problem(mm: MaximalModel, ocp: ManipulatorOCP, jit: bool) -> TrajectoryProblem:
    """The NLP of a point-to-point motion with obstacles (eq. 27–28, 57, 62)."""
    N, nb = ocp.N, mm.nb
    layout = multibody_layout(mm, N, ocp.dt, jit=jit)
    terms = list(layout.terms)
    k, b = (a.ravel() for a in np.meshgrid(np.arange(1, N + 1), np.arange(nb), indexing="ij"))
    scale = np.where(k == N, ocp.terminal_factor, 1.0)
    weights = np.stack([0.5 * ocp.w_q * scale, 0.5 * ocp.w_v * scale / ocp.dt**2], axis=1)
    R_target = _about_axis(mm, np.asarray(ocp.q_target, dtype=float))
    limit_params = None
    if ocp.position_limits is not None or ocp.velocity_limit is not None:
        lo, hi = (
            ocp.position_limits
            if ocp.position_limits is not None
            else (np.full(nb, -np.pi), np.full(nb, np.pi))
        )
        vmax = (
            np.full(nb, np.inf)
            if ocp.velocity_limit is None
            else np.asarray(ocp.velocity_limit, dtype=float)
        )
        half = np.minimum(0.5 * (hi - lo), np.pi)
        limit_params = {
            "R_mid": _about_axis(mm, 0.5 * (lo + hi))[b],
            "cos_half": np.cos(half)[b],
            "cos_step": np.cos(np.minimum(vmax * ocp.dt, np.pi))[b],
        }
    for world in (True, False):
        mask = (mm.parent[b] < 0) == world
        if not mask.any():
            continue
        kk, bb = k[mask], b[mask]
        bind = {"Rc": ("R", kk * nb + bb), "Fc": ("F", kk * nb + bb)}
        if not world:
            par = mm.parent[bb]
            bind |= {"Rp": ("R", kk * nb + par), "Fp": ("F", kk * nb + par)}
        suffix = "_world" if world else ""
        cost_params = {"R_t": R_target[bb], "w": weights[mask]}
        terms.append(
            Term(
                f"joint_cost{suffix}",
                "cost",
                _joint_function("cost", jit, world),
                bind,
                cost_params,
            )
        )
        if limit_params is not None:
            params = {n: v[mask] for n, v in limit_params.items()}
            terms.append(
                Term(
                    f"joint_limits{suffix}",
                    "ineq",
                    _joint_function("limits", jit, world),
                    bind,
                    params,
                )
            )
    sites = k * nb + b
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
                cylinder_clearance_function(jit),
                {"p": ("p", sites)},
                {"c": c},
            )
        )
    if ocp.collision_pairs is not None:
        pairs = ocp.collision_pairs
        kp, ip = (
            a.ravel()
            for a in np.meshgrid(np.arange(1, N + 1), np.arange(pairs.size), indexing="ij")
        )
        body_sites = kp * nb + pair_bodies(mm, pairs)[ip]
        terms.append(
            Term(
                "coal_distance",
                "ineq",
                distance_constraint_function(mm, pairs),
                {"R": ("R", body_sites), "p": ("p", body_sites)},
                {"pair": ip.astype(float), "margin": ocp.collision_margin},
            )
        )
    return TrajectoryProblem(TrajectoryVariables(layout.blocks), terms)
