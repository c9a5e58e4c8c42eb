"""The products' layouts of :class:`~mbplan.solvers.kkt.reduced.reduction.Reduction` (symbolic, once per
plan and pattern): the reduced columns, the pattern of ``H_f`` (``H`` with room for the folded
inequality rows), ``W = H_f T`` row by row with each block's dependent rows as one dense panel
over the union of their columns, ``H_r = tril(Tᵀ H_f T)`` and where every product term lands
in it, ``A_E,kept T``, and the segments of :func:`~mbplan.solvers.kkt.reduced.products.times_t`."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mbplan.solvers.kkt.reduced.symbolic import Slots

_I64 = np.int64


def _product_pattern(*pairs: tuple[sp.csr_matrix, sp.csr_matrix]) -> sp.csr_matrix:
    """The structural pattern of ``Σ a @ b`` over the pairs (values of ones: no cancellation),
    zero values."""

    def one(m: sp.csr_matrix) -> sp.csr_matrix:
        return sp.csr_matrix((np.ones(m.nnz), m.indices, m.indptr), shape=m.shape)

    p = sp.csr_matrix(sum(one(a) @ one(b) for a, b in pairs))
    p.sort_indices()
    p.data[:] = 0.0
    return p


def _transpose(m: sp.csr_matrix) -> sp.csr_matrix:
    """``mᵀ``'s pattern (ones, sorted)."""
    t = sp.csr_matrix((np.ones(m.nnz), m.indices, m.indptr), shape=m.shape).T.tocsr()
    t.sort_indices()
    return t


def _csr_rows(m: sp.csr_matrix, rows: np.ndarray) -> list[np.ndarray]:
    return [m.indices[m.indptr[k] : m.indptr[k + 1]] for k in rows]


class ReductionLayout:
    """The product layouts of :class:`~mbplan.solvers.kkt.reduced.reduction.Reduction` (they set its index
    arrays; the symbolic phase of :mod:`mbplan.solvers.kkt.reduced.symbolic` runs first)."""

    n: int
    me: int
    mi: int

    def _transform(self) -> None:
        """The reduced columns, each block's reach in reduced indices, and ``T``'s pattern
        (``n × n_r``: identity on the kept columns, ``E_b`` dense on block ``b``'s dependent
        rows over its reach), for the symbolic products."""
        n, B = self.n, len(self.shape)
        is_dep = np.zeros(n, bool)
        is_dep[self.dep] = True
        self.red_cols = np.flatnonzero(~is_dep)
        self.nr = len(self.red_cols)
        red_of = -np.ones(n, _I64)
        red_of[self.red_cols] = np.arange(self.nr)
        self.red_of = red_of
        reach_red = [red_of[c] for c in self.reach]
        self.reach_red = np.concatenate([*reach_red, np.zeros(0, _I64)])
        self.reach_ptr = np.concatenate([[0], np.cumsum([len(c) for c in reach_red])]).astype(_I64)
        m = self.shape[:, 1]
        rows = np.concatenate([self.red_cols, *(np.repeat(self.dep[self.uoff[b] : self.uoff[b + 1]], m[b]) for b in range(B))])  # fmt: skip
        cols = np.concatenate([np.arange(self.nr), *(np.tile(reach_red[b], self.shape[b, 0]) for b in range(B))])  # fmt: skip
        self.T = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, self.nr))
        self.T.sort_indices()

    def _products(self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix) -> None:
        """Patterns and slots of ``H_f``, ``W``, ``H_r``, ``A_E,kept T`` (module docstring)."""
        self._fold_pattern(hess, ai)
        self._w_layout()
        self._hr_layout()
        is_y = np.zeros(self.me, bool)
        is_y[self.y_rows] = True
        self.kept = np.flatnonzero(~is_y)
        self.ae_p, self.ae_i, self.ae_data = ae.indptr, ae.indices, np.zeros(ae.nnz)
        self.ai_p, self.ai_i, self.ai_data = ai.indptr, ai.indices, np.zeros(ai.nnz)
        ae_pos = sp.csr_matrix(
            (np.arange(ae.nnz, dtype=float) + 1, ae.indices, ae.indptr), shape=ae.shape
        )[self.kept]
        ae_pos.sort_indices()
        self.ak = sp.csr_matrix(
            (np.zeros(ae_pos.nnz), ae_pos.indices, ae_pos.indptr), shape=ae_pos.shape
        )
        self.ak_src = ae_pos.data.astype(_I64) - 1
        self.Ar = _product_pattern((self.ak, self.T))
        rows = np.arange(len(self.kept))
        self.ak_seg = self._segments(
            self.ak, self.Ar.indptr[:-1], np.repeat(rows, np.diff(self.Ar.indptr)),
            self.Ar.indices, rows, rows, np.full(len(rows), self.nr),
        )[0]  # fmt: skip
        m = self.shape[:, 1] if len(self.shape) else np.zeros(1, _I64)
        r = self.shape[:, 0] if len(self.shape) else np.zeros(1, _I64)
        width = max(
            int(m.max(initial=0)), int(r.max(initial=0)), int(self.pwidth.max(initial=0)), 1
        )
        self.acc, self.tmp = np.zeros(4 * width), np.zeros(width)
        self.sigma, self.sigma_used = np.zeros(self.mi), np.zeros(self.mi)
        self.hr_ok = False  # hr_base holds Tᵀ H_f T for these values and sigma_used
        self.ttt_ok = False  # ttt holds Tᵀ T for these values
        self.hr_base, self.ttt = np.zeros(self.Hr.nnz), np.zeros(self.Hr.nnz)
        ndep = len(self.dep)
        self.xu, self.rz, self.yv = np.zeros(ndep), np.zeros(self.mi), np.zeros(ndep)
        self.vx, self.kv, self.se = np.zeros(self.n), np.zeros(self.n), np.zeros(self.me)
        self.hw = np.zeros(self.n)
        self.rhs_r = np.zeros(self.nr + len(self.kept))

    def _fold_pattern(self, hess: sp.csr_matrix, ai: sp.csr_matrix) -> None:
        """``H_f``'s pattern (``H`` symmetric, the diagonal, ``A_Iᵀ A_I``: ``hs``); ``H`` as its
        strictly lower CSR ``hl`` (values from ``hess.data[hl_src]``; their slots in ``H_f``
        ``hl_lo`` and mirrored ``hl_up``) and its diagonal ``hd`` (``hd_src``, ``-1``: zero;
        slots ``hd_slot``); per pair of entries ``(e, f)`` of an inequality row (row by row,
        ``e`` then ``f`` in row order), its slot in ``H_f``."""
        n = self.n
        h_rows = np.repeat(np.arange(n), np.diff(hess.indptr))
        low = np.flatnonzero(h_rows >= hess.indices)
        r, c = h_rows[low], hess.indices[low]
        off = r != c
        fold = _product_pattern((_transpose(ai), ai)).tocoo()
        rr = np.concatenate([r, c[off], np.arange(n), fold.row])
        cc = np.concatenate([c, r[off], np.arange(n), fold.col])
        keys = np.unique(rr * n + cc)
        self.hs = sp.csr_matrix(
            (np.zeros(len(keys)), keys % n, np.searchsorted(keys // n, np.arange(n + 1))),
            shape=(n, n),
        )
        self.hf_data = np.zeros(len(keys))
        strict = np.flatnonzero(off)  # H's strictly lower entries as CSR, its diagonal apart
        self.hl = sp.csr_matrix(
            (np.zeros(len(strict)), c[strict], np.searchsorted(r[strict], np.arange(n + 1))),
            shape=(n, n),
        )
        self.hl_src, self.hd_src = low[strict], -np.ones(n, _I64)
        self.hd_src[r[~off]] = low[~off]
        slots = Slots(self.hs)
        self.hl_lo, self.hl_up = (
            slots.pairs(r[strict], c[strict]),
            slots.pairs(c[strict], r[strict]),
        )
        self.hd_slot = slots.pairs(np.arange(n), np.arange(n))
        self.hd = np.zeros(n)
        lens = np.diff(ai.indptr).astype(_I64)
        sq = lens * lens
        t = np.arange(sq.sum()) - np.repeat(np.cumsum(sq) - sq, sq)
        width, start = np.repeat(lens, sq), np.repeat(ai.indptr[:-1].astype(_I64), sq)
        fold_e, fold_f = start + t // width, start + t % width
        self.fold_slot = slots.pairs(ai.indices[fold_e], ai.indices[fold_f])

    def _w_layout(self) -> None:
        """``W = H_f T`` block by block: block ``b``'s dependent rows as a dense panel
        (``r_b × pwidth[b]``, at ``panel_off[b]`` of a virtual buffer, computed in ``pbuf``) over
        ``U_b``, the sorted union of their columns, then the kept rows (their own columns, in
        ``kbuf``, at ``panel_off[B]``); per row of ``H_f`` where it goes (``ostart``; the row and
        column of each position: ``orow``, ``ocol``); block ``b``'s segments from
        ``bseg_ptr[b]``, the kept rows' from ``bseg_ptr[B]``."""
        P = _product_pattern((self.hs, self.T))
        B, uoff = len(self.shape), self.uoff
        U = [np.unique(np.concatenate([np.zeros(0, _I64), *_csr_rows(P, self.dep[uoff[b] : uoff[b + 1]])])) for b in range(B)]  # fmt: skip
        self.union = U
        self.pwidth = np.array([len(u) for u in U], _I64)
        sizes = self.shape[:, 0] * self.pwidth if B else np.zeros(0, _I64)
        self.panel_off = np.concatenate([[0], np.cumsum(sizes)]).astype(_I64)
        ostart = np.zeros(self.n, _I64)
        for b in range(B):
            dep = self.dep[uoff[b] : uoff[b + 1]]
            ostart[dep] = self.panel_off[b] + np.arange(len(dep)) * self.pwidth[b]
        kept_rows = _csr_rows(P, self.red_cols)
        klen = np.array([len(c) for c in kept_rows], _I64)
        ostart[self.red_cols] = self.panel_off[-1] + np.concatenate([[0], np.cumsum(klen)[:-1]])
        self.ostart = ostart
        ocol = np.concatenate(
            [*(np.tile(U[b], self.shape[b, 0]) for b in range(B)), *kept_rows, np.zeros(0, _I64)]
        ).astype(_I64)
        self._kept_rows = kept_rows
        orow = np.concatenate(
            [*(np.repeat(self.dep[uoff[b] : uoff[b + 1]], self.pwidth[b]) for b in range(B)),
             np.repeat(self.red_cols, klen), np.zeros(0, _I64)]
        )  # fmt: skip
        row_key = np.arange(self.n)  # rows with the same output columns share their maps
        for b in range(B):
            row_key[self.dep[uoff[b] : uoff[b + 1]]] = self.n + b
        rank = np.empty(self.n, _I64)  # the blocks' dependent rows first, block by block
        rank[np.concatenate([self.dep, self.red_cols])] = np.arange(self.n)
        bound = self.red_of.copy()  # W's entries needed: the lower triangle of Tᵀ W
        for b in range(B):
            reach = self.reach_red[self.reach_ptr[b] : self.reach_ptr[b + 1]]
            bound[self.dep[uoff[b] : uoff[b + 1]]] = reach.max(initial=-1)
        self.hs_seg, seg_row = self._segments(self.hs, ostart, orow, ocol, row_key, rank, bound)
        row_block = np.full(self.n, B, _I64)
        row_block[self.dep] = np.repeat(np.arange(B), np.diff(uoff))
        self.bseg_ptr = np.searchsorted(row_block[seg_row], np.arange(B + 2)).astype(_I64)
        self.pbuf = np.zeros(max(int(sizes.max(initial=0)), 1))
        self.kbuf = np.zeros(max(int(klen.sum()), 1))

    def _hr_layout(self) -> None:
        """``H_r``'s lower pattern and the slots of ``tril(Tᵀ W)``'s terms (the kept rows'
        entries ``kw_pos`` → ``kw_slot``; block ``b``'s row ``q`` over the prefix of ``U_b`` up
        to ``R_b[q]``: ``lo_ptr``, ``lo_slot``) and of ``tril(Tᵀ D T)``'s (``diag_slot``, per
        block the lower triangle of ``R_b × R_b`` row by row: ``tt_off``, ``tt_slot``)."""
        B, nr = len(self.shape), self.nr
        klen = np.array([len(c) for c in self._kept_rows], _I64)
        kr = np.repeat(np.arange(nr), klen)  # kept row i of W: reduced row i of H_r
        kc = np.concatenate([*self._kept_rows, np.zeros(0, _I64)]).astype(_I64)
        low = kc <= kr
        kw_pos = (self.ostart[self.red_cols] - self.panel_off[-1])[kr] + (np.arange(len(kc)) - np.repeat(np.cumsum(klen) - klen, klen))  # fmt: skip
        rows, cols = [kr[low]], [kc[low]]
        lo_len, tt_rows, tt_cols = [], [], []
        for b in range(B):
            R = self.reach_red[self.reach_ptr[b] : self.reach_ptr[b + 1]]
            q, u = np.nonzero(self.union[b][None, :] <= R[:, None])  # prefixes (sorted union)
            lo_len.append(np.bincount(q, minlength=len(R)))
            rows.append(R[q])
            cols.append(self.union[b][u])
            q2, q1 = np.tril_indices(len(R))
            tt_rows.append(R[q2])
            tt_cols.append(R[q1])
        rows.append(np.arange(nr))
        cols.append(np.arange(nr))
        rr, cc = np.concatenate(rows), np.concatenate(cols)
        keys = np.unique(rr * nr + cc)
        self.Hr = sp.csr_matrix(
            (np.zeros(len(keys)), keys % nr, np.searchsorted(keys // nr, np.arange(nr + 1))),
            shape=(nr, nr),
        )
        slots = Slots(self.Hr)
        n_kept = len(rows[0])
        self.kw_pos = kw_pos[low].astype(_I64)
        self.kw_slot = slots.pairs(rr[:n_kept], cc[:n_kept])
        self.lo_slot = slots.pairs(rr[n_kept : len(rr) - nr], cc[n_kept : len(cc) - nr])
        self.lo_ptr = np.concatenate([[0], np.cumsum(np.concatenate([*lo_len, np.zeros(0, _I64)]))]).astype(_I64)  # fmt: skip
        self.diag_slot = slots.pairs(np.arange(nr), np.arange(nr))
        m = self.shape[:, 1] if B else np.zeros(0, _I64)
        self.tt_off = np.concatenate([[0], np.cumsum(m * (m + 1) // 2)]).astype(_I64)
        self.tt_slot = slots.pairs(
            np.concatenate([*tt_rows, np.zeros(0, _I64)]),
            np.concatenate([*tt_cols, np.zeros(0, _I64)]),
        )
        if min(self.kw_slot.min(initial=0), self.lo_slot.min(initial=0), self.tt_slot.min(initial=0)) < 0:  # fmt: skip
            raise ValueError("reduction layout: a product term outside H_r's pattern")

    def _segments(
        self, x: sp.csr_matrix, ostart: np.ndarray, orow: np.ndarray, ocol: np.ndarray,
        row_key: np.ndarray, rank: np.ndarray, bound: np.ndarray,
    ) -> tuple[tuple[np.ndarray, ...], np.ndarray]:  # fmt: skip
        """For :func:`~mbplan.solvers.kkt.reduced.products.times_t` (``X T`` for ``x``'s pattern,
        row ``i``'s result at ``out[ostart[i] + k]`` over its sorted columns, position by position
        ``orow``, ``ocol``): ``x``'s entries row by row in segments of one block's dependent
        columns (``seg_block``; ``-1``: the kept columns), per segment its entries ``seg_e``
        (positions in ``x.data``) and its row's ``seg_out = ostart[i]``; per entry ``seg_arg``:
        the dependent column's row in the block's ``E`` (a kept column: its position in the
        row's result); per block segment ``seg_map``: where the block's reach lies in the row's
        result (``pos[seg_map[s] + q]``, shared by rows of equal ``row_key``) and ``seg_len``:
        how many of the block's reach columns (sorted) are at most the row's ``bound`` (the
        others are not needed). Rows in the order of ``rank``; also each segment's row."""
        block_of, local = -np.ones(self.n, _I64), np.zeros(self.n, _I64)
        for b in range(len(self.shape)):
            dep = self.dep[self.uoff[b] : self.uoff[b + 1]]
            block_of[dep], local[dep] = b, np.arange(len(dep))
        nr = max(self.nr, 1)
        okey = np.asarray(orow, _I64) * nr + np.asarray(ocol, _I64)
        order = np.argsort(okey, kind="stable")
        sorted_keys = okey[order]

        def where(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:  # positions in out
            want = rows * nr + cols
            at = order[np.minimum(np.searchsorted(sorted_keys, want), len(order) - 1)]
            if np.any(okey[at] != want):
                raise ValueError("reduction layout: a product term outside its row's pattern")
            return at

        rows = np.repeat(np.arange(x.shape[0]), np.diff(x.indptr))
        blk = block_of[x.indices]
        seg_e = np.lexsort((blk, np.asarray(rank)[rows]))
        r_s, b_s, c_s = rows[seg_e], blk[seg_e], x.indices[seg_e]
        new = np.ones(len(r_s), bool)
        new[1:] = (r_s[1:] != r_s[:-1]) | (b_s[1:] != b_s[:-1])
        starts = np.flatnonzero(new)
        seg_row, seg_block = r_s[starts], b_s[starts]
        seg_out = np.asarray(ostart, _I64)[seg_row]
        kept = b_s < 0
        seg_arg = local[c_s]
        seg_arg[kept] = where(r_s[kept], self.red_of[c_s[kept]]) - np.asarray(ostart)[r_s[kept]]
        seg_map = np.zeros(len(starts), _I64)
        blocks = np.flatnonzero(seg_block >= 0)
        key = np.asarray(row_key, _I64)[seg_row[blocks]] * (len(self.shape) + 1) + seg_block[blocks]
        _, first, inv = np.unique(key, return_index=True, return_inverse=True)
        i, b = seg_row[blocks[first]], seg_block[blocks[first]]  # one row per map
        length = self.reach_ptr[b + 1] - self.reach_ptr[b]
        at = np.repeat(self.reach_ptr[b] - np.cumsum(length) + length, length) + np.arange(length.sum())  # fmt: skip
        pos = (where(np.repeat(i, length), self.reach_red[at]) - np.repeat(np.asarray(ostart)[i], length)).astype(_I64)  # fmt: skip
        seg_map[blocks] = (np.cumsum(length) - length)[inv]
        seg_len = np.zeros(len(starts), _I64)
        b, bnd = seg_block[blocks], np.asarray(bound, _I64)[seg_row[blocks]]
        block_of_reach = np.repeat(np.arange(len(self.shape)), np.diff(self.reach_ptr))
        reach_key = block_of_reach * (nr + 1) + self.reach_red  # sorted: blocks, then reach
        seg_len[blocks] = (
            np.searchsorted(reach_key, b * (nr + 1) + bnd, "right") - self.reach_ptr[b]
        )
        return (np.append(starts, len(r_s)).astype(_I64), seg_block.astype(_I64),
                seg_e.astype(_I64), seg_arg.astype(_I64), seg_out, seg_map, pos, seg_len), seg_row  # fmt: skip
