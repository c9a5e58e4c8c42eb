"""The problem interface of the RIPM: Problem 2 of the RIPM paper (eq. 46) on a manifold.

``min f(x)  s.t.  h(x) = 0,  g(x) ≤ 0`` over a manifold whose points are opaque objects. Every
tangent space is ``Rⁿ`` (coordinates in a fixed basis, Euclidean metric in those coordinates), so
the Riemannian gradient of ``f`` at ``x`` is the plain gradient of the pullback ``ξ ↦ f(R_x(ξ))`` at
``ξ = 0``, Jacobians are ``(m, n)`` matrices, and — the retraction being second order — the
Riemannian Hessian of the Lagrangian (eq. 54) is the Euclidean Hessian of its pullback at 0.

A solver only needs :class:`RIPMProblem`: sizes, ``retract``, one combined ``evaluate`` per iterate
and one ``values`` per line-search trial. :class:`ManifoldNLP` derives both from one method per
function; a problem that evaluates everything in one vectorised call (a trajectory NLP) overrides
``evaluate`` and ``values`` or implements :class:`RIPMProblem` directly.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError

Point = Any
"""A point of the manifold: opaque to the solver (an array, a dict of arrays, ...)."""


@dataclass(frozen=True)
class NLPEvaluation:
    """Everything one Newton step needs at a point.

    ``hessian_lower`` is ``Hess(σ f + yᵀh + zᵀg)`` (eq. 54): the solver reads only the entries with
    ``row ≥ col``, so the lower triangle or the full symmetric matrix may be given. Sparse matrices
    should keep one sparsity pattern from call to call (explicit zeros included): the solver then
    reuses the ordering and symbolic factorization of its KKT matrix.
    """

    objective: float
    gradient: np.ndarray
    eq: np.ndarray
    eq_jacobian: sp.spmatrix | sp.sparray
    ineq: np.ndarray
    ineq_jacobian: sp.spmatrix | sp.sparray
    hessian_lower: sp.spmatrix | sp.sparray | None


@runtime_checkable
class RIPMProblem(Protocol):
    """What :func:`~mbplan.solvers.ripm.driver.solve_ripm` calls (structural type).

    ``evaluate`` is called once per iterate; ``values`` once per line-search trial. A problem
    may also provide ``elimination_plan(eq_jacobian) -> EliminationPlan | None``
    (:mod:`mbplan.solvers.kkt.elimination`), used by ``RIPMOptions.kkt_method``, and
    ``accept(x)``, called at every accepted iterate: it may move the charts its functions are
    written in (a reference angle) to ``x``, leaving every value near ``x`` unchanged.
    """

    n: int
    n_eq: int
    n_ineq: int

    def retract(self, x: Point, dx: np.ndarray) -> Point: ...

    def evaluate(
        self,
        x: Point,
        obj_factor: float = 1.0,
        y: np.ndarray | None = None,
        z: np.ndarray | None = None,
        hessian: bool = True,
    ) -> NLPEvaluation: ...

    def values(self, x: Point) -> tuple[float, np.ndarray, np.ndarray]: ...


class ManifoldNLP(ABC):
    """Problem 2 (eq. 46) from one method per function; see the module docstring.

    Subclasses set ``n``, ``n_eq``, ``n_ineq`` (class attributes or properties) and implement the
    abstract methods. ``lagrangian_hessian`` returns ``Hess(obj_factor·f + yᵀh + zᵀg)`` with the
    convention of :class:`NLPEvaluation` (lower triangle, or full).
    """

    @property
    @abstractmethod
    def n(self) -> int:
        """Tangent-space dimension."""

    @property
    @abstractmethod
    def n_eq(self) -> int:
        """Number of equality constraints ``h``."""

    @property
    @abstractmethod
    def n_ineq(self) -> int:
        """Number of inequality constraints ``g ≤ 0``."""

    @abstractmethod
    def retract(self, x: Point, dx: np.ndarray) -> Point:
        """Second-order retraction ``R_x(dx)``, ``dx ∈ Rⁿ`` in the tangent basis at ``x``."""

    @abstractmethod
    def objective(self, x: Point) -> float: ...

    @abstractmethod
    def gradient(self, x: Point) -> np.ndarray:
        """Riemannian gradient of ``f``, shape ``(n,)``."""

    def eq(self, x: Point) -> np.ndarray:
        return np.zeros(0)

    def eq_jacobian(self, x: Point) -> sp.csr_matrix:
        """Riemannian Jacobian of ``h``, shape ``(n_eq, n)`` (rows are ``grad h_i``, eq. 51)."""
        return sp.csr_matrix((0, self.n))

    def ineq(self, x: Point) -> np.ndarray:
        return np.zeros(0)

    def ineq_jacobian(self, x: Point) -> sp.csr_matrix:
        """Riemannian Jacobian of ``g``, shape ``(n_ineq, n)`` (eq. 52)."""
        return sp.csr_matrix((0, self.n))

    @abstractmethod
    def lagrangian_hessian(
        self, x: Point, obj_factor: float, y: np.ndarray, z: np.ndarray
    ) -> sp.spmatrix | sp.sparray:
        """``Hess(obj_factor·f + yᵀh + zᵀg)`` (eq. 54), ``(n, n)``, lower triangle or full."""

    def evaluate(
        self,
        x: Point,
        obj_factor: float = 1.0,
        y: np.ndarray | None = None,
        z: np.ndarray | None = None,
        hessian: bool = True,
    ) -> NLPEvaluation:
        """All quantities at ``x``; override to compute them in one vectorised call."""
        y = np.zeros(self.n_eq) if y is None else y
        z = np.zeros(self.n_ineq) if z is None else z
        return NLPEvaluation(
            objective=float(self.objective(x)),
            gradient=np.asarray(self.gradient(x), dtype=float),
            eq=np.asarray(self.eq(x), dtype=float),
            eq_jacobian=self.eq_jacobian(x),
            ineq=np.asarray(self.ineq(x), dtype=float),
            ineq_jacobian=self.ineq_jacobian(x),
            hessian_lower=self.lagrangian_hessian(x, obj_factor, y, z) if hessian else None,
        )

    def values(self, x: Point) -> tuple[float, np.ndarray, np.ndarray]:
        """``f(x), h(x), g(x)``: what a line-search trial needs."""
        return (
            float(self.objective(x)),
            np.asarray(self.eq(x), dtype=float),
            np.asarray(self.ineq(x), dtype=float),
        )


def _fixed_pattern_csr(a: Any, shape: tuple[int, int], lower: bool = False) -> sp.csr_matrix:
    """CSR with a pattern that does not depend on the values: a dense input keeps every entry
    (of the lower triangle if ``lower``), explicit zeros included."""
    if sp.issparse(a):
        out = sp.csr_matrix(a)
        if out.shape != shape:
            raise InputError(f"sparse matrix has shape {out.shape}, expected {shape}")
        return sp.tril(out, format="csr") if lower else out
    a = np.asarray(a, dtype=float).reshape(shape)
    rows, cols = np.tril_indices(shape[0]) if lower else np.indices(shape).reshape(2, -1)
    counts = np.bincount(rows, minlength=shape[0])
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return sp.csr_matrix((a[rows, cols], cols, indptr), shape=shape)


class EuclideanNLP(ManifoldNLP):
    """Problem 2 on ``Rⁿ`` (``retract(x, dx) = x + dx``) from callables, for tests and small models.

    ``hessian(x, obj_factor, y, z)`` returns the Lagrangian Hessian; Jacobians and the Hessian may
    be dense arrays (stored with a fixed full pattern) or scipy sparse matrices.
    """

    def __init__(
        self,
        n: int,
        objective: Callable[[np.ndarray], float],
        gradient: Callable[[np.ndarray], np.ndarray],
        hessian: Callable[[np.ndarray, float, np.ndarray, np.ndarray], Any],
        *,
        eq: Callable[[np.ndarray], np.ndarray] | None = None,
        eq_jacobian: Callable[[np.ndarray], Any] | None = None,
        n_eq: int = 0,
        ineq: Callable[[np.ndarray], np.ndarray] | None = None,
        ineq_jacobian: Callable[[np.ndarray], Any] | None = None,
        n_ineq: int = 0,
    ) -> None:
        for name, fun, jac, m in (
            ("eq", eq, eq_jacobian, n_eq),
            ("ineq", ineq, ineq_jacobian, n_ineq),
        ):
            if (fun is None) != (jac is None) or (fun is None) != (m == 0):
                raise InputError(f"{name}, {name}_jacobian and n_{name} > 0 go together")
        self._n, self._n_eq, self._n_ineq = int(n), int(n_eq), int(n_ineq)
        self._f, self._grad, self._hess = objective, gradient, hessian
        self._h, self._jh, self._g, self._jg = eq, eq_jacobian, ineq, ineq_jacobian

    @property
    def n(self) -> int:
        return self._n

    @property
    def n_eq(self) -> int:
        return self._n_eq

    @property
    def n_ineq(self) -> int:
        return self._n_ineq

    def retract(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return np.asarray(x, dtype=float) + dx

    def objective(self, x: np.ndarray) -> float:
        return float(self._f(x))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self._grad(x), dtype=float).reshape(self.n)

    def eq(self, x: np.ndarray) -> np.ndarray:
        return np.zeros(0) if self._h is None else np.asarray(self._h(x), dtype=float).ravel()

    def eq_jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        if self._jh is None:
            return sp.csr_matrix((0, self.n))
        return _fixed_pattern_csr(self._jh(x), (self.n_eq, self.n))

    def ineq(self, x: np.ndarray) -> np.ndarray:
        return np.zeros(0) if self._g is None else np.asarray(self._g(x), dtype=float).ravel()

    def ineq_jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        if self._jg is None:
            return sp.csr_matrix((0, self.n))
        return _fixed_pattern_csr(self._jg(x), (self.n_ineq, self.n))

    def lagrangian_hessian(
        self, x: np.ndarray, obj_factor: float, y: np.ndarray, z: np.ndarray
    ) -> sp.csr_matrix:
        return _fixed_pattern_csr(self._hess(x, obj_factor, y, z), (self.n, self.n), lower=True)
