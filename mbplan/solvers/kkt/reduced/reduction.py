"""The two congruences of an :class:`~mbplan.solvers.kkt.elimination.EliminationPlan` for
:class:`~mbplan.solvers.kkt.reduced.system.ReducedKKTSystem`: the symbolic phase
(:mod:`mbplan.solvers.kkt.reduced.symbolic`, :mod:`mbplan.solvers.kkt.reduced.layout`, kept in
the caller's :class:`~mbplan.workspace.Workspace` by the values it picks on), the numeric
phase (compiled kernels of :mod:`mbplan.solvers.kkt.reduced.kernels`,
:mod:`mbplan.solvers.kkt.reduced.products`, :mod:`mbplan.solvers.kkt.reduced.solves`), the
factorization of the reduced matrix ``K_r`` and one solve through the reduction."""

from __future__ import annotations

import copy
import dataclasses
import weakref

import numpy as np
import scipy.sparse as sp

from mbplan.solvers.kkt.elimination import EliminationPlan
from mbplan.solvers.kkt.reduced.kernels import (
    block_values,
    copy_values,
    group_values,
    sigma_of,
)
from mbplan.solvers.kkt.reduced.layout import ReductionLayout
from mbplan.solvers.kkt.reduced.products import hr_values, tdt_values, times_t
from mbplan.solvers.kkt.reduced.solves import expand_solution, reduce_rhs, residual
from mbplan.solvers.kkt.reduced.symbolic import ReductionSymbolic, Slots
from mbplan.solvers.kkt.system import Inertia, KKTSystem
from mbplan.workspace import Workspace, shared

REDUCED_STATIC_REG = 1e-8
"""Static regularization of ``K_r`` (at least): its zero-diagonal multiplier-like columns break
the unpivoted LDLᵀ down with ``1e-9``."""


def reduction(
    plan: EliminationPlan,
    hess: sp.csr_matrix,
    ae: sp.csr_matrix,
    ai: sp.csr_matrix,
    ordering: str,
    pivot_threshold: float = 0.0,
    workspace: Workspace | None = None,
) -> Reduction:
    """A :class:`Reduction` of its own for ``plan`` and the blocks' patterns, with the replaced
    rows and dependent columns picked on the values of ``ae`` (QR with column pivoting): a
    function of the plan, the patterns and the values of the rows the pick reads, so the
    symbolic phase is kept in ``workspace`` by all of them (the problems that pick on the same
    values share it). Raises one of ``PLAN_ERRORS`` for a plan or values it cannot use."""

    def key() -> tuple:
        return (
            ordering,
            pivot_threshold,
            *(getattr(plan, f.name).tobytes() for f in dataclasses.fields(plan)),
            *(a.tobytes() for m in (hess, ae, ai) for a in (m.indptr, m.indices)),
            ae.data[picked_entries(plan, ae)].tobytes(),
        )

    def build() -> Reduction:
        return Reduction(plan, hess, ae, ai, ordering, pivot_threshold, workspace)

    return shared(workspace, "reduction", key, build, disk=True).fresh()  # most of a 1st solve


def picked_entries(plan: EliminationPlan, ae: sp.csr_matrix) -> np.ndarray:
    """Which entries of ``ae.data`` the pick reads: those of the groups' source and subtracted
    rows and of the blocks' rows (the symbolic phase reads no other value)."""
    rows = np.concatenate([plan.group_sources.ravel(), plan.group_subtract.ravel(),
                           plan.block_rows.ravel()])  # fmt: skip
    read = np.zeros(ae.shape[0], bool)
    read[rows[rows >= 0]] = True
    return np.repeat(read, np.diff(ae.indptr))


class Reduction(ReductionSymbolic, ReductionLayout):
    """Symbolic phase of one plan and one pattern of ``(H, A_E, A_I)``, its replaced rows and
    dependent columns picked on the values of ``ae``, and the work arrays of the numeric phase
    (``workspace``: where ``K_r``'s analysis is kept)."""

    def __init__(
        self,
        plan: EliminationPlan,
        hess: sp.csr_matrix,
        ae: sp.csr_matrix,
        ai: sp.csr_matrix,
        ordering: str,
        pivot_threshold: float = 0.0,
        workspace: Workspace | None = None,
    ) -> None:
        n, me = ae.shape[1], ae.shape[0]
        self.n, self.me, self.mi = n, me, ai.shape[0]
        slots = Slots(ae)
        self._groups(plan, ae, slots)
        self._blocks(plan, ae, slots)
        self._transform()
        self._products(hess, ae, ai)
        self.factor_options = {
            "ordering": ordering,
            "pivot_threshold": pivot_threshold,
            "workspace": workspace,
        }
        self.kkt = KKTSystem(self.nr, len(self.kept), 0, **self.factor_options)
        self.ok = False
        self._pool: list[dict] = []  # work arrays of copies no longer alive (:meth:`fresh`)
        for name in ("T", "hs", "union", "reach", "outer", "_kept_rows", "ostart"):
            delattr(self, name)  # the symbolic phase's own
        self._compact()
        self.dep_key = (self.g_sel.tobytes(), self.tgt.tobytes(), self.dep.tobytes())  # the choice
        self._tuples()

    def _compact(self) -> None:
        """Every index array as ``int32`` (half the memory the kernels stream per iteration)."""

        def small(a):
            if isinstance(a, tuple):
                return tuple(small(x) for x in a)
            if isinstance(a, np.ndarray) and a.dtype == np.int64 and a.size:
                if -(2**31) <= a.min() and a.max() < 2**31:
                    return a.astype(np.int32)
            return a

        for name, value in list(vars(self).items()):
            setattr(self, name, small(value))

    _WORK = ("M", "new_rows", "g_a", "g_x", "g_piv", "lval", "ebuf", "lu", "dinv", "piv", "hf_data", "pbuf", "kbuf", "hr_base", "ttt",
             "sigma", "sigma_used", "ae_data", "ai_data", "acc", "tmp", "xu", "rz", "yv",
             "vx", "kv", "se", "rhs_r", "hw", "hd")  # fmt: skip
    _MATRICES = ("hl", "ak", "Ar", "Hr")

    def fresh(self) -> Reduction:
        """A copy sharing the symbolic arrays, with its own work arrays, matrices' values and
        ``K_r`` system: those of a copy no longer alive if there is one (they return to the
        pool when their copy is collected), else new ones (every one is written before it is
        read)."""
        new = copy.copy(self)
        try:
            own = self._pool.pop()
        except IndexError:
            own = {name: np.empty_like(getattr(self, name)) for name in self._WORK}
            for name in self._MATRICES:
                m = getattr(self, name)
                own[name] = sp.csr_matrix((np.empty_like(m.data), m.indices, m.indptr), m.shape)
            own["kkt"] = KKTSystem(self.nr, len(self.kept), 0, **self.factor_options)
        for name, value in own.items():
            setattr(new, name, value)
        weakref.finalize(new, self._pool.append, own)
        new.ok = new.hr_ok = new.ttt_ok = False
        new._tuples()
        return new

    def _tuples(self) -> None:
        """The solve kernels' argument tuples (:mod:`mbplan.solvers.kkt.reduced.solves`)."""
        hl, ak = self.hl, self.ak
        self._h = (hl.indptr, hl.indices, hl.data, self.hd)
        self._ai = (self.ai_p, self.ai_i, self.ai_data)
        self._ak = (ak.indptr, ak.indices, ak.data)
        self._grp = (self.tgt, self.src, self.sub, self.M)
        blocks = (self.lu, self.lu_off, self.piv, self.dinv)
        self._bf = (self.lval, self.shape, self.uoff, self.bc_ptr, self.bc_row, self.bc_col,
                    self.bc_val, *blocks, self.lu_begin)  # fmt: skip
        self._bb = (self.lval, self.shape, self.uoff, self.bc_ptr, self.bt_row, self.bt_col,
                    self.bt_val, *blocks, self.lu_end)  # fmt: skip
        self._tr = (self.red_cols, self.dep, self.ebuf, self.eoff, self.shape, self.reach_red,
                    self.reach_ptr, self.uoff, self.tmp)  # fmt: skip

    # ------------------------------------------------------------------ numeric
    def set_values(self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix) -> bool:
        """``M_j``, ``E``, ``H``'s values, ``A_E,kept T`` for new values (``H``, ``A_E`` and
        ``A_I`` with this reduction's patterns; ``H_f`` and ``Tᵀ H_f T`` follow in
        :meth:`factorize`, with ``Σ``); False on a breakdown."""
        self.ok = self.hr_ok = self.ttt_ok = False
        self.ae_data[:] = ae.data
        self.ai_data[:] = ai.data
        if len(self.M) and not group_values(
            ae.data, self.g_sel, self.h_sel, self.pad, self.g_begin, self.g_end, self.g_outer, self.h_outer,
            self.M, self.new_rows, self.g_a, self.g_x, self.g_piv,
        ):  # fmt: skip
            return False
        if not block_values(
            ae.data, self.new_rows, self.la_src, self.ln_src, self.lval, self.shape, self.eoff,
            self.lu_off, self.uoff, self.lu_begin, self.lu_end, self.a_ptr, self.a_src, self.a_dst, self.fe_ptr, self.fe_src,
            self.fe_dst, self.cptr, self.cblk, self.nz_ptr, self.nz_a, self.nz_p, self.nz_src,
            self.rmap_off, self.rmap, self.lu, self.piv, self.dinv, self.ebuf, self.tmp,
        ):  # fmt: skip
            return False
        if not copy_values(hess.data, self.hl.data, self.hl_src, self.hd, self.hd_src, ae.data,
                           self.ak.data, self.ak_src, self.ebuf):  # fmt: skip
            return False
        times_t(self.ak.data, *self.ak_seg, self.ebuf, self.eoff, self.shape, self.Ar.data,
                self.acc)  # fmt: skip
        self.ok = True
        return True

    def factorize(self, diagonal: np.ndarray, static_reg: float) -> Inertia | None:
        """Factorize ``K_r`` for ``K``'s diagonal (``Tᵀ D_x T`` added to ``Tᵀ H T``; the
        inequality rows folded in, ``Σ = -D_I⁻¹``); the inertia of ``K`` (``None``: a nonzero
        diagonal on a local row, ``D_I`` not negative, or a breakdown)."""
        n = self.n
        status = sigma_of(diagonal, n, self.me, self.y_rows, self.sigma, self.sigma_used)
        if not self.ok or status < 0:
            return None
        if not self.hr_ok or status == 1:  # Tᵀ H_f T for new values or a new Σ
            self.sigma_used[:] = self.sigma
            self.hr_ok = hr_values(
                self.hl.data, self.hl_lo, self.hl_up, self.hd, self.hd_slot, self.hf_data,
                self.fold_slot, self.ai_p, self.ai_data, self.sigma,
                *self.hs_seg, self.bseg_ptr, self.ebuf, self.eoff, self.shape, self.reach_ptr,
                self.panel_off, self.pwidth, self.pbuf, self.kbuf, self.kw_pos, self.kw_slot,
                self.lo_ptr, self.lo_slot, self.hr_base, self.acc,
            )  # fmt: skip
            if not self.hr_ok:
                return None
        dx, hr = diagonal[:n], self.Hr.data
        if not dx.any():
            hr[:] = self.hr_base
        elif np.all(dx == dx[0]):  # δ_w (+ζ) I: Tᵀ D T = d TᵀT, TᵀT once per matrix
            if not self.ttt_ok:
                self._tdt(self.ttt, np.zeros_like(hr), np.ones(n))
                self.ttt_ok = True
            np.multiply(self.ttt, dx[0], out=hr)
            hr += self.hr_base
        else:
            self._tdt(hr, self.hr_base, dx)
        self.kkt.set_matrices(self.Hr, self.Ar, None)
        diag_r = np.concatenate([np.zeros(self.nr), diagonal[n + self.kept]])
        inertia = self.kkt.factorize(diag_r, max(static_reg, REDUCED_STATIC_REG))
        if inertia is None:
            return None
        m = len(self.dep)
        return Inertia(inertia.positive + m, inertia.negative + m + self.mi, 0)

    def _tdt(self, out: np.ndarray, base: np.ndarray, d: np.ndarray) -> None:
        """``out = base + tril(Tᵀ diag(d) T)``."""
        tdt_values(out, base, d, self.dep, self.red_cols, self.ebuf, self.eoff, self.shape,
                   self.uoff, self.tt_off, self.tt_slot, self.diag_slot, self.acc)  # fmt: skip

    def residual(self, b: np.ndarray, x: np.ndarray, diagonal: np.ndarray) -> tuple[np.ndarray, float]:  # fmt: skip
        """``b - K x`` for the values of :meth:`set_values` and ``K``'s ``diagonal``, and IPOPT's
        residual ratio."""
        res = np.empty(len(b))
        ratio = residual(*self._h, self.ae_p, self.ae_i, self.ae_data, *self._ai, diagonal, x, b,
                         res)  # fmt: skip
        return res, ratio

    def matvec(self, x: np.ndarray, diagonal: np.ndarray) -> np.ndarray:
        """``K x`` for the values of :meth:`set_values` and ``K``'s ``diagonal``."""
        return -self.residual(np.zeros(len(x)), x, diagonal)[0]

    def solve_once(
        self, b: np.ndarray, diagonal: np.ndarray, ratio_max: float, min_refinement: int = 1
    ) -> np.ndarray:
        """``K⁻¹ b`` through the reduction (module docstring; ``diagonal``: ``K``'s), ``K_r``
        solved to the residual ratio ``ratio_max`` (at least ``min_refinement`` steps)."""
        common = (diagonal, self.sigma, self.n, self.me, self.y_rows, self.kept, self._h,
                  self._ai, self._ak, self._grp, self._bf, self._bb, self._tr)  # fmt: skip
        reduce_rhs(b, *common, self.xu, self.rz, self.rhs_r, self.vx, self.kv, self.se)
        xr = self.kkt.solve(self.rhs_r, 10, ratio_max, min_refinement)[0]
        w = np.empty(len(b))
        expand_solution(b, xr, *common, self.xu, self.rz, w, self.kv, self.yv, self.hw)
        return w
