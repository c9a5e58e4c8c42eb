"""The reduced KKT matrix of the RIPM and its inertia-revealing sparse LDLᵀ factorization.

Eliminating ``ds`` from the Newton system (53) (see :mod:`mbplan.solvers.ripm.driver`) leaves the
symmetric quasi-definite-shaped matrix, unknowns ordered ``(dx, dy, dz)``::

    K = [[H + D_x,  A_Eᵀ,  A_Iᵀ],
         [A_E,      D_y,   0   ],
         [A_I,      0,     D_z ]]

with diagonal blocks ``D_*`` chosen by the caller (``δ_w I``, ``-δ_c I``, ``-(Σ⁻¹ + δ_c I)``).
The pattern (the union of ``H``'s lower triangle, the Jacobians and the full diagonal) is built
once by index arrays (:mod:`mbplan.solvers.kkt.pattern`); each new matrix with the same
pattern is a scatter of its values.

The factorization (symbolic analysis in :mod:`mbplan.solvers.kkt.ldl.symbolic`, numeric kernels in
:mod:`mbplan.solvers.kkt.ldl.kernels`, work arrays in :mod:`mbplan.solvers.kkt.ldl.supernodal`) is a
supernodal multifrontal ``P K Pᵀ = (I + L) D (I + L)ᵀ`` with a diagonal ``D`` and no pivoting
(optionally 1 × 1 / 2 × 2 threshold pivoting inside each supernode, ``D`` block diagonal:
:mod:`mbplan.solvers.kkt.ldl.pivot`), compiled with numba. Its symbolic analysis takes the approximate minimum
degree ordering qdldl computes (SuiteSparse AMD), postorders the elimination tree, groups
columns into fundamental supernodes merged by CHOLMOD's relaxed amalgamation rule, merges
sibling leaves with equal rows and moves small leaves right before their parent, which they
update directly (:mod:`mbplan.solvers.kkt.ldl.layout`), and precomputes where every entry of
``K`` and every child's update matrix lands; it is kept in the caller's
:class:`~mbplan.workspace.Workspace` (the KKT systems of one task family share theirs). The numeric
factorization works on small dense fronts with register-blocked loops: on trajectory-optimization
KKT matrices, whose elimination ends in a chain of dense knot-to-knot blocks, it is about twice
as fast as qdldl's column-by-column up-looking LDLᵀ with the same ordering, and it counts the
pivot signs as it goes (qdldl's Python binding returns ``D`` only with a copy of ``L``).
Compiled kernels are cached on disk by numba; the first use in a fresh environment compiles
them (seconds).

By Sylvester's law of inertia the signs of ``D`` are the inertia of ``K``. Without pivoting the
factorization breaks down on a zero pivot, which a structurally zero diagonal (a variable
entering the Lagrangian linearly, an equality row) produces whenever the ordering eliminates it
first. A tiny static regularization (``+ε`` on the primal, ``-ε`` on the dual diagonal, as in
QDLDL-based solvers such as OSQP and Clarabel) avoids that; every solve is then followed by
iterative refinement against the unregularized matrix, and a residual that refinement cannot
reduce is reported to the caller, who treats the matrix as singular (IPOPT's
``PDFullSpaceSolver``). The regularization does not change the inertia of a nonsingular matrix
whose smallest eigenvalue magnitude exceeds ``ε``.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mbplan.engine.jit import numba_cached
from mbplan.errors import InputError
from mbplan.solvers.kkt.ldl.supernodal import SupernodalLDL
from mbplan.solvers.kkt.ldl.symbolic import Analysis
from mbplan.solvers.kkt.pattern import (
    _ENTRY_KERNELS,
    ORDERINGS,
    _BlockPattern,
    _kkt_pattern,
    _same_pattern,
)
from mbplan.solvers.kkt.scatter import matrix_values, scatter_blocks
from mbplan.workspace import Workspace

_NONE = np.zeros(0, np.int64)
_NONE_F = np.zeros(0)


@dataclass(frozen=True)
class Inertia:
    """Numbers of positive, negative and zero pivots of the LDLᵀ factorization."""

    positive: int
    negative: int
    zero: int


# process-wide cache, result-neutral: a read-only all-zero matrix of the shape alone
@functools.lru_cache(maxsize=16)
def _empty_csr(shape: tuple[int, int]) -> sp.csr_matrix:
    """An all-zero block (shared, read only: built once per shape)."""
    return sp.csr_matrix(shape)


def _csr(a: sp.spmatrix | sp.sparray | None, shape: tuple[int, int]) -> sp.csr_matrix:
    if a is None:
        return _empty_csr(shape)
    if type(a) is sp.csr_matrix and a.shape == shape and a.has_canonical_format:
        return a  # read only: no copy needed
    out = sp.csr_matrix(a)
    if out.shape != shape:
        raise InputError(f"KKT block has shape {out.shape}, expected {shape}")
    if not out.has_canonical_format:
        out = out.copy()
        out.sum_duplicates()
    return out


PERTURBATION = 1e-14
"""With pivoting, a pivot of magnitude at most this times ``max |K|`` (and below a tenth of the
static regularization) is perturbed to that magnitude (PARDISO-style static pivoting;
refinement against ``K`` corrects the solve)."""


class KKTSystem:
    """Assembles ``K`` for a fixed pattern, factorizes it (supernodal LDLᵀ) and solves with
    refinement.

    Typical use per Newton step: :meth:`set_matrices` once, then :meth:`factorize` for each trial
    perturbation of the diagonal (inertia correction) and :meth:`solve` for each right-hand side.
    ``ordering`` selects the elimination order (:func:`analysis`). ``pivot_threshold`` ``u > 0``
    turns on threshold 1 × 1 / 2 × 2 pivoting inside each supernode (a pivot ``|d| < u`` times
    its column's largest entry is replaced); ``0``: no pivoting. ``workspace``: where the
    patterns and analyses are kept (``None``: this system's own).
    """

    def __init__(
        self,
        n: int,
        n_eq: int,
        n_ineq: int,
        *,
        ordering: str = "amd",
        pivot_threshold: float = 0.0,
        workspace: Workspace | None = None,
    ) -> None:
        if ordering not in ORDERINGS:
            raise InputError(f"ordering: expected one of {ORDERINGS}, got {ordering!r}")
        if not 0.0 <= pivot_threshold <= 1.0:
            raise InputError(f"pivot_threshold: expected a value in [0, 1], got {pivot_threshold}")
        self.ordering = ordering
        self.pivot_threshold = float(pivot_threshold)
        self.workspace = Workspace() if workspace is None else workspace
        self.n, self.n_eq, self.n_ineq = n, n_eq, n_ineq
        self.dim = n + n_eq + n_ineq
        self._patterns: tuple[_BlockPattern | None, ...] = (None, None, None)
        self._solver: SupernodalLDL | None = None
        self.n_factorizations = 0
        self.n_analyses = 0

    # ------------------------------------------------------------------ pattern
    def _build_pattern(self, hess: sp.csr_matrix, jac_eq: sp.csr_matrix, jac_in: sp.csr_matrix):
        pat = _kkt_pattern(
            self.n, self.n_eq, self.n_ineq, hess, jac_eq, jac_in, self.ordering, self.workspace
        )
        self._release()
        self._pattern, self._patterns = pat, pat.blocks
        self._diag_slot = pat.diag_slot
        self._indptr, self._indices = pat.indptr, pat.indices
        self._ws = ws = pat.work_arrays()
        self._base = ws.base
        self._full_data = ws.full_data  # K in the full symmetric pattern
        # the factorized values, entry by entry of the lower CSR arrays (= upper CSC arrays)
        self._factor_data = ws.factor_data
        self._solver = ws.solver
        # expected pivot signs in pivot order (perturbed pivots get them): + primal, - dual
        self._sign = pat.sign
        self.n_analyses += 1

    def _release(self) -> None:
        """Hand the work arrays back to their pattern (the system is gone or changes pattern)."""
        ws, self._ws = getattr(self, "_ws", None), None
        if ws is not None:
            self._pattern.release(ws)

    def __del__(self) -> None:
        self._release()

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
            hess = _empty_csr((n, n))
        h0, e0, i0 = self._patterns
        if not (
            _same_pattern(hess, h0) and _same_pattern(jac_eq, e0) and _same_pattern(jac_ineq, i0)
        ):
            self._build_pattern(hess, jac_eq, jac_ineq)
        pat = self._pattern
        h_data, h_src, h_slot = (
            (hess.data, pat.h_src, pat.h_slot) if not zero_hessian else (_NONE_F, _NONE, _NONE)
        )
        scatter_blocks(
            self._base, h_data, h_src, h_slot, jac_eq.data, pat.e_slot, jac_ineq.data,
            pat.i_slot,
        )  # fmt: skip

    # ------------------------------------------------------------------ factorization
    def factorize(self, diagonal: np.ndarray, static_reg: float = 0.0) -> Inertia | None:
        """Factorize ``K`` with ``diagonal`` (length ``dim``) added to its diagonal.

        ``static_reg`` is added to the primal and subtracted from the dual diagonal of the
        *factorized* matrix only (not of ``K``): it keeps the LDLᵀ away from zero pivots of a
        structurally zero diagonal, and :meth:`solve` removes its effect by iterative refinement
        against ``K``. Returns the inertia, or ``None`` when the factorization broke down.

        With pivoting, a pivot of magnitude ``<= δ = min(PERTURBATION · max|K|, static_reg / 10)``
        that no pivot of its supernode can replace is perturbed to ``δ`` with the sign of the static
        regularization (``+`` primal, ``-`` dual) and counted with it: the inertia is the
        perturbed matrix's, as the static regularization's is; refinement against ``K``
        decides whether the factorization solves ``K`` (:meth:`solve`'s ratio, which the
        Newton step checks). :attr:`pivot_stats` says what the last factorization did."""
        if self._solver is None:
            raise InputError("KKTSystem.factorize: call set_matrices first")
        diagonal = np.asarray(diagonal, dtype=np.float64)
        if diagonal.shape != (self.dim,):
            raise InputError(f"KKT diagonal has shape {diagonal.shape}, expected ({self.dim},)")
        values = self._factor_data
        pat = self._pattern
        matrix_values(
            self._base, self._diag_slot, diagonal, self.n, float(static_reg), pat.full_src,
            self._full_data, values,
        )  # fmt: skip
        self.n_factorizations += 1
        u = self.pivot_threshold
        delta = 0.0
        if u > 0.0:  # tiny: at round-off level of K, and below the static regularization
            delta = PERTURBATION * float(np.max(np.abs(values), initial=0.0))
            if static_reg > 0.0:
                delta = min(delta, 0.1 * float(static_reg))
        positive, negative, _, ok = self._solver.factor(values, u, delta, self._sign)
        if not ok:  # a non-finite pivot, or a zero one without pivoting
            return None
        return Inertia(positive, negative, 0)

    @property
    def pivot_stats(self) -> dict[str, int]:
        """What pivoting did in the last factorization: fronts refactorized with pivoting,
        2 × 2 pivots, perturbed pivots, 1 × 1 pivots accepted below the threshold (none
        acceptable in their supernode)."""
        if self._solver is None:
            raise InputError("KKTSystem.pivot_stats: call set_matrices first")
        st = self._solver.stats
        keys = ("pivoted_fronts", "two_by_two", "perturbed", "below_threshold")
        return {k: int(v) for k, v in zip(keys, st, strict=True)}

    @property
    def analysis(self) -> Analysis:
        """The symbolic analysis in use (elimination order, supernodes, ``flops``,
        ``nnz_factor``); available after the first :meth:`set_matrices`."""
        if self._solver is None:
            raise InputError("KKTSystem.analysis: call set_matrices first")
        return self._solver.a

    def _full(self) -> sp.csr_matrix:
        pat = self._pattern
        return sp.csr_matrix(
            (self._full_data, pat.full_indices, pat.full_indptr), shape=(self.dim, self.dim)
        )

    def matrix(self) -> sp.csc_matrix:
        """The last factorized ``K`` (diagonal included, static regularization excluded), full,
        with the fixed pattern (explicit zeros kept)."""
        return self._full().tocsc(copy=True)

    def matvec(self, v: np.ndarray) -> np.ndarray:
        """``K v`` with the last factorized matrix (one SpMV with the full symmetric pattern)."""
        return self._full() @ v

    def solve(
        self,
        rhs: np.ndarray,
        max_refinement: int = 10,
        ratio_max: float = 1e-10,
        min_refinement: int = 1,
    ) -> tuple[np.ndarray, float]:
        """Solve ``K x = rhs`` with iterative refinement against ``K``: at least
        ``min_refinement`` steps (IPOPT's default: 1) and at most ``max_refinement``, stopping
        at a residual ratio ``<= ratio_max`` or when a step does not reduce it (one compiled
        kernel: triangular solves, residuals with the full symmetric pattern, the loop).

        Returns ``x`` and IPOPT's residual ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``."""
        if self._solver is None:
            raise InputError("KKTSystem.solve: call set_matrices and factorize first")
        rhs = np.asarray(rhs, dtype=np.float64)
        if rhs.shape != (self.dim,):
            raise InputError(f"KKTSystem.solve: rhs has shape {rhs.shape}, expected ({self.dim},)")
        return self._solver.refined_solve(
            rhs, self._pattern.full_indptr, self._pattern.full_indices, self._full_data,
            max_refinement, ratio_max, min_refinement,
        )  # fmt: skip


def compile_kernels_in_background() -> threading.Thread | None:
    """If the numba kernels are not cached yet, compile them in a daemon thread (a tiny KKT
    system through the public path, so with the dtypes of real use) and return it: a caller
    that then spends its time in a C compiler (the CasADi JIT) gets them for free."""
    if all(numba_cached(k) for k in _ENTRY_KERNELS):
        return None

    def tiny_solve() -> None:
        kkt = KKTSystem(2, 1, 1)
        one = sp.csr_matrix(np.ones((1, 2)))
        kkt.set_matrices(sp.eye(2, format="csr"), one, one)
        kkt.set_matrices(sp.eye(2, format="csr"), one, one)  # same pattern: compiles the check
        kkt.factorize(np.array([0.0, 0.0, -1.0, -1.0]), 1e-9)
        kkt.solve(np.ones(4))

    thread = threading.Thread(target=tiny_solve, name="mbplan-numba-compile", daemon=True)
    thread.start()
    return thread
