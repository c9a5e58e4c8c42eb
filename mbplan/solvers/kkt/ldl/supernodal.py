"""Numeric supernodal LDLᵀ of one :class:`~mbplan.solvers.kkt.ldl.symbolic.Analysis`: work arrays, the
factorization (large fronts' Schur updates by single-threaded BLAS) and the refined solve, over
the compiled kernels of :mod:`mbplan.solvers.kkt.ldl.kernels`."""

from __future__ import annotations

import functools
import threading
from typing import Any

import numpy as np
import threadpoolctl

from mbplan.solvers.kkt.ldl.dense import BLAS_PIVOTS
from mbplan.solvers.kkt.ldl.kernels import ldl_factor
from mbplan.solvers.kkt.ldl.solve import refined_solve
from mbplan.solvers.kkt.ldl.symbolic import Analysis

BLAS_FRONT_ROWS = 256
"""Fronts with at least this many update rows get their Schur update from single-threaded BLAS
(faster than the numba kernels from this size on)."""


class OneBlasThread:
    """Limits BLAS to one thread while any factorization with BLAS updates runs (threadpoolctl's
    limit is process-wide: the first entering thread sets it, the last leaving one restores it)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._users = 0
        self._limiter: Any = None  # threadpoolctl's limiter while some factorization runs

    def __enter__(self) -> None:
        with self._lock:
            if self._users == 0:
                self._limiter = _blas_controller().limit(limits=1, user_api="blas")
            self._users += 1

    def __exit__(self, *exc: object) -> None:
        with self._lock:
            self._users -= 1
            if self._users == 0 and self._limiter is not None:
                self._limiter.restore_original_limits()
                self._limiter = None


# process-wide cache, result-neutral: the BLAS thread-pool handle: no numeric content
@functools.cache
def _blas_controller() -> threadpoolctl.ThreadpoolController:
    return threadpoolctl.ThreadpoolController()


_ONE_BLAS_THREAD = OneBlasThread()


class SupernodalLDL:
    """Numeric factorization and solves for an :class:`Analysis` (own work arrays)."""

    def __init__(self, analysis: Analysis, blas_rows: int | None = None) -> None:
        self.a = analysis
        self.lbuf = np.empty(analysis.loff[-1])
        self.ubuf = np.empty(analysis.uoff[-1])
        self.d = np.empty(analysis.n)
        self.e = np.zeros(analysis.n)  # 2 × 2 pivots' off-diagonals (pivoted supernodes)
        self.piv = np.zeros(analysis.n, np.int64)  # local pivot order (pivoted supernodes)
        self.spiv = np.zeros(len(analysis.sfirst) - 1, np.bool_)
        self.sent = np.zeros(len(analysis.sfirst) - 1, np.bool_)  # see ldl_factor
        self.stats = np.zeros(4, np.int64)  # see ldl_factor
        self._save = np.empty(0)  # work array of pivoted fronts, and the entries of each front:
        self._eptr = np.zeros(len(analysis.loff), np.int64)
        self._eidx = np.zeros(0, np.int64)
        self._work = np.empty(6 * analysis.n + analysis.wmax)  # the refined solve's
        self.blas_rows = BLAS_FRONT_ROWS if blas_rows is None else blas_rows
        k, m = np.diff(analysis.sfirst), np.diff(analysis.fptr)
        self.uses_blas = bool(np.any((m - k >= self.blas_rows) & (k >= BLAS_PIVOTS)))

    def factor(
        self,
        vals: np.ndarray,
        pivot_threshold: float = 0.0,
        delta: float = 0.0,
        sign: np.ndarray | None = None,
    ) -> tuple[int, int, int, bool]:
        """Numeric factorization of the values ``vals`` (the analysis' entry order): the
        numbers of positive, negative and perturbed pivots and ``False`` on a breakdown.
        ``pivot_threshold > 0``: threshold pivoting inside each supernode, pivots with
        ``|d| <= delta`` perturbed to ``sign · delta`` (``sign``: the expected pivot signs in
        pivot order, default +1; :func:`~mbplan.solvers.kkt.ldl.kernels.ldl_factor`)."""
        a = self.a
        if pivot_threshold > 0.0 and self._save.size == 0:
            self._save = np.empty(int(np.max(np.diff(a.loff), initial=1)))
            front = np.searchsorted(a.loff, a.amap, side="right") - 1  # each entry's front
            self._eidx = np.argsort(front, kind="stable")
            self._eptr = np.searchsorted(front[self._eidx], np.arange(len(a.loff)))
        self.e[:] = 0.0
        if sign is None:
            sign = np.ones(a.n)
        args = (
            vals, a.amap, a.sfirst, a.fptr, a.loff, a.uoff, a.zero_at, a.rptr, a.rel, a.cptr, a.child,
            a.sparent, a.direct, self.sent, self.lbuf, self.ubuf, self.d, self.blas_rows, float(pivot_threshold), float(delta),
            sign, self.piv, self.e, self.spiv, self._eptr, self._eidx,
            self._save if self._save.size else self.d, self.stats,
        )  # fmt: skip
        if not self.uses_blas:
            return ldl_factor(*args)
        with _ONE_BLAS_THREAD:
            return ldl_factor(*args)

    def refined_solve(
        self, b: np.ndarray, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
        max_refinement: int, ratio_max: float, min_refinement: int = 1,
    ) -> tuple[np.ndarray, float]:  # fmt: skip
        a = self.a
        return refined_solve(
            np.ascontiguousarray(b, dtype=np.float64), a.perm, a.sfirst, a.fptr, a.rows,
            a.loff, self.lbuf, self.d, self.piv, self.e, self.spiv, indptr, indices, data,
            self._work, max_refinement, ratio_max, min_refinement,
        )  # fmt: skip
