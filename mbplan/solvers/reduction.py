"""The two congruences of an :class:`~mbplan.solvers.elimination.EliminationPlan` for
:class:`~mbplan.solvers.reduced_step.ReducedKKTSystem`: the symbolic phase (replaced rows and
dependent columns by QR with column pivoting on the first matrix's values, couplings, reach
sets, every fixed pattern; memoized per process), the numeric phase (compiled kernels of
:mod:`mbplan.solvers.reduced_kernels`), the factorization of the reduced matrix ``K_r`` and
one solve through the reduction."""

from __future__ import annotations

import copy
import dataclasses
import threading
from collections import OrderedDict

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from mbplan.engine.jit import announce_uncached_numba
from mbplan.errors import InputError
from mbplan.solvers.elimination import EliminationPlan
from mbplan.solvers.linear_solver import Inertia, KKTSystem
from mbplan.solvers.reduced_kernels import (
    REDUCED_KERNELS,
    b_solve,
    block_values,
    bt_solve,
    csr_matvec,
    fold_values,
    group_values,
    kkt_matvec,
    lower_ends,
    rows_matvec,
    rows_t_matvec,
    s_apply,
    spgemm,
    spgemm_lower,
)

REDUCED_STATIC_REG = 1e-8
"""Static regularization of ``K_r`` (at least): its zero-diagonal multiplier-like columns break
the unpivoted LDLᵀ down with ``1e-9`` (docs/ripm-speed.md, session 5)."""


_REDUCTIONS: OrderedDict[tuple, Reduction] = OrderedDict()
_REDUCTIONS_KEPT = 8
_REDUCTIONS_LOCK = threading.Lock()


def reduction(
    plan: EliminationPlan,
    hess: sp.csr_matrix,
    ae: sp.csr_matrix,
    ai: sp.csr_matrix,
    ordering: str,
    pivot_threshold: float = 0.0,
) -> Reduction:
    """A :class:`Reduction` of its own for ``plan`` and the blocks' patterns; the symbolic
    phase is memoized per process for the last few (the solves of one task family share it,
    with the replaced rows and dependent columns picked on the first one's values)."""
    key = (
        ordering,
        pivot_threshold,
        *(getattr(plan, f.name).tobytes() for f in dataclasses.fields(plan)),
        *(a.tobytes() for m in (hess, ae, ai) for a in (m.indptr, m.indices)),
    )
    with _REDUCTIONS_LOCK:
        hit = _REDUCTIONS.get(key)
        if hit is not None:
            _REDUCTIONS.move_to_end(key)
            return hit.fresh()
    announce_uncached_numba(*REDUCED_KERNELS)  # first run only
    hit = Reduction(plan, hess, ae, ai, ordering, pivot_threshold)
    with _REDUCTIONS_LOCK:
        _REDUCTIONS[key] = hit
        while len(_REDUCTIONS) > _REDUCTIONS_KEPT:
            _REDUCTIONS.popitem(last=False)
    return hit.fresh()


class _Slots:
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


class Reduction:
    """Symbolic phase of one plan and one pattern of ``(H, A_E, A_I)``, and the work arrays of
    the numeric phase."""

    def __init__(
        self,
        plan: EliminationPlan,
        hess: sp.csr_matrix,
        ae: sp.csr_matrix,
        ai: sp.csr_matrix,
        ordering: str,
        pivot_threshold: float = 0.0,
    ) -> None:
        n, me = ae.shape[1], ae.shape[0]
        self.n, self.me, self.mi = n, me, ai.shape[0]
        slots = _Slots(ae)
        self._groups(plan, ae, slots)
        self._blocks(plan, ae, slots)
        self._transform()
        self._products(hess, ae, ai)
        self.factor_options = {"ordering": ordering, "pivot_threshold": pivot_threshold}
        self.kkt = KKTSystem(self.nr, len(self.kept), 0, **self.factor_options)
        self.ok = False

    _WORK = ("M", "new_rows", "lbuf", "ebuf", "lu", "piv", "work", "hr_base", "dt_data", "ttt",
             "sigma", "sigma_used", "ae_data", "ai_data")  # fmt: skip
    _MATRICES = ("T", "Tt", "hs", "hf", "W", "Hr", "ak", "Ar")

    def fresh(self) -> Reduction:
        """A copy sharing the symbolic arrays, with its own work arrays and ``K_r`` system."""
        new = copy.copy(self)
        for name in self._WORK:
            setattr(new, name, getattr(self, name).copy())
        for name in self._MATRICES:
            m = getattr(self, name)
            setattr(new, name, sp.csr_matrix((m.data.copy(), m.indices, m.indptr), shape=m.shape))
        new.kkt = KKTSystem(self.nr, len(self.kept), 0, **self.factor_options)
        new.ok = new.hr_ok = False
        return new

    # ------------------------------------------------------------------ symbolic
    def _groups(self, plan: EliminationPlan, ae: sp.csr_matrix, slots: _Slots) -> None:
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

    def _blocks(self, plan: EliminationPlan, ae: sp.csr_matrix, slots: _Slots) -> None:
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
        self.fold_slot = _Slots(self.hs)(*cols).reshape(-1)
        self.W = _product_pattern((self.hs, self.T))
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

    # ------------------------------------------------------------------ numeric
    def set_values(self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix) -> bool:
        """``M_j``, ``E``, ``T``, ``A_E,kept T`` for new values (``H``, ``A_E`` and ``A_I`` with
        this reduction's patterns; ``Tᵀ H_f T`` follows in :meth:`factorize`, with ``Σ``);
        False on a breakdown."""
        self.ok = False
        self.ae_data[:] = ae.data
        self.ai_data[:] = ai.data
        if len(self.M) and not group_values(
            ae.data, self.g_sel, self.h_sel, self.pad, self.g_outer, self.h_outer, self.M,
            self.new_rows,
        ):  # fmt: skip
            return False
        if not block_values(
            ae.data, self.new_rows, self.l_dst_a, self.l_src_a, self.l_dst_n, self.l_src_n,
            self.lbuf, self.shape, self.loff, self.eoff, self.cptr, self.cblk, self.ccol,
            self.fmap_off, self.fmap, self.rmap_off, self.rmap, self.lu, self.lu_off, self.piv,
            self.uoff, self.ebuf,
        ):  # fmt: skip
            return False
        T, Tt = self.T, self.Tt
        T.data[self.t_e] = -self.ebuf[self.t_e_src]
        Tt.data[:] = T.data[self.tt_src]
        self.hs.data[:] = 0.0
        self.hs.data[self.hs_slot] = hess.data[self.hs_src]
        self.hr_ok = False
        self.ttt_ok = False
        self.ak.data[:] = ae.data[self.ak_src]
        self._product(self.ak, T, self.Ar)
        self.ok = bool(np.isfinite(T.data).all())
        return self.ok

    def _product(self, a: sp.csr_matrix, b: sp.csr_matrix, c: sp.csr_matrix) -> None:
        """``c = a @ b`` in ``c``'s pattern."""
        c.data[:] = 0.0
        spgemm(a.indptr, a.indices, a.data, b.indptr, b.indices, b.data, c.indptr, c.indices,
               c.data, self.work)  # fmt: skip

    def _add_lower(
        self, a: sp.csr_matrix, b: sp.csr_matrix, b_data: np.ndarray, ends: np.ndarray
    ) -> None:
        """``H_r += tril(a @ b)`` with ``b``'s values ``b_data`` (``ends``: :func:`lower_ends`)."""
        hr = self.Hr
        spgemm_lower(a.indptr, a.indices, a.data, b.indptr, b.indices, b_data, ends, hr.indptr,
                     hr.indices, hr.data, self.work)  # fmt: skip

    def factorize(self, diagonal: np.ndarray, static_reg: float) -> Inertia | None:
        """Factorize ``K_r`` for ``K``'s diagonal (``Tᵀ D_x T`` added to ``Tᵀ H T``; the
        inequality rows folded in, ``Σ = -D_I⁻¹``); the inertia of ``K`` (``None``: a nonzero
        diagonal on a local row, ``D_I`` not negative, or a breakdown)."""
        n, me = self.n, self.me
        d_i = diagonal[n + me :]
        if not self.ok or np.any(diagonal[n + self.y_rows] != 0.0) or not np.all(d_i < 0.0):
            return None
        np.divide(-1.0, d_i, out=self.sigma)
        if not (self.hr_ok and np.array_equal(self.sigma, self.sigma_used)):  # Tᵀ H_f T
            hf = self.hf
            hf.data[:] = self.hs.data
            fold_values(hf.data, self.fold_slot, self.fold_e, self.fold_f, self.fold_row,
                        self.ai_data, self.sigma)  # fmt: skip
            self._product(hf, self.T, self.W)
            self.Hr.data[:] = 0.0
            self._add_lower(self.Tt, self.W, self.W.data, self.tw_end)
            self.hr_base[:] = self.Hr.data
            self.sigma_used[:] = self.sigma
            self.hr_ok = bool(np.isfinite(self.hr_base).all())
            if not self.hr_ok:
                return None
        dx = diagonal[:n]
        if not dx.any():
            self.Hr.data[:] = self.hr_base
        elif np.all(dx == dx[0]):  # δ_w (+ζ) I: Tᵀ D T = d TᵀT, TᵀT once per matrix
            if not self.ttt_ok:
                self.Hr.data[:] = 0.0
                self._add_lower(self.Tt, self.T, self.T.data, self.tt_end)
                self.ttt[:] = self.Hr.data
                self.ttt_ok = True
            np.multiply(self.ttt, dx[0], out=self.Hr.data)
            self.Hr.data += self.hr_base
        else:
            np.multiply(self.T.data, dx[self.t_rows], out=self.dt_data)
            self.Hr.data[:] = self.hr_base
            self._add_lower(self.Tt, self.T, self.dt_data, self.tt_end)
        self.kkt.set_matrices(self.Hr, self.Ar, None)
        diag_r = np.concatenate([np.zeros(self.nr), diagonal[n + self.kept]])
        inertia = self.kkt.factorize(diag_r, max(static_reg, REDUCED_STATIC_REG))
        if inertia is None:
            return None
        m = len(self.dep)
        return Inertia(inertia.positive + m, inertia.negative + m + self.mi, 0)

    def matvec(self, x: np.ndarray, diagonal: np.ndarray) -> np.ndarray:
        """``K x`` for the values of :meth:`set_values` and ``K``'s ``diagonal``."""
        hs = self.hs
        return kkt_matvec(hs.indptr, hs.indices, hs.data, self.ae_p, self.ae_i, self.ae_data,
                          self.ai_p, self.ai_i, self.ai_data, diagonal, x)  # fmt: skip

    def solve_once(self, b: np.ndarray, diagonal: np.ndarray, ratio_max: float) -> np.ndarray:
        """``K⁻¹ b`` through the reduction (module docstring; ``diagonal``: ``K``'s), ``K_r``
        solved to the residual ratio ``ratio_max``."""
        n, me, nr, dep = self.n, self.me, self.nr, self.dep
        bx, be, bi = b[:n], b[n : n + me], b[n + me :]
        blk = (self.lbuf, self.shape, self.loff, self.cptr, self.cblk, self.ccol, self.lu,
               self.lu_off, self.piv, self.uoff)  # fmt: skip
        xu = b_solve(s_apply(be, self.tgt, self.src, self.sub, self.M, False)[self.y_rows], *blk)
        hs, ak, T, Tt = self.hs, self.ak, self.T, self.Tt
        ai = (self.ai_p, self.ai_i, self.ai_data)
        v = np.zeros(n)
        v[dep] = xu
        kv = rows_t_matvec(hs.indptr, hs.indices, hs.data, dep, xu, n)  # (K [x_U; 0])_x
        kv[dep] += diagonal[dep] * xu
        rz = bi - csr_matvec(*ai, v)
        kv -= rows_t_matvec(*ai, self.all_ineq, self.sigma * rz, n)  # the folded rows
        rx = csr_matvec(Tt.indptr, Tt.indices, Tt.data, bx - kv)
        re = be[self.kept] - csr_matvec(ak.indptr, ak.indices, ak.data, v)
        xr = self.kkt.solve(np.concatenate([rx, re]), 10, ratio_max)[0]
        w = np.zeros(len(b))
        w[:n] = csr_matvec(T.indptr, T.indices, T.data, xr[:nr])
        wz = self.sigma * (csr_matvec(*ai, w[:n]) - rz)
        w[dep] += xu
        w[n + self.kept] = xr[nr:]
        w[n + me :] = wz
        kw = rows_matvec(hs.indptr, hs.indices, hs.data, dep, w[:n]) + diagonal[dep] * w[dep]
        at_w = rows_t_matvec(ak.indptr, ak.indices, ak.data, self.all_kept, xr[nr:], n)
        at_w += rows_t_matvec(*ai, self.all_ineq, wz, n)
        w[n + self.y_rows] = bt_solve(bx[dep] - kw - at_w[dep], *blk)
        w[n : n + me] = s_apply(w[n : n + me], self.tgt, self.src, self.sub, self.M, True)
        return w
