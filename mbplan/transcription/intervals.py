"""The bodies' poses between the LGVI's knots, where obstacle rows that hold between knots are
evaluated in maximal coordinates.

The LGVI steps each body by ``R_{k+1} = R_k F_k`` and ``p_{k+1} = p_k + Δt v_k`` (eq. 27), so
the pose at the fraction ``s ∈ [0, 1]`` of interval ``k`` is taken on the geodesic between the
knots, ``(R_k exp(s log F_k), p_k + sΔt v_k)``: a function of knot ``k``'s variables alone, equal
to the knots at ``s = 0`` and ``s = 1``. It is the chord of the body's path over the interval,
within ``⅛Δt²‖a‖`` of the continuous motion (``a``: the body's acceleration), like the knots
themselves lie on it to second order.
"""

from __future__ import annotations

from typing import Any

import casadi as cs
import numpy as np

from mbplan.lie import SO3

FRACTIONS = (0.5,)
"""The fractions ``s`` of every interval at the centre of its obstacle rows' secant (the knots
are ``s = 0`` and ``s = 1``)."""
SECANT_HALF_WIDTH = 0.25
"""An obstacle row between knots is the line through its values at the fractions ``s ∓ δ`` of
the interval, evaluated at both ends, :data:`SECANT_ENDS`. Where the row is concave along the
interval (a distance to a convex obstacle along a straight motion) the line lies above it
outside ``[s - δ, s + δ]``, so both ends ``≤ 0`` keep the row ``≤ 0`` there. Between the samples
it can exceed the line by the row's curvature times ``δ²/2``, or by its slope times ``δ`` where
the row has a kink (a link passing a box's edge: a tent peaking between the samples); the row
at the centre ``s`` itself halves that span."""
SECANT_ENDS = np.array([0.0, 1.0])
INTERVAL_ROWS = len(SECANT_ENDS) + 1
"""Rows of an obstacle row between knots per interval: the secant at :data:`SECANT_ENDS` and
the row at the secant's centre."""


def secant_weights(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples ``(K, 3)`` ``s - δ, s, s + δ`` of the rows between knots centred at ``s (K,)``
    and their weights ``(K, 3, 3)`` ``[site, row, sample]``: rows 0 and 1 the line through the
    values at ``s ∓ δ`` at ``σ = 0, 1``, row 2 the value at ``s``."""
    s = np.asarray(s, dtype=float)
    lo, hi = s - SECANT_HALF_WIDTH, s + SECANT_HALF_WIDTH
    width = (hi - lo)[:, None]
    ends = len(SECANT_ENDS)
    weights = np.zeros((s.size, INTERVAL_ROWS, 3))  # samples s - δ, s, s + δ
    weights[:, :ends, 0] = (hi[:, None] - SECANT_ENDS[None]) / width
    weights[:, :ends, 2] = (SECANT_ENDS[None] - lo[:, None]) / width
    weights[:, ends, 1] = 1.0
    return np.stack([lo, s, hi], axis=1), weights


def interval_pose(R: Any, p: Any, F: Any, v: Any, s: Any, h: Any) -> tuple[Any, Any]:
    """``(R exp(s log F), p + h v)`` with ``h = sΔt``: CasADi symbols, or NumPy batches ``R, F
    (K, 3, 3)``, ``p, v (K, 3)``, ``s, h (K,)``."""
    if isinstance(R, np.ndarray):
        phi = SO3.log(F) * np.asarray(s)[:, None]
        return R @ SO3.exp(phi), p + np.asarray(h)[:, None] * v
    return cs.mtimes(R, SO3.exp(s * SO3.log(F))), p + h * v


def interval_samples(knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The intervals ``k = knot - 1`` ending at an item's ``knots``, without interval 0 (its
    variables are the fixed initial state), once per fraction: ``(k, s)``, interval-major."""
    intervals = np.asarray(knots, dtype=np.int64) - 1
    intervals = intervals[intervals >= 1]
    k, s = np.meshgrid(intervals, np.asarray(FRACTIONS), indexing="ij")
    return k.ravel(), s.ravel()
