"""Coulomb friction at a point contact or a flat rectangular sole on the ground (normal ``+z``
of the contact frame)."""

from __future__ import annotations

import numpy as np


def pyramid(friction: float) -> np.ndarray:
    """The rows ``A (4, 3)`` of the friction pyramid ``A f ≤ 0`` inscribed in the cone
    ``‖f_xy‖ ≤ μ f_z``: ``±f_x - μ' f_z ≤ 0``, ``±f_y - μ' f_z ≤ 0`` with ``μ' = μ/√2`` (its
    edges lie on the cone; it also makes the normal force unilateral, ``f_z ≥ 0``)."""
    mu = friction / np.sqrt(2.0)
    return np.array([[1.0, 0.0, -mu], [-1.0, 0.0, -mu], [0.0, 1.0, -mu], [0.0, -1.0, -mu]])


def pyramid_edges(friction: float) -> np.ndarray:
    """The four edges ``(±μ', ±μ', 1)`` ``(4, 3)`` of the :func:`pyramid`: its forces are their
    non-negative combinations."""
    mu = friction / np.sqrt(2.0)
    return np.array([[mu, mu, 1.0], [mu, -mu, 1.0], [-mu, mu, 1.0], [-mu, -mu, 1.0]])


def cone_violation(forces: np.ndarray, friction: float) -> np.ndarray:
    """``max(‖f_xy‖ - μ f_z, 0)`` of forces ``(..., 3)``: how far each leaves the cone (N)."""
    f = np.asarray(forces, dtype=float)
    return np.maximum(np.linalg.norm(f[..., :2], axis=-1) - friction * f[..., 2], 0.0)


def _corners(length: float, width: float) -> np.ndarray:
    """The corners ``(±X, ±Y, 0)`` ``(4, 3)`` of a ``length × width`` sole (half-sizes ``X, Y``)."""
    x, y = 0.5 * length, 0.5 * width
    return np.array([[x, y, 0.0], [x, -y, 0.0], [-x, y, 0.0], [-x, -y, 0.0]])


def wrench_cone(friction: float, length: float, width: float) -> np.ndarray:
    """The rows ``A (16, 6)`` of the contact wrench cone ``A w ≤ 0`` of a rectangular sole
    (``length`` along its ``x``, ``width`` along its ``y``) for wrenches ``w = (f, τ)`` about
    its centre in its frame: the wrenches of corner forces inside the :func:`pyramid`
    (Caron, Pham & Nakamura 2015, eq. 17–19 with ``μ' = μ/√2``): the pyramid on ``f``, the
    centre of pressure inside the sole (``|τ_x| ≤ Y f_z``, ``|τ_y| ≤ X f_z``) and the yaw
    torque between ``-μ'(X+Y) f_z + |Y f_x ∓ μ' τ_x| + |X f_y ∓ μ' τ_y|`` and its mirror."""
    mu, x, y = friction / np.sqrt(2.0), 0.5 * length, 0.5 * width
    rows = [np.concatenate([a, np.zeros(3)]) for a in pyramid(friction)]
    for sx in (1.0, -1.0):
        rows.append([0.0, 0.0, -y, sx, 0.0, 0.0])  # ±τ_x - Y f_z
        rows.append([0.0, 0.0, -x, 0.0, sx, 0.0])  # ±τ_y - X f_z
    for sz in (1.0, -1.0):  # τ_z ≤ τ_max (sz = 1), -τ_z ≤ -τ_min (sz = -1)
        for s1 in (1.0, -1.0):
            for s2 in (1.0, -1.0):
                rows.append([s1 * y, s2 * x, -mu * (x + y), sz * s1 * mu, sz * s2 * mu, sz])
    return np.array(rows)


def wrench_cone_edges(friction: float, length: float, width: float) -> np.ndarray:
    """The 16 wrenches ``(16, 6)`` about the sole's centre of the :func:`pyramid_edges` at its
    corners: the :func:`wrench_cone`'s wrenches are their non-negative combinations."""
    edges = pyramid_edges(friction)
    return np.array(
        [np.concatenate([e, np.cross(c, e)]) for c in _corners(length, width) for e in edges]
    )


def wrench_cone_violation(
    wrenches: np.ndarray, friction: float, length: float, width: float
) -> np.ndarray:
    """``max(A w, 0)`` of wrenches ``(..., 6)`` in their sole's frame (:func:`wrench_cone`'s
    rows as written: N for the pyramid, N m for the centre of pressure and the yaw torque):
    how far each leaves the cone."""
    A = wrench_cone(friction, length, width)
    return np.maximum(np.max(np.asarray(wrenches, dtype=float) @ A.T, axis=-1), 0.0)


def cone_rows(friction: float, sole: tuple[float, float] | None = None) -> np.ndarray:
    """The rows ``A`` of a contact's cone ``A w ≤ 0`` on its variable: a point's
    :func:`pyramid` (``w = f``), a ``sole = (length, width)``'s :func:`wrench_cone`."""
    return pyramid(friction) if sole is None else wrench_cone(friction, *sole)


def cone_edges(friction: float, sole: tuple[float, float] | None = None) -> np.ndarray:
    """The edges ``(n, 3)`` or ``(16, 6)`` of :func:`cone_rows`' cone: its variables are their
    non-negative combinations."""
    return pyramid_edges(friction) if sole is None else wrench_cone_edges(friction, *sole)
