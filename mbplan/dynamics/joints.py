"""Joints between rigid bodies in maximal coordinates: constraints ``h(x) = 0`` (eq. 24, 28,
Table I rows 5–6) and the generalized forces ``J(x)ᵀλ`` (eq. 25–27) plus actuation they apply.

Generalized forces are expressed per body as a body-frame torque and a world-frame force, the
same coordinates as the body's LGVI rows (:func:`mbplan.dynamics.rigid_body.body_dynamics`, in
N·m and N), so a joint term adds ``-torque`` to a body's rotational and ``-force`` to its
translational row. Pivot / slide multipliers are then forces in N and axis / rotation
multipliers torques in N·m.

Both joint kinds have 5 multipliers: a revolute joint's pivot (3) and axis (2) constraints, a
prismatic joint's fixed relative rotation (3) and slide constraints (2). Actuation ``u`` (torque
or force along the axis) and any other generalized joint force ``u`` enter as ``u ∇q(x)``, the
gradient of the joint coordinate in the same Riemannian coordinates, so the lever arms of a
prismatic force are those of its two pivot points by construction.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import casadi as cs

from mbplan.dynamics.constraints import axis_constraint, pivot_constraint
from mbplan.lie import SO3

Pose = tuple[cs.SX, cs.SX, cs.SX, cs.SX]  # (R_parent, p_parent, R_child, p_child)


def revolute_constraint(
    Rp: cs.SX, pp: cs.SX, Rc: cs.SX, pc: cs.SX, r_p: cs.SX, r_c: cs.SX, perp_p: cs.SX, axis_c: cs.SX
) -> cs.SX:
    """Pivot (3) + axis (2): the 5 residuals of a revolute joint (Table I rows 5–6).

    ``r_p``/``r_c``: joint centre from each COM in body coordinates; ``axis_c``: joint axis in the
    child frame; ``perp_p`` (3×2, columns): two unit vectors orthogonal to the axis in the parent.
    """
    return cs.vertcat(
        pivot_constraint(Rp, pp, Rc, pc, r_p, r_c), axis_constraint(Rp, Rc, perp_p.T, axis_c)
    )


def prismatic_constraint(
    Rp: cs.SX, pp: cs.SX, Rc: cs.SX, pc: cs.SX, r_p: cs.SX, r_c: cs.SX, perp_p: cs.SX, R_rel0: cs.SX
) -> cs.SX:
    """Fixed relative rotation (3) + slide (2): the 5 residuals of a prismatic joint.

    ``vee(M - Mᵀ)/2 = 0`` with ``M = R_rel0ᵀ R_pᵀ R_c`` (equal to ``log M`` to first order) and
    ``perp_pᵀ R_pᵀ (R_c r_c + p_c - R_p r_p - p_p) = 0``: the pivot points separate along the axis.
    """
    M = cs.mtimes([R_rel0.T, Rp.T, Rc])
    rotation = 0.5 * SO3.vee(M - M.T)
    slide = cs.mtimes(perp_p.T, cs.mtimes(Rp.T, -pivot_constraint(Rp, pp, Rc, pc, r_p, r_c)))
    return cs.vertcat(rotation, slide)


def revolute_increment(a: Pose, b: Pose, axis_c: cs.SX) -> cs.SX:
    """Joint angle from configuration ``a`` to ``b``: ``θ`` of ``R_rel,aᵀ R_rel,b = exp(θ axis_c)``
    (``atan2`` form, free of wrapping for steps below π)."""
    E = cs.mtimes([a[2].T, a[0], b[0].T, b[2]])
    s = 0.5 * cs.dot(axis_c, SO3.vee(E - E.T))
    return cs.atan2(s, 0.5 * (cs.trace(E) - 1.0))


def prismatic_displacement(x: Pose, r_p: cs.SX, r_c: cs.SX, axis_p: cs.SX) -> cs.SX:
    """Joint displacement ``(R_p axis_p)ᵀ(R_c r_c + p_c - R_p r_p - p_p)`` (m)."""
    Rp, pp, Rc, pc = x
    return cs.dot(cs.mtimes(Rp, axis_p), -pivot_constraint(Rp, pp, Rc, pc, r_p, r_c))


def prismatic_increment(a: Pose, b: Pose, r_p: cs.SX, r_c: cs.SX, axis_p: cs.SX) -> cs.SX:
    """Joint displacement from configuration ``a`` to ``b`` (m)."""
    return prismatic_displacement(b, r_p, r_c, axis_p) - prismatic_displacement(a, r_p, r_c, axis_p)


def constraint_forces(
    h: Callable[..., cs.SX], bodies: Sequence[tuple[cs.SX, cs.SX]], lam: cs.SX
) -> list[tuple[cs.SX, cs.SX]]:
    """``J(x)ᵀλ`` of ``h(R₁, p₁, R₂, p₂, …)`` per body as (body torque, world force) (eq. 26–27).

    ``J`` is the Riemannian Jacobian along ``R exp(η)``, ``p + δp``, taken symbolically so that it
    stays exact for any constraint; the result is an expression of the bodies' states and ``λ``.
    """
    eta = cs.SX.sym("eta", 6 * len(bodies))
    perturbed = []
    for i, (R, p) in enumerate(bodies):
        e = eta[6 * i : 6 * i + 6]
        perturbed += [cs.mtimes(R, cs.DM.eye(3) + cs.skew(e[:3])), p + e[3:]]
    J = cs.jacobian(h(*perturbed), eta)
    gen = cs.substitute(cs.mtimes(J.T, lam), eta, cs.DM.zeros(eta.size1()))
    return [(gen[6 * i : 6 * i + 3], gen[6 * i + 3 : 6 * i + 6]) for i in range(len(bodies))]


def joint_coordinate_forces(increment: Callable[[Pose, Pose], cs.SX], x: Pose, u: cs.SX) -> cs.SX:
    """Rows ``-u ∇q(x)`` (parent rot., trans., child rot., trans.; 12) of a generalized joint
    force ``u``, with ``∇q`` the gradient of ``increment(x, ·)`` at ``x``."""
    (tp, fp), (tc, fc) = constraint_forces(
        lambda *y: increment(x, y), [(x[0], x[1]), (x[2], x[3])], u
    )
    return cs.vertcat(-tp, -fp, -tc, -fc)


def revolute_forces(
    Rp: cs.SX,
    pp: cs.SX,
    Rc: cs.SX,
    pc: cs.SX,
    lam: cs.SX,
    tau: cs.SX,
    r_p: cs.SX,
    r_c: cs.SX,
    perp_p: cs.SX,
    axis_c: cs.SX,
) -> cs.SX:
    """Contributions of a revolute joint to the dynamics rows of its two bodies (12 rows).

    Rows: parent rotational (3), parent translational (3), child rotational (3), child
    translational (3). Actuation ``τ`` turns the child about the axis (``+τ a`` in the child
    frame) and the parent the other way (``-τ R_pᵀR_c a``).
    """

    def h(Rp_, pp_, Rc_, pc_):
        return revolute_constraint(Rp_, pp_, Rc_, pc_, r_p, r_c, perp_p, axis_c)

    (tp, fp), (tc, fc) = constraint_forces(h, [(Rp, pp), (Rc, pc)], lam)
    act_c = tau * axis_c
    act_p = -tau * cs.mtimes([Rp.T, Rc, axis_c])
    return cs.vertcat(-(tp + act_p), -fp, -(tc + act_c), -fc)


def prismatic_forces(
    Rp: cs.SX,
    pp: cs.SX,
    Rc: cs.SX,
    pc: cs.SX,
    lam: cs.SX,
    tau: cs.SX,
    r_p: cs.SX,
    r_c: cs.SX,
    perp_p: cs.SX,
    axis_p: cs.SX,
    R_rel0: cs.SX,
) -> cs.SX:
    """:func:`revolute_forces` of a prismatic joint: ``J(x)ᵀλ`` of :func:`prismatic_constraint`
    and the force ``τ`` along the axis, equal and opposite on the two pivot points."""

    def h(Rp_, pp_, Rc_, pc_):
        return prismatic_constraint(Rp_, pp_, Rc_, pc_, r_p, r_c, perp_p, R_rel0)

    (tp, fp), (tc, fc) = constraint_forces(h, [(Rp, pp), (Rc, pc)], lam)
    x = (Rp, pp, Rc, pc)
    act = joint_coordinate_forces(lambda a, b: prismatic_increment(a, b, r_p, r_c, axis_p), x, tau)
    return cs.vertcat(-tp, -fp, -tc, -fc) + act


def world_child_rows(forces: Callable[..., cs.SX]) -> Callable[..., cs.SX]:
    """``forces`` for a joint to a fixed parent (the world, ``Rp``/``pp`` data): child rows (6)."""

    def child(Rc, pc, lam, tau, Rp, pp, **params):
        return forces(Rp, pp, Rc, pc, lam, tau, **params)[6:]

    return child
