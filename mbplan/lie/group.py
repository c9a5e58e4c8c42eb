"""Generic matrix Lie group: the operations every group shares, built from its Lie-algebra basis.

Conventions (RIPM paper §III.B, eq. 11–15): ``hat`` maps R^d to the Lie algebra, ``vee`` is its
inverse, ``exp(ξ) = expm(ξ^)``, ``Ad_X ξ = (X ξ^ X⁻¹)^∨`` (14), ``ad_ξ η = [ξ^, η^]^∨`` (15).
Jacobians: ``X exp(ξ + δ) ≈ X exp(ξ) exp(J_r(ξ) δ)`` and ``exp(ξ + δ) ≈ exp(J_l(ξ) δ) exp(ξ)``,
so ``J_r(ξ) = Σ_k (-ad_ξ)^k / (k+1)!`` and ``J_l(ξ) = J_r(-ξ)``.

Numeric functions accept a batch of leading dimensions; symbolic (CasADi) ones take one element.
Subclasses override the generic formulas with closed forms where those are faster or more stable.
"""

from __future__ import annotations

import casadi as cs
import numba as nb
import numpy as np
import scipy.linalg

from mbplan.errors import InputError
from mbplan.lie.backend import Array, as_numeric, check_symbolic_shape, column, is_symbolic

MEMBERSHIP_TOL = 1e-6
"""Largest ``|XᵀX - I|`` (and ``|det X - 1|``) accepted as group membership."""
_SYM_EXP_SQUARINGS = 6
_SYM_EXP_TERMS = 12


class MatrixLieGroup:
    """A matrix Lie group of ``n x n`` matrices with a ``dim``-dimensional Lie algebra."""

    name: str
    n: int
    dim: int

    def __init__(self, name: str, n: int, basis: np.ndarray) -> None:
        self.name = name
        self.n = n
        self.dim = basis.shape[0]
        self._basis = basis
        # Dual basis: vee(A) = <dual_i, A>, exact on the Lie algebra (least squares off it).
        flat = basis.reshape(self.dim, n * n)
        self._dual = np.linalg.pinv(flat).T.reshape(self.dim, n, n)

    def __repr__(self) -> str:
        return self.name

    @property
    def element_shape(self) -> tuple[int, ...]:
        return (self.n, self.n)

    def basis(self) -> np.ndarray:
        """The generators ``E_i = e_i^`` as an array of shape (dim, n, n)."""
        return self._basis.copy()

    # ------------------------------------------------------------------ validation
    def _tangent(self, xi: Array, what: str = "tangent vector") -> Array:
        if is_symbolic(xi):
            xi = column(xi)
            check_symbolic_shape(xi, (self.dim, 1), f"{self.name} {what}")
            return xi
        return as_numeric(xi, (self.dim,), f"{self.name} {what}")

    def _element(self, X: Array, what: str = "element") -> Array:
        if is_symbolic(X):
            check_symbolic_shape(X, (self.n, self.n), f"{self.name} {what}")
            return X
        a = as_numeric(X, self.element_shape, f"{self.name} {what}")
        self._check_membership(a, what)
        return a

    def _check_membership(self, X: np.ndarray, what: str) -> None:
        """Raise :class:`InputError` if ``X`` is not in the group (within a tolerance)."""

    def check(self, X: Array) -> np.ndarray:
        """Validate a numeric group element and return it as an array."""
        return self._element(X)

    # ------------------------------------------------------------------ algebra
    def hat(self, xi: Array) -> Array:
        """R^dim → Lie algebra (eq. 11)."""
        xi = self._tangent(xi)
        if is_symbolic(xi):
            return sum(
                (xi[i] * cs.DM(self._basis[i]) for i in range(self.dim)),
                cs.DM.zeros(self.n, self.n),
            )
        return np.einsum("...i,ijk->...jk", xi, self._basis)

    def vee(self, A: Array) -> Array:
        """Lie algebra → R^dim (eq. 11)."""
        if is_symbolic(A):
            check_symbolic_shape(A, (self.n, self.n), f"{self.name} Lie-algebra matrix")
            return cs.vertcat(
                *[cs.sum1(cs.sum2(cs.DM(self._dual[i]) * A)) for i in range(self.dim)]
            )
        A = as_numeric(A, (self.n, self.n), f"{self.name} Lie-algebra matrix")
        return np.einsum("...jk,ijk->...i", A, self._dual)

    # ------------------------------------------------------------------ group operations
    def identity(self) -> np.ndarray:
        return np.eye(self.n)

    def compose(self, X: Array, Y: Array) -> Array:
        X, Y = self._element(X), self._element(Y)
        if is_symbolic(X, Y):
            return cs.mtimes(X, Y)
        return X @ Y

    def inverse(self, X: Array) -> Array:
        X = self._element(X)
        if is_symbolic(X):
            return cs.inv(X)
        return np.linalg.inv(X)

    def exp(self, xi: Array) -> Array:
        """Lie exponential ``expm(ξ^)`` (eq. 12)."""
        A = self.hat(xi)
        if is_symbolic(A):
            return _symbolic_expm(A)
        return _batch(scipy.linalg.expm, A, (self.n, self.n))

    def log(self, X: Array) -> Array:
        """Principal logarithm (eq. 13); numeric only for general groups."""
        X = self._element(X)
        if is_symbolic(X):
            raise InputError(f"{self.name}.log has no symbolic form; use a numeric element")
        return _batch(lambda M: self.vee(self._principal_logm(M)), X, (self.dim,))

    def _principal_logm(self, X: np.ndarray) -> np.ndarray:
        L = scipy.linalg.logm(X)
        if np.iscomplexobj(L):
            if np.max(np.abs(L.imag)) > 1e-9:
                raise InputError(f"{self.name}.log: element has no real principal logarithm")
            L = L.real
        return L

    # ------------------------------------------------------------------ adjoints
    def Ad(self, X: Array) -> Array:
        """Adjoint matrix of ``X`` acting on R^dim (eq. 14)."""
        X = self._element(X)
        if is_symbolic(X):
            Xinv = cs.inv(X)
            cols = [self.vee(cs.mtimes([X, cs.DM(E), Xinv])) for E in self._basis]
            return cs.horzcat(*cols)
        Xinv = np.linalg.inv(X)
        conj = np.einsum("...ab,ibc,...cd->...iad", X, self._basis, Xinv)
        return np.swapaxes(self.vee(conj), -1, -2)

    def ad(self, xi: Array) -> Array:
        """Adjoint matrix of ``ξ``: ``ad_ξ η = [ξ^, η^]^∨`` (eq. 15)."""
        A = self.hat(xi)
        if is_symbolic(A):
            cols = [self.vee(cs.mtimes(A, cs.DM(E)) - cs.mtimes(cs.DM(E), A)) for E in self._basis]
            return cs.horzcat(*cols)
        br = np.einsum("...ab,ibc->...iac", A, self._basis) - np.einsum(
            "iab,...bc->...iac", self._basis, A
        )
        return np.swapaxes(self.vee(br), -1, -2)

    # ------------------------------------------------------------------ Jacobians
    def jac_right(self, xi: Array) -> Array:
        """Right Jacobian ``J_r(ξ) = Σ_k (-ad_ξ)^k/(k+1)!`` (top-right block of a block expm)."""
        adm = self.ad(xi)
        d = self.dim
        if is_symbolic(adm):
            block = cs.blockcat([[-adm, cs.DM.eye(d)], [cs.DM.zeros(d, d), cs.DM.zeros(d, d)]])
            return _symbolic_expm(block)[:d, d:]
        block = np.zeros((*adm.shape[:-2], 2 * d, 2 * d))
        block[..., :d, :d] = -adm
        block[..., :d, d:] = np.eye(d)
        return _batch(scipy.linalg.expm, block, (2 * d, 2 * d))[..., :d, d:]

    def jac_left(self, xi: Array) -> Array:
        """Left Jacobian ``J_l(ξ) = J_r(-ξ)``."""
        return self.jac_right(-self._tangent(xi))

    def jac_right_inv(self, xi: Array) -> Array:
        J = self.jac_right(xi)
        return cs.inv(J) if is_symbolic(J) else np.linalg.inv(J)

    def jac_left_inv(self, xi: Array) -> Array:
        J = self.jac_left(xi)
        return cs.inv(J) if is_symbolic(J) else np.linalg.inv(J)

    # ------------------------------------------------------------------ retraction helpers
    def retract(self, X: Array, xi: Array) -> Array:
        """The exponential retraction ``X exp(ξ)`` (eq. 39). ``X`` is validated; ``exp(ξ)`` is
        in the group by construction and is not checked again."""
        X = self._element(X)
        E = self.exp(xi)
        if is_symbolic(X, E):
            return cs.mtimes(X, E)
        return X @ E

    def local(self, X: Array, Y: Array) -> Array:
        """Inverse of :meth:`retract`: ``log(X⁻¹ Y)``."""
        return self.log(self.compose(self.inverse(X), Y))

    def retract_second_order(self, X: Array, xi: Array) -> Array:
        """``X (I + ξ^ + ξ^²/2)``: agrees with ``X exp(ξ)`` to second order in ξ (eq. 43).

        Derivatives up to order two at ξ = 0 of any function composed with this curve equal
        those along the exact retraction, without the removable singularities of closed forms.
        """
        A = self.hat(xi)
        if is_symbolic(X, A):
            return cs.mtimes(X, cs.DM.eye(self.n) + A + 0.5 * cs.mtimes(A, A))
        return X @ (np.eye(self.n) + A + 0.5 * A @ A)

    def random(self, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
        """A random element ``exp(ξ)`` with ξ ~ N(0, scale² I)."""
        return self.exp(scale * rng.standard_normal(self.dim))


def _batch(fn, A: np.ndarray, out_shape: tuple[int, ...]) -> np.ndarray:
    """Apply a single-matrix function over the leading batch dimensions of ``A``."""
    lead = A.shape[:-2]
    flat = A.reshape(-1, *A.shape[-2:])
    out = np.stack([fn(M) for M in flat]) if len(flat) else np.zeros((0, *out_shape))
    return out.reshape(*lead, *out_shape)


def _symbolic_expm(A: Array) -> Array:
    """Matrix exponential of a CasADi matrix by scaling and squaring of a Taylor series.

    Accurate to machine precision for ``‖A‖ ≲ 2^6``; adequate for the tangent steps of a solver.
    """
    n = A.size1()
    B = A / 2.0**_SYM_EXP_SQUARINGS
    term = cs.DM.eye(n)
    out = cs.DM.eye(n)
    for k in range(1, _SYM_EXP_TERMS + 1):
        term = cs.mtimes(term, B) / k
        out = out + term
    for _ in range(_SYM_EXP_SQUARINGS):
        out = cs.mtimes(out, out)
    return out


def check_orthogonal(R: np.ndarray, group: str, what: str) -> None:
    """Raise unless every matrix in ``R`` (finite) is a proper rotation."""
    n = R.shape[-1]
    if n == 3 and R.dtype == np.float64:
        err, det_min = _rotation_errors(np.ascontiguousarray(R).reshape(-1))
    else:
        err = np.max(np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(n)), initial=0.0)
        det_min = np.min(np.linalg.det(R), initial=np.inf)
    if err > MEMBERSHIP_TOL:
        raise InputError(f"{group} {what}: not orthogonal (max |RᵀR - I| = {err:.2e})")
    if det_min <= 0:
        raise InputError(f"{group} {what}: determinant is not +1 (a reflection)")


@nb.njit(inline="always")
def rotation_error(a: np.ndarray, o: int) -> tuple[float, float]:  # pragma: no cover - numba
    """``max |RᵀR - I|`` and ``det R`` of the row-major 3 x 3 matrix ``a[o : o + 9]``."""
    err = 0.0
    for i in range(3):
        for j in range(3):
            g = a[o + i] * a[o + j] + a[o + 3 + i] * a[o + 3 + j] + a[o + 6 + i] * a[o + 6 + j]
            err = max(err, abs(g - (1.0 if i == j else 0.0)))
    det = (
        a[o] * (a[o + 4] * a[o + 8] - a[o + 5] * a[o + 7])
        - a[o + 1] * (a[o + 3] * a[o + 8] - a[o + 5] * a[o + 6])
        + a[o + 2] * (a[o + 3] * a[o + 7] - a[o + 4] * a[o + 6])
    )
    return err, det


@nb.njit(cache=True)
def _rotation_errors(R: np.ndarray) -> tuple[float, float]:
    """``max |RᵀR - I|`` and the smallest determinant over a batch of row-major 3 x 3
    matrices, raveled."""
    err, det_min = 0.0, np.inf
    for k in range(R.shape[0] // 9):
        e, d = rotation_error(R, 9 * k)
        err, det_min = max(err, e), min(det_min, d)
    return err, det_min


def check_unit_determinant(X: np.ndarray, group: str, what: str) -> None:
    det = np.linalg.det(X)
    err = np.max(np.abs(det - 1.0), initial=0.0)
    if err > MEMBERSHIP_TOL:
        raise InputError(f"{group} {what}: determinant is not 1 (max |det - 1| = {err:.2e})")
