"""Dense kernels of one front of the supernodal LDLᵀ (:mod:`mbplan.solvers.kkt.ldl.kernels`): its
pivot columns, unpivoted, four (or two) at a time, and the Schur update of its update matrix,
register-blocked or by BLAS for large fronts. ``L[t]`` is front column ``t`` (its rows in
front order), ``U`` the ``r × r`` update matrix (entries ``a >= b`` of row ``b`` used). Inner
loops run over zero-based views: their indices are provably non-negative, so LLVM vectorizes
them (numba's negative-index wraparound code does not).
"""

from __future__ import annotations

import numba as nb
import numpy as np

_WIDE = 24  # fronts with at least this many rows below the pivot get the 4 x 4 kernels
BLAS_PIVOTS = 8  # the BLAS update needs at least this many pivot columns to pay for its copy


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _schur_update2(L, d, k, U):
    """``U[b, a] -= Σ_t L[t, k+b] d_t L[t, k+a]`` for ``a >= b``: two rows of ``U`` and four
    pivot columns at a time (``L[t]`` is front column ``t``, ``d`` its pivots)."""
    r = U.shape[0]
    k4 = k - k % 4
    for b in range(0, r - 1, 2):
        n = r - b
        u0, u1 = U[b, b:], U[b + 1, b:]
        for t in range(0, k4, 4):
            l0, l1, l2, l3 = L[t, k + b :], L[t + 1, k + b :], L[t + 2, k + b :], L[t + 3, k + b :]
            a0, a1, a2, a3 = l0[0] * d[t], l1[0] * d[t + 1], l2[0] * d[t + 2], l3[0] * d[t + 3]
            b0, b1 = l0[1] * d[t], l1[1] * d[t + 1]
            b2, b3 = l2[1] * d[t + 2], l3[1] * d[t + 3]
            if a0 == 0.0 and a1 == 0.0 and a2 == 0.0 and a3 == 0.0:
                if b0 == 0.0 and b1 == 0.0 and b2 == 0.0 and b3 == 0.0:
                    continue
            for a in range(n):
                x0, x1, x2, x3 = l0[a], l1[a], l2[a], l3[a]
                u0[a] -= a0 * x0 + a1 * x1 + a2 * x2 + a3 * x3
                u1[a] -= b0 * x0 + b1 * x1 + b2 * x2 + b3 * x3
        for t in range(k4, k):
            lt = L[t, k + b :]
            a0, b0 = lt[0] * d[t], lt[1] * d[t]
            for a in range(n):
                u0[a] -= a0 * lt[a]
                u1[a] -= b0 * lt[a]
    if r % 2 == 1:
        for t in range(k):
            x = L[t, k + r - 1]
            U[r - 1, r - 1] -= x * d[t] * x


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _schur_update4(L, d, k, U):
    """``U[b, a] -= Σ_t L[t, k+b] d_t L[t, k+a]`` for ``a >= b``: four rows of ``U`` and four
    pivot columns at a time (``L[t]`` is front column ``t``, ``d`` its pivots; entries ``a < b``
    of the four rows are written too and never read)."""
    r = U.shape[0]
    k4, r4 = k - k % 4, r - r % 4
    for b in range(0, r4, 4):
        n = r - b
        u0, u1, u2, u3 = U[b, b:], U[b + 1, b:], U[b + 2, b:], U[b + 3, b:]
        for t in range(0, k4, 4):
            l0, l1, l2, l3 = L[t, k + b :], L[t + 1, k + b :], L[t + 2, k + b :], L[t + 3, k + b :]
            d0, d1, d2, d3 = d[t], d[t + 1], d[t + 2], d[t + 3]
            c00, c01, c02, c03 = l0[0] * d0, l1[0] * d1, l2[0] * d2, l3[0] * d3
            c10, c11, c12, c13 = l0[1] * d0, l1[1] * d1, l2[1] * d2, l3[1] * d3
            c20, c21, c22, c23 = l0[2] * d0, l1[2] * d1, l2[2] * d2, l3[2] * d3
            c30, c31, c32, c33 = l0[3] * d0, l1[3] * d1, l2[3] * d2, l3[3] * d3
            if (
                c00 == 0.0 and c01 == 0.0 and c02 == 0.0 and c03 == 0.0
                and c10 == 0.0 and c11 == 0.0 and c12 == 0.0 and c13 == 0.0
                and c20 == 0.0 and c21 == 0.0 and c22 == 0.0 and c23 == 0.0
                and c30 == 0.0 and c31 == 0.0 and c32 == 0.0 and c33 == 0.0
            ):  # fmt: skip
                continue
            for a in range(n):
                x0, x1, x2, x3 = l0[a], l1[a], l2[a], l3[a]
                u0[a] -= c00 * x0 + c01 * x1 + c02 * x2 + c03 * x3
                u1[a] -= c10 * x0 + c11 * x1 + c12 * x2 + c13 * x3
                u2[a] -= c20 * x0 + c21 * x1 + c22 * x2 + c23 * x3
                u3[a] -= c30 * x0 + c31 * x1 + c32 * x2 + c33 * x3
        for t in range(k4, k):
            lt = L[t, k + b :]
            e0, e1, e2, e3 = lt[0] * d[t], lt[1] * d[t], lt[2] * d[t], lt[3] * d[t]
            for a in range(n):
                x = lt[a]
                u0[a] -= e0 * x
                u1[a] -= e1 * x
                u2[a] -= e2 * x
                u3[a] -= e3 * x
    for b in range(r4, r):
        ub = U[b, b:]
        for t in range(k):
            lt = L[t, k + b :]
            e = lt[0] * d[t]
            if e != 0.0:
                for a in range(r - b):
                    ub[a] -= e * lt[a]


@nb.njit(cache=True, error_model="numpy")
def _schur_blas(L, d, k, U):
    """``U -= Bᵀ diag(d) B`` with ``B = L[:, k:]`` as one BLAS ``dgemm`` (both triangles; the
    entries ``a < b`` are never read): the large fronts' update."""
    B = np.ascontiguousarray(L[:, k:])
    U -= (B * d.reshape(-1, 1)).T @ B


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _apply_previous(L, d, t, two):
    """Front column ``t`` (and ``t+1`` if ``two``), rows ``t..``, minus the contributions of the
    columns before ``t``, four at a time."""
    ca = L[t, t:]
    cb = L[t + 1, t:] if two else ca
    m = ca.shape[0]
    t4 = t - t % 4
    for p in range(0, t4, 4):
        l0 = L[p, t:]
        l1 = L[p + 1, t:]
        l2 = L[p + 2, t:]
        l3 = L[p + 3, t:]
        a0, a1, a2, a3 = l0[0] * d[p], l1[0] * d[p + 1], l2[0] * d[p + 2], l3[0] * d[p + 3]
        if two:
            b0, b1 = l0[1] * d[p], l1[1] * d[p + 1]
            b2, b3 = l2[1] * d[p + 2], l3[1] * d[p + 3]
            for i in range(m):
                x0, x1, x2, x3 = l0[i], l1[i], l2[i], l3[i]
                ca[i] -= a0 * x0 + a1 * x1 + a2 * x2 + a3 * x3
                cb[i] -= b0 * x0 + b1 * x1 + b2 * x2 + b3 * x3
        elif a0 != 0.0 or a1 != 0.0 or a2 != 0.0 or a3 != 0.0:
            for i in range(m):
                ca[i] -= a0 * l0[i] + a1 * l1[i] + a2 * l2[i] + a3 * l3[i]
    for p in range(t4, t):
        lp = L[p, t:]
        a0 = lp[0] * d[p]
        b0 = lp[1] * d[p] if two else 0.0
        for i in range(m):
            ca[i] -= a0 * lp[i]
            if two:
                cb[i] -= b0 * lp[i]


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _apply_previous4(L, d, t):
    """Front columns ``t .. t+3``, rows ``t..``, minus the contributions of the columns before
    ``t``, four at a time (entries above each column's diagonal are written and never read)."""
    c0, c1, c2, c3 = L[t, t:], L[t + 1, t:], L[t + 2, t:], L[t + 3, t:]
    m = c0.shape[0]
    c = np.empty((4, 4))
    t4 = t - t % 4
    for p in range(0, t4, 4):
        l0, l1, l2, l3 = L[p, t:], L[p + 1, t:], L[p + 2, t:], L[p + 3, t:]
        nonzero = False
        for i in range(4):
            for j in range(4):
                c[i, j] = L[p + j, t + i] * d[p + j]
                nonzero = nonzero or c[i, j] != 0.0
        if not nonzero:
            continue
        a00, a01, a02, a03 = c[0, 0], c[0, 1], c[0, 2], c[0, 3]
        a10, a11, a12, a13 = c[1, 0], c[1, 1], c[1, 2], c[1, 3]
        a20, a21, a22, a23 = c[2, 0], c[2, 1], c[2, 2], c[2, 3]
        a30, a31, a32, a33 = c[3, 0], c[3, 1], c[3, 2], c[3, 3]
        for i in range(m):
            x0, x1, x2, x3 = l0[i], l1[i], l2[i], l3[i]
            c0[i] -= a00 * x0 + a01 * x1 + a02 * x2 + a03 * x3
            c1[i] -= a10 * x0 + a11 * x1 + a12 * x2 + a13 * x3
            c2[i] -= a20 * x0 + a21 * x1 + a22 * x2 + a23 * x3
            c3[i] -= a30 * x0 + a31 * x1 + a32 * x2 + a33 * x3
    for p in range(t4, t):
        lp = L[p, t:]
        e0, e1, e2, e3 = lp[0] * d[p], lp[1] * d[p], lp[2] * d[p], lp[3] * d[p]
        for i in range(m):
            x = lp[i]
            c0[i] -= e0 * x
            c1[i] -= e1 * x
            c2[i] -= e2 * x
            c3[i] -= e3 * x


@nb.njit(cache=True, error_model="numpy")
def _scale_checked(col, lo, hi, dt, u):
    """``col[lo:hi] /= dt``; returns ``False`` when a scaled entry exceeds ``1/u`` (the
    threshold test ``|dt| >= u max |col|`` fails; ``u = 0``: no test)."""
    inv = 1.0 / dt
    big = 0.0
    for i in range(lo, hi):
        col[i] *= inv
        a = abs(col[i])
        if a > big:
            big = a
    return big * u <= 1.0


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _front_columns(L, df, k, m, u, delta):
    """The front's pivot columns, unpivoted, four (at the end two or one) at a time; returns
    the pivot counts and 0 (done), 1 (breakdown: a zero or non-finite pivot) or 2 (a pivot
    failed the threshold test ``u`` or ``|d| <= delta``; the Schur update is the caller's)."""
    npos = nneg = 0
    t = 0
    while t < k:
        w = 4 if t + 4 <= k and m - t >= _WIDE else min(2, k - t)
        if w == 4:
            _apply_previous4(L, df, t)
        else:
            _apply_previous(L, df, t, w == 2)
        for step in range(w):
            col = L[t + step]
            dt = col[t + step]
            if not np.isfinite(dt):
                return npos, nneg, 1
            if abs(dt) <= delta:
                return npos, nneg, 2 if u > 0.0 else 1
            df[t + step] = dt
            if dt > 0.0:
                npos += 1
            else:
                nneg += 1
            if u > 0.0:
                if not _scale_checked(col, t + step + 1, m, dt, u):
                    return npos, nneg, 2
            else:
                inv = 1.0 / dt
                below = col[t + step + 1 :]
                for i in range(m - t - step - 1):
                    below[i] *= inv
            for j in range(t + step + 1, t + w):  # the group's later columns
                coef = col[j] * dt
                if coef != 0.0:
                    nxt, src = L[j, j:], col[j:]
                    for i in range(m - j):
                        nxt[i] -= coef * src[i]
        t += w
    return npos, nneg, 0


@nb.njit(cache=True, error_model="numpy")
def _schur(L, df, k, U, blas_rows):
    """``U -= Σ_t d_t l_t l_tᵀ`` over the front's update rows, by the kernel for its size."""
    r = U.shape[0]
    if r >= blas_rows and k >= BLAS_PIVOTS:
        _schur_blas(L, df, k, U)
    elif r >= _WIDE:
        _schur_update4(L, df, k, U)
    elif r > 0:
        _schur_update2(L, df, k, U)
