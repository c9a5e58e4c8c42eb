"""The pattern of the RIPM's KKT matrix (:mod:`mbplan.solvers.kkt.system`): where its blocks
land in the lower CSR pattern, the full symmetric pattern for refinement residuals, the
elimination order and the symbolic analysis; kept in the caller's
:class:`~mbplan.workspace.Workspace` (the KKT systems of one task family share theirs), with
pooled work arrays."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.solvers.kkt.ldl.kernels import NUMERIC_KERNELS
from mbplan.solvers.kkt.ldl.solve import SOLVE_KERNELS
from mbplan.solvers.kkt.ldl.supernodal import SupernodalLDL
from mbplan.solvers.kkt.ldl.symbolic import SYMBOLIC_KERNELS, Analysis
from mbplan.solvers.kkt.ordering import amd_order, metis_order, nested_dissection_order
from mbplan.solvers.kkt.scatter import SCATTER_KERNELS, same_csr_pattern
from mbplan.workspace import Workspace, shared

_ENTRY_KERNELS = SYMBOLIC_KERNELS + NUMERIC_KERNELS + SOLVE_KERNELS + SCATTER_KERNELS


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


ORDERINGS = ("amd", "nested", "metis", "auto")
_ORDERS = {"amd": amd_order, "nested": nested_dissection_order, "metis": metis_order}
AUTO_MIN_FLOPS = 1e7
"""``"auto"`` orders by METIS too only when AMD's factorization needs at least this many
multiply-adds: below it METIS's ordering costs more than it can save."""


def analysis(
    indptr: np.ndarray,
    indices: np.ndarray,
    ordering: str = "amd",
    workspace: Workspace | None = None,
) -> Analysis:
    """The analysis of the pattern given as lower CSR arrays, kept in ``workspace``: the KKT
    systems of one task family (every case of a benchmark, every solve of a receding-horizon
    loop) share their pattern, and its ordering and symbolic factorization cost as much as a
    few numeric factorizations. ``ordering``: ``"amd"``, ``"metis"``,
    ``"nested"`` (:mod:`mbplan.solvers.kkt.ordering`) or ``"auto"``: AMD's analysis, or METIS's if
    it predicts fewer multiply-adds (:attr:`Analysis.flops`; METIS is tried only when AMD's
    count reaches :data:`AUTO_MIN_FLOPS`)."""
    if ordering not in ORDERINGS:
        raise InputError(f"ordering: expected one of {ORDERINGS}, got {ordering!r}")
    return shared(
        workspace,
        "analysis",
        lambda: (len(indptr) - 1, indptr.tobytes(), indices.tobytes(), ordering),
        lambda: _analysis(indptr, indices, ordering, workspace),
        disk=True,  # an ordering (METIS) of a large pattern costs seconds
    )


def _analysis(
    indptr: np.ndarray, indices: np.ndarray, ordering: str, workspace: Workspace | None
) -> Analysis:
    """:func:`analysis`, built (``"auto"``: of the kept candidates)."""
    if ordering == "auto":
        amd = analysis(indptr, indices, "amd", workspace)
        if amd.flops < AUTO_MIN_FLOPS:
            return amd
        metis = analysis(indptr, indices, "metis", workspace)
        return metis if metis.flops < amd.flops else amd
    n = len(indptr) - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    return Analysis(n, rows, indices, _ORDERS[ordering](indptr, indices))


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
    spare: list[_WorkArrays] = field(default_factory=list, compare=False)
    spares: ClassVar[int] = 2
    spare_max_entries: ClassVar[int] = 1 << 20
    """Released work arrays kept (:meth:`release`): at most ``spares``, each with at most
    ``spare_max_entries`` factor entries (8 MB): a new system of a small pattern (each case of a
    task family) then allocates nothing, while a large one's allocation costs little beside its
    factorization. (Class attributes: a
    system's ``__del__`` may run at interpreter exit, after the module's globals are gone.)"""

    def work_arrays(self) -> _WorkArrays:
        """Released work arrays of this pattern, or new ones."""
        try:
            return self.spare.pop()  # atomic: threads never share one
        except IndexError:
            return _WorkArrays(self)

    def release(self, ws: _WorkArrays) -> None:
        """Keep ``ws`` for the next system of this pattern (a few, if small)."""
        if len(self.spare) < self.spares and len(ws.solver.lbuf) <= self.spare_max_entries:
            self.spare.append(ws)


class _WorkArrays:
    """The arrays one KKT system writes: ``K``'s values in the lower pattern (without and with
    the diagonal and regularization) and in the full pattern, and the numeric factorization."""

    def __init__(self, pat: _KKTPattern) -> None:
        nnz = len(pat.indices)
        self.base = np.zeros(nnz)
        self.full_data = np.zeros(len(pat.full_src))
        self.factor_data = np.zeros(nnz)
        self.solver = SupernodalLDL(pat.analysis)


def _kkt_pattern(
    n: int,
    n_eq: int,
    n_ineq: int,
    hess: sp.csr_matrix,
    jac_eq: sp.csr_matrix,
    jac_in: sp.csr_matrix,
    ordering: str,
    workspace: Workspace | None = None,
) -> _KKTPattern:
    """The pattern of ``K`` for the blocks' patterns, kept in ``workspace`` like
    :func:`analysis` (a solve builds it once, a benchmark of many cases sharing a workspace
    once)."""
    blocks = (hess, jac_eq, jac_in)
    return shared(
        workspace,
        "kkt_pattern",
        lambda: (
            n,
            n_eq,
            n_ineq,
            ordering,
            *(a.tobytes() for m in blocks for a in (m.indptr, m.indices)),
        ),
        lambda: _new_kkt_pattern(n, n_eq, n_ineq, blocks, ordering, workspace),
        disk=True,
    )


def _new_kkt_pattern(
    n: int,
    n_eq: int,
    n_ineq: int,
    blocks: tuple[sp.csr_matrix, ...],
    ordering: str,
    workspace: Workspace | None,
) -> _KKTPattern:
    """:func:`_kkt_pattern` of the blocks ``(H, A_E, A_I)``, built."""
    hess, jac_eq, jac_in = blocks
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
    hit_analysis = analysis(indptr, indices, ordering, workspace)
    return _KKTPattern(
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
