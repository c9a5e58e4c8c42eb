"""Compiled kernels of :class:`~mbplan.solvers.reduced_step.ReducedKKTSystem`: the row groups'
combinations ``M_j``, the blocks' null-space coefficients ``E`` (small dense LU with partial
pivoting, block by block in plan order), products with fixed sparsity patterns, and the solves
with the eliminated pairs' block-triangular ``B`` (:mod:`mbplan.solvers.elimination`)."""

from __future__ import annotations

import numba as nb
import numpy as np

PIVOT_TOL = 1e-12
"""A block's or a group's LU breaks down on a pivot below this times the
block's largest entry: the caller then factorizes the full matrix."""


@nb.njit(cache=True)
def _gather(data, slot, out) -> None:
    """``out = data[slot]`` (``0`` where ``slot < 0``), 2-D."""
    for a in range(slot.shape[0]):
        for q in range(slot.shape[1]):
            out[a, q] = data[slot[a, q]] if slot[a, q] >= 0 else 0.0


@nb.njit(cache=True)
def _lu(A, piv) -> bool:
    """In-place LU with partial pivoting (``piv``: row swaps); False on a tiny pivot."""
    r = A.shape[0]
    scale = 0.0
    for a in range(r):
        for b in range(r):
            scale = max(scale, abs(A[a, b]))
    for k in range(r):
        p = k
        for a in range(k + 1, r):
            if abs(A[a, k]) > abs(A[p, k]):
                p = a
        if not abs(A[p, k]) > PIVOT_TOL * scale:
            return False
        piv[k] = p
        if p != k:
            for b in range(r):
                A[k, b], A[p, b] = A[p, b], A[k, b]
        for a in range(k + 1, r):
            if A[a, k] != 0.0:  # the blocks are sparse: skip the zero multipliers
                A[a, k] /= A[k, k]
                f = A[a, k]
                for b in range(k + 1, r):
                    A[a, b] -= f * A[k, b]
    return True


@nb.njit(cache=True)
def _lu_solve(A, piv, X) -> None:
    """``X ← A⁻¹ X`` with the factors of :func:`_lu` (``X``: ``(r, q)``)."""
    r = A.shape[0]
    for k in range(r):
        p = piv[k]
        if p != k:
            for c in range(X.shape[1]):
                X[k, c], X[p, c] = X[p, c], X[k, c]
    q = X.shape[1]
    for a in range(r):  # row by row: contiguous updates over the columns, zeros skipped
        for b in range(a):
            f = A[a, b]
            if f != 0.0:
                for c in range(q):
                    X[a, c] -= f * X[b, c]
    for a in range(r - 1, -1, -1):
        for b in range(a + 1, r):
            f = A[a, b]
            if f != 0.0:
                for c in range(q):
                    X[a, c] -= f * X[b, c]
        for c in range(q):
            X[a, c] /= A[a, a]


@nb.njit(cache=True)
def _lu_solve_t(A, piv, x) -> None:
    """``x ← A⁻ᵀ x`` with the factors of :func:`_lu`."""
    r = A.shape[0]
    for a in range(r):  # Uᵀ
        t = x[a]
        for b in range(a):
            t -= A[b, a] * x[b]
        x[a] = t / A[a, a]
    for a in range(r - 1, -1, -1):  # Lᵀ (unit)
        t = x[a]
        for b in range(a + 1, r):
            t -= A[b, a] * x[b]
        x[a] = t
    for k in range(r - 1, -1, -1):
        p = piv[k]
        if p != k:
            x[k], x[p] = x[p], x[k]


@nb.njit(cache=True)
def group_values(ae, g_sel, h_sel, pad, g_outer, h_outer, M, new_rows) -> bool:
    """Per group ``j``: ``M_j = A_h G⁻¹`` on ``g`` selected cancelled columns (``G``: the source
    rows there, square; ``A_h``: the subtracted rows), and the new rows
    ``M_j A[sources] - A[subtract]`` on the outer columns. ``g_sel`` ``(J, g, g)``, ``h_sel``
    ``(J, r, g)``, ``g_outer`` ``(J, g, o)``, ``h_outer`` ``(J, r, o)``: slots of the entries in
    ``ae`` (``-1``: zero); a padded source row (``pad``) gets a unit pivot. False on a
    breakdown (:func:`_lu`)."""
    J, g = g_sel.shape[0], g_sel.shape[1]
    r, o = h_sel.shape[1], g_outer.shape[2]
    A, Hs = np.empty((g, g)), np.empty((r, g))
    Go, Ho = np.empty((g, o)), np.empty((r, o))
    piv = np.empty(g, np.int64)
    for j in range(J):
        _gather(ae, g_sel[j], A)
        for a in range(g):
            if pad[j, a]:
                A[a, a] = 1.0
        if not _lu(A, piv):
            return False
        _gather(ae, h_sel[j], Hs)
        for i in range(r):
            _lu_solve_t(A, piv, Hs[i])
        M[j] = Hs
        _gather(ae, g_outer[j], Go)
        _gather(ae, h_outer[j], Ho)
        for i in range(r):
            for q in range(o):
                new_rows[j, i, q] = -Ho[i, q]
        for a in range(g):
            for q in range(o):
                v = Go[a, q]
                if v != 0.0:
                    for i in range(r):
                        new_rows[j, i, q] += Hs[i, a] * v
    return True


@nb.njit(cache=True)
def block_values(
    ae, new_rows, l_dst_a, l_src_a, l_dst_n, l_src_n, lbuf, shape, loff, eoff, cptr, cblk,
    ccol, fmap_off, fmap, rmap_off, rmap, lu, lu_off, piv, uoff, ebuf,
) -> bool:  # fmt: skip
    """Local rows ``L_b`` (scattered from ``ae`` and the groups' new rows), then per block in
    plan order ``E_b = L_b[:, dep]⁻¹ (L_b[:, free] + Σ_i (L_b[:, free_i] - L_b[:, dep_i] E_i))``
    over its reach ``R_b`` (own free columns first), coupled blocks ``i`` from
    ``cblk[cptr[b]:cptr[b+1]]`` (columns from ``ccol``, positions of their free columns and
    reach in ``R_b`` from ``fmap`` / ``rmap``). ``shape[b] = (r, w, |R_b|, f)``; LU factors of
    ``L_b[:, dep]`` kept in ``lu`` / ``piv`` (at ``lu_off`` / ``uoff``) for the solves. False
    on a breakdown."""
    lbuf[:] = 0.0
    for e in range(l_dst_a.shape[0]):
        lbuf[l_dst_a[e]] = ae[l_src_a[e]]
    flat_new = new_rows.reshape(-1)
    for e in range(l_dst_n.shape[0]):
        lbuf[l_dst_n[e]] = flat_new[l_src_n[e]]
    work = np.empty(np.max(shape[:, 0] * shape[:, 2]) if shape.shape[0] else 0)
    for b in range(shape.shape[0]):
        r, w, nr, f = shape[b, 0], shape[b, 1], shape[b, 2], shape[b, 3]
        L = lbuf[loff[b] : loff[b] + r * w].reshape(r, w)
        rhs = work[: r * nr].reshape(r, nr)
        rhs[:, :] = 0.0
        rhs[:, :f] = L[:, r : r + f]
        for k in range(cptr[b], cptr[b + 1]):
            i, co = cblk[k], ccol[k]
            ri, nri, fi = shape[i, 0], shape[i, 2], shape[i, 3]
            Ei = ebuf[eoff[i] : eoff[i] + ri * nri].reshape(ri, nri)
            fm = fmap[fmap_off[k] : fmap_off[k] + fi]
            rm = rmap[rmap_off[k] : rmap_off[k] + nri]
            for a in range(r):
                for q in range(fi):
                    rhs[a, fm[q]] += L[a, co + ri + q]
                for p in range(ri):
                    v = L[a, co + p]
                    if v != 0.0:
                        for q in range(nri):
                            rhs[a, rm[q]] -= v * Ei[p, q]
        A = lu[lu_off[b] : lu_off[b] + r * r].reshape(r, r)
        A[:, :] = L[:, :r]
        if not _lu(A, piv[uoff[b] : uoff[b] + r]):
            return False
        _lu_solve(A, piv[uoff[b] : uoff[b] + r], rhs)
        ebuf[eoff[b] : eoff[b] + r * nr] = rhs.reshape(-1)
    return True


@nb.njit(cache=True)
def spgemm(ap, ai, ax, bp, bi, bx, cp, ci, cx, work) -> None:
    """``C += A B`` into ``C``'s fixed CSR pattern, a superset of the product's (``work``: zeros
    of length ``B``'s columns, left zero)."""
    for i in range(ap.shape[0] - 1):
        for ka in range(ap[i], ap[i + 1]):
            k, a = ai[ka], ax[ka]
            for kb in range(bp[k], bp[k + 1]):
                work[bi[kb]] += a * bx[kb]
        for kc in range(cp[i], cp[i + 1]):
            cx[kc] += work[ci[kc]]
            work[ci[kc]] = 0.0


@nb.njit(cache=True)
def times_t(hx, row_seg, seg_ptr, seg_block, seg_e, seg_arg, ebuf, eoff, shape, reach_red,
            reach_ptr, wp, wi, wx, work) -> None:  # fmt: skip
    """``W = H T`` into ``W``'s fixed CSR pattern, ``T`` given by the blocks (identity on the
    kept columns, ``-E_b`` on block ``b``'s dependent rows over its reach): row by row, each
    segment of ``H``'s entries on one block's dependent columns is summed densely over the
    block's reach (contiguous rows of ``E_b``), then scattered once (segments from
    :meth:`~mbplan.solvers.reduction_symbolic.ReductionSymbolic._segments`; ``work``: zeros of
    length ``n_r``, left zero)."""
    acc = np.zeros(np.max(shape[:, 2]) if shape.shape[0] else 0)
    for i in range(row_seg.shape[0] - 1):
        for s in range(row_seg[i], row_seg[i + 1]):
            b = seg_block[s]
            if b < 0:
                for t in range(seg_ptr[s], seg_ptr[s + 1]):
                    work[seg_arg[t]] += hx[seg_e[t]]
                continue
            m = shape[b, 2]
            for q in range(m):
                acc[q] = 0.0
            for t in range(seg_ptr[s], seg_ptr[s + 1]):
                a, off = hx[seg_e[t]], eoff[b] + seg_arg[t] * m
                for q in range(m):
                    acc[q] -= a * ebuf[off + q]
            rc = reach_ptr[b]
            for q in range(m):
                work[reach_red[rc + q]] += acc[q]
        for kc in range(wp[i], wp[i + 1]):
            wx[kc] = work[wi[kc]]
            work[wi[kc]] = 0.0


@nb.njit(cache=True)
def lower_ends(ap, ai, bp, bi) -> np.ndarray:
    """Per entry ``(i, k)`` of ``A``: the end of row ``k`` of ``B`` (sorted column indices)
    within the lower triangle of row ``i`` of ``A B`` (symbolic, for :func:`spgemm_lower`)."""
    ends = np.empty(ai.shape[0], np.int64)
    for i in range(ap.shape[0] - 1):
        for ka in range(ap[i], ap[i + 1]):
            k = ai[ka]
            kb = bp[k]
            while kb < bp[k + 1] and bi[kb] <= i:
                kb += 1
            ends[ka] = kb
    return ends


@nb.njit(cache=True)
def spgemm_lower(ap, ai, ax, bp, bi, bx, ends, cp, ci, cx, work) -> None:
    """``C += tril(A B)`` into ``C``'s fixed lower CSR pattern (``ends`` from
    :func:`lower_ends`; :func:`spgemm`'s other conventions)."""
    for i in range(ap.shape[0] - 1):
        for ka in range(ap[i], ap[i + 1]):
            k, a = ai[ka], ax[ka]
            for kb in range(bp[k], ends[ka]):
                work[bi[kb]] += a * bx[kb]
        for kc in range(cp[i], cp[i + 1]):
            cx[kc] += work[ci[kc]]
            work[ci[kc]] = 0.0


@nb.njit(cache=True)
def fold_values(hf, slot, e, f, row, ai, sigma) -> None:
    """``H_f += A_Iᵀ diag(σ) A_I`` term by term: ``hf[slot] += σ[row] ai[e] ai[f]``."""
    for t in range(slot.shape[0]):
        hf[slot[t]] += sigma[row[t]] * ai[e[t]] * ai[f[t]]


@nb.njit(cache=True)
def csr_matvec(indptr, indices, data, x) -> np.ndarray:
    """``A x`` for CSR arrays (one pass, no scipy call overhead)."""
    y = np.zeros(indptr.shape[0] - 1)
    for i in range(y.shape[0]):
        t = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            t += data[e] * x[indices[e]]
        y[i] = t
    return y


@nb.njit(cache=True)
def rows_matvec(indptr, indices, data, rows, x) -> np.ndarray:
    """``(A x)[rows]`` for CSR arrays."""
    y = np.zeros(rows.shape[0])
    for k in range(rows.shape[0]):
        t = 0.0
        for e in range(indptr[rows[k]], indptr[rows[k] + 1]):
            t += data[e] * x[indices[e]]
        y[k] = t
    return y


@nb.njit(cache=True)
def rows_t_matvec(indptr, indices, data, rows, v, n) -> np.ndarray:
    """``A[rows]ᵀ v`` (length ``n``) for CSR arrays: for a symmetric ``A``, ``A[:, rows] v``."""
    y = np.zeros(n)
    for k in range(rows.shape[0]):
        vk = v[k]
        if vk != 0.0:
            for e in range(indptr[rows[k]], indptr[rows[k] + 1]):
                y[indices[e]] += data[e] * vk
    return y


@nb.njit(cache=True)
def kkt_matvec(hp, hi, hx, ep, ei, ex, ip, ii, ix, diag, x) -> np.ndarray:
    """``K x`` from its blocks: ``H`` (full symmetric CSR), ``A_E``, ``A_I`` (CSR) and the
    diagonal ``diag`` (module :mod:`mbplan.solvers.linear_solver`'s ``K``)."""
    n, me = hp.shape[0] - 1, ep.shape[0] - 1
    y = diag * x
    for i in range(n):
        t = 0.0
        for e in range(hp[i], hp[i + 1]):
            t += hx[e] * x[hi[e]]
        y[i] += t
    for off, p, idx, v in ((n, ep, ei, ex), (n + me, ip, ii, ix)):
        for r in range(p.shape[0] - 1):
            t, xr = 0.0, x[off + r]
            for e in range(p[r], p[r + 1]):
                t += v[e] * x[idx[e]]
                y[idx[e]] += v[e] * xr
            y[off + r] += t
    return y


@nb.njit(cache=True)
def b_solve(rhs, lbuf, shape, loff, cptr, cblk, ccol, lu, lu_off, piv, uoff) -> np.ndarray:
    """``B⁻¹ rhs``, ``B`` lower block triangular: per block ``L_b[:, dep]`` on the diagonal and
    ``L_b[:, dep_i]`` below (``rhs``, result: blocks' local rows / dependent columns at
    ``uoff``)."""
    x = rhs.copy()
    for b in range(shape.shape[0]):
        r, w = shape[b, 0], shape[b, 1]
        L = lbuf[loff[b] : loff[b] + r * w].reshape(r, w)
        xb = x[uoff[b] : uoff[b] + r].reshape(r, 1)
        for k in range(cptr[b], cptr[b + 1]):
            i, co = cblk[k], ccol[k]
            ri = shape[i, 0]
            xi = x[uoff[i] : uoff[i] + ri]
            for a in range(r):
                t = 0.0
                for q in range(ri):
                    t += L[a, co + q] * xi[q]
                xb[a, 0] -= t
        A = lu[lu_off[b] : lu_off[b] + r * r].reshape(r, r)
        _lu_solve(A, piv[uoff[b] : uoff[b] + r], xb)
    return x


@nb.njit(cache=True)
def bt_solve(rhs, lbuf, shape, loff, cptr, cblk, ccol, lu, lu_off, piv, uoff) -> np.ndarray:
    """``B⁻ᵀ rhs`` (:func:`b_solve`'s ``B``), blocks in reverse order."""
    x = rhs.copy()
    for b in range(shape.shape[0] - 1, -1, -1):
        r, w = shape[b, 0], shape[b, 1]
        xb = x[uoff[b] : uoff[b] + r]
        A = lu[lu_off[b] : lu_off[b] + r * r].reshape(r, r)
        _lu_solve_t(A, piv[uoff[b] : uoff[b] + r], xb)
        L = lbuf[loff[b] : loff[b] + r * w].reshape(r, w)
        for k in range(cptr[b], cptr[b + 1]):
            i, co = cblk[k], ccol[k]
            ri = shape[i, 0]
            for q in range(ri):
                t = 0.0
                for a in range(r):
                    t += L[a, co + q] * xb[a]
                x[uoff[i] + q] -= t
    return x


@nb.njit(cache=True)
def s_apply(b, tgt, src, sub, M, transpose: bool) -> np.ndarray:
    """``S b`` (row ``tgt[j, i]`` becomes ``Σ_g M[j, i, g] b[src[j, g]] - b[sub[j, i]]``) or
    ``Sᵀ b``."""
    out = b.copy()
    J, r, g = M.shape
    if not transpose:
        for j in range(J):
            for i in range(r):
                t = -b[sub[j, i]]
                for q in range(g):
                    if src[j, q] >= 0:
                        t += M[j, i, q] * b[src[j, q]]
                out[tgt[j, i]] = t
        return out
    for j in range(J):
        for i in range(r):
            out[tgt[j, i]] -= b[tgt[j, i]]
    for j in range(J):
        for i in range(r):
            v = b[tgt[j, i]]
            out[sub[j, i]] -= v
            for q in range(g):
                if src[j, q] >= 0:
                    out[src[j, q]] += M[j, i, q] * v
    return out


REDUCED_KERNELS = (
    group_values,
    block_values,
    spgemm,
    spgemm_lower,
    times_t,
    lower_ends,
    fold_values,
    csr_matvec,
    rows_matvec,
    rows_t_matvec,
    kkt_matvec,
    b_solve,
    bt_solve,
    s_apply,
)
