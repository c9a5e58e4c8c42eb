"""Fixed-pattern sparse assembly: scatter per-knot nonzeros into a CSR matrix by index arrays."""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.workspace import Workspace


class SparsePattern:
    """Sums values given at (possibly repeated) ``(rows, cols)`` into a CSR matrix.

    Entries with a negative column (a fixed coordinate) are dropped. The pattern is computed
    once; each :meth:`assemble` is one compiled pass summing into the slots: no Python loop
    over knots, bodies or terms.
    """

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> None:
        self.shape = shape
        # the index arrays it was built from (read-only copies): what a kept one is checked against
        self.entries = tuple(np.array(a) for a in (rows, cols))
        for a in self.entries:
            a.setflags(write=False)
        kept = cols >= 0
        keys = rows[kept].astype(np.int64) * shape[1] + cols[kept].astype(np.int64)
        unique, slot = np.unique(keys, return_inverse=True)
        self.rows, self.cols = unique // shape[1], unique % shape[1]
        self.nnz = len(unique)
        # dropped entries go to one extra bin past the matrix's, cut off after the sum
        self.slot = np.full(len(cols), self.nnz, np.int64)
        self.slot[kept] = slot.ravel()
        indptr = np.concatenate([[0], np.cumsum(np.bincount(self.rows, minlength=shape[0]))])
        # int32 indices when they fit: scipy then skips an index-dtype pass per assembly
        itype = np.int32 if max(self.nnz, *shape) < np.iinfo(np.int32).max else np.int64
        self._indptr, self._cols = indptr.astype(itype), self.cols.astype(itype)
        # every assembled matrix shares these (and a workspace shares them across problems):
        # read-only, so that an in-place scipy operation on one cannot corrupt the others
        for index in (self._indptr, self._cols, self.slot):
            index.setflags(write=False)
        self._template = sp.csr_matrix((np.zeros(self.nnz), self._cols, self._indptr), shape)
        # canonical by construction (sorted unique keys): scipy's flag, copied with the template
        self._template.has_canonical_format = True

    def assemble(self, values: np.ndarray) -> sp.csr_matrix:
        """The matrix of the values at the pattern's entries (repeated entries summed)."""
        values = np.asarray(values, dtype=float)
        if values.shape != self.slot.shape:
            raise InputError(f"{len(self.slot)} values expected, got shape {values.shape}")
        return self.wrap(accumulate(self.slot, values, self.nnz + 1)[: self.nnz])

    def wrap(self, data: np.ndarray) -> sp.csr_matrix:
        """The matrix with the nonzeros ``data`` (length :attr:`nnz`, kept as given): a shallow
        copy of the validated template (what copy.copy does, without its reduce protocol),
        since scipy's constructor checks the fixed index arrays on every call."""
        out = sp.csr_matrix.__new__(sp.csr_matrix)
        out.__dict__.update(self._template.__dict__)
        out.data = data
        return out


_SAMPLES = 1024  # entries of each index array in a workspace key


def sparse_pattern(
    rows: np.ndarray,
    cols: np.ndarray,
    shape: tuple[int, int],
    workspace: Workspace | None = None,
) -> SparsePattern:
    """``SparsePattern(rows, cols, shape)``, kept in ``workspace``: every problem of a task
    family has the same (its sort costs ~10× the lookup). The key holds an evenly spaced sample
    of each array; a kept pattern is used only if its arrays are equal (else one is built)."""
    rows, cols = np.asarray(rows), np.asarray(cols)
    if workspace is None:
        return SparsePattern(rows, cols, shape)
    key = (tuple(shape), rows.dtype.str, cols.dtype.str, rows.shape, cols.shape)
    key += tuple(a[:: max(1, a.size // _SAMPLES)].tobytes() for a in (rows, cols))
    kept = workspace.get_or_build("sparse_pattern", key, lambda: SparsePattern(rows, cols, shape))
    if all(map(np.array_equal, kept.entries, (rows, cols))):
        return kept
    return SparsePattern(rows, cols, shape)


@nb.njit(cache=True)
def accumulate(slot: np.ndarray, values: np.ndarray, bins: int) -> np.ndarray:
    """``np.bincount(slot, weights=values, minlength=bins)`` (the same additions in the same
    order) in one pass, without bincount's pass for the largest index."""
    out = np.zeros(bins)
    for i in range(slot.size):
        out[slot[i]] += values[i]
    return out
