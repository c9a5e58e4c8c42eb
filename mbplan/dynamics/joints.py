"""Joints between rigid bodies in maximal coordinates: constraints ``h(x) = 0`` (eq. 24, 28,
Table I rows 5–6) and the generalized forces ``J(x)ᵀλ`` (eq. 25–27) plus actuation they apply.

Generalized forces are expressed per body as a body-frame torque and a world-frame force, the
same coordinates as the body's LGVI rows (:func:`mbplan.dynamics.rigid_body.body_dynamics`, in
N·m and N), so a joint term adds ``-torque`` to a body's rotational and ``-force`` to its
translational row. Pivot multipliers are then forces in N and axis multipliers torques in N·m.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import casadi as cs

from mbplan.dynamics.constraints import axis_constraint, pivot_constraint


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


def revolute_forces_on_child(
    Rc: cs.SX,
    pc: cs.SX,
    lam: cs.SX,
    tau: cs.SX,
    Rp: cs.SX,
    pp: cs.SX,
    r_p: cs.SX,
    r_c: cs.SX,
    perp_p: cs.SX,
    axis_c: cs.SX,
) -> cs.SX:
    """:func:`revolute_forces` for a joint to a fixed parent (the world): child rows only (6)."""
    return revolute_forces(Rp, pp, Rc, pc, lam, tau, r_p, r_c, perp_p, axis_c)[6:]
