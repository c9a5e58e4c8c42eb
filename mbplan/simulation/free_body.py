"""A free body's discrete dynamics in NumPy: the forced LGVI (RIPM paper eq. 30–35, 60) rolled
forward, with Newton's method on SO(3) for the implicit rotational step (34)."""

from __future__ import annotations

import numpy as np

from mbplan.errors import InputError
from mbplan.lie import SO3

_HAT_BASIS = SO3.hat(np.eye(3))  # e_i^ for the unit vectors e_i
_NEWTON_MAX_ITER = 30
_NEWTON_STEP_TOL = 1e-14  # |ξ| of the last Newton update on SO(3)


def solve_rotational_step(target: np.ndarray, J: np.ndarray, F: np.ndarray, k: int) -> np.ndarray:
    """Newton on SO(3) for ``(F⁺ J - J F⁺ᵀ)^∨ = target`` (eq. 34), started at ``F``.

    The update is ``F ← F exp(ξ^)``; the Jacobian of ``(F exp(ξ^) J - J exp(-ξ^) Fᵀ)^∨`` at
    ``ξ = 0`` is ``ξ ↦ (F ξ^ J + J ξ^ Fᵀ)^∨``.
    """
    for _ in range(_NEWTON_MAX_ITER):
        residual = SO3.vee(F @ J - J @ F.T) - target
        jac = np.column_stack([SO3.vee(F @ E @ J + J @ E @ F.T) for E in _HAT_BASIS])
        try:
            xi = -np.linalg.solve(jac, residual)
        except np.linalg.LinAlgError:
            break
        F = F @ SO3.exp(xi)
        if np.linalg.norm(xi) <= _NEWTON_STEP_TOL:
            return F
    raise InputError(
        f"u[{k}]: the implicit rotational equation (34) has no solution near F_{k}; "
        "angular velocity or torque too large for dt"
    )


def lgvi_step(
    state: tuple[np.ndarray, ...],
    torque: np.ndarray,
    force: np.ndarray,
    J: np.ndarray,
    mass: float,
    gravity: np.ndarray,
    dt: float,
    k: int = 0,
) -> tuple[np.ndarray, ...]:
    """``(R, p, F, v)`` at knot ``k+1`` from knot ``k`` under the body torque ``torque`` and
    the body force ``force`` (rotated to the world by ``R_{k+1}``, eq. 60)."""
    R, p, F, v = state
    R1 = R @ F
    target = SO3.vee(J @ F - F.T @ J) + torque * dt**2
    F1 = solve_rotational_step(target, J, F, k)
    return R1, p + v * dt, F1, v + gravity * dt + R1 @ force * (dt / mass)
