"""The two congruences of an :class:`~mbplan.solvers.elimination.EliminationPlan` for
:class:`~mbplan.solvers.reduced_step.ReducedKKTSystem`: the symbolic phase
(:mod:`mbplan.solvers.reduction_symbolic`, memoized per process), the numeric phase (compiled
kernels of :mod:`mbplan.solvers.reduced_kernels`), the factorization of the reduced matrix
``K_r`` and one solve through the reduction."""

from __future__ import annotations

import copy
import dataclasses
import threading
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp

from mbplan.engine.jit import announce_uncached_numba
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
    rows_matvec,
    rows_t_matvec,
    s_apply,
    spgemm,
    spgemm_lower,
    times_t,
)
from mbplan.solvers.reduction_symbolic import ReductionSymbolic, Slots

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


class Reduction(ReductionSymbolic):
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
        slots = Slots(ae)
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
            W = self.W
            times_t(hf.data, self.row_seg, self.seg_ptr, self.seg_block, self.seg_e,
                    self.seg_arg, self.ebuf, self.eoff, self.shape, self.reach_red,
                    self.reach_ptr, W.indptr, W.indices, W.data, self.work)  # fmt: skip
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
