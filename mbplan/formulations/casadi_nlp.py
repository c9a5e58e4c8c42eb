"""CasADi plumbing of an NLP evaluated in NumPy (Pinocchio has no CasADi bindings): fixed
triplet sparsity patterns and ``casadi.Callback`` functions for ``nlpsol``'s ``g``, ``jac_g`` and
``hess_lag``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import casadi as cs
import numpy as np
import scipy.sparse as sp


def block(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triplet indices of dense blocks ``rows (..., a) × cols (..., b)`` in C order."""
    shape = (*rows.shape, cols.shape[-1])
    return (
        np.broadcast_to(rows[..., None], shape).ravel(),
        np.broadcast_to(cols[..., None, :], shape).ravel(),
    )


class SparsePattern:
    """A fixed sparsity given by triplets (duplicates are summed), kept where ``keep``."""

    def __init__(self, shape: tuple[int, int], rows: np.ndarray, cols: np.ndarray, keep):
        self.shape, self.keep = shape, keep
        linear = cols[keep] * shape[0] + rows[keep]
        unique, self.inverse = np.unique(linear, return_inverse=True)
        self.row, self.col = unique % shape[0], unique // shape[0]
        self.sparsity = cs.Sparsity.triplet(*shape, self.row.tolist(), self.col.tolist())

    def nonzeros(self, values: np.ndarray) -> np.ndarray:
        """Nonzeros in column-major (CCS) order from values listed like the triplets."""
        return np.bincount(self.inverse, weights=values[self.keep], minlength=self.row.size)

    def csc(self, values: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((self.nonzeros(values), (self.row, self.col)), shape=self.shape)


class NumpyCallback(cs.Callback):
    """A CasADi function evaluated by ``fn`` on NumPy vectors."""

    def __init__(self, name: str, sp_in, sp_out, fn: Callable[..., list[cs.DM]]):
        cs.Callback.__init__(self)
        self._sp_in, self._sp_out, self._fn = sp_in, sp_out, fn
        self.construct(name, {})

    def get_n_in(self) -> int:
        return len(self._sp_in)

    def get_n_out(self) -> int:
        return len(self._sp_out)

    def get_sparsity_in(self, i: int) -> cs.Sparsity:
        return self._sp_in[i]

    def get_sparsity_out(self, i: int) -> cs.Sparsity:
        return self._sp_out[i]

    def eval(self, arg: list[cs.DM]) -> list[cs.DM]:
        return self._fn(*(a.full().ravel() for a in arg))


class SparseNLP(Protocol):
    """An NLP ``min f(z) s.t. g(z)`` evaluated in NumPy, its derivatives' values listed like the
    triplets of fixed patterns."""

    n: int
    m: int
    jac_pattern: SparsePattern
    hess_pattern: SparsePattern

    def constraints(self, z: np.ndarray) -> np.ndarray: ...

    def jacobian_values(self, z: np.ndarray) -> np.ndarray: ...

    def hessian_values(self, z: np.ndarray, sigma: float, lam: np.ndarray) -> np.ndarray: ...


def callbacks(nlp: SparseNLP, name: str) -> tuple[NumpyCallback, NumpyCallback, NumpyCallback]:
    """``g(z)``, ``jac_g(z, p) -> (g, ∂g/∂z)`` and ``hess_lag(z, p, σ, λ) -> triu ∇²L`` of
    ``nlp`` for ``casadi.nlpsol`` (its ``g`` and the ``jac_g``/``hess_lag`` options)."""
    dense_z, dense_g = cs.Sparsity.dense(nlp.n, 1), cs.Sparsity.dense(nlp.m, 1)
    no_p, scalar = cs.Sparsity(0, 1), cs.Sparsity.dense(1, 1)
    jac, hess = nlp.jac_pattern, nlp.hess_pattern

    def g(z):
        return [cs.DM(nlp.constraints(z))]

    def jac_g(z, _p):
        values = jac.nonzeros(nlp.jacobian_values(z))
        return [cs.DM(nlp.constraints(z)), cs.DM(jac.sparsity, values)]

    def hess_lag(z, _p, sigma, lam):
        values = hess.nonzeros(nlp.hessian_values(z, float(sigma[0]), lam))
        return [cs.DM(hess.sparsity, values)]

    return (
        NumpyCallback(f"{name}_g", [dense_z], [dense_g], g),
        NumpyCallback(f"{name}_jac_g", [dense_z, no_p], [dense_g, jac.sparsity], jac_g),
        NumpyCallback(
            f"{name}_hess_lag", [dense_z, no_p, scalar, dense_g], [hess.sparsity], hess_lag
        ),
    )
