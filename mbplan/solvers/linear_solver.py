"""The reduced KKT matrix of the RIPM and its inertia-revealing sparse LDLᵀ factorization.

Eliminating ``ds`` from the Newton system (53) (see :mod:`mbplan.solvers.ripm`) leaves the
symmetric quasi-definite-shaped matrix, unknowns ordered ``(dx, dy, dz)``::

    K = [[H + D_x,  A_Eᵀ,  A_Iᵀ],
         [A_E,      D_y,   0   ],
         [A_I,      0,     D_z ]]

with diagonal blocks ``D_*`` chosen by the caller (``δ_w I``, ``-δ_c I``, ``-(Σ⁻¹ + δ_c I)``).
The pattern (the union of ``H``'s lower triangle, the Jacobians and the full diagonal) is built
once by index arrays; each new matrix with the same pattern is a scatter of its values.

The factorization (symbolic analysis in :mod:`mbplan.solvers.ldl_symbolic`, numeric kernels in
:mod:`mbplan.solvers.ldl_kernels`, work arrays in :mod:`mbplan.solvers.supernodal_ldl`) is a
supernodal multifrontal ``P K Pᵀ = (I + L) D (I + L)ᵀ`` with a diagonal ``D`` and no pivoting
(optionally 1 × 1 / 2 × 2 threshold pivoting inside each supernode, ``D`` block diagonal:
:mod:`mbplan.solvers.ldl_pivot`), compiled with numba. Its symbolic analysis takes the approximate minimum
degree ordering qdldl computes (SuiteSparse AMD), postorders the elimination tree, groups
columns into fundamental supernodes merged by CHOLMOD's relaxed amalgamation rule, merges
sibling leaves with equal rows and moves small leaves right before their parent, which they
update directly (:mod:`mbplan.solvers.ldl_layout`), and precomputes where every entry of
``K`` and every child's update matrix lands; it is memoized per
process for the last few patterns (the KKT systems of one task family share theirs). The numeric
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
import itertools
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import scipy.sparse as sp

from mbplan.engine.jit import announce_uncached_numba, numba_cached
from mbplan.errors import InputError
from mbplan.solvers.kkt_scatter import (
    SCATTER_KERNELS,
    matrix_values,
    same_csr_pattern,
    scatter_blocks,
)
from mbplan.solvers.ldl_kernels import NUMERIC_KERNELS
from mbplan.solvers.ldl_solve import SOLVE_KERNELS
from mbplan.solvers.ldl_symbolic import SYMBOLIC_KERNELS, Analysis
from mbplan.solvers.ordering import amd_order, metis_order, nested_dissection_order
from mbplan.solvers.supernodal_ldl import SupernodalLDL

_NONE = np.zeros(0, np.int64)
_NONE_F = np.zeros(0)


@dataclass(frozen=True)
class Inertia:
    """Numbers of positive, negative and zero pivots of the LDLᵀ factorization."""

    positive: int
    negative: int
    zero: int


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


@dataclass(frozen=True)
class _BlockPattern:
    """A block's sparsity pattern: its shape and copies of its CSR index arrays."""

    shape: tuple[int, int]
    indptr: np.ndarray
    indices: np.ndarray


def _same_pattern(a: sp.csr_matrix | _BlockPattern, b: _BlockPattern | None) -> bool:
    return (
        b is not None
        and a.shape == b.shape
        and same_csr_pattern(a.indptr, a.indices, b.indptr, b.indices)
    )


_ANALYSES: OrderedDict[tuple[int, bytes, bytes, str], Analysis] = OrderedDict()
_ANALYSES_KEPT = 8
_ANALYSES_LOCK = threading.Lock()
ORDERINGS = ("amd", "nested", "metis", "auto")
_ORDERS = {"amd": amd_order, "nested": nested_dissection_order, "metis": metis_order}
PERTURBATION = 1e-14
"""With pivoting, a pivot of magnitude at most this times ``max |K|`` (and below a tenth of the
static regularization) is perturbed to that magnitude (PARDISO-style static pivoting;
refinement against ``K`` corrects the solve)."""
AUTO_MIN_FLOPS = 1e7
"""``"auto"`` orders by METIS too only when AMD's factorization needs at least this many
multiply-adds: below it METIS's ordering costs more than it can save (docs/ripm-speed.md)."""


def analysis(indptr: np.ndarray, indices: np.ndarray, ordering: str = "amd") -> Analysis:
    """The analysis of the pattern given as lower CSR arrays, memoized per process for the last
    few patterns: the KKT systems of one task family (every case of a benchmark, every solve of
    a receding-horizon loop) share their pattern, and its ordering and symbolic factorization
    cost as much as a few numeric factorizations. ``ordering``: ``"amd"``, ``"metis"``,
    ``"nested"`` (:mod:`mbplan.solvers.ordering`) or ``"auto"``: AMD's analysis, or METIS's if
    it predicts fewer multiply-adds (:attr:`Analysis.flops`; METIS is tried only when AMD's
    count reaches :data:`AUTO_MIN_FLOPS`)."""
    if ordering not in ORDERINGS:
        raise InputError(f"ordering: expected one of {ORDERINGS}, got {ordering!r}")
    key = (len(indptr) - 1, indptr.tobytes(), indices.tobytes(), ordering)
    with _ANALYSES_LOCK:
        hit = _ANALYSES.get(key)
        if hit is not None:
            _ANALYSES.move_to_end(key)
            return hit
    if ordering == "auto":
        hit = analysis(indptr, indices, "amd")
        if hit.flops >= AUTO_MIN_FLOPS:
            metis = analysis(indptr, indices, "metis")
            hit = metis if metis.flops < hit.flops else hit
    else:
        announce_uncached_numba(*_ENTRY_KERNELS)  # first run only
        n = key[0]
        rows = np.repeat(np.arange(n), np.diff(indptr))
        hit = Analysis(n, rows, indices, _ORDERS[ordering](indptr, indices))
    with _ANALYSES_LOCK:
        _ANALYSES[key] = hit
        while len(_ANALYSES) > _ANALYSES_KEPT:
            _ANALYSES.popitem(last=False)
    return hit


@dataclass(frozen=True)
class _KKTPattern:
    """Where the blocks of ``K`` land in its lower CSR pattern, the full symmetric pattern for
    refinement residuals and the symbolic analysis: read-only, shared by every KKTSystem of the
    same block patterns."""

    h_src: np.ndarray
    h_slot: np.ndarray
    e_slot: np.ndarray
    i_slot: np.ndarray
    diag_slot: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    full_src: np.ndarray
    full_indptr: np.ndarray
    full_indices: np.ndarray
    analysis: Analysis
    blocks: tuple[_BlockPattern, _BlockPattern, _BlockPattern]  # the blocks' patterns (copies)
    sign: np.ndarray  # expected pivot signs in pivot order: + primal, - dual
    spare: list[_Workspace] = field(default_factory=list, compare=False)
    spares: ClassVar[int] = 2
    spare_max_entries: ClassVar[int] = 1 << 20
    """Released workspaces kept (:meth:`release`): at most ``spares``, each with at most
    ``spare_max_entries`` factor entries (8 MB): a new system of a small pattern (a solve's
    least-squares and Newton systems, each case of a task family) then allocates nothing, while
    a large one's allocation costs little beside its factorization. (Class attributes: a
    system's ``__del__`` may run at interpreter exit, after the module's globals are gone.)"""

    def workspace(self) -> _Workspace:
        """A released workspace of this pattern, or a new one."""
        try:
            return self.spare.pop()  # atomic: threads never share one
        except IndexError:
            return _Workspace(self)

    def release(self, ws: _Workspace) -> None:
        """Keep ``ws`` for the next system of this pattern (a few, if small)."""
        if len(self.spare) < self.spares and len(ws.solver.lbuf) <= self.spare_max_entries:
            self.spare.append(ws)


class _Workspace:
    """The arrays one KKT system writes: ``K``'s values in the lower pattern (without and with
    the diagonal and regularization) and in the full pattern, and the numeric factorization."""

    def __init__(self, pat: _KKTPattern) -> None:
        nnz = len(pat.indices)
        self.base = np.zeros(nnz)
        self.full_data = np.zeros(len(pat.full_src))
        self.factor_data = np.zeros(nnz)
        self.solver = SupernodalLDL(pat.analysis)


_PATTERNS: OrderedDict[tuple, _KKTPattern] = OrderedDict()


def _kkt_pattern(
    n: int,
    n_eq: int,
    n_ineq: int,
    hess: sp.csr_matrix,
    jac_eq: sp.csr_matrix,
    jac_in: sp.csr_matrix,
    ordering: str,
) -> _KKTPattern:
    """The pattern of ``K`` for the blocks' patterns, memoized like :func:`analysis` (a solve
    builds it once, a benchmark of many cases once per process)."""
    key = (
        n,
        n_eq,
        n_ineq,
        ordering,
        *tuple(a.tobytes() for m in (hess, jac_eq, jac_in) for a in (m.indptr, m.indices)),
    )
    with _ANALYSES_LOCK:
        hit = _PATTERNS.get(key)
        if hit is not None:
            _PATTERNS.move_to_end(key)
            return hit
    N = n + n_eq + n_ineq
    h_rows = np.repeat(np.arange(n), np.diff(hess.indptr))
    h_mask = h_rows >= hess.indices
    sources = [
        (h_rows[h_mask], hess.indices[h_mask]),
        (n + np.repeat(np.arange(n_eq), np.diff(jac_eq.indptr)), jac_eq.indices),
        (n + n_eq + np.repeat(np.arange(n_ineq), np.diff(jac_in.indptr)), jac_in.indices),
        (np.arange(N), np.arange(N)),
    ]
    keys = np.concatenate([r.astype(np.int64) * N + c for r, c in sources])
    unique, slot = np.unique(keys, return_inverse=True)
    sizes = np.cumsum([0] + [len(r) for r, _ in sources])
    slot = slot.astype(np.int32)  # int32 index arrays, as the pattern's: half the traffic
    h_slot, e_slot, i_slot, diag_slot = (slot[a:b] for a, b in itertools.pairwise(sizes))
    rows = unique // N
    cols = unique % N
    indices = cols.astype(np.int32)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=N))]).astype(np.int32)
    # the full symmetric matrix for refinement residuals (one SpMV): entry e of the lower
    # triangle lands in its own slot and, off the diagonal, in the mirrored one
    off = rows != cols
    f_rows = np.concatenate([rows, cols[off]])
    f_cols = np.concatenate([cols, rows[off]])
    order = np.lexsort((f_cols, f_rows))
    hit_analysis = analysis(indptr, indices, ordering)
    hit = _KKTPattern(
        h_src=np.flatnonzero(h_mask).astype(np.int32),
        h_slot=h_slot,
        e_slot=e_slot,
        i_slot=i_slot,
        diag_slot=diag_slot,
        indptr=indptr,
        indices=indices,
        full_src=np.concatenate([np.arange(len(unique)), np.flatnonzero(off)])[order].astype(
            np.int32
        ),
        full_indptr=np.concatenate([[0], np.cumsum(np.bincount(f_rows, minlength=N))]).astype(
            np.int32
        ),
        full_indices=f_cols[order].astype(np.int32),
        analysis=hit_analysis,
        blocks=tuple(
            _BlockPattern(a.shape, a.indptr.copy(), a.indices.copy())
            for a in (hess, jac_eq, jac_in)
        ),
        sign=np.where(hit_analysis.perm < n, 1.0, -1.0),
    )
    with _ANALYSES_LOCK:
        _PATTERNS[key] = hit
        while len(_PATTERNS) > _ANALYSES_KEPT:
            _PATTERNS.popitem(last=False)
    return hit


class KKTSystem:
    """Assembles ``K`` for a fixed pattern, factorizes it (supernodal LDLᵀ) and solves with
    refinement.

    Typical use per Newton step: :meth:`set_matrices` once, then :meth:`factorize` for each trial
    perturbation of the diagonal (inertia correction) and :meth:`solve` for each right-hand side.
    ``ordering`` selects the elimination order (:func:`analysis`). ``pivot_threshold`` ``u > 0``
    turns on threshold 1 × 1 / 2 × 2 pivoting inside each supernode (a pivot ``|d| < u`` times
    its column's largest entry is replaced); ``0``: no pivoting.
    """

    def __init__(
        self, n: int, n_eq: int, n_ineq: int, *, ordering: str = "amd", pivot_threshold: float = 0.0
    ) -> None:
        if ordering not in ORDERINGS:
            raise InputError(f"ordering: expected one of {ORDERINGS}, got {ordering!r}")
        if not 0.0 <= pivot_threshold <= 1.0:
            raise InputError(f"pivot_threshold: expected a value in [0, 1], got {pivot_threshold}")
        self.ordering = ordering
        self.pivot_threshold = float(pivot_threshold)
        self.n, self.n_eq, self.n_ineq = n, n_eq, n_ineq
        self.dim = n + n_eq + n_ineq
        self._patterns: tuple[_BlockPattern | None, ...] = (None, None, None)
        self._solver: SupernodalLDL | None = None
        self.n_factorizations = 0
        self.n_analyses = 0

    # ------------------------------------------------------------------ pattern
    def _build_pattern(self, hess: sp.csr_matrix, jac_eq: sp.csr_matrix, jac_in: sp.csr_matrix):
        pat = _kkt_pattern(self.n, self.n_eq, self.n_ineq, hess, jac_eq, jac_in, self.ordering)
        self._release()
        self._pattern, self._patterns = pat, pat.blocks
        self._diag_slot = pat.diag_slot
        self._indptr, self._indices = pat.indptr, pat.indices
        self._ws = ws = pat.workspace()
        self._base = ws.base
        self._full_data = ws.full_data  # K in the full symmetric pattern
        # the factorized values, entry by entry of the lower CSR arrays (= upper CSC arrays)
        self._factor_data = ws.factor_data
        self._solver = ws.solver
        # expected pivot signs in pivot order (perturbed pivots get them): + primal, - dual
        self._sign = pat.sign
        self.n_analyses += 1

    def _release(self) -> None:
        """Hand the workspace back to its pattern (the system is gone or changes pattern)."""
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
        self, rhs: np.ndarray, max_refinement: int = 10, ratio_max: float = 1e-10
    ) -> tuple[np.ndarray, float]:
        """Solve ``K x = rhs`` with iterative refinement against ``K``: at least one step
        (IPOPT's default) and at most ``max_refinement``, stopping at a residual ratio
        ``<= ratio_max`` or when a step does not reduce it (one compiled kernel: triangular
        solves, residuals with the full symmetric pattern, the loop).

        Returns ``x`` and IPOPT's residual ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``."""
        if self._solver is None:
            raise InputError("KKTSystem.solve: call set_matrices and factorize first")
        rhs = np.asarray(rhs, dtype=np.float64)
        if rhs.shape != (self.dim,):
            raise InputError(f"KKTSystem.solve: rhs has shape {rhs.shape}, expected ({self.dim},)")
        return self._solver.refined_solve(
            rhs, self._pattern.full_indptr, self._pattern.full_indices, self._full_data,
            max_refinement, ratio_max,
        )  # fmt: skip


_ENTRY_KERNELS = SYMBOLIC_KERNELS + NUMERIC_KERNELS + SOLVE_KERNELS + SCATTER_KERNELS


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
