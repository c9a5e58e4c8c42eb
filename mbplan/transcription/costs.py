"""Cost residuals (RIPM paper §VIII.A): weighted chordal distance on SO(3) and quadratic on Rⁿ."""

from __future__ import annotations

import casadi as cs


def chordal_cost(R: cs.SX, R_d: cs.SX, W: cs.SX) -> cs.SX:
    """``½ tr((R R_dᵀ - I) W (R R_dᵀ - I)ᵀ)`` (eq. 57)."""
    E = cs.mtimes(R, R_d.T) - cs.DM.eye(3)
    return 0.5 * cs.trace(cs.mtimes([E, W, E.T]))


def quadratic_cost(x: cs.SX, x_d: cs.SX, W: cs.SX) -> cs.SX:
    """``½ (x - x_d)ᵀ W (x - x_d)`` (eq. 59)."""
    e = x - x_d
    return 0.5 * cs.mtimes([e.T, W, e])
