"""Triangular solves with the supernodal LDLᵀ of :mod:`mbplan.solvers.kkt.ldl.kernels` (1 × 1 and
2 × 2 pivots, pivot order inside supernodes) and iterative refinement against ``K``, compiled
with numba; storage as described in :mod:`mbplan.solvers.kkt.ldl.symbolic`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from mbplan.solvers.kkt.borrow import borrowed
from mbplan.solvers.kkt.ldl.kernels import SMALL_COLUMNS, U64


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def _forward_front(L, w, k, m):
    """``w ← (I + L_front)⁻¹ w`` on a gathered front (``L[t]`` is front column ``t``), four
    columns at a time (zero-based inner loops: they vectorize)."""
    k4 = k - k % 4
    for t in range(0, k4, 4):
        l0, l1, l2, l3 = L[t], L[t + 1], L[t + 2], L[t + 3]
        a0 = w[t]
        a1 = w[t + 1] - l0[t + 1] * a0
        a2 = w[t + 2] - l0[t + 2] * a0 - l1[t + 2] * a1
        a3 = w[t + 3] - l0[t + 3] * a0 - l1[t + 3] * a1 - l2[t + 3] * a2
        w[t + 1], w[t + 2], w[t + 3] = a1, a2, a3
        wv, v0, v1, v2, v3 = w[t + 4 :], l0[t + 4 :], l1[t + 4 :], l2[t + 4 :], l3[t + 4 :]
        for i in range(m - t - 4):
            wv[i] -= a0 * v0[i] + a1 * v1[i] + a2 * v2[i] + a3 * v3[i]
    for t in range(k4, k):
        a0, wv, lt = w[t], w[t + 1 :], L[t, t + 1 :]
        for i in range(m - t - 1):
            wv[i] -= a0 * lt[i]


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def _backward_front(L, w, k, m):
    """``w[:k] ← w[:k] - L_frontᵀ w`` solved backwards (``(I + L)ᵀ``), four columns at a time."""
    k4 = k - k % 4
    for t in range(k - 1, k4 - 1, -1):
        lt, wv = L[t, t + 1 :], w[t + 1 :]
        acc = 0.0
        for i in range(m - t - 1):
            acc += lt[i] * wv[i]
        w[t] -= acc
    for t in range(k4 - 4, -1, -4):
        l0, l1, l2, l3 = L[t], L[t + 1], L[t + 2], L[t + 3]
        wv, v0, v1, v2, v3 = w[t + 4 :], l0[t + 4 :], l1[t + 4 :], l2[t + 4 :], l3[t + 4 :]
        a0 = a1 = a2 = a3 = 0.0
        for i in range(m - t - 4):
            x = wv[i]
            a0 += v0[i] * x
            a1 += v1[i] * x
            a2 += v2[i] * x
            a3 += v3[i] * x
        x3 = w[t + 3] - a3
        x2 = w[t + 2] - a2 - l2[t + 3] * x3
        x1 = w[t + 1] - a1 - l1[t + 2] * x2 - l1[t + 3] * x3
        w[t] -= a0 + l0[t + 1] * x1 + l0[t + 2] * x2 + l0[t + 3] * x3
        w[t + 1], w[t + 2], w[t + 3] = x1, x2, x3


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy", inline="always")
def _forward_small(y, rows, lbuf, f, fp, lo, k, m):
    """The forward pass of an unpivoted supernode with ``k <= SMALL_COLUMNS`` columns on flat
    indices: its own block, then each row below updated once by all its columns (one exit:
    numba then drops the arrays' reference counting from the inlined code)."""
    l1, l2, l3 = lo + m, lo + 2 * m, lo + 3 * m
    y0 = y[f]
    if k == 1:
        for i in range(1, m):
            y[U64(rows[U64(fp + i)])] -= lbuf[U64(lo + i)] * y0
    elif k == 2:
        y1 = y[f + 1] - lbuf[lo + 1] * y0
        y[f + 1] = y1
        for i in range(2, m):
            y[U64(rows[U64(fp + i)])] -= lbuf[U64(lo + i)] * y0 + lbuf[U64(l1 + i)] * y1
    elif k == 3:
        y1 = y[f + 1] - lbuf[lo + 1] * y0
        y2 = y[f + 2] - lbuf[lo + 2] * y0 - lbuf[l1 + 2] * y1
        y[f + 1], y[f + 2] = y1, y2
        for i in range(3, m):
            y[U64(rows[U64(fp + i)])] -= (
                lbuf[U64(lo + i)] * y0 + lbuf[U64(l1 + i)] * y1 + lbuf[U64(l2 + i)] * y2
            )
    else:
        y1 = y[f + 1] - lbuf[lo + 1] * y0
        y2 = y[f + 2] - lbuf[lo + 2] * y0 - lbuf[l1 + 2] * y1
        y3 = y[f + 3] - lbuf[lo + 3] * y0 - lbuf[l1 + 3] * y1 - lbuf[l2 + 3] * y2
        y[f + 1], y[f + 2], y[f + 3] = y1, y2, y3
        for i in range(4, m):
            y[U64(rows[U64(fp + i)])] -= (
                lbuf[U64(lo + i)] * y0
                + lbuf[U64(l1 + i)] * y1
                + lbuf[U64(l2 + i)] * y2
                + lbuf[U64(l3 + i)] * y3
            )


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy", inline="always")
def _backward_small(y, rows, lbuf, f, fp, lo, k, m):
    """The backward pass of an unpivoted supernode with ``k <= SMALL_COLUMNS`` columns: each
    row below read once for all its columns, then its own block (one exit, as above)."""
    l1, l2, l3 = lo + m, lo + 2 * m, lo + 3 * m
    a0 = a1 = a2 = a3 = 0.0
    if k == 1:
        for i in range(1, m):
            a0 += lbuf[U64(lo + i)] * y[U64(rows[U64(fp + i)])]
    elif k == 2:
        for i in range(2, m):
            x = y[U64(rows[U64(fp + i)])]
            a0 += lbuf[U64(lo + i)] * x
            a1 += lbuf[U64(l1 + i)] * x
        y[f + 1] -= a1
        a0 += lbuf[lo + 1] * y[f + 1]
    elif k == 3:
        for i in range(3, m):
            x = y[U64(rows[U64(fp + i)])]
            a0 += lbuf[U64(lo + i)] * x
            a1 += lbuf[U64(l1 + i)] * x
            a2 += lbuf[U64(l2 + i)] * x
        y2 = y[f + 2] - a2
        y1 = y[f + 1] - a1 - lbuf[l1 + 2] * y2
        y[f + 2], y[f + 1] = y2, y1
        a0 += lbuf[lo + 1] * y1 + lbuf[lo + 2] * y2
    else:
        for i in range(4, m):
            x = y[U64(rows[U64(fp + i)])]
            a0 += lbuf[U64(lo + i)] * x
            a1 += lbuf[U64(l1 + i)] * x
            a2 += lbuf[U64(l2 + i)] * x
            a3 += lbuf[U64(l3 + i)] * x
        y3 = y[f + 3] - a3
        y2 = y[f + 2] - a2 - lbuf[l2 + 3] * y3
        y1 = y[f + 1] - a1 - lbuf[l1 + 2] * y2 - lbuf[l1 + 3] * y3
        y[f + 3], y[f + 2], y[f + 1] = y3, y2, y1
        a0 += lbuf[lo + 1] * y1 + lbuf[lo + 2] * y2 + lbuf[lo + 3] * y3
    y[f] -= a0


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def _solve_into(b, x, y, w, perm, sfirst, fptr, rows, loff, lbuf, d, piv, e, spiv):
    """``x = K⁻¹ b`` with the factorization, into ``x`` (``y``: length ``n``, ``w``: the
    largest front, work arrays): forward, (block) diagonal and backward substitution; a
    supernode with many columns, or pivoted inside (``spiv``; ``piv``: its local order, ``e``:
    its 2 × 2 blocks), works on a gathered copy of its rows of the right-hand side. ``y`` holds
    a pivoted supernode's own entries in pivot order from its forward to its backward pass."""
    n = b.shape[0]
    ns = sfirst.shape[0] - 1
    for i in range(n):
        y[i] = b[U64(perm[i])]
    for s in range(ns):
        f, fp, lo = sfirst[s], fptr[s], loff[s]
        k = sfirst[s + 1] - f
        m = fptr[s + 1] - fp
        if k <= SMALL_COLUMNS and not spiv[s]:  # flat indexing: no views for the many small ones
            _forward_small(y, rows, lbuf, f, fp, lo, k, m)
            continue
        L = lbuf[lo : lo + k * m].reshape(k, m)
        if spiv[s]:
            for i in range(k):
                w[i] = y[f + piv[f + i]]
        else:
            for i in range(k):
                w[i] = y[f + i]
        for i in range(k, m):
            w[i] = 0.0
        _forward_front(L, w, k, m)
        for i in range(k):
            y[f + i] = w[i]
        for i in range(k, m):
            y[U64(rows[U64(fp + i)])] += w[i]
    i = 0
    while i < n:
        if e[i] == 0.0:
            y[i] /= d[i]
            i += 1
            continue
        a, c, g = d[i], e[i], d[i + 1]  # the 2 × 2 block [[a, c], [c, g]]
        det = a * g - c * c
        y0, y1 = y[i], y[i + 1]
        y[i] = (g * y0 - c * y1) / det
        y[i + 1] = (a * y1 - c * y0) / det
        i += 2
    for s in range(ns - 1, -1, -1):
        f, fp, lo = sfirst[s], fptr[s], loff[s]
        k = sfirst[s + 1] - f
        m = fptr[s + 1] - fp
        if k <= SMALL_COLUMNS and not spiv[s]:
            _backward_small(y, rows, lbuf, f, fp, lo, k, m)
            continue
        L = lbuf[lo : lo + k * m].reshape(k, m)
        for i in range(k):
            w[i] = y[f + i]
        for i in range(k, m):
            w[i] = y[U64(rows[U64(fp + i)])]
        _backward_front(L, w, k, m)
        if spiv[s]:
            for i in range(k):
                y[f + piv[f + i]] = w[i]
        else:
            for i in range(k):
                y[f + i] = w[i]
    for i in range(n):
        x[U64(perm[i])] = y[i]


@nb.njit(cache=True, error_model="numpy")
def _residual_into(indptr, indices, data, b, x, r):
    """``r = b - K x`` with ``K`` in CSR arrays (row sums in SciPy's order, so the same
    rounding as ``b - K @ x``); returns ``(‖r‖∞, ‖x‖∞)``, NaN if either has a NaN."""
    for i in range(b.shape[0]):
        acc = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            acc += data[U64(e)] * x[U64(indices[U64(e)])]
        r[i] = b[i] - acc
    return _max_abs(r), _max_abs(x)


@nb.njit(cache=True, error_model="numpy")
def _max_abs(v):
    """``‖v‖∞``, NaN if ``v`` has a NaN."""
    out = 0.0
    for i in range(v.shape[0]):
        a = abs(v[i])
        if a > out:
            out = a
        elif a != a:
            return np.nan
    return out


@nb.njit(cache=True, error_model="numpy")
def _ratio(nrm_r, nrm_x, nrm_b):
    """IPOPT's residual ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``, ``inf`` if not finite."""
    denom = min(nrm_x, 1e6 * nrm_b) + nrm_b if nrm_x == nrm_x else nrm_x
    ratio = nrm_r / denom if denom > 0 else nrm_r
    return ratio if np.isfinite(ratio) else np.inf


@nb.njit(cache=True, error_model="numpy")
def refined_solve(
    b, perm, sfirst, fptr, rows, loff, lbuf, d, piv, e, spiv, indptr, indices, data, work,
    max_refinement, ratio_max, min_refinement,
):  # fmt: skip
    """Solve ``K x = b`` with the factorization of the regularized ``K`` and iterative
    refinement against ``K`` (full CSR arrays ``indptr, indices, data``): at least
    ``min_refinement`` (IPOPT: 1) and at most ``max_refinement`` steps, stopping at a residual
    ratio ``<= ratio_max`` or when a step does not reduce it. ``work``: ``6 n`` plus the largest
    front. Returns ``x`` (a new array) and the ratio."""
    n = b.shape[0]
    b, perm, sfirst, fptr, rows = (
        borrowed(b),
        borrowed(perm),
        borrowed(sfirst),
        borrowed(fptr),
        borrowed(rows),
    )
    loff, lbuf, d, piv, e, spiv = (
        borrowed(loff),
        borrowed(lbuf),
        borrowed(d),
        borrowed(piv),
        borrowed(e),
        borrowed(spiv),
    )
    indptr, indices, data, work = (
        borrowed(indptr),
        borrowed(indices),
        borrowed(data),
        borrowed(work),
    )
    y, sol, cand, dx = work[:n], work[n : 2 * n], work[2 * n : 3 * n], work[3 * n : 4 * n]
    resid, cand_resid, w = work[4 * n : 5 * n], work[5 * n : 6 * n], work[6 * n :]
    nrm_b = _max_abs(b)
    _solve_into(b, sol, y, w, perm, sfirst, fptr, rows, loff, lbuf, d, piv, e, spiv)
    nrm_r, nrm_x = _residual_into(indptr, indices, data, b, sol, resid)
    ratio = _ratio(nrm_r, nrm_x, nrm_b)
    for step in range(max_refinement):
        if step >= min_refinement and ratio <= ratio_max:
            break
        _solve_into(resid, dx, y, w, perm, sfirst, fptr, rows, loff, lbuf, d, piv, e, spiv)
        for i in range(n):
            cand[i] = sol[i] + dx[i]
        nrm_r, nrm_x = _residual_into(indptr, indices, data, b, cand, cand_resid)
        cand_ratio = _ratio(nrm_r, nrm_x, nrm_b)
        if not cand_ratio < ratio:
            break
        sol, cand = cand, sol
        resid, cand_resid = cand_resid, resid
        ratio = cand_ratio
    return sol.copy(), ratio


SOLVE_KERNELS = (refined_solve,)  # compiled entry points (for the cache check)
