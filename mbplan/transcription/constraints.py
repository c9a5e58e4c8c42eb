"""Constraint residuals shared by the transcriptions (RIPM paper §VIII): obstacle clearance, at a
knot and between knots (:mod:`mbplan.transcription.intervals`)."""

from __future__ import annotations

from functools import cache

import casadi as cs

from mbplan.engine import RiemannianFunction
from mbplan.lie import R
from mbplan.transcription.intervals import SECANT_ENDS, SECANT_HALF_WIDTH


def cylinder_clearance(p: cs.SX, c: cs.SX) -> cs.SX:
    """``r² - ‖p_xy - c_xy‖²`` for the vertical cylinder ``c = (x_c, y_c, r)``: ``≤ 0`` iff the
    point ``p`` is outside it (eq. 62)."""
    d = p[0:2] - c[0:2]
    return c[2] ** 2 - cs.dot(d, d)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def cylinder_clearance_function(jit: bool) -> RiemannianFunction:
    """:func:`cylinder_clearance` of a point ``p ∈ R³`` with the cylinder as parameter ``c``."""
    return RiemannianFunction(
        "cylinder_clearance", [("p", R(3))], cylinder_clearance, [("c", 3)], jit=jit
    )


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def interval_cylinder_clearance_function(jit: bool) -> RiemannianFunction:
    """The rows between knots (:func:`~mbplan.transcription.intervals.secant_weights`) of
    :func:`cylinder_clearance` of the point ``p + tΔt v``: the line through its values at
    ``t = s ∓ δ`` at both ends of the interval, and its value at ``t = s``; the cylinder ``c``,
    the centre ``s`` and ``Δt`` as parameters."""

    def clearance(p: cs.SX, v: cs.SX, c: cs.SX, s: cs.SX, dt: cs.SX) -> cs.SX:
        lo, hi = s - SECANT_HALF_WIDTH, s + SECANT_HALF_WIDTH
        at = [cylinder_clearance(p + t * dt * v, c) for t in (lo, s, hi)]
        line = [(at[0] * (hi - end) + at[2] * (end - lo)) / (hi - lo) for end in SECANT_ENDS]
        return cs.vertcat(*line, at[1])

    return RiemannianFunction(
        "interval_cylinder_clearance",
        [("p", R(3)), ("v", R(3))],
        clearance,
        [("c", 3), ("s", 1), ("dt", 1)],
        jit=jit,
    )
