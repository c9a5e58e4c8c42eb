"""The symbolic phase of :class:`~mbplan.solvers.reduction.Reduction` (once per plan and
pattern): the replaced rows and dependent columns by QR with column pivoting on the first
matrix's values, couplings, reach sets, the patterns of ``T``, ``Tᵀ``, ``H_f``, ``H_f T``,
``A_E,kept T`` and ``H_r``, and every index array of the numeric phase."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.solvers.elimination import EliminationPlan
from mbplan.solvers.reduced_kernels import group_values, lower_ends


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


def _pivots(m: np.ndarray) -> np.ndarray:
    """Column order of a QR with column pivoting (the first ``rank`` are well conditioned)."""
    return sla.qr(m, pivoting=True, mode="r")[1]


def _product_pattern(*pairs: tuple[sp.csr_matrix, sp.csr_matrix]) -> sp.csr_matrix:
    """The structural pattern of ``Σ a @ b`` over the pairs (values of ones: no cancellation),
    zero values."""

    def one(m: sp.csr_matrix) -> sp.csr_matrix:
        return sp.csr_matrix((np.ones(m.nnz), m.indices, m.indptr), shape=m.shape)

    p = sp.csr_matrix(sum(one(a) @ one(b) for a, b in pairs))
    p.sort_indices()
    p.data[:] = 0.0
    return p


def _transpose(m: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
    """``mᵀ``'s pattern (zero values, sorted) and where each of its entries is in ``m.data``."""
    pos = sp.csr_matrix((np.arange(m.nnz, dtype=float) + 1, m.indices, m.indptr), shape=m.shape)
    pos_t = pos.T.tocsr()
    pos_t.sort_indices()
    shape = (m.shape[1], m.shape[0])
    t = sp.csr_matrix((np.zeros(pos_t.nnz), pos_t.indices, pos_t.indptr), shape=shape)
    return t, pos_t.data.astype(np.int64) - 1


def _rows_of(a: sp.csr_matrix, row: int) -> np.ndarray:
    return a.indices[a.indptr[row] : a.indptr[row + 1]]


class ReductionSymbolic:
    """The symbolic builders of :class:`~mbplan.solvers.reduction.Reduction` (they set its
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
        self.g_sel, self.h_sel, self.pad = slots(src, sel), slots(sub, sel), src < 0
        self.g_outer = slots(src, self.outer)
        self.h_outer = slots(sub, self.outer)
        self.src, self.sub = src, sub
        self.M = np.zeros((J, r, src.shape[1]))
        self.new_rows = np.zeros((J, r, o))
        if J and not group_values(
            ae.data, self.g_sel, self.h_sel, self.pad, self.g_outer, self.h_outer, self.M,
            self.new_rows,
        ):  # fmt: skip
            raise InputError("EliminationPlan: a group's source rows are rank deficient")
        self.tgt = np.zeros((J, r), np.int64)
        for j in range(J):
            t = plan.group_targets[j][plan.group_targets[j] >= 0]
            where = np.array([np.flatnonzero(src[j] == x)[0] for x in t])
            self.tgt[j] = np.sort(t[_pivots(self.M[j][:, where])[:r]])

    def _blocks(self, plan: EliminationPlan, ae: sp.csr_matrix, slots: Slots) -> None:
        """Local rows, dependent columns (QR pivoting of the first values), couplings, reach
        sets and the scatter of ``L_b``."""
        n, B, r = self.n, plan.n_blocks, self.M.shape[1]
        col_block = -np.ones(n, np.int64)
        for b in range(B):
            own = plan.block_cols[b][plan.block_cols[b] >= 0]
            if np.any(col_block[own] >= 0):
                raise InputError("EliminationPlan: a column in two blocks")
            col_block[own] = b
        rows_of_block, entries = [], []  # per block: local row ids (eq rows), {(a, col): src}
        for b in range(B):
            j = plan.block_groups[b]
            rows, ent = [], {}
            if j >= 0:
                for i in range(r):
                    rows.append(self.tgt[j, i])
                    for q, c in enumerate(self.outer[j]):
                        if c >= 0:
                            ent[(len(rows) - 1, int(c))] = (
                                "n",
                                (j * r + i) * self.outer.shape[1] + q,
                            )
            for row in plan.block_rows[b][plan.block_rows[b] >= 0]:
                rows.append(int(row))
                for e in range(ae.indptr[row], ae.indptr[row + 1]):
                    ent[(len(rows) - 1, int(ae.indices[e]))] = ("a", e)
            rows_of_block.append(np.array(rows, np.int64))
            entries.append(ent)
        dep, free, couple = [], [], []
        for b in range(B):
            own = plan.block_cols[b][plan.block_cols[b] >= 0]
            touched = {c for _, c in entries[b]}
            others = sorted({int(col_block[c]) for c in touched} - {b})
            if any(c not in set(own) and col_block[c] < 0 for c in touched) or any(
                i > b for i in others
            ):
                raise InputError(
                    f"EliminationPlan: block {b}'s local rows touch a column outside it and "
                    "the blocks before it"
                )
            nr = len(rows_of_block[b])
            dense = np.zeros((nr, len(own)))
            pos = {int(c): q for q, c in enumerate(own)}
            for (a, c), (kind, s) in entries[b].items():
                if c in pos:
                    dense[a, pos[c]] = ae.data[s] if kind == "a" else self.new_rows.reshape(-1)[s]
            piv = _pivots(dense)
            dep.append(own[np.sort(piv[:nr])])
            free.append(own[np.sort(piv[nr:])])
            couple.append(others)
        reach = []
        cptr, cblk, ccol, fmap, rmap = [0], [], [], [], []
        fmap_off, rmap_off = [], []
        shape = np.zeros((B, 4), np.int64)
        l_dst_a, l_src_a, l_dst_n, l_src_n = [], [], [], []
        loff = [0]
        for b in range(B):
            R = list(free[b])
            for i in couple[b]:
                R += [c for c in reach[i] if c not in set(R)]
            reach.append(np.array(R, np.int64))
            rpos = {int(c): q for q, c in enumerate(R)}
            lc = list(dep[b]) + list(free[b])
            for i in couple[b]:
                cblk.append(i)
                ccol.append(len(lc))
                lc += list(dep[i]) + list(free[i])
                fmap_off.append(len(fmap))
                fmap += [rpos[int(c)] for c in free[i]]
                rmap_off.append(len(rmap))
                rmap += [rpos[int(c)] for c in reach[i]]
            cptr.append(len(cblk))
            nr, w = len(rows_of_block[b]), len(lc)
            shape[b] = (nr, w, len(R), len(free[b]))
            lpos = {int(c): q for q, c in enumerate(lc)}
            for (a, c), (kind, s) in entries[b].items():
                dst = loff[-1] + a * w + lpos[c]
                (l_dst_a if kind == "a" else l_dst_n).append(dst)
                (l_src_a if kind == "a" else l_src_n).append(s)
            loff.append(loff[-1] + nr * w)
        i64 = lambda x: np.asarray(x, np.int64)  # noqa: E731
        self.shape, self.loff = shape, i64(loff)
        self.l_dst_a, self.l_src_a = i64(l_dst_a), i64(l_src_a)
        self.l_dst_n, self.l_src_n = i64(l_dst_n), i64(l_src_n)
        self.cptr, self.cblk, self.ccol = i64(cptr), i64(cblk), i64(ccol)
        self.fmap_off, self.fmap = i64(fmap_off), i64(fmap)
        self.rmap_off, self.rmap = i64(rmap_off), i64(rmap)
        self.eoff = i64(np.concatenate([[0], np.cumsum(shape[:, 0] * shape[:, 2])]))
        self.lu_off = i64(np.concatenate([[0], np.cumsum(shape[:, 0] ** 2)]))
        self.uoff = i64(np.concatenate([[0], np.cumsum(shape[:, 0])]))
        self.lbuf = np.zeros(self.loff[-1])
        self.ebuf = np.zeros(self.eoff[-1])
        self.lu = np.zeros(self.lu_off[-1])
        self.piv = np.zeros(self.uoff[-1], np.int64)
        self.dep = np.concatenate(dep) if B else np.zeros(0, np.int64)
        self.y_rows = np.concatenate(rows_of_block) if B else np.zeros(0, np.int64)
        self.reach = reach
        if len(np.unique(self.y_rows)) != len(self.y_rows):
            raise InputError("EliminationPlan: a local row in two blocks")

    def _transform(self) -> None:
        """The pattern of ``T`` (``n × n_r``: identity on the kept columns, ``-E`` on the
        dependent rows) and of ``Tᵀ``, and where ``E``'s entries land."""
        n = self.n
        is_dep = np.zeros(n, bool)
        is_dep[self.dep] = True
        self.red_cols = np.flatnonzero(~is_dep)
        self.nr = len(self.red_cols)
        red_of = -np.ones(n, np.int64)
        red_of[self.red_cols] = np.arange(self.nr)
        rows = [self.red_cols]
        cols = [np.arange(self.nr)]
        e_id = [-np.ones(self.nr, np.int64)]
        u = 0
        for b in range(len(self.shape)):
            r, nrb = self.shape[b, 0], self.shape[b, 2]
            deps = self.dep[u : u + r]
            rows.append(np.repeat(deps, nrb))
            cols.append(np.tile(red_of[self.reach[b]], r))
            e_id.append(self.eoff[b] + np.arange(r * nrb))
            u += r
        rows, cols, e_id = (np.concatenate(x) for x in (rows, cols, e_id))
        order = np.lexsort((cols, rows))
        rows, cols, e_id = rows[order], cols[order], e_id[order]
        self.T = sp.csr_matrix(
            (np.ones(len(rows)), cols, np.searchsorted(rows, np.arange(n + 1))), shape=(n, self.nr)
        )
        self.t_e = np.flatnonzero(e_id >= 0)
        self.t_e_src = e_id[self.t_e]
        self.Tt, self.tt_src = _transpose(self.T)
        self.t_rows = np.repeat(np.arange(n), np.diff(self.T.indptr))
        self.red_of = red_of
        self.reach_red = np.concatenate([red_of[c] for c in self.reach] + [cols[:0]])
        self.reach_ptr = np.concatenate([[0], np.cumsum([len(c) for c in self.reach])]).astype(int)

    def _products(self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix) -> None:
        """Patterns of ``H_sym`` (with room for ``A_Iᵀ Σ A_I``: ``H_f``, the inequality rows
        folded in), ``H_f T``, ``A_E,kept T`` and ``H_r = tril(Tᵀ H_f T)``; the slots of the
        fold's terms."""
        n, me = self.n, self.me
        h_rows = np.repeat(np.arange(n), np.diff(hess.indptr))
        low = np.flatnonzero(h_rows >= hess.indices)
        r, c = h_rows[low], hess.indices[low]
        off = r != c
        fold = _product_pattern((_transpose(ai)[0], ai)).tocoo()
        rr = np.concatenate([r, c[off], np.arange(n), fold.row])
        cc = np.concatenate([c, r[off], np.arange(n), fold.col])
        src = np.concatenate([low, low[off], -np.ones(n + fold.nnz, np.int64)])
        keys, inv = np.unique(rr * n + cc, return_inverse=True)
        self.hs = sp.csr_matrix(
            (np.zeros(len(keys)), keys % n, np.searchsorted(keys // n, np.arange(n + 1))),
            shape=(n, n),
        )
        self.hs_slot, self.hs_src = inv[src >= 0], src[src >= 0]
        self.hf = sp.csr_matrix((np.zeros(len(keys)), self.hs.indices, self.hs.indptr), (n, n))
        # per pair of entries (e, f) of an inequality row: its slot in H_f
        lens = np.diff(ai.indptr).astype(np.int64)
        sq = lens * lens
        self.fold_row = np.repeat(np.arange(self.mi), sq)
        t = np.arange(len(self.fold_row)) - np.repeat(np.cumsum(sq) - sq, sq)
        width, start = np.repeat(lens, sq), np.repeat(ai.indptr[:-1].astype(np.int64), sq)
        self.fold_e, self.fold_f = start + t // width, start + t % width
        cols = (ai.indices[self.fold_e][:, None], ai.indices[self.fold_f][:, None])
        self.fold_slot = Slots(self.hs)(*cols).reshape(-1)
        self.W = _product_pattern((self.hs, self.T))
        self._segments()
        is_y = np.zeros(me, bool)
        is_y[self.y_rows] = True
        self.kept = np.flatnonzero(~is_y)
        self.ae_p, self.ae_i, self.ae_data = ae.indptr, ae.indices, np.zeros(ae.nnz)
        self.ai_p, self.ai_i, self.ai_data = ai.indptr, ai.indices, np.zeros(ai.nnz)
        sub = ae[self.kept]
        sub.sort_indices()
        ae_pos = sp.csr_matrix(
            (np.arange(ae.nnz, dtype=float) + 1, ae.indices, ae.indptr), shape=ae.shape
        )[self.kept]
        ae_pos.sort_indices()
        self.ak = sp.csr_matrix((np.zeros(sub.nnz), ae_pos.indices, ae_pos.indptr), shape=sub.shape)
        self.ak_src = ae_pos.data.astype(np.int64) - 1
        self.Ar = _product_pattern((self.ak, self.T))
        self.Hr = sp.csr_matrix(sp.tril(_product_pattern((self.Tt, self.W)), format="csr"))
        self.Hr.sort_indices()
        ends = lambda a, b: lower_ends(a.indptr, a.indices, b.indptr, b.indices)  # noqa: E731
        self.tw_end, self.tt_end = ends(self.Tt, self.W), ends(self.Tt, self.T)
        self.sigma = np.zeros(self.mi)
        self.sigma_used = np.zeros(self.mi)  # the Σ of hr_base
        self.hr_ok = False  # hr_base holds Tᵀ H_f T for these values and sigma_used
        self.all_kept, self.all_ineq = np.arange(len(self.kept)), np.arange(self.mi)
        self.work = np.zeros(max(self.nr, 1))
        self.hr_base = np.zeros(self.Hr.nnz)
        self.dt_data = np.zeros(self.T.nnz)
        self.ttt = np.zeros(self.Hr.nnz)  # TᵀT in Hr's pattern
        self.ttt_ok = False

    def _segments(self) -> None:
        """``H_f``'s entries row by row in segments of one block's dependent columns (``-1``:
        the kept columns), for :func:`~mbplan.solvers.reduced_kernels.times_t`: per segment its
        block and entries, per entry its ``H_f`` slot and the dependent column's row in the
        block's ``E`` (the kept column's reduced index)."""
        n, hf = self.n, self.hs
        block_of, local = -np.ones(n, np.int64), np.zeros(n, np.int64)
        for b in range(len(self.shape)):
            dep = self.dep[self.uoff[b] : self.uoff[b + 1]]
            block_of[dep], local[dep] = b, np.arange(len(dep))
        rows = np.repeat(np.arange(n), np.diff(hf.indptr))
        blk = block_of[hf.indices]
        self.seg_e = np.lexsort((blk, rows))
        r_s, b_s, c_s = rows[self.seg_e], blk[self.seg_e], hf.indices[self.seg_e]
        new = np.ones(len(r_s), bool)
        new[1:] = (r_s[1:] != r_s[:-1]) | (b_s[1:] != b_s[:-1])
        starts = np.flatnonzero(new)
        self.seg_block = b_s[starts]
        self.seg_ptr = np.append(starts, len(r_s))
        self.row_seg = np.searchsorted(r_s[starts], np.arange(n + 1))
        self.seg_arg = np.where(b_s >= 0, local[c_s], self.red_of[c_s])
