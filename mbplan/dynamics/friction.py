"""Coulomb friction at a point contact on a horizontal ground (normal ``+z``)."""

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
