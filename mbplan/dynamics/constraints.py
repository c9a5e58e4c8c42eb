"""Holonomic constraints between rigid bodies (RIPM paper §VI.A–B, eq. 36–45, Table I)."""

from __future__ import annotations

import casadi as cs

from mbplan.lie import SO3


def pivot_constraint(R1: cs.SX, p1: cs.SX, R2: cs.SX, p2: cs.SX, r1: cs.SX, r2: cs.SX) -> cs.SX:
    """``R₁r₁ + p₁ - (R₂r₂ + p₂) = 0``: a point fixed in both bodies coincides (eq. 44)."""
    return cs.mtimes(R1, r1) + p1 - cs.mtimes(R2, r2) - p2


def axis_constraint(R1: cs.SX, R2: cs.SX, perp1: cs.SX, axis2: cs.SX) -> cs.SX:
    """``(R₁ e_i)ᵀ(R₂ a) = 0`` for the two rows ``e_i`` of ``perp1`` (2×3), eq. 45.

    With ``a`` the joint axis in body 2 and ``e_i`` orthogonal to the axis in body 1, the two
    residuals vanish iff the axis is the same line direction in both bodies.
    """
    return cs.mtimes(cs.mtimes(perp1, R1.T), cs.mtimes(R2, axis2))


def kinematic_chain(factors: list[cs.SX], Ybar_inv: cs.SX, group=SO3) -> cs.SX:
    """``log(Ȳ⁻¹ X₁ X₂ ⋯ X_n)`` for ``X₁⋯X_n = I`` shifted to the operating point (eq. 37–38).

    ``group`` must have a symbolic ``log`` (SO(3) or SE(3)).
    """
    return group.log(cs.mtimes([Ybar_inv, *factors]))
