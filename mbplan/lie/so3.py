"""SO(3): closed-form exp/log/Jacobians, stable near 0 and near π, numeric and symbolic.

``hat(φ) = [[0, -z, y], [z, 0, -x], [-y, x, 0]]``; ``Ad_R = R``; ``ad_φ = φ^``.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from mbplan.lie.backend import Array, as_numeric, check_symbolic_shape, is_symbolic
from mbplan.lie.group import MatrixLieGroup, check_orthogonal
from mbplan.lie.so3_kernels import SMALL as _SMALL
from mbplan.lie.so3_kernels import exp_batch, product_batch

_NEAR_PI = 1e-4  # sin²θ below which (with cos θ < 0) log uses the symmetric part


def _so3_basis() -> np.ndarray:
    E = np.zeros((3, 3, 3))
    E[0, 2, 1], E[0, 1, 2] = 1.0, -1.0
    E[1, 0, 2], E[1, 2, 0] = 1.0, -1.0
    E[2, 1, 0], E[2, 0, 1] = 1.0, -1.0
    return E


class SO3Group(MatrixLieGroup):
    """The rotation group SO(3)."""

    def __init__(self) -> None:
        super().__init__("SO(3)", 3, _so3_basis())

    def _check_membership(self, X: np.ndarray, what: str) -> None:
        check_orthogonal(X, self.name, what)

    def hat(self, xi: Array) -> Array:
        xi = self._tangent(xi)
        if is_symbolic(xi):
            return cs.skew(xi)
        return _hat_numeric(xi)

    def vee(self, A: Array) -> Array:
        if is_symbolic(A):
            check_symbolic_shape(A, (3, 3), f"{self.name} Lie-algebra matrix")
            return 0.5 * cs.vertcat(A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1])
        A = as_numeric(A, (3, 3), f"{self.name} Lie-algebra matrix")
        return 0.5 * np.stack(
            [A[..., 2, 1] - A[..., 1, 2], A[..., 0, 2] - A[..., 2, 0], A[..., 1, 0] - A[..., 0, 1]],
            -1,
        )

    def inverse(self, X: Array) -> Array:
        X = self._element(X)
        return X.T if is_symbolic(X) else np.swapaxes(X, -1, -2)

    def exp(self, xi: Array) -> Array:
        """Rodrigues' formula ``I + a φ^ + b φ^²``."""
        xi = self._tangent(xi)
        if not is_symbolic(xi):
            return _exp_numeric(xi)
        a, b, _ = _coefficients(xi)
        K = self.hat(xi)
        return cs.DM.eye(3) + a * K + b * cs.mtimes(K, K)

    def retract(self, X: Array, xi: Array) -> Array:
        """``X exp(ξ)`` (eq. 39); ``X`` validated. Numeric batches of equal shape multiply in
        :mod:`~mbplan.lie.so3_kernels`' order (as the packed retraction of trajectory
        variables does)."""
        X = self._element(X)
        E = self.exp(xi)
        if is_symbolic(X, E):
            return cs.mtimes(X, E)
        if X.shape == E.shape and X.dtype == np.float64:
            flat = (-1, 3, 3)
            return product_batch(np.ascontiguousarray(X).reshape(flat), E.reshape(flat)).reshape(
                X.shape
            )
        return X @ E

    def log(self, X: Array) -> Array:
        """Rotation vector of ``X`` with angle in [0, π], accurate near 0 and near π."""
        X = self._element(X)
        if is_symbolic(X):
            return _log_symbolic(X)
        return _log_numeric(X)

    def Ad(self, X: Array) -> Array:
        return self._element(X)

    def ad(self, xi: Array) -> Array:
        return self.hat(xi)

    def jac_right(self, xi: Array) -> Array:
        """``J_r(φ) = I - b φ^ + c φ^²``."""
        return self._jac(xi, sign=-1.0)

    def jac_left(self, xi: Array) -> Array:
        """``J_l(φ) = I + b φ^ + c φ^²``."""
        return self._jac(xi, sign=1.0)

    def jac_right_inv(self, xi: Array) -> Array:
        """``J_r⁻¹(φ) = I + φ^/2 + d φ^²``."""
        return self._jac_inv(xi, sign=1.0)

    def jac_left_inv(self, xi: Array) -> Array:
        """``J_l⁻¹(φ) = I - φ^/2 + d φ^²``."""
        return self._jac_inv(xi, sign=-1.0)

    def _jac(self, xi: Array, sign: float) -> Array:
        xi = self._tangent(xi)
        K = self.hat(xi)
        _, b, c = _coefficients(xi)
        if is_symbolic(xi):
            return cs.DM.eye(3) + sign * b * K + c * cs.mtimes(K, K)
        return np.eye(3) + sign * b[..., None, None] * K + c[..., None, None] * (K @ K)

    def _jac_inv(self, xi: Array, sign: float) -> Array:
        xi = self._tangent(xi)
        K = self.hat(xi)
        d = _inverse_coefficient(xi)
        if is_symbolic(xi):
            return cs.DM.eye(3) + sign * 0.5 * K + d * cs.mtimes(K, K)
        return np.eye(3) + sign * 0.5 * K + d[..., None, None] * (K @ K)


# hat(φ) as a flat 3 x 3: entries (row-major position) taken from φ's components with a sign
_HAT_DST = np.array([1, 2, 3, 5, 6, 7])
_HAT_SRC = np.array([2, 1, 2, 0, 1, 0])
_HAT_SIGN = np.array([-1.0, 1.0, 1.0, -1.0, -1.0, 1.0])


def _hat_numeric(xi: np.ndarray) -> np.ndarray:
    K = np.zeros((*xi.shape[:-1], 9))
    K[..., _HAT_DST] = xi[..., _HAT_SRC] * _HAT_SIGN
    return K.reshape(*xi.shape[:-1], 3, 3)


def _exp_numeric(xi: np.ndarray) -> np.ndarray:
    """Rodrigues' formula ``(I + a φ^) + b φ^φ^`` on a batch, compiled (the arithmetic of
    :func:`_coefficients`, products in :mod:`~mbplan.lie.so3_kernels`' order)."""
    flat = np.ascontiguousarray(xi.reshape(-1, 3), dtype=np.float64)
    return exp_batch(flat).reshape(*xi.shape[:-1], 3, 3)


def _coefficients(xi: Array) -> tuple[Array, Array, Array]:
    """``a = sinθ/θ``, ``b = (1-cosθ)/θ²``, ``c = (θ-sinθ)/θ³`` with Taylor series near 0."""
    if is_symbolic(xi):
        t2 = cs.dot(xi, xi)
        small = t2 < _SMALL
        t = cs.sqrt(cs.if_else(small, 1.0, t2))
        s, co = cs.sin(t), cs.cos(t)
        a = cs.if_else(small, 1 - t2 / 6 + t2**2 / 120, s / t)
        b = cs.if_else(small, 0.5 - t2 / 24 + t2**2 / 720, (1 - co) / t**2)
        c = cs.if_else(small, 1 / 6 - t2 / 120 + t2**2 / 5040, (t - s) / t**3)
        return a, b, c
    t2 = np.sum(xi * xi, axis=-1)
    small = t2 < _SMALL
    t = np.sqrt(np.where(small, 1.0, t2))
    s, co = np.sin(t), np.cos(t)
    a = np.where(small, 1 - t2 / 6 + t2**2 / 120, s / t)
    b = np.where(small, 0.5 - t2 / 24 + t2**2 / 720, (1 - co) / t**2)
    c = np.where(small, 1 / 6 - t2 / 120 + t2**2 / 5040, (t - s) / t**3)
    return a, b, c


def _inverse_coefficient(xi: Array) -> Array:
    """``d = 1/θ² - (1+cosθ)/(2θ sinθ) = 1/θ² - cot(θ/2)/(2θ)`` with its Taylor series near 0.

    The cotangent form avoids the cancellation in ``1 + cosθ`` near θ = π.
    """
    if is_symbolic(xi):
        t2 = cs.dot(xi, xi)
        small = t2 < _SMALL
        t = cs.sqrt(cs.if_else(small, 1.0, t2))
        return cs.if_else(
            small,
            1 / 12 + t2 / 720 + t2**2 / 30240,
            1 / t**2 - 1 / (2 * t * cs.tan(t / 2)),
        )
    t2 = np.sum(xi * xi, axis=-1)
    small = t2 < _SMALL
    t = np.sqrt(np.where(small, 1.0, t2))
    with np.errstate(divide="ignore", invalid="ignore"):
        general = 1 / t**2 - 1 / (2 * t * np.tan(t / 2))
    return np.where(small, 1 / 12 + t2 / 720 + t2**2 / 30240, general)


def _log_numeric(R: np.ndarray) -> np.ndarray:
    w = 0.5 * np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1
    )
    c = np.clip(0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    s2 = np.sum(w * w, axis=-1)
    s = np.sqrt(s2)
    theta = np.arctan2(s, c)
    # Generic and small-angle branch: φ = θ/sinθ · w (series of asin(s)/s near 0).
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(s2 < _SMALL, 1 + s2 / 6 + 3 * s2**2 / 40, theta / s)
    phi = factor[..., None] * w
    near_pi = (c < 0) & (s2 < _NEAR_PI)
    if np.any(near_pi):
        phi[near_pi] = _log_near_pi(R[near_pi], w[near_pi], c[near_pi], theta[near_pi])
    return phi


def _log_near_pi(R: np.ndarray, w: np.ndarray, c: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Axis from the symmetric part ``(R+Rᵀ)/2 - cosθ I = (1-cosθ) a aᵀ``, sign from ``w``."""
    B = 0.5 * (R + np.swapaxes(R, -1, -2)) - c[:, None, None] * np.eye(3)
    i = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
    rows = np.arange(len(i))
    col = B[rows, :, i]
    axis = col / np.sqrt(B[rows, i, i] * (1.0 - c))[:, None]
    sign = np.where(np.sum(axis * w, axis=-1) < 0, -1.0, 1.0)
    return (sign * theta)[:, None] * axis


def _log_symbolic(R: Array) -> Array:
    """Branches as in :func:`_log_numeric`. Every branch is evaluated at a safe argument when it is
    not selected, so automatic derivatives never form ``0 · inf`` (NaN) at θ = 0 or θ = π."""
    w = 0.5 * cs.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    c = 0.5 * (cs.trace(R) - 1.0)
    s2 = cs.dot(w, w)
    small = s2 < _SMALL
    s = cs.sqrt(cs.if_else(small, 1.0, s2))
    generic = cs.if_else(small, 1 + s2 / 6 + 3 * s2**2 / 40, cs.atan2(s, c) / s) * w
    near_pi = cs.logic_and(c < 0, s2 < _NEAR_PI)
    # Symmetric part (R+Rᵀ)/2 - cosθ I = (1-cosθ) a aᵀ; use the column of the largest diagonal.
    B = 0.5 * (R + R.T) - c * cs.DM.eye(3)
    q = [B[i, i] * (1.0 - c) for i in range(3)]
    axes = [B[:, i] / cs.sqrt(cs.if_else(q[i] > _SMALL, q[i], 1.0)) for i in range(3)]
    axis = cs.if_else(
        B[0, 0] >= cs.fmax(B[1, 1], B[2, 2]),
        axes[0],
        cs.if_else(B[1, 1] >= B[2, 2], axes[1], axes[2]),
    )
    axis = cs.if_else(cs.dot(axis, w) < 0, -axis, axis)
    s_pi = cs.sqrt(cs.if_else(near_pi, s2, 0.0))
    c_pi = cs.if_else(near_pi, c, -1.0)
    return cs.if_else(near_pi, cs.atan2(s_pi, c_pi) * axis, generic)


SO3 = SO3Group()
