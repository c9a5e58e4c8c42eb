"""SE(3) as 4x4 homogeneous matrices; tangent ordering ξ = (v, ω) as in Pinocchio."""

from __future__ import annotations

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.lie.backend import Array, is_symbolic
from mbplan.lie.group import MatrixLieGroup, check_orthogonal
from mbplan.lie.so3 import SO3


def _se3_basis() -> np.ndarray:
    E = np.zeros((6, 4, 4))
    for i in range(3):
        E[i, i, 3] = 1.0
        E[3 + i, :3, :3] = SO3.basis()[i]
    return E


class SE3Group(MatrixLieGroup):
    """Rigid motions ``[[R, t], [0, 1]]``; ``exp(v, ω) = [[exp(ω), J_l(ω) v], [0, 1]]``."""

    def __init__(self) -> None:
        super().__init__("SE(3)", 4, _se3_basis())

    def _check_membership(self, X: np.ndarray, what: str) -> None:
        check_orthogonal(X[..., :3, :3], self.name, f"{what} rotation block")
        bottom = np.max(np.abs(X[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])), initial=0.0)
        if bottom > 1e-12:
            raise InputError(f"{self.name} {what}: last row is not [0, 0, 0, 1]")

    def inverse(self, X: Array) -> Array:
        X = self._element(X)
        if is_symbolic(X):
            R, t = X[:3, :3], X[:3, 3]
            return cs.vertcat(cs.horzcat(R.T, -cs.mtimes(R.T, t)), cs.DM([[0, 0, 0, 1]]))
        out = np.zeros_like(X)
        Rt = np.swapaxes(X[..., :3, :3], -1, -2)
        out[..., :3, :3] = Rt
        out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, X[..., :3, 3])
        out[..., 3, 3] = 1.0
        return out

    def exp(self, xi: Array) -> Array:
        xi = self._tangent(xi)
        v, w = (
            xi[..., :3] if not is_symbolic(xi) else xi[:3],
            xi[..., 3:] if not is_symbolic(xi) else xi[3:],
        )
        R = SO3.exp(w)
        Jl = SO3.jac_left(w)
        if is_symbolic(xi):
            return cs.vertcat(cs.horzcat(R, cs.mtimes(Jl, v)), cs.DM([[0, 0, 0, 1]]))
        out = np.zeros((*xi.shape[:-1], 4, 4))
        out[..., :3, :3] = R
        out[..., :3, 3] = np.einsum("...ij,...j->...i", Jl, v)
        out[..., 3, 3] = 1.0
        return out

    def log(self, X: Array) -> Array:
        X = self._element(X)
        if is_symbolic(X):
            w = SO3.log(X[:3, :3])
            return cs.vertcat(cs.mtimes(SO3.jac_left_inv(w), X[:3, 3]), w)
        w = SO3.log(X[..., :3, :3])
        v = np.einsum("...ij,...j->...i", SO3.jac_left_inv(w), X[..., :3, 3])
        return np.concatenate([v, w], axis=-1)

    def Ad(self, X: Array) -> Array:
        """``[[R, t^ R], [0, R]]``."""
        X = self._element(X)
        if is_symbolic(X):
            R, t = X[:3, :3], X[:3, 3]
            return cs.blockcat([[R, cs.mtimes(cs.skew(t), R)], [cs.DM.zeros(3, 3), R]])
        R, t = X[..., :3, :3], X[..., :3, 3]
        out = np.zeros((*X.shape[:-2], 6, 6))
        out[..., :3, :3] = R
        out[..., 3:, 3:] = R
        out[..., :3, 3:] = SO3.hat(t) @ R
        return out

    def ad(self, xi: Array) -> Array:
        """``[[ω^, v^], [0, ω^]]``."""
        xi = self._tangent(xi)
        if is_symbolic(xi):
            W, V = cs.skew(xi[3:]), cs.skew(xi[:3])
            return cs.blockcat([[W, V], [cs.DM.zeros(3, 3), W]])
        W, V = SO3.hat(xi[..., 3:]), SO3.hat(xi[..., :3])
        out = np.zeros((*xi.shape[:-1], 6, 6))
        out[..., :3, :3] = W
        out[..., 3:, 3:] = W
        out[..., :3, 3:] = V
        return out


SE3 = SE3Group()
