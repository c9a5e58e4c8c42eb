"""Transcription of a maximal-coordinate multi-body system (RIPM paper §V.A, §VI.B–C, Fig. 2).

Blocks (``count = nb`` elements per knot, one per body or per joint), knots ``k = 0 … N``:
``R, F`` (SO(3)), ``p, v`` (R³), ``lam`` (R⁵ per revolute joint: pivot force, axis torques),
``tau`` (R¹ per joint: actuation torque). Knot 0 is the fixed initial state.

Equations (eq. 27–28 with 34–35 per body), per step ``k = 0 … N-1``:

* body kinematics ``R_{k+1} = R_k F_k``, ``p_{k+1} = p_k + v_k Δt``;
* body LGVI ``(F_k, v_k) → (F_{k+1}, v_{k+1})`` with gravity and, added into the same rows by
  joint terms, the constraint forces ``J(x_{k+1})ᵀλ_{k+1}`` and actuation ``τ_{k+1}``;
* joint constraints on the next configuration ``h(R_{k+1} F_{k+1}, p_{k+1} + v_{k+1} Δt) = 0``.

Each term is one engine function vectorised over (knot, body) or (knot, joint) sites, so the
Jacobian has the graph structure of Fig. 2 and evaluation cost is linear in bodies and horizon.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics import body_dynamics, body_kinematics, revolute_constraint
from mbplan.dynamics.joints import revolute_forces, revolute_forces_on_child
from mbplan.engine import RiemannianFunction
from mbplan.errors import RobotModelError
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block

LAMBDA_DIM = 5  # pivot (3) + axis (2) per revolute joint


@cache
def _kinematics_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "body_kinematics",
        [("R0", SO3), ("R1", SO3), ("F0", SO3), ("p0", R(3)), ("p1", R(3)), ("v0", R(3))],
        body_kinematics,
        [("dt", 1)],
        jit=jit,
    )


@cache
def _dynamics_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "body_dynamics",
        [("F0", SO3), ("F1", SO3), ("v0", R(3)), ("v1", R(3))],
        body_dynamics,
        [("J", (3, 3)), ("mass", 1), ("gravity", 3), ("dt", 1)],
        jit=jit,
    )


_JOINT_PARAMS = [("r_p", 3), ("r_c", 3), ("perp_p", (3, 2)), ("axis_c", 3)]


@cache
def _joint_forces_function(jit: bool, world_parent: bool) -> RiemannianFunction:
    child = [("Rc", SO3), ("pc", R(3)), ("lam", R(LAMBDA_DIM)), ("tau", R(1))]
    if world_parent:
        return RiemannianFunction(
            "revolute_forces_world",
            child,
            revolute_forces_on_child,
            [("Rp", (3, 3)), ("pp", 3), *_JOINT_PARAMS],
            jit=jit,
        )
    return RiemannianFunction(
        "revolute_forces",
        [("Rp", SO3), ("pp", R(3)), *child],
        revolute_forces,
        _JOINT_PARAMS,
        jit=jit,
    )


def _next_constraint(Rp, Fp, pp, vp, Rc, Fc, pc, vc, r_p, r_c, perp_p, axis_c, dt):
    """``h(x_{k+1})`` with ``x_{k+1} = (R_k F_k, p_k + v_k Δt)`` for both bodies."""
    return revolute_constraint(
        cs.mtimes(Rp, Fp), pp + vp * dt, cs.mtimes(Rc, Fc), pc + vc * dt, r_p, r_c, perp_p, axis_c
    )


def _next_constraint_world(Rc, Fc, pc, vc, Rp, pp, r_p, r_c, perp_p, axis_c, dt):
    return revolute_constraint(Rp, pp, cs.mtimes(Rc, Fc), pc + vc * dt, r_p, r_c, perp_p, axis_c)


@cache
def _constraint_function(jit: bool, world_parent: bool) -> RiemannianFunction:
    body = [("R", SO3), ("F", SO3), ("p", R(3)), ("v", R(3))]
    child = [(f"{n}c", g) for n, g in body]
    if world_parent:
        return RiemannianFunction(
            "revolute_constraint_world",
            child,
            _next_constraint_world,
            [("Rp", (3, 3)), ("pp", 3), *_JOINT_PARAMS, ("dt", 1)],
            jit=jit,
        )
    return RiemannianFunction(
        "revolute_constraint",
        [(f"{n}p", g) for n, g in body] + child,
        _next_constraint,
        [*_JOINT_PARAMS, ("dt", 1)],
        jit=jit,
    )


@dataclass(frozen=True)
class MultibodyLayout:
    """Blocks and equality terms of the multi-body dynamics over ``N`` steps."""

    blocks: list[Block]
    terms: list[Term]
    n_dynamics_rows: int


def check_supported(mm: MaximalModel) -> None:
    """The transcription handles revolute joints (continuous included)."""
    bad = [(n, t) for n, t in zip(mm.joint_names, mm.joint_types, strict=True) if t != "revolute"]
    if bad:
        raise RobotModelError(
            f"{mm.name}: maximal-coordinate dynamics support revolute joints only; "
            f"unsupported: {', '.join(f'{n} ({t})' for n, t in bad)}"
        )


def multibody_layout(
    mm: MaximalModel,
    N: int,
    dt: float,
    *,
    jit: bool,
    kinematics: bool = True,
    fixed_tau_knots: tuple[int, ...] = (0,),
) -> MultibodyLayout:
    """Blocks and equality terms for ``N`` steps of the multi-body LGVI.

    ``kinematics=False`` leaves out the kinematics rows (for a one-step simulator whose ``R, p``
    at both knots are data). ``fixed_tau_knots`` are the knots whose torques are data.
    """
    check_supported(mm)
    nb = mm.nb
    blocks = [
        Block("R", SO3, N + 1, (0,) if kinematics else (0, 1), nb),
        Block("p", R(3), N + 1, (0,) if kinematics else (0, 1), nb),
        Block("F", SO3, N + 1, (0,), nb),
        Block("v", R(3), N + 1, (0,), nb),
        Block("lam", R(LAMBDA_DIM), N + 1, (0,), nb),
        Block("tau", R(1), N + 1, fixed_tau_knots, nb),
    ]
    k, b = (a.ravel() for a in np.meshgrid(np.arange(N), np.arange(nb), indexing="ij"))
    site0, site1 = k * nb + b, (k + 1) * nb + b  # body b at knots k and k+1
    terms: list[Term] = []
    if kinematics:
        kin = {"R0": ("R", site0), "R1": ("R", site1), "F0": ("F", site0)}
        kin |= {"p0": ("p", site0), "p1": ("p", site1), "v0": ("v", site0)}
        terms.append(Term("body_kinematics", "eq", _kinematics_function(jit), kin, {"dt": dt}))
    dyn_offset = 6 * N * nb if kinematics else 0
    dyn_bind = {"F0": ("F", site0), "F1": ("F", site1), "v0": ("v", site0), "v1": ("v", site1)}
    dyn_params = {
        "J": mm.inertia_nonstandard[b],
        "mass": mm.mass[b],
        "gravity": mm.gravity,
        "dt": dt,
    }
    terms.append(Term("body_dynamics", "eq", _dynamics_function(jit), dyn_bind, dyn_params))

    def dyn_rows(step: np.ndarray, body: np.ndarray) -> np.ndarray:
        return dyn_offset + 6 * (step * nb + body)[:, None] + np.arange(6)

    for world in (True, False):
        joints = np.flatnonzero((mm.parent < 0) == world)
        if joints.size == 0:
            continue
        kj, j = (a.ravel() for a in np.meshgrid(np.arange(N), joints, indexing="ij"))
        par = mm.parent[j]
        params = {
            "r_p": mm.r_parent[j],
            "r_c": mm.r_child[j],
            "perp_p": np.swapaxes(mm.perp_parent[j], -1, -2),
            "axis_c": mm.axis_child[j],
            "dt": dt,
        }
        if world:
            params |= {"Rp": np.eye(3), "pp": np.zeros(3)}
        nxt = (kj + 1) * nb
        child = {
            "Rc": ("R", nxt + j),
            "pc": ("p", nxt + j),
            "lam": ("lam", nxt + j),
            "tau": ("tau", nxt + j),
        }
        rows = dyn_rows(kj, j)
        if not world:
            child |= {"Rp": ("R", nxt + par), "pp": ("p", nxt + par)}
            rows = np.concatenate([dyn_rows(kj, par), rows], axis=1)
        name = "joint_forces_world" if world else "joint_forces"
        forces = {n: v for n, v in params.items() if n != "dt"}
        terms.append(Term(name, "eq", _joint_forces_function(jit, world), child, forces, rows=rows))
        # Constraints on x_{k+2} = (R_{k+1} F_{k+1}, p_{k+1} + v_{k+1} Δt), from knot k+1's data.
        cons = {f"{n}c": (n, nxt + j) for n in ("R", "F", "p", "v")}
        if not world:
            cons |= {f"{n}p": (n, nxt + par) for n in ("R", "F", "p", "v")}
        terms.append(
            Term(
                f"joint_constraints{'_world' if world else ''}",
                "eq",
                _constraint_function(jit, world),
                cons,
                params,
            )
        )
    return MultibodyLayout(blocks, terms, dyn_offset + 6 * N * nb)
