"""R^n as an additive Lie group whose elements are plain vectors."""

from __future__ import annotations

import operator
from functools import cache

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.lie.backend import Array, as_numeric, check_symbolic_shape, column, is_symbolic


class RnGroup:
    """``exp(ξ) = ξ``, ``X·Y = X + Y``, ``Ad = I``, ``ad = 0``, Jacobians ``I``."""

    def __init__(self, n: int) -> None:
        if n < 1:
            raise InputError(f"R^n needs n >= 1, got {n}")
        self.n = n
        self.dim = n
        self.name = f"R^{n}"

    def __repr__(self) -> str:
        return self.name

    @property
    def element_shape(self) -> tuple[int, ...]:
        return (self.n,)

    def _vec(self, x: Array, what: str) -> Array:
        if is_symbolic(x):
            x = column(x)
            check_symbolic_shape(x, (self.n, 1), f"{self.name} {what}")
            return x
        return as_numeric(x, (self.n,), f"{self.name} {what}")

    def check(self, X: Array) -> np.ndarray:
        return self._vec(X, "element")

    def identity(self) -> np.ndarray:
        return np.zeros(self.n)

    def hat(self, xi: Array) -> Array:
        """Matrix form ``[[0, ξ], [0, 0]]`` of the Lie algebra of ``[[I, x], [0, 1]]``."""
        xi = self._vec(xi, "tangent vector")
        if is_symbolic(xi):
            return cs.vertcat(
                cs.horzcat(cs.DM.zeros(self.n, self.n), xi), cs.DM.zeros(1, self.n + 1)
            )
        out = np.zeros((*xi.shape[:-1], self.n + 1, self.n + 1))
        out[..., : self.n, self.n] = xi
        return out

    def vee(self, A: Array) -> Array:
        return A[: self.n, self.n] if is_symbolic(A) else np.asarray(A)[..., : self.n, self.n]

    def exp(self, xi: Array) -> Array:
        return self._vec(xi, "tangent vector")

    def log(self, X: Array) -> Array:
        return self._vec(X, "element")

    def compose(self, X: Array, Y: Array) -> Array:
        return self._vec(X, "element") + self._vec(Y, "element")

    def inverse(self, X: Array) -> Array:
        return -self._vec(X, "element")

    def _eye(self, x: Array) -> Array:
        if is_symbolic(x):
            return cs.DM.eye(self.n)
        return np.broadcast_to(np.eye(self.n), (*x.shape[:-1], self.n, self.n)).copy()

    def Ad(self, X: Array) -> Array:
        return self._eye(self._vec(X, "element"))

    def ad(self, xi: Array) -> Array:
        return 0 * self._eye(self._vec(xi, "tangent vector"))

    def jac_right(self, xi: Array) -> Array:
        return self._eye(self._vec(xi, "tangent vector"))

    jac_left = jac_right_inv = jac_left_inv = jac_right

    def retract(self, X: Array, xi: Array) -> Array:
        if type(X) is np.ndarray and type(xi) is np.ndarray and X.shape == xi.shape:
            out = X + xi  # validated below only when not finite (then as compose does)
            if (
                X.shape[-1:] == (self.n,)
                and X.dtype == xi.dtype == float
                and np.isfinite(out).all()
            ):
                return out
        return self.compose(X, xi)

    def local(self, X: Array, Y: Array) -> Array:
        return self._vec(Y, "element") - self._vec(X, "element")

    def retract_second_order(self, X: Array, xi: Array) -> Array:
        return X + xi

    def random(self, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
        return scale * rng.standard_normal(self.n)


def R(n: int) -> RnGroup:
    """R^n, one group object per dimension (equal blocks of R^n are equal memo keys)."""
    try:
        n = operator.index(n)
    except TypeError:
        raise InputError(f"R^n needs an integer n, got {n!r}") from None
    return _rn(n)


# process-wide cache, result-neutral: the group R^n of the dimension alone
@cache
def _rn(n: int) -> RnGroup:
    return RnGroup(n)
