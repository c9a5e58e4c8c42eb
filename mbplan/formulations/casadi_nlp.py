"""CasADi plumbing of an NLP evaluated in NumPy (Pinocchio has no CasADi bindings): fixed
triplet sparsity patterns and ``casadi.Callback`` functions for ``nlpsol``'s ``g``, ``jac_g`` and
``hess_lag``."""

from __future__ import annotations

from collections.abc import Callable

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
