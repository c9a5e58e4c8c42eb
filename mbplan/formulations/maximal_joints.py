"""Joint-space residuals of an :class:`~mbplan.OCP` on the bodies' poses (maximal coordinates).

Revolute joints, from ``R_rel = R_pᵀR_c = R_rel0 exp(θ a)`` and ``E = R_targetᵀ R_rel =
exp(Δθ a)``:

* joint position: a cost is the chordal distance (eq. 57) ``w (1 - cos Δθ) ≈ ½ w Δθ²`` and a
  constraint ``Δθ = atan2(aᵀ vee(E - Eᵀ)/2, (tr E - 1)/2) = 0``;
* joint velocity, from the steps ``θ_{k+1} - θ_k`` (``R_rel,k+1 = F_pᵀ R_rel,k F_c``): a cost
  (target zero only) ``w (1 - cos(θ_{k+1} - θ_k))/Δt²``, a constraint the central difference
  ``(θ_{k+1} - θ_{k-1})/(2Δt)`` of ``atan2`` steps (the velocity a plan reports);
* joint position limits ``cos(θ - θ_mid) ≥ cos(θ_half)`` and velocity limits
  ``cos(θ_{k+1} - θ_k) ≥ cos(v_max Δt)`` (exact for ranges below 2π:
  :class:`~mbplan.residuals.JointPositionLimits`; symmetric velocity limits); for ranges of a
  turn or more, the angle counted from a reference
  ``θ_ref`` per knot (the warm start's), ``θ = θ_ref + atan2(…)`` of ``E = R_refᵀ R_rel``, in
  ``[lo, hi]``: exact while the joint stays within π of its reference.

Prismatic joints, from the displacement ``d = (R_p a_p)ᵀ(pivot_c - pivot_p)``
(:func:`mbplan.dynamics.joints.prismatic_displacement`): ``½ w (d - d_t)²`` and ``d - d_t``,
the step ``(d_{k+1} - d_k)/Δt`` for velocity costs and limits, ``(d_{k+1} - d_{k-1})/(2Δt)`` for
velocity equalities, and the limits ``(lo - x, x - hi) ≤ 0`` of both.
"""

from __future__ import annotations

from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics.joints import prismatic_displacement
from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.ocp.problem import Item
from mbplan.transcription.costs import chordal_cost
from mbplan.transcription.terms import Term


def _relative(Rp, Fp, Rc, Fc):
    rel = cs.mtimes(Rp.T, Rc)
    return rel, cs.mtimes([Fp.T, rel, Fc])


def _cos_angle(A, B):
    return 0.5 * (cs.trace(cs.mtimes(A.T, B)) - 1.0)


def _angle(A, B, a):
    """Signed angle of ``AᵀB = exp(θ a)`` about ``a``."""
    E = cs.mtimes(A.T, B)
    s = 0.5 * cs.dot(a, cs.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]))
    return cs.atan2(s, 0.5 * (cs.trace(E) - 1.0))


def _position_cost(Rp, Fp, Rc, Fc, R_t, w):
    return chordal_cost(_relative(Rp, Fp, Rc, Fc)[0], R_t, 0.5 * w * cs.DM.eye(3))


def _position_eq(Rp, Fp, Rc, Fc, R_t, a):
    return _angle(R_t, _relative(Rp, Fp, Rc, Fc)[0], a)


def _velocity_cost(Rp, Fp, Rc, Fc, w):
    rel, nxt = _relative(Rp, Fp, Rc, Fc)
    return chordal_cost(nxt, rel, 0.5 * w * cs.DM.eye(3))


def _velocity_eq(Rp, Fp, Fp0, Rc, Fc, Fc0, a, target, dt):
    rel, nxt = _relative(Rp, Fp, Rc, Fc)
    prev = cs.mtimes([Fp0, rel, Fc0.T])  # R_rel,k-1 = F_p,k-1 R_rel,k F_c,k-1ᵀ
    return (_angle(prev, rel, a) + _angle(rel, nxt, a)) / (2.0 * dt) - target


def _position_limits(Rp, Fp, Rc, Fc, R_mid, cos_half):
    return cos_half - _cos_angle(R_mid, _relative(Rp, Fp, Rc, Fc)[0])


def _position_winding(Rp, Fp, Rc, Fc, R_ref, theta_ref, a, lo, hi):
    theta = theta_ref + _angle(R_ref, _relative(Rp, Fp, Rc, Fc)[0], a)
    return cs.vertcat(lo - theta, theta - hi)


def _velocity_limits(Rp, Fp, Rc, Fc, cos_step):
    rel, nxt = _relative(Rp, Fp, Rc, Fc)
    return cos_step - _cos_angle(rel, nxt)


_REVOLUTE = {
    "position_cost": (_position_cost, [("R_t", (3, 3)), ("w", 1)]),
    "position_eq": (_position_eq, [("R_t", (3, 3)), ("a", 3)]),
    "velocity_cost": (_velocity_cost, [("w", 1)]),
    "velocity_eq": (_velocity_eq, [("a", 3), ("target", 1), ("dt", 1)]),
    "position_limits": (_position_limits, [("R_mid", (3, 3)), ("cos_half", 1)]),
    "velocity_limits": (_velocity_limits, [("cos_step", 1)]),
    "position_winding": (
        _position_winding,
        [("R_ref", (3, 3)), ("theta_ref", 1), ("a", 3), ("lo", 1), ("hi", 1)],
    ),
}
_REVOLUTE_VARS = [("Rp", SO3), ("Fp", SO3), ("Rc", SO3), ("Fc", SO3)]


def _displacements(Rp, Fp, pp, vp, Rc, Fc, pc, vc, r_p, r_c, axis_p, dt):
    """``d_k`` and ``d_{k+1}`` of a prismatic joint from knot ``k``'s body states."""
    now = (Rp, pp, Rc, pc)
    nxt = (cs.mtimes(Rp, Fp), pp + vp * dt, cs.mtimes(Rc, Fc), pc + vc * dt)
    return prismatic_displacement(now, r_p, r_c, axis_p), prismatic_displacement(
        nxt, r_p, r_c, axis_p
    )


def _slide_position_cost(*x, t, w, **g):
    return 0.5 * w * (_displacements(*x, **g)[0] - t) ** 2


def _slide_position_eq(*x, t, **g):
    return _displacements(*x, **g)[0] - t


def _slide_velocity_cost(*x, w, **g):
    d0, d1 = _displacements(*x, **g)
    return 0.5 * w * (d1 - d0) ** 2


def _slide_velocity_eq(Rp, Fp, pp, vp, Fp0, vp0, Rc, Fc, pc, vc, Fc0, vc0, target, **g):
    dt = g["dt"]
    prev = (cs.mtimes(Rp, Fp0.T), pp - vp0 * dt, cs.mtimes(Rc, Fc0.T), pc - vc0 * dt)
    d_prev = prismatic_displacement(prev, g["r_p"], g["r_c"], g["axis_p"])
    d1 = _displacements(Rp, Fp, pp, vp, Rc, Fc, pc, vc, **g)[1]
    return (d1 - d_prev) / (2.0 * dt) - target


def _slide_position_limits(*x, lo, hi, **g):
    d = _displacements(*x, **g)[0]
    return cs.vertcat(lo - d, d - hi)


def _slide_velocity_limits(*x, lo, hi, **g):
    d0, d1 = _displacements(*x, **g)
    rate = (d1 - d0) / g["dt"]
    return cs.vertcat(rate - hi, lo - rate)


_PRISMATIC = {
    "position_cost": (_slide_position_cost, [("t", 1), ("w", 1)]),
    "position_eq": (_slide_position_eq, [("t", 1)]),
    "velocity_cost": (_slide_velocity_cost, [("w", 1)]),
    "velocity_eq": (_slide_velocity_eq, [("target", 1)]),
    "position_limits": (_slide_position_limits, [("lo", 1), ("hi", 1)]),
    "velocity_limits": (_slide_velocity_limits, [("lo", 1), ("hi", 1)]),
}
_PRISMATIC_VARS = [
    ("Rp", SO3),
    ("Fp", SO3),
    ("pp", R(3)),
    ("vp", R(3)),
    ("Rc", SO3),
    ("Fc", SO3),
    ("pc", R(3)),
    ("vc", R(3)),
]
_PRISMATIC_GEOMETRY = [("r_p", 3), ("r_c", 3), ("axis_p", 3), ("dt", 1)]
# A velocity equality is the central difference (θ_{k+1} - θ_{k-1})/(2Δt), the velocity the
# plan reports and the verifier checks: it also reads the steps of knot k-1 ("…0").
_CENTRAL = {"revolute": ("F",), "prismatic": ("F", "v")}


def _variables(jtype: str, kind: str) -> list:
    own = _REVOLUTE_VARS if jtype == "revolute" else _PRISMATIC_VARS
    if kind != "velocity_eq":
        return own
    half = own[: len(own) // 2]
    extra = {"F": SO3, "v": R(3)}
    prev = [(f"{n}{side}0", extra[n]) for side in "pc" for n in _CENTRAL[jtype]]
    return half + prev[: len(prev) // 2] + own[len(own) // 2 :] + prev[len(prev) // 2 :]


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def joint_function(jtype: str, kind: str, jit: bool, world: bool) -> RiemannianFunction:
    """The residual ``kind`` of a ``jtype`` joint to a body parent or to the world."""
    variables = _variables(jtype, kind)
    if jtype == "revolute":
        fn, params = _REVOLUTE[kind]
    else:
        slide, own = _PRISMATIC[kind]
        params = own + _PRISMATIC_GEOMETRY

        def fn(*x, **p):
            return slide(*x, **p)

    name = f"joint_{kind}" if jtype == "revolute" else f"prismatic_{kind}"
    if not world:
        return RiemannianFunction(name, variables, fn, params, jit=jit)
    eye, zero = cs.DM.eye(3), cs.DM.zeros(3)
    parent = {"Rp": eye, "Fp": eye, "pp": zero, "vp": zero, "Fp0": eye, "vp0": zero}
    child = variables[len(variables) // 2 :]

    def world_fn(**x):
        return fn(**{n: parent[n] for n, _ in variables[: len(child)]}, **x)

    return RiemannianFunction(f"{name}_world", child, world_fn, params, jit=jit)


def joint_term_name(name: str, jtype: str, world: bool) -> str:
    """The name of the term of the joint residual ``name`` on the ``jtype`` joints with a body
    parent (``world``: to the world) that :func:`joint_terms` makes."""
    return name + ("" if jtype == "revolute" else "_prismatic") + ("_world" if world else "")


def joint_terms(
    mm: MaximalModel,
    item: Item,
    kind: str,
    jit: bool,
    bodies: np.ndarray,
    per_body: dict[str, dict[str, np.ndarray]],
    shared: dict[str, dict[str, float]],
    dt: float,
) -> list[Term]:
    """Terms of residual ``kind`` at ``item.knots × bodies`` per joint type and parent kind.

    ``per_body[jtype]`` holds arrays indexed like ``bodies`` (only that type's entries are
    used), ``shared[jtype]`` scalars."""
    nb = mm.nb
    kk, ii = (a.ravel() for a in np.meshgrid(item.knots, np.arange(len(bodies)), indexing="ij"))
    b = bodies[ii]
    types = np.array(mm.joint_types)[b]
    sense = "cost" if item.role == "cost" else item.residual.sense
    out = []
    for jtype in ("revolute", "prismatic"):
        for world in (True, False):
            mask = ((mm.parent[b] < 0) == world) & (types == jtype)
            if not mask.any():
                continue
            k, bb = kk[mask], b[mask]
            names = ("R", "F") if jtype == "revolute" else ("R", "F", "p", "v")
            bind = {f"{n}c": (n, k * nb + bb) for n in names}
            if not world:
                bind |= {f"{n}p": (n, k * nb + mm.parent[bb]) for n in names}
            if kind == "velocity_eq":  # state knots k ≥ 1: knot k-1 exists
                sides = ("c",) if world else ("c", "p")
                body = {"c": bb, "p": mm.parent[bb]}
                bind |= {
                    f"{n}{s}0": (n, (k - 1) * nb + body[s]) for s in sides for n in _CENTRAL[jtype]
                }
            params = {n: v[ii[mask]] for n, v in per_body[jtype].items()} | shared[jtype]
            if jtype == "prismatic":
                params |= {
                    "r_p": mm.r_parent[bb],
                    "r_c": mm.r_child[bb],
                    "axis_p": mm.axis_parent[bb],
                    "dt": dt,
                }
            fn = joint_function(jtype, kind, jit, world)
            out.append(Term(joint_term_name(item.name, jtype, world), sense, fn, bind, params))
    return out
