"""The symbolic phase of :class:`~mbplan.solvers.kkt.reduced.reduction.Reduction` (once per plan and
pattern, :mod:`mbplan.solvers.kkt.reduced.layout` for the products): the replaced rows and
dependent columns by QR with column pivoting on given values, couplings, reach sets and the
index arrays of the groups' and blocks' values."""

from __future__ import annotations

import functools

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, maximum_bipartite_matching

from mbplan.errors import InputError
from mbplan.solvers.kkt.elimination import EliminationPlan
from mbplan.solvers.kkt.reduced.kernels import group_values


class Slots:
    """Positions of entries ``(row, col)`` in a canonical CSR matrix (``-1``: not stored)."""

    def __init__(self, a: sp.csr_matrix) -> None:
        self.n = a.shape[1]
        self.keys = np.repeat(np.arange(a.shape[0], dtype=np.int64), np.diff(a.indptr)) * self.n
        self.keys += a.indices

    def __call__(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        want = rows[..., :, None] * self.n + cols[..., None, :]
        pos = np.minimum(np.searchsorted(self.keys, want), max(len(self.keys) - 1, 0))
        ok = (rows[..., :, None] >= 0) & (cols[..., None, :] >= 0)
        hit = ok & (self.keys[pos] == want) if len(self.keys) else ok & False
        return np.where(hit, pos, -1)

    def pairs(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Slots of the entries ``(rows[t], cols[t])`` (``-1``: not stored)."""
        want = np.asarray(rows, np.int64) * self.n + np.asarray(cols, np.int64)
        pos = np.minimum(np.searchsorted(self.keys, want), max(len(self.keys) - 1, 0))
        hit = self.keys[pos] == want if len(self.keys) else want < 0
        return np.where(hit, pos, -1)


def _pivots(m: np.ndarray) -> np.ndarray:
    """Column order of a QR with column pivoting (the first ``rank`` are well conditioned)."""
    return sla.qr(m, pivoting=True, mode="r")[1]


def _btf(pattern: np.ndarray) -> tuple[np.ndarray, ...]:
    """Row and column orders making the square boolean ``pattern`` block upper triangular with
    irreducible diagonal blocks (a matching on the diagonal, then the strong components in
    topological order), and per position the beginning and the end of its diagonal block."""
    return _btf_of(pattern.shape[0], np.packbits(pattern).tobytes())


# process-wide cache, result-neutral: orders of the boolean pattern (the key), never of values
@functools.lru_cache(maxsize=4096)
def _btf_of(g: int, packed: bytes) -> tuple[np.ndarray, ...]:
    pattern = np.unpackbits(np.frombuffer(packed, np.uint8), count=g * g).reshape(g, g) > 0
    match = maximum_bipartite_matching(sp.csr_matrix(pattern.astype(float)), perm_type="column")
    if np.any(match < 0):
        raise InputError("EliminationPlan: a group's or block's matrix is structurally singular")
    diag = pattern[:, match]  # row i -> column i: an edge i -> k for every entry (i, k)
    n_comp, label = connected_components(sp.csr_matrix(diag), directed=True, connection="strong")
    succ = [set() for _ in range(n_comp)]
    for i, k in zip(*np.nonzero(diag), strict=True):
        if label[i] != label[k]:
            succ[label[i]].add(label[k])
    indegree = np.zeros(n_comp, np.int64)
    for c in range(n_comp):
        for k in succ[c]:
            indegree[k] += 1
    order, ready = [], [c for c in range(n_comp) if indegree[c] == 0]
    while ready:
        c = ready.pop()
        order.append(c)
        for k in sorted(succ[c]):
            indegree[k] -= 1
            if indegree[k] == 0:
                ready.append(k)
    rows = np.concatenate([np.flatnonzero(label == c) for c in order] + [np.zeros(0, np.int64)])
    sizes = np.bincount(label, minlength=n_comp)[order]
    end = np.repeat(np.cumsum(sizes), sizes).astype(np.int64)
    begin = np.repeat(np.cumsum(sizes) - sizes, sizes).astype(np.int64)
    return rows.astype(np.int64), match[rows].astype(np.int64), begin, end


def _rows_of(a: sp.csr_matrix, row: int) -> np.ndarray:
    return a.indices[a.indptr[row] : a.indptr[row + 1]]


class ReductionSymbolic:
    """The symbolic builders of :class:`~mbplan.solvers.kkt.reduced.reduction.Reduction` (they set its
    index arrays and patterns)."""

    n: int
    me: int
    mi: int

    def _groups(self, plan: EliminationPlan, ae: sp.csr_matrix, slots: Slots) -> None:
        """Slots of the groups' entries: as many cancelled columns as source rows (QR pivoting
        of the first values), the outer columns; the replaced rows from QR pivoting of
        ``M_j``."""
        src, sub, can = plan.group_sources, plan.group_subtract, plan.group_cancel
        J = plan.n_groups
        r = sub.shape[1] if J else 0
        if J and np.any(sub < 0):
            raise InputError("EliminationPlan: every group subtracts the same number of rows")
        outer = []
        for j in range(J):
            cols = np.unique(np.concatenate([_rows_of(ae, q) for q in src[j][src[j] >= 0]]))
            outer.append(np.setdiff1d(cols, can[j][can[j] >= 0]))
        o = max((len(c) for c in outer), default=0)
        self.outer = -np.ones((J, o), np.int64)
        for j, c in enumerate(outer):
            self.outer[j, : len(c)] = c
        g_cancel = slots(src, can)
        dense = np.where(g_cancel >= 0, ae.data[g_cancel], 0.0)
        sel = -np.ones(src.shape, np.int64)
        for j in range(J):
            valid = src[j] >= 0
            chosen = can[j][_pivots(dense[j][valid])[: valid.sum()]]
            if np.any(chosen < 0):
                raise InputError("EliminationPlan: a group's source rows are rank deficient")
            sel[j, valid] = chosen
        src, self.g_begin, self.g_end = src.copy(), np.zeros(src.shape, np.int64), np.zeros(src.shape, np.int64)  # fmt: skip
        pattern = (slots(src, sel) >= 0) | np.eye(src.shape[1], dtype=bool)[None] * (src < 0)[..., None]  # fmt: skip
        for j in range(J):  # sources and selected columns in block triangular order
            rows, cols, self.g_begin[j], self.g_end[j] = _btf(pattern[j])
            src[j], sel[j] = src[j][rows], sel[j][cols]
        self.g_sel, self.h_sel, self.pad = slots(src, sel), slots(sub, sel), src < 0
        self.g_outer = slots(src, self.outer)
        self.h_outer = slots(sub, self.outer)
        self.src, self.sub = src, sub
        g = src.shape[1]
        self.M = np.zeros((J, r, g))
        self.new_rows = np.zeros((J, r, o))
        self.g_a, self.g_x, self.g_piv = np.zeros((g, g)), np.zeros((g, r)), np.zeros(g, np.int64)
        if J and not group_values(
            ae.data, self.g_sel, self.h_sel, self.pad, self.g_begin, self.g_end, self.g_outer, self.h_outer,
            self.M, self.new_rows, self.g_a, self.g_x, self.g_piv,
        ):  # fmt: skip
            raise InputError("EliminationPlan: a group's source rows are rank deficient")
        self.tgt = np.zeros((J, r), np.int64)
        for j in range(J):
            t = plan.group_targets[j][plan.group_targets[j] >= 0]
            where = np.array([np.flatnonzero(src[j] == x)[0] for x in t])
            self.tgt[j] = np.sort(t[_pivots(self.M[j][:, where])[:r]])

    def _blocks(self, plan: EliminationPlan, ae: sp.csr_matrix, slots: Slots) -> None:
        """Local rows, dependent columns (QR pivoting of the first values, then the block
        triangular order of the square part), couplings, reach sets and where each local row
        entry goes (:meth:`_block_entries`)."""
        n, B = self.n, plan.n_blocks
        col_block, col_local = -np.ones(n, np.int64), np.zeros(n, np.int64)
        for b in range(B):
            own = plan.block_cols[b][plan.block_cols[b] >= 0]
            if np.any(col_block[own] >= 0):
                raise InputError("EliminationPlan: a column in two blocks")
            col_block[own], col_local[own] = b, np.arange(len(own))
        rows_of_block, (eb, ea, ec, ek, es) = self._local_entries(plan, ae)
        cb = col_block[ec]
        if np.any((cb < 0) | (cb > eb)):
            raise InputError(
                f"EliminationPlan: block {eb[np.flatnonzero((cb < 0) | (cb > eb))[0]]}'s local "
                "rows touch a column outside it and the blocks before it"
            )
        val = np.zeros(len(es))
        val[ek], val[~ek] = self.new_rows.reshape(-1)[es[ek]], ae.data[es[~ek]]
        ptr = np.searchsorted(eb, np.arange(B + 1))
        dep, free, couple, lu_begin, lu_end = [], [], [], [], []
        for b in range(B):
            own = plan.block_cols[b][plan.block_cols[b] >= 0]
            t = np.arange(ptr[b], ptr[b + 1])
            mine = t[cb[t] == b]
            nr = len(rows_of_block[b])
            dense, stored = np.zeros((nr, len(own))), np.zeros((nr, len(own)), bool)
            dense[ea[mine], col_local[ec[mine]]] = val[mine]
            stored[ea[mine], col_local[ec[mine]]] = True
            piv = _pivots(dense)
            d = np.sort(piv[:nr])
            rows, cols, begin, end = _btf(stored[:, d])  # rows, dependent columns: triangular
            new_row = np.empty(nr, np.int64)
            new_row[rows] = np.arange(nr)
            ea[t] = new_row[ea[t]]
            rows_of_block[b] = rows_of_block[b][rows]
            dep.append(own[d[cols]])
            free.append(own[np.sort(piv[nr:])])
            couple.append(np.unique(cb[t][cb[t] != b]))
            lu_begin.append(begin)
            lu_end.append(end)
        self.lu_begin = np.concatenate([*lu_begin, np.zeros(0, np.int64)])
        self.lu_end = np.concatenate([*lu_end, np.zeros(0, np.int64)])
        self.dep = np.concatenate(dep) if B else np.zeros(0, np.int64)
        self.y_rows = np.concatenate(rows_of_block) if B else np.zeros(0, np.int64)
        if len(np.unique(self.y_rows)) != len(self.y_rows):
            raise InputError("EliminationPlan: a local row in two blocks")
        self._block_entries((eb, ea, ec, ek, es), dep, free, couple, [len(x) for x in rows_of_block])  # fmt: skip

    def _local_entries(self, plan: EliminationPlan, ae: sp.csr_matrix) -> tuple[list, tuple]:
        """Per block its local rows (the group's new rows, then its plan rows) and the entries
        of these rows as arrays sorted by block, local row and column: block, local row, column,
        from the groups' new rows (else ``A_E``), source (in ``new_rows.flat`` or ``ae.data``)."""
        B, r, o = plan.n_blocks, self.M.shape[1], self.outer.shape[1]
        j = plan.block_groups
        g = np.flatnonzero(j >= 0)  # the new rows: r per grouped block, dense over its outer cols
        gb, gi, gq = (x.reshape(-1) for x in np.meshgrid(g, np.arange(r), np.arange(o), indexing="ij"))  # fmt: skip
        gc = self.outer[j[gb], gq]
        keep = gc >= 0
        gb, gi, gq, gc = gb[keep], gi[keep], gq[keep], gc[keep]
        gs = (j[gb] * r + gi) * o + gq
        valid = plan.block_rows >= 0  # the plan rows after them
        rb, rk = np.nonzero(valid)
        ra = np.where(j[rb] >= 0, r, 0) + np.cumsum(valid, axis=1)[rb, rk] - 1
        row = plan.block_rows[rb, rk]
        nnz = np.diff(ae.indptr)[row]
        at = np.repeat(ae.indptr[row] - np.cumsum(nnz) + nnz, nnz) + np.arange(nnz.sum())
        eb = np.concatenate([gb, np.repeat(rb, nnz)]).astype(np.int64)
        ea = np.concatenate([gi, np.repeat(ra, nnz)]).astype(np.int64)
        ec = np.concatenate([gc, ae.indices[at]]).astype(np.int64)
        ek = np.concatenate([np.ones(len(gb), bool), np.zeros(len(at), bool)])
        es = np.concatenate([gs, at]).astype(np.int64)
        order = np.lexsort((ec, ea, eb))
        rows = [np.concatenate([self.tgt[j[b]] if j[b] >= 0 else np.zeros(0, np.int64), row[rb == b]]).astype(np.int64) for b in range(B)]  # fmt: skip
        return rows, (eb[order], ea[order], ec[order], ek[order], es[order])

    def _block_entries(self, entries: tuple, dep: list, free: list, couple: list,
                       n_rows: list[int]) -> None:  # fmt: skip
        """Per block its sorted reach ``R_b`` (own free columns and the coupled blocks' reach),
        ``shape[b] = (r_b, |R_b|)``, and where each entry of its local rows (``entries``:
        :meth:`_local_entries`, local rows in their final order) goes: the values ``lval``
        (``A_E``'s entries first, ``lval[t] = ae[la_src[t]]``, then the groups' new rows',
        ``new_rows.flat[ln_src]``), from there to ``L_b[:, dep]`` (``a_src`` → ``a_dst`` in
        ``lu``), to the right-hand side of ``E_b`` (a free column: ``fe_src`` → ``fe_dst`` in
        ``ebuf``; both lists per block at ``a_ptr``, ``fe_ptr``) or to coupling ``k`` (a coupled
        block's dependent column ``p``: ``nz_a``, ``nz_p``, ``nz_src``, sorted by row, at
        ``nz_ptr[k]``; ``rmap``: the coupled block's reach in ``R_b``)."""
        n, B = self.n, len(dep)
        eb, ea, ec, ek, es = entries
        self.reach, cptr, cblk, rmap = [], [0], [], []
        for b in range(B):
            R = np.unique(np.concatenate([free[b], *(self.reach[i] for i in couple[b])]))
            self.reach.append(R.astype(np.int64))
            for i in couple[b]:
                cblk.append(int(i))
                rmap.append(np.searchsorted(R, self.reach[i]))
            cptr.append(len(cblk))
        i64 = lambda x: np.asarray(x, np.int64)  # noqa: E731
        r, m = i64(n_rows), i64([len(x) for x in self.reach])
        self.shape = np.stack([r, m], axis=1) if B else np.zeros((0, 2), np.int64)
        self.eoff = i64(np.concatenate([[0], np.cumsum(r * m)]))
        self.lu_off = i64(np.concatenate([[0], np.cumsum(r * r)]))
        self.uoff = i64(np.concatenate([[0], np.cumsum(r)]))
        self.cptr, self.cblk = i64(cptr), i64(cblk)
        self.rmap_off = i64(np.concatenate([[0], np.cumsum([len(x) for x in rmap])]))
        self.rmap = i64(np.concatenate([*rmap, np.zeros(0, np.int64)]))
        order = np.argsort(ek, kind="stable")  # A_E's entries first
        self.la_src, self.ln_src = es[order][~ek[order]], es[order][ek[order]]
        lval_of = np.empty(len(order), np.int64)
        lval_of[order] = np.arange(len(order))
        dep_block, dep_pos = -np.ones(n, np.int64), np.zeros(n, np.int64)
        for b in range(B):
            dep_block[dep[b]], dep_pos[dep[b]] = b, np.arange(len(dep[b]))
        db = dep_block[ec]
        own, coupled, fr = db == eb, (db >= 0) & (db != eb), db < 0
        self.a_src = lval_of[own]
        self.a_dst = self.lu_off[eb[own]] + ea[own] * r[eb[own]] + dep_pos[ec[own]]
        self.a_ptr = i64(np.searchsorted(eb[own], np.arange(B + 1)))
        reach_key = np.concatenate([b * n + self.reach[b] for b in range(B)] + [np.zeros(0, np.int64)])  # fmt: skip
        rstart = np.concatenate([[0], np.cumsum(m)])[:-1] if B else np.zeros(0, np.int64)
        rpos = np.searchsorted(reach_key, eb[fr] * n + ec[fr]) - rstart[eb[fr]]
        self.fe_src = lval_of[fr]
        self.fe_dst = self.eoff[eb[fr]] + ea[fr] * m[eb[fr]] + rpos
        self.fe_ptr = i64(np.searchsorted(eb[fr], np.arange(B + 1)))
        k_block = np.repeat(np.arange(B), np.diff(self.cptr))
        k = np.searchsorted(k_block * B + self.cblk, eb[coupled] * B + db[coupled])
        nz_a, nz_p, nz_src = ea[coupled], dep_pos[ec[coupled]], lval_of[coupled]
        by = np.lexsort((nz_p, nz_a, k))
        self.nz_a, self.nz_p, self.nz_src, k = nz_a[by], nz_p[by], nz_src[by], k[by]
        self.nz_ptr = i64(np.searchsorted(k, np.arange(len(cblk) + 1)))
        # the same entries per block as rows and columns of B (its local rows / dependent
        # columns at uoff), by row for B⁻¹ and by column for B⁻ᵀ
        k_of = np.repeat(np.arange(len(cblk)), np.diff(self.nz_ptr))
        b_of = np.searchsorted(self.cptr, k_of, side="right") - 1
        row = self.uoff[b_of] + self.nz_a
        col = self.uoff[self.cblk[k_of]] + self.nz_p
        by_row, by_col = np.lexsort((col, row, b_of)), np.lexsort((row, col, b_of))
        self.bc_ptr = i64(np.searchsorted(b_of[by_row], np.arange(B + 1)))
        self.bc_row, self.bc_col, self.bc_val = row[by_row], col[by_row], self.nz_src[by_row]
        self.bt_row, self.bt_col, self.bt_val = row[by_col], col[by_col], self.nz_src[by_col]
        self.lval = np.zeros(len(order))
        self.ebuf = np.zeros(self.eoff[-1])
        self.lu, self.dinv = np.zeros(self.lu_off[-1]), np.zeros(self.uoff[-1])
        self.piv = np.zeros(self.uoff[-1], np.int64)
