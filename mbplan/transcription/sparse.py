"""Fixed-pattern sparse assembly: scatter per-knot nonzeros into a CSR matrix by index arrays."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class SparsePattern:
    """Sums values given at (possibly repeated) ``(rows, cols)`` into a CSR matrix.

    The pattern is computed once; each :meth:`assemble` is one ``np.bincount``: no Python loop
    over knots, bodies or terms.
    """

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> None:
        self.shape = shape
        keys = rows.astype(np.int64) * shape[1] + cols.astype(np.int64)
        unique, self._slot = np.unique(keys, return_inverse=True)
        self.rows, self.cols = unique // shape[1], unique % shape[1]
        self.nnz = len(unique)
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(self.rows, minlength=shape[0]))])

    def assemble(self, values: np.ndarray) -> sp.csr_matrix:
        data = np.bincount(self._slot, weights=values, minlength=self.nnz)
        return sp.csr_matrix((data, self.cols, self._indptr), shape=self.shape)
