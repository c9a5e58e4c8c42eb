"""SO(n) and SL(n) for any n, from their Lie-algebra bases (MLG-IPM paper §II)."""

from __future__ import annotations

import numpy as np
import scipy.linalg

from mbplan.errors import InputError
from mbplan.lie.backend import Array, is_symbolic
from mbplan.lie.group import MatrixLieGroup, check_orthogonal, check_unit_determinant


def _son_basis(n: int) -> np.ndarray:
    """``E_ij = e_j e_iᵀ - e_i e_jᵀ`` for i < j (row-major pair order)."""
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    E = np.zeros((len(pairs), n, n))
    for k, (i, j) in enumerate(pairs):
        E[k, j, i], E[k, i, j] = 1.0, -1.0
    return E


def _sln_basis(n: int) -> np.ndarray:
    """Off-diagonal units ``e_i e_jᵀ`` (i ≠ j), then ``e_i e_iᵀ - e_{i+1} e_{i+1}ᵀ``."""
    mats = []
    for i in range(n):
        for j in range(n):
            if i != j:
                M = np.zeros((n, n))
                M[i, j] = 1.0
                mats.append(M)
    for i in range(n - 1):
        M = np.zeros((n, n))
        M[i, i], M[i + 1, i + 1] = 1.0, -1.0
        mats.append(M)
    return np.array(mats)


class SOnGroup(MatrixLieGroup):
    """Rotations of R^n."""

    def __init__(self, n: int) -> None:
        if n < 2:
            raise InputError(f"SO(n) needs n >= 2, got {n}")
        super().__init__(f"SO({n})", n, _son_basis(n))

    def _check_membership(self, X: np.ndarray, what: str) -> None:
        check_orthogonal(X, self.name, what)

    def inverse(self, X: Array) -> Array:
        X = self._element(X)
        return X.T if is_symbolic(X) else np.swapaxes(X, -1, -2)

    def _principal_logm(self, X: np.ndarray) -> np.ndarray:
        """Log from the real Schur form ``X = Q T Qᵀ``: T is block diagonal with 2×2 rotations
        and ±1 entries; each rotation block gives its angle, and the −1 entries (an even number,
        det X = 1) pair up into rotations by π. Exact at angle π, where ``logm`` goes complex."""
        T, Q = scipy.linalg.schur(X, output="real")
        L = np.zeros_like(T)
        minus_one: list[int] = []
        i = 0
        while i < self.n:
            if i + 1 < self.n and abs(T[i + 1, i]) > 1e-14:
                angle = np.arctan2(
                    0.5 * (T[i + 1, i] - T[i, i + 1]), 0.5 * (T[i, i] + T[i + 1, i + 1])
                )
                L[i + 1, i], L[i, i + 1] = angle, -angle
                i += 2
                continue
            if T[i, i] < 0:
                minus_one.append(i)
            i += 1
        for a, b in zip(minus_one[::2], minus_one[1::2], strict=True):
            L[b, a], L[a, b] = np.pi, -np.pi
        L = Q @ L @ Q.T
        return 0.5 * (L - L.T)


class SLnGroup(MatrixLieGroup):
    """Matrices of determinant one. No bi-invariant metric exists (Assumption 1 fails)."""

    def __init__(self, n: int) -> None:
        if n < 2:
            raise InputError(f"SL(n) needs n >= 2, got {n}")
        super().__init__(f"SL({n})", n, _sln_basis(n))

    def _check_membership(self, X: np.ndarray, what: str) -> None:
        check_unit_determinant(X, self.name, what)

    def _principal_logm(self, X: np.ndarray) -> np.ndarray:
        """Real principal log; defined iff no eigenvalue lies on the closed negative real axis."""
        ev = np.linalg.eigvals(X)
        scale = max(1.0, float(np.max(np.abs(ev))))
        bad = (ev.real <= 0) & (np.abs(ev.imag) <= 1e-12 * scale)
        if np.any(bad):
            raise InputError(
                f"{self.name}.log: element has eigenvalue(s) {ev[bad].real} on the closed negative "
                "real axis, outside the domain of the principal logarithm"
            )
        L = super()._principal_logm(X)
        return L - np.trace(L) / self.n * np.eye(self.n)


def SO(n: int) -> MatrixLieGroup:
    """SO(n); for n = 3 this is the closed-form :data:`mbplan.lie.SO3`."""
    if n == 3:
        from mbplan.lie.so3 import SO3

        return SO3
    return SOnGroup(n)


def SL(n: int) -> SLnGroup:
    return SLnGroup(n)
