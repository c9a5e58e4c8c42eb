"""Transcription of a maximal-coordinate multi-body system (RIPM paper §V.A, §VI.B–C, Fig. 2).

Blocks (``nb`` elements per knot, one per body, or ``nj`` per knot, one per joint slot:
:attr:`~mbplan.multibody.MaximalModel.jointed`), knots ``k = 0 … N``: ``R, F`` (SO(3)), ``p, v``
(R³), ``lam`` (R⁵ per joint: a revolute joint's pivot force and axis torques, a prismatic
joint's rotation torques and slide forces), ``tau`` (R¹ per joint: actuation torque or force).
A floating base is a body without a joint: no multipliers, no actuation, no constraint rows.
Knot 0 is the fixed initial state.

Equations (eq. 27–28 with 34–35 per body), per step ``k = 0 … N-1``:

* body kinematics ``R_{k+1} = R_k F_k``, ``p_{k+1} = p_k + v_k Δt``;
* body LGVI ``(F_k, v_k) → (F_{k+1}, v_{k+1})`` with gravity and, added into the same rows by
  joint terms, the constraint forces ``J(x_{k+1})ᵀλ_{k+1}``, actuation ``τ_{k+1}`` and viscous
  damping ``-c q̇_{k+1}`` (:mod:`mbplan.dynamics.damping`; joints with ``c > 0`` only);
* joint constraints on the next configuration ``h(R_{k+1} F_{k+1}, p_{k+1} + v_{k+1} Δt) = 0``;
* loop closures alike, with a block of multipliers per closure size
  (:mod:`mbplan.transcription.loops`).

Each term is one engine function vectorised over (knot, body) or (knot, joint) sites, per joint
kind (revolute, prismatic) and parent (a body or the world), so the Jacobian has the graph
structure of Fig. 2 and evaluation cost is linear in bodies and horizon.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics import body_dynamics, body_kinematics
from mbplan.dynamics.damping import damping_forces
from mbplan.dynamics.joints import (
    prismatic_constraint,
    prismatic_forces,
    prismatic_increment,
    revolute_constraint,
    revolute_forces,
    revolute_increment,
    world_child_rows,
)
from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.transcription.loops import loop_blocks, loop_terms
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block
from mbplan.workspace import Workspace, shared

LAMBDA_DIM = 5  # pivot (3) + axis (2) per revolute joint, rotation (3) + slide (2) per prismatic


@dataclass(frozen=True)
class JointKind:
    """The functions of one joint kind and the :class:`MaximalModel` fields of its parameters."""

    constraint: Callable[..., cs.SX]  # h(Rp, pp, Rc, pc, **params), 5 rows
    forces: Callable[..., cs.SX]  # (Rp, pp, Rc, pc, lam, tau, **params), 12 rows
    increment: Callable[..., cs.SX]  # (pose_a, pose_b, **params): joint coordinate change
    params: tuple[tuple[str, int | tuple[int, int]], ...]


def _revolute_constraint(Rp, pp, Rc, pc, r_p, r_c, perp_p, axis_c):
    return revolute_constraint(Rp, pp, Rc, pc, r_p, r_c, perp_p, axis_c)


def _prismatic_constraint(Rp, pp, Rc, pc, r_p, r_c, perp_p, axis_p, R_rel0):
    return prismatic_constraint(Rp, pp, Rc, pc, r_p, r_c, perp_p, R_rel0)


def _revolute_increment(a, b, r_p, r_c, perp_p, axis_c):
    return revolute_increment(a, b, axis_c)


def _prismatic_increment(a, b, r_p, r_c, perp_p, axis_p, R_rel0):
    return prismatic_increment(a, b, r_p, r_c, axis_p)


_COMMON = (("r_p", 3), ("r_c", 3), ("perp_p", (3, 2)))
JOINT_KINDS: dict[str, JointKind] = {
    "revolute": JointKind(
        _revolute_constraint, revolute_forces, _revolute_increment, (*_COMMON, ("axis_c", 3))
    ),
    "prismatic": JointKind(
        _prismatic_constraint,
        prismatic_forces,
        _prismatic_increment,
        (*_COMMON, ("axis_p", 3), ("R_rel0", (3, 3))),
    ),
}


def joint_parameters(mm: MaximalModel, joints: np.ndarray, kind: str) -> dict[str, np.ndarray]:
    """Per-joint parameter arrays of :data:`JOINT_KINDS` ``[kind]`` for ``joints``."""
    source = {
        "r_p": mm.r_parent,
        "r_c": mm.r_child,
        "perp_p": np.swapaxes(mm.perp_parent, -1, -2),
        "axis_c": mm.axis_child,
        "axis_p": mm.axis_parent,
        "R_rel0": mm.R_rel0,
    }
    return {name: source[name][joints] for name, _ in JOINT_KINDS[kind].params}


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _kinematics_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "body_kinematics",
        [("R0", SO3), ("R1", SO3), ("F0", SO3), ("p0", R(3)), ("p1", R(3)), ("v0", R(3))],
        body_kinematics,
        [("dt", 1)],
        jit=jit,
    )


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _dynamics_function(jit: bool) -> RiemannianFunction:
    return RiemannianFunction(
        "body_dynamics",
        [("F0", SO3), ("F1", SO3), ("v0", R(3)), ("v1", R(3))],
        body_dynamics,
        [("J", (3, 3)), ("mass", 1), ("gravity", 3), ("dt", 1)],
        jit=jit,
    )


_WORLD = [("Rp", (3, 3)), ("pp", 3)]  # a world parent's fixed pose, as parameters


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _joint_forces_function(
    jit: bool, world_parent: bool, kind: str = "revolute"
) -> RiemannianFunction:
    """``J(x_{k+1})ᵀλ_{k+1}`` and actuation ``τ_{k+1}`` of a joint (12 rows, 6 to the world)."""
    jk = JOINT_KINDS[kind]
    child = [("Rc", SO3), ("pc", R(3)), ("lam", R(LAMBDA_DIM)), ("tau", R(1))]
    if world_parent:
        fn = world_child_rows(jk.forces)
        return RiemannianFunction(f"{kind}_forces_world", child, fn, [*_WORLD, *jk.params], jit=jit)
    variables = [("Rp", SO3), ("pp", R(3)), *child]
    return RiemannianFunction(f"{kind}_forces", variables, jk.forces, list(jk.params), jit=jit)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _constraint_function(
    jit: bool, world_parent: bool, kind: str = "revolute"
) -> RiemannianFunction:
    """``h(x_{k+1})`` with ``x_{k+1} = (R_k F_k, p_k + v_k Δt)`` for both bodies."""
    jk = JOINT_KINDS[kind]
    body = [("R", SO3), ("F", SO3), ("p", R(3)), ("v", R(3))]
    child = [(f"{n}c", g) for n, g in body]
    params = [*jk.params, ("dt", 1)]
    if world_parent:

        def world_fn(Rc, Fc, pc, vc, Rp, pp, dt, **g):
            return jk.constraint(Rp, pp, cs.mtimes(Rc, Fc), pc + vc * dt, **g)

        name = f"{kind}_constraint_world"
        return RiemannianFunction(name, child, world_fn, [*_WORLD, *params], jit=jit)

    def fn(Rp, Fp, pp, vp, Rc, Fc, pc, vc, dt, **g):
        return jk.constraint(cs.mtimes(Rp, Fp), pp + vp * dt, cs.mtimes(Rc, Fc), pc + vc * dt, **g)

    variables = [(f"{n}p", g) for n, g in body] + child
    return RiemannianFunction(f"{kind}_constraint", variables, fn, params, jit=jit)


_MOTION = [("R", SO3), ("p", R(3)), ("F0", SO3), ("F1", SO3), ("v0", R(3)), ("v1", R(3))]


def _side(side: str) -> list[tuple[str, object]]:
    """``_MOTION`` variables of the parent (``"p"``) or child (``"c"``): ``Rc, pc, Fc0, …``."""
    return [(n[0] + side + n[1:], g) for n, g in _MOTION]


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _damping_function(jit: bool, world_parent: bool, kind: str = "revolute") -> RiemannianFunction:
    """Viscous damping ``-c q̇_{k+1}`` of a joint (:mod:`mbplan.dynamics.damping`)."""
    jk = JOINT_KINDS[kind]
    params = [*jk.params, ("damping", 1), ("dt", 1)]

    def fn(Rp, pp, Fp0, Fp1, vp0, vp1, Rc, pc, Fc0, Fc1, vc0, vc1, damping, dt, **g):
        def increment(a, b):
            return jk.increment(a, b, **g)

        motion = (Rp, pp, Fp0, Fp1, vp0, vp1, Rc, pc, Fc0, Fc1, vc0, vc1)
        return damping_forces(increment, *motion, damping, dt)

    if world_parent:

        def world_fn(Rc, pc, Fc0, Fc1, vc0, vc1, Rp, pp, damping, dt, **g):
            eye, zero = cs.DM.eye(3), cs.DM.zeros(3)
            still = (Rp, pp, eye, eye, zero, zero)
            return fn(*still, Rc, pc, Fc0, Fc1, vc0, vc1, damping, dt, **g)[6:]

        name = f"{kind}_damping_world"
        return RiemannianFunction(name, _side("c"), world_fn, [*_WORLD, *params], jit=jit)
    return RiemannianFunction(f"{kind}_damping", _side("p") + _side("c"), fn, params, jit=jit)


def dynamics_rows(
    nb: int, N: int, step: np.ndarray, body: np.ndarray, kinematics: bool = True
) -> np.ndarray:
    """The ``(K, 6)`` LGVI dynamics rows of ``body`` at ``step`` (arrays of ``K``) in the
    equality rows of :func:`multibody_layout` (after the kinematics rows, if any)."""
    offset = 6 * N * nb if kinematics else 0
    return offset + 6 * (np.asarray(step) * nb + np.asarray(body))[:, None] + np.arange(6)


@dataclass(frozen=True)
class MultibodyLayout:
    """Blocks and equality terms of the multi-body dynamics over ``N`` steps."""

    blocks: tuple[Block, ...]
    terms: tuple[Term, ...]
    n_dynamics_rows: int


def multibody_layout(
    mm: MaximalModel,
    N: int,
    dt: float,
    *,
    jit: bool,
    kinematics: bool = True,
    fixed_tau_knots: tuple[int, ...] = (0,),
    workspace: Workspace | None = None,
) -> MultibodyLayout:
    """Blocks and equality terms for ``N`` steps of the multi-body LGVI (kept in ``workspace``:
    the terms are shared, never modified).

    ``kinematics=False`` leaves out the kinematics rows (for a one-step simulator whose ``R, p``
    at both knots are data). ``fixed_tau_knots`` are the knots whose torques are data.
    """
    key = (mm, int(N), float(dt), bool(jit), bool(kinematics), tuple(fixed_tau_knots))
    return shared(workspace, "multibody_layout", lambda: key, lambda: _multibody_layout(*key))


def _multibody_layout(
    mm: MaximalModel,
    N: int,
    dt: float,
    jit: bool,
    kinematics: bool,
    fixed_tau_knots: tuple[int, ...],
) -> MultibodyLayout:
    """:func:`multibody_layout`, built."""
    nb = mm.nb
    blocks = [
        Block("R", SO3, N + 1, (0,) if kinematics else (0, 1), nb),
        Block("p", R(3), N + 1, (0,) if kinematics else (0, 1), nb),
        Block("F", SO3, N + 1, (0,), nb),
        Block("v", R(3), N + 1, (0,), nb),
        Block("lam", R(LAMBDA_DIM), N + 1, (0,), mm.nj),
        Block("tau", R(1), N + 1, fixed_tau_knots, mm.nj),
        *loop_blocks(mm, N),
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
        return dynamics_rows(nb, N, step, body, kinematics)

    types = np.array(mm.joint_types)
    for kind in JOINT_KINDS:
        prefix = "" if kind == "revolute" else f"{kind}_"
        for world in (True, False):
            joints = np.flatnonzero(((mm.parent < 0) == world) & (types == kind))
            if joints.size == 0:
                continue
            kj, j = (a.ravel() for a in np.meshgrid(np.arange(N), joints, indexing="ij"))
            par = mm.parent[j]
            params: dict = joint_parameters(mm, j, kind)
            if world:
                params |= {"Rp": np.eye(3), "pp": np.zeros(3)}
            now, nxt = kj * nb, (kj + 1) * nb
            slot = (kj + 1) * mm.nj + mm.joint_slot[j]
            child = {
                "Rc": ("R", nxt + j),
                "pc": ("p", nxt + j),
                "lam": ("lam", slot),
                "tau": ("tau", slot),
            }
            rows = dyn_rows(kj, j)
            if not world:
                child |= {"Rp": ("R", nxt + par), "pp": ("p", nxt + par)}
                rows = np.concatenate([dyn_rows(kj, par), rows], axis=1)
            suffix = "_world" if world else ""
            fn = _joint_forces_function(jit, world, kind)
            terms.append(Term(f"{prefix}joint_forces{suffix}", "eq", fn, child, params, rows=rows))
            # Constraints on x_{k+2} = (R_{k+1} F_{k+1}, p_{k+1} + v_{k+1} Δt), from knot k+1's data.
            cons = {f"{n}c": (n, nxt + j) for n in ("R", "F", "p", "v")}
            if not world:
                cons |= {f"{n}p": (n, nxt + par) for n in ("R", "F", "p", "v")}
            fn = _constraint_function(jit, world, kind)
            terms.append(
                Term(f"{prefix}joint_constraints{suffix}", "eq", fn, cons, params | {"dt": dt})
            )
            damped = mm.damping[j] > 0.0
            if damped.any():
                terms.append(
                    _damping_term(mm, kind, world, jit, now, nxt, j, damped, params, rows, dt)
                )
    terms += loop_terms(mm, N, dt, jit, dyn_rows)
    return MultibodyLayout(tuple(blocks), tuple(terms), dyn_offset + 6 * N * nb)


def _damping_term(mm, kind, world, jit, now, nxt, j, damped, params, rows, dt) -> Term:
    """The damping term of the damped joints ``j[damped]`` (sites of one joint-force term)."""
    now, nxt, j = now[damped], nxt[damped], j[damped]
    sides = [("c", j)] if world else [("p", mm.parent[j]), ("c", j)]
    bind = {}
    for side, body in sides:
        bind |= {f"R{side}": ("R", nxt + body), f"p{side}": ("p", nxt + body)}
        bind |= {f"F{side}0": ("F", now + body), f"F{side}1": ("F", nxt + body)}
        bind |= {f"v{side}0": ("v", now + body), f"v{side}1": ("v", nxt + body)}
    per = {n: (v[damped] if n not in ("Rp", "pp") or not world else v) for n, v in params.items()}
    per |= {"damping": mm.damping[j], "dt": dt}
    fn = _damping_function(jit, world, kind)
    name = f"{'' if kind == 'revolute' else kind + '_'}joint_damping{'_world' if world else ''}"
    return Term(name, "eq", fn, bind, per, rows=rows[damped])
