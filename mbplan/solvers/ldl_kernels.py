"""Numeric kernels of the supernodal LDLᵀ (:mod:`mbplan.solvers.linear_solver`): the multifrontal
factorization (counting the pivot signs), unpivoted or with threshold pivoting inside each
supernode (:mod:`mbplan.solvers.ldl_pivot`), compiled with numba (the solves:
:mod:`mbplan.solvers.ldl_solve`); storage as described in :mod:`mbplan.solvers.ldl_symbolic`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from mbplan.solvers.ldl_pivot import pivoted_front, rotate_pairs
from mbplan.solvers.numba_borrow import borrowed

U64 = nb.uint64  # unsigned flat indices: no negative-index wraparound code in the loops
SMALL_COLUMNS = 4  # supernodes with at most this many columns are solved without a gathered copy
_WIDE = 24  # fronts with at least this many rows below the pivot get the 4 x 4 kernels
BLAS_PIVOTS = 8  # the BLAS update needs at least this many pivot columns to pay for its copy


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _schur_update2(L, d, k, U):
    """``U[b, a] -= Σ_t L[t, k+b] d_t L[t, k+a]`` for ``a >= b``: two rows of ``U`` and four
    pivot columns at a time (``L[t]`` is front column ``t``, ``d`` its pivots). Inner loops
    run over zero-based views: their indices are provably non-negative, so they vectorize."""
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
    of the four rows are written too and never read; zero-based inner loops, as above)."""
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


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy", inline="always")
def _small_front(lbuf, ubuf, d, f, k, m, lo, uo, u, delta, schur):
    """The front's ``k <= SMALL_COLUMNS`` pivot columns, unpivoted, and (``schur``) its Schur
    update (column by column; for ``u > 0`` after all pivots), on flat indices (no array
    views). Returns the pivot counts and 0 (done), 1 (breakdown: a zero or non-finite pivot) or
    2 (a pivot failed the threshold test ``u`` or ``|d| <= delta``: the Schur update is not
    done)."""
    npos = nneg = 0
    for t in range(k):
        ct = lo + t * m
        for p in range(t):
            cp = lo + p * m
            coef = lbuf[cp + t] * d[f + p]
            if coef != 0.0:
                for i in range(t, m):
                    lbuf[U64(ct + i)] -= coef * lbuf[U64(cp + i)]
        dt = lbuf[ct + t]
        if not np.isfinite(dt):
            return npos, nneg, 1
        if abs(dt) <= delta:
            return npos, nneg, 2 if u > 0.0 else 1
        d[f + t] = dt
        if dt > 0.0:
            npos += 1
        else:
            nneg += 1
        if u > 0.0:
            if not _scale_checked(lbuf[ct + t + 1 : ct + m], 0, m - t - 1, dt, u):
                return npos, nneg, 2
            continue
        inv = 1.0 / dt
        for i in range(t + 1, m):
            lbuf[U64(ct + i)] *= inv
        if schur:
            _small_update(lbuf, ubuf, k, m, ct, uo, dt)
    if u > 0.0 and schur:  # the Schur update once every pivot has passed
        for t in range(k):
            _small_update(lbuf, ubuf, k, m, lo + t * m, uo, d[f + t])
    return npos, nneg, 0


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy", inline="always")
def _small_update(lbuf, ubuf, k, m, ct, uo, dt):
    """The Schur update of the front's pivot column at ``lbuf[ct]`` (pivot ``dt``)."""
    r = m - k
    for b in range(r):
        coef = lbuf[ct + k + b] * dt
        if coef != 0.0:
            ub, lb = uo + b * r, ct + k
            for a in range(b, r):
                ubuf[U64(ub + a)] -= coef * lbuf[U64(lb + a)]


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _front_columns(L, df, k, m, u, delta):
    """The front's pivot columns, unpivoted, four (at the end two or one) at a time; return
    values as :func:`_small_front` (the Schur update is the caller's)."""
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


@nb.njit(cache=True, error_model="numpy", inline="always")
def _zero_upper(ubuf, uo, r):
    """Zero the entries ``a >= b`` of the ``r × r`` update matrix at ``ubuf[uo]`` (the others are
    never read)."""
    for b in range(r):
        ubuf[uo + b * r + b : uo + (b + 1) * r] = 0.0


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _direct_update(c, p, sfirst, fptr, loff, uoff, rptr, rel, lbuf, ubuf, d, pivot_only):
    """Subtract the Schur update ``Σ_t d_t l_t l_tᵀ`` of the factorized leaf front ``c``
    (``k <= DIRECT_COLUMNS`` pivot columns) from its parent ``p``'s front: its pivot columns
    in ``lbuf`` and (unless ``pivot_only``) its update matrix in ``ubuf``. Unsigned indices:
    no negative-index wraparound in the scatter loops."""
    f = sfirst[c]
    k, m = sfirst[c + 1] - f, fptr[c + 1] - fptr[c]
    r = m - k
    l0 = loff[c] + k  # l_t[a] (row k + a of front column t): lbuf[l0 + t m + a]
    l1, l2, l3 = l0 + m, l0 + 2 * m, l0 + 3 * m
    pk = sfirst[p + 1] - sfirst[p]
    pm = fptr[p + 1] - fptr[p]
    rp = rptr[c]
    for bb in range(r):
        col = rel[rp + bb]
        if col < pk:
            out, dst = lbuf, loff[p] + col * pm
        elif pivot_only:
            break  # rel increases: the remaining rows are all in the update matrix
        else:
            out, dst = ubuf, uoff[p] + (col - pk) * (pm - pk) - pk
        c0 = lbuf[l0 + bb] * d[f]
        if k == 1:
            for aa in range(bb, r):
                out[U64(dst + rel[U64(rp + aa)])] -= c0 * lbuf[U64(l0 + aa)]
        elif k == 2:
            c1 = lbuf[l1 + bb] * d[f + 1]
            for aa in range(bb, r):
                out[U64(dst + rel[U64(rp + aa)])] -= (
                    c0 * lbuf[U64(l0 + aa)] + c1 * lbuf[U64(l1 + aa)]
                )
        elif k == 3:
            c1, c2 = lbuf[l1 + bb] * d[f + 1], lbuf[l2 + bb] * d[f + 2]
            for aa in range(bb, r):
                out[U64(dst + rel[U64(rp + aa)])] -= (
                    c0 * lbuf[U64(l0 + aa)] + c1 * lbuf[U64(l1 + aa)] + c2 * lbuf[U64(l2 + aa)]
                )
        else:
            c1, c2 = lbuf[l1 + bb] * d[f + 1], lbuf[l2 + bb] * d[f + 2]
            c3 = lbuf[l3 + bb] * d[f + 3]
            for aa in range(bb, r):
                out[U64(dst + rel[U64(rp + aa)])] -= (
                    c0 * lbuf[U64(l0 + aa)] + c1 * lbuf[U64(l1 + aa)] + c2 * lbuf[U64(l2 + aa)]
                    + c3 * lbuf[U64(l3 + aa)]
                )  # fmt: skip


@nb.njit(cache=True, error_model="numpy", inline="always")
def _assemble_children(
    s, sfirst, fptr, loff, uoff, rptr, rel, cptr, child, sent, lbuf, ubuf, d, pivot_only
):  # fmt: skip
    """Add the children's update matrices into front ``s`` (its pivot columns in ``lbuf``, its
    own update matrix in ``ubuf``); children that sent theirs directly (``sent``) are skipped,
    or with ``pivot_only`` (reassembling the pivot columns only) sent again."""
    k = sfirst[s + 1] - sfirst[s]
    m = fptr[s + 1] - fptr[s]
    r = m - k
    lo, uo = loff[s], uoff[s]
    for ci in range(cptr[s], cptr[s + 1]):
        c = child[ci]
        if sent[c]:
            if pivot_only:
                _direct_update(c, s, sfirst, fptr, loff, uoff, rptr, rel, lbuf, ubuf, d, True)
            continue
        rc, uc, rp = rptr[c + 1] - rptr[c], uoff[c], rptr[c]
        for bb in range(rc):
            col = rel[rp + bb]
            src = uc + bb * rc
            if col < k:  # into a pivot column of the front
                dst = lo + col * m
                for aa in range(bb, rc):
                    lbuf[U64(dst + rel[U64(rp + aa)])] += ubuf[U64(src + aa)]
            elif not pivot_only:  # into the front's own update matrix
                dst = uo + (col - k) * r - k
                for aa in range(bb, rc):
                    ubuf[U64(dst + rel[U64(rp + aa)])] += ubuf[U64(src + aa)]


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def ldl_factor(
    vals, amap, sfirst, fptr, loff, uoff, zero_at, rptr, rel, cptr, child, sparent, direct, sent,
    lbuf, ubuf, d, blas_rows, u, delta, sign, piv, e, spiv, eptr, eidx, save, stats,
):  # fmt: skip
    """Multifrontal ``LDLᵀ``. Fronts with at least ``blas_rows`` update rows (and
    ``BLAS_PIVOTS`` pivot columns) get their Schur update from BLAS. ``u = 0``: no pivoting, a
    zero or non-finite pivot is a breakdown. ``u > 0``: a front whose unpivoted pivots fail the
    threshold test (or ``|d| <= delta``) is assembled again (``eidx[eptr[s]:eptr[s+1]]``: the
    entries of K in front s) and refactorized (``save``: work array) by
    :func:`~mbplan.solvers.ldl_pivot.pivoted_front`: 1 × 1 / 2 × 2 pivots among its own columns
    (``piv``: local order, ``e``: 2 × 2 off-diagonals, ``spiv[s]``: supernode s pivoted), tiny
    pivots perturbed to ``sign · delta`` (``sign``: expected pivot signs, pivot order). ``stats``: pivoted fronts, 2 × 2 pivots, perturbed pivots,
    pivots accepted below the threshold. A leaf front flagged ``direct`` (parent ``sparent``)
    subtracts its Schur update from its parent's front itself (``sent``: it did). Returns the
    numbers of positive, negative and perturbed pivots and ``False`` on a breakdown."""
    vals, amap, sfirst, fptr, loff = (
        borrowed(vals),
        borrowed(amap),
        borrowed(sfirst),
        borrowed(fptr),
        borrowed(loff),
    )
    uoff, zero_at, rptr, rel, cptr, child = (
        borrowed(uoff),
        borrowed(zero_at),
        borrowed(rptr),
        borrowed(rel),
        borrowed(cptr),
        borrowed(child),
    )
    sparent, direct, sent, lbuf, ubuf = (
        borrowed(sparent),
        borrowed(direct),
        borrowed(sent),
        borrowed(lbuf),
        borrowed(ubuf),
    )
    d, sign, piv, e, spiv = borrowed(d), borrowed(sign), borrowed(piv), borrowed(e), borrowed(spiv)
    eptr, eidx, save, stats = borrowed(eptr), borrowed(eidx), borrowed(save), borrowed(stats)
    lbuf[:] = 0.0
    for q in range(vals.shape[0]):
        lbuf[U64(amap[q])] += vals[q]
    stats[:] = 0
    npos = nneg = npert = 0
    kmax = 1
    for s in range(sfirst.shape[0] - 1):
        kmax = max(kmax, sfirst[s + 1] - sfirst[s])
    rest, v1, v2 = np.empty(kmax, np.int64), np.empty(kmax), np.empty(kmax)
    for s in range(sfirst.shape[0] - 1):
        f = sfirst[s]
        k = sfirst[s + 1] - f
        m = fptr[s + 1] - fptr[s]
        r = m - k
        lo, uo = loff[s], uoff[s]
        p, z = sparent[s], zero_at[s]
        if z != -1:  # an update matrix starts (its own, or its parent's for direct children)
            _zero_upper(ubuf, uoff[z], fptr[z + 1] - fptr[z] - sfirst[z + 1] + sfirst[z])
        _assemble_children(
            s, sfirst, fptr, loff, uoff, rptr, rel, cptr, child, sent, lbuf, ubuf, d, False
        )  # fmt: skip
        spiv[s] = sent[s] = False
        if direct[s]:
            ip, ineg, status = _small_front(lbuf, ubuf, d, f, k, m, lo, uo, u, delta, False)
            if status == 0:
                _direct_update(s, p, sfirst, fptr, loff, uoff, rptr, rel, lbuf, ubuf, d, False)
                sent[s] = True
            else:  # the pivoted path below computes its update matrix
                _zero_upper(ubuf, uo, r)
        elif k <= SMALL_COLUMNS:  # few pivot columns: plain loops on flat indices (no views)
            ip, ineg, status = _small_front(lbuf, ubuf, d, f, k, m, lo, uo, u, delta, True)
        else:
            L = lbuf[lo : lo + k * m].reshape(k, m)
            ip, ineg, status = _front_columns(L, d[f : f + k], k, m, u, delta)
            if status == 0:
                _schur(L, d[f : f + k], k, ubuf[uo : uo + r * r].reshape(r, r), blas_rows)
        if status == 1:
            return npos, nneg, npert, False
        if status == 0:
            npos += ip
            nneg += ineg
            continue
        # threshold pivoting inside the front: its pivot columns assembled again (the
        # children's update matrices are kept, the front's own is untouched)
        lbuf[lo : lo + k * m] = 0.0
        for q in eidx[eptr[s] : eptr[s + 1]]:
            lbuf[amap[q]] += vals[q]
        _assemble_children(
            s, sfirst, fptr, loff, uoff, rptr, rel, cptr, child, sent, lbuf, ubuf, d, True
        )  # fmt: skip
        L = lbuf[lo : lo + k * m].reshape(k, m)
        out = save[: k * m].reshape(k, m)
        ip, ineg, ipert, weak, ok = pivoted_front(
            L,
            k,
            m,
            u,
            delta,
            sign[f : f + k],
            out,
            rest,
            v1,
            v2,
            piv[f : f + k],
            d[f : f + k],
            e[f : f + k],
        )
        if not ok:
            return npos, nneg, npert, False
        spiv[s] = True
        npos += ip
        nneg += ineg
        npert += ipert
        stats[0] += 1
        stats[2] += ipert
        stats[3] += weak
        ef = e[f : f + k]
        pairs = 0
        for q in range(k):
            if ef[q] != 0.0:
                pairs += 1
        stats[1] += pairs
        if r == 0:
            continue
        U = ubuf[uo : uo + r * r].reshape(r, r)
        if pairs:
            lam = v1[:k]
            rotate_pairs(L, k, m, d[f : f + k], ef, out, lam)
            _schur(out, lam, k, U, blas_rows)
        else:
            _schur(L, d[f : f + k], k, U, blas_rows)
    return npos, nneg, npert, True


NUMERIC_KERNELS = (ldl_factor,)  # compiled entry points (for the cache check)
