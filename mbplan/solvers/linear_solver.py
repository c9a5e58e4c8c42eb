"""The reduced KKT matrix of the RIPM and its inertia-revealing sparse LDLᵀ factorization.

Eliminating ``ds`` from the Newton system (53) (see :mod:`mbplan.solvers.ripm`) leaves the
symmetric quasi-definite-shaped matrix, unknowns ordered ``(dx, dy, dz)``::

    K = [[H + D_x,  A_Eᵀ,  A_Iᵀ],
         [A_E,      D_y,   0   ],
         [A_I,      0,     D_z ]]

with diagonal blocks ``D_*`` chosen by the caller (``δ_w I``, ``-δ_c I``, ``-(Σ⁻¹ + δ_c I)``).
The pattern (the union of ``H``'s lower triangle, the Jacobians and the full diagonal) is built
once by index arrays; each new matrix with the same pattern is a scatter of its values, and the
factorization reuses qdldl's AMD ordering and elimination tree (``Solver.update``). The
lower-triangular CSR arrays of ``K`` are the upper-triangular CSC arrays qdldl reads.

qdldl factors ``P K Pᵀ = (I + L) D (I + L)ᵀ`` with a diagonal ``D`` and no pivoting, so by
Sylvester's law of inertia the signs of ``D`` (``Solver.factors()``) are the inertia of ``K``.
Without pivoting the factorization breaks down on a zero pivot, which a structurally zero diagonal
(a variable entering the Lagrangian linearly, an equality row) produces whenever the ordering
eliminates it first. A tiny static regularization (``+ε`` on the primal, ``-ε`` on the dual
diagonal, as in QDLDL-based solvers such as OSQP and Clarabel) avoids that; every solve is then
followed by iterative refinement against the unregularized matrix, and a residual that refinement
cannot reduce is reported to the caller, who treats the matrix as singular (IPOPT's
``PDFullSpaceSolver``). The regularization does not change the inertia of a nonsingular matrix
whose smallest eigenvalue magnitude exceeds ``ε``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import qdldl
import scipy.sparse as sp

from mbplan.errors import InputError


@dataclass(frozen=True)
class Inertia:
    """Numbers of positive, negative and zero pivots of the LDLᵀ factorization."""

    positive: int
    negative: int
    zero: int


def _csr(a: sp.spmatrix | sp.sparray | None, shape: tuple[int, int]) -> sp.csr_matrix:
    if a is None:
        return sp.csr_matrix(shape)
    out = sp.csr_matrix(a)
    if out.shape != shape:
        raise InputError(f"KKT block has shape {out.shape}, expected {shape}")
    if not out.has_canonical_format:
        out = out.copy()
        out.sum_duplicates()
    return out


def _same_pattern(a: sp.csr_matrix, b: sp.csr_matrix | None) -> bool:
    return (
        b is not None
        and a.shape == b.shape
        and a.nnz == b.nnz
        and np.array_equal(a.indptr, b.indptr)
        and np.array_equal(a.indices, b.indices)
    )


class KKTSystem:
    """Assembles ``K`` for a fixed pattern, factorizes it with qdldl and solves with refinement.

    Typical use per Newton step: :meth:`set_matrices` once, then :meth:`factorize` for each trial
    perturbation of the diagonal (inertia correction) and :meth:`solve` for each right-hand side.
    """

    def __init__(self, n: int, n_eq: int, n_ineq: int) -> None:
        self.n, self.n_eq, self.n_ineq = n, n_eq, n_ineq
        self.dim = n + n_eq + n_ineq
        self._patterns: tuple[sp.csr_matrix | None, ...] = (None, None, None)
        self._solver: qdldl.Solver | None = None
        self._matrix: sp.csr_matrix | None = None
        self.n_factorizations = 0
        self.n_analyses = 0

    # ------------------------------------------------------------------ pattern
    def _build_pattern(self, hess: sp.csr_matrix, jac_eq: sp.csr_matrix, jac_in: sp.csr_matrix):
        n, N = self.n, self.dim
        h_rows = np.repeat(np.arange(n), np.diff(hess.indptr))
        self._h_mask = h_rows >= hess.indices
        sources = [
            (h_rows[self._h_mask], hess.indices[self._h_mask]),
            (n + np.repeat(np.arange(self.n_eq), np.diff(jac_eq.indptr)), jac_eq.indices),
            (
                n + self.n_eq + np.repeat(np.arange(self.n_ineq), np.diff(jac_in.indptr)),
                jac_in.indices,
            ),
            (np.arange(N), np.arange(N)),
        ]
        keys = np.concatenate([r.astype(np.int64) * N + c for r, c in sources])
        unique, slot = np.unique(keys, return_inverse=True)
        sizes = np.cumsum([0] + [len(r) for r, _ in sources])
        self._h_slot, self._e_slot, self._i_slot, self._diag_slot = (
            slot[a:b] for a, b in itertools.pairwise(sizes)
        )
        rows = unique // N
        cols = unique % N
        self._indices = cols.astype(np.int32)
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=N))]).astype(
            np.int32
        )
        self._base = np.zeros(len(unique))
        self._data = np.zeros(len(unique))
        # the factorized matrix: qdldl reads the lower CSR arrays as upper CSC; one persistent
        # object whose values are overwritten (no scipy constructor per factorization)
        self._upper = sp.csc_matrix(
            (np.zeros(len(unique)), self._indices, self._indptr), shape=(N, N)
        )
        # the full symmetric matrix for refinement residuals: one SpMV; entry e of the lower
        # triangle lands in slot _full_map[e] and, off the diagonal, also in _full_mirror[.]
        off = rows != cols
        f_rows = np.concatenate([rows, cols[off]])
        f_cols = np.concatenate([cols, rows[off]])
        order = np.lexsort((f_cols, f_rows))
        self._full_src = np.concatenate([np.arange(len(unique)), np.flatnonzero(off)])[order]
        self._full = sp.csr_matrix(
            (
                np.zeros(len(order)),
                f_cols[order].astype(np.int32),
                np.concatenate([[0], np.cumsum(np.bincount(f_rows, minlength=N))]).astype(np.int32),
            ),
            shape=(N, N),
        )
        self._solver = None
        self.n_analyses += 1

    def set_matrices(
        self,
        hessian: sp.spmatrix | sp.sparray | None,
        jac_eq: sp.spmatrix | sp.sparray | None,
        jac_ineq: sp.spmatrix | sp.sparray | None,
    ) -> None:
        """New ``H`` (lower triangle read), ``A_E``, ``A_I``; ``hessian=None`` means ``H = 0``
        (the pattern of the previous Hessian is kept)."""
        n = self.n
        jac_eq = _csr(jac_eq, (self.n_eq, n))
        jac_ineq = _csr(jac_ineq, (self.n_ineq, n))
        zero_hessian = hessian is None
        hess = self._patterns[0] if zero_hessian else _csr(hessian, (n, n))
        if hess is None:
            hess = sp.csr_matrix((n, n))
        new = (hess, jac_eq, jac_ineq)
        if not all(_same_pattern(a, b) for a, b in zip(new, self._patterns, strict=True)):
            self._build_pattern(*new)
            self._patterns = tuple(
                sp.csr_matrix((np.zeros(a.nnz), a.indices.copy(), a.indptr.copy()), shape=a.shape)
                for a in new
            )
        base = self._base
        base[:] = 0.0
        if not zero_hessian:
            base[self._h_slot] = hess.data[self._h_mask]
        base[self._e_slot] = jac_eq.data
        base[self._i_slot] = jac_ineq.data

    # ------------------------------------------------------------------ factorization
    def factorize(self, diagonal: np.ndarray, static_reg: float = 0.0) -> Inertia | None:
        """Factorize ``K`` with ``diagonal`` (length ``dim``) added to its diagonal.

        ``static_reg`` is added to the primal and subtracted from the dual diagonal of the
        *factorized* matrix only (not of ``K``): it keeps qdldl away from zero pivots of a
        structurally zero diagonal, and :meth:`solve` removes its effect by iterative refinement
        against ``K``. Returns the inertia, or ``None`` when the factorization broke down."""
        data = self._data
        np.copyto(data, self._base)
        data[self._diag_slot] += diagonal
        self._full.data[:] = data[self._full_src]
        upper_csc = self._upper
        np.copyto(upper_csc.data, data)
        if static_reg:
            upper_csc.data[self._diag_slot[: self.n]] += static_reg
            upper_csc.data[self._diag_slot[self.n :]] -= static_reg
        self.n_factorizations += 1
        try:
            if self._solver is None:
                self._solver = qdldl.Solver(upper_csc, upper=True)
            else:
                self._solver.update(upper_csc, upper=True)
            d = self._solver.factors()[1]
        except RuntimeError:
            self._solver = None  # rebuild qdldl's workspace after a breakdown
            return None
        if not np.all(np.isfinite(d)):
            return None
        zero = int(np.count_nonzero(d == 0.0))
        return Inertia(int(np.count_nonzero(d > 0.0)), int(np.count_nonzero(d < 0.0)), zero)

    def matrix(self) -> sp.csc_matrix:
        """The last factorized ``K`` (diagonal included, static regularization excluded), full,
        with the fixed pattern (explicit zeros kept)."""
        return self._full.tocsc(copy=True)

    def matvec(self, v: np.ndarray) -> np.ndarray:
        """``K v`` with the last factorized matrix (one SpMV with the full symmetric pattern)."""
        return self._full @ v

    def solve(
        self, rhs: np.ndarray, max_refinement: int = 10, ratio_max: float = 1e-10
    ) -> tuple[np.ndarray, float]:
        """Solve ``K x = rhs`` with iterative refinement (at least one step, IPOPT's default).

        Returns ``x`` and IPOPT's residual ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``."""
        sol = self._solver.solve(rhs)
        nrm_b = np.max(np.abs(rhs), initial=0.0)
        resid, ratio = self._residual(rhs, sol, nrm_b)
        for step in range(max_refinement):
            if step >= 1 and ratio <= ratio_max:
                break
            cand = sol + self._solver.solve(resid)
            cand_resid, cand_ratio = self._residual(rhs, cand, nrm_b)
            if not cand_ratio < ratio:
                break
            sol, resid, ratio = cand, cand_resid, cand_ratio
        return sol, ratio

    def _residual(self, rhs: np.ndarray, sol: np.ndarray, nrm_b: float) -> tuple[np.ndarray, float]:
        resid = rhs - self.matvec(sol)
        denom = min(np.max(np.abs(sol), initial=0.0), 1e6 * nrm_b) + nrm_b
        nrm_r = np.max(np.abs(resid), initial=0.0)
        ratio = nrm_r / denom if denom > 0 else nrm_r
        return resid, float(ratio) if np.isfinite(ratio) else np.inf
