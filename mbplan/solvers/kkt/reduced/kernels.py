"""Compiled kernels of :class:`~mbplan.solvers.kkt.reduced.system.ReducedKKTSystem`'s values: the row
groups' combinations ``M_j``, the blocks' null-space coefficients ``E`` (small dense LU with
partial pivoting, block by block in plan order) and the solves with the eliminated pairs'
block-triangular ``B`` (:mod:`mbplan.solvers.kkt.elimination`). Every entry kernel borrows its
arguments (:mod:`mbplan.solvers.kkt.borrow`: no reference counting of the per-block views);
inner loops are zero-based over contiguous rows, so that they vectorize."""

from __future__ import annotations

import numba as nb

from mbplan.solvers.kkt.borrow import borrowed

PIVOT_TOL = 1e-12
"""A block's or a group's LU breaks down on a pivot below this times the
block's largest entry: the caller then picks the replaced rows and dependent columns again on
these values (:meth:`~mbplan.solvers.kkt.reduced.system.ReducedKKTSystem._set_values`), else
factorizes the full matrix."""

U64 = nb.uint64  # unsigned flat indices: no negative-index wraparound code in the loops
_FAST = {"cache": True, "fastmath": {"contract", "reassoc"}, "error_model": "numpy"}


@nb.njit(**_FAST)
def _lu(A, piv, end) -> bool:
    """In-place LU with partial pivoting (``piv``: row swaps) of a block upper triangular ``A``
    (``end[k]``: the end of column ``k``'s diagonal block, below it zeros: the pivot is searched
    and rows are eliminated within it); False on a pivot below :data:`PIVOT_TOL` times the
    largest entry."""
    r = A.shape[0]
    flat = A.reshape(-1)
    s0 = s1 = s2 = s3 = 0.0  # four chains: the maximum has no reassociation
    n4 = r * r - r * r % 4
    for t in range(0, n4, 4):
        s0, s1 = max(s0, abs(flat[t])), max(s1, abs(flat[t + 1]))
        s2, s3 = max(s2, abs(flat[t + 2])), max(s3, abs(flat[t + 3]))
    for t in range(n4, r * r):
        s0 = max(s0, abs(flat[t]))
    scale = max(max(s0, s1), max(s2, s3))
    for k in range(r):
        p, e = k, end[k]
        for a in range(k + 1, e):
            if abs(A[a, k]) > abs(A[p, k]):
                p = a
        if not abs(A[p, k]) > PIVOT_TOL * scale:
            return False
        piv[k] = p
        if p != k:
            for b in range(r):
                A[k, b], A[p, b] = A[p, b], A[k, b]
        ak = A[k, k + 1 :]
        for a in range(k + 1, e):
            if A[a, k] != 0.0:  # the blocks are sparse: skip the zero multipliers
                A[a, k] /= A[k, k]
                f, aa = A[a, k], A[a, k + 1 :]
                for b in range(r - k - 1):
                    aa[b] -= f * ak[b]
    return True


@nb.njit(**_FAST)
def _lu_solve(A, piv, X, begin) -> None:
    """``X ← A⁻¹ X`` with the factors of :func:`_lu` (``X``: ``(r, q)``; ``begin[a]``: the
    beginning of row ``a``'s diagonal block, where ``L`` lives), row by row: contiguous
    updates over the columns, ``U``'s zero factors skipped."""
    r, q = A.shape[0], X.shape[1]
    for k in range(r):
        p = piv[k]
        if p != k:
            for c in range(q):
                X[k, c], X[p, c] = X[p, c], X[k, c]
    for a in range(r):
        xa = X[a]
        for b in range(begin[a], a):
            f, xb = A[a, b], X[b]
            for c in range(q):
                xa[c] -= f * xb[c]
    for a in range(r - 1, -1, -1):
        xa = X[a]
        for b in range(a + 1, r):
            f = A[a, b]
            if f != 0.0:
                xb = X[b]
                for c in range(q):
                    xa[c] -= f * xb[c]
        inv = 1.0 / A[a, a]
        for c in range(q):
            xa[c] *= inv


@nb.njit(**_FAST)
def _lu_solve_t_rows(A, piv, X, begin) -> None:
    """``X ← A⁻ᵀ X`` with the factors of :func:`_lu` (``X``: ``(r, q)``, few columns; ``begin``
    as in :func:`_lu_solve`), row by row without branches."""
    r, q = A.shape[0], X.shape[1]
    for a in range(r):  # Uᵀ
        xa, ua = X[a], A[a]
        inv = 1.0 / ua[a]
        for c in range(q):
            xa[c] *= inv
        for b in range(a + 1, r):
            f, xb = ua[b], X[b]
            for c in range(q):
                xb[c] -= f * xa[c]
    for a in range(r - 1, -1, -1):  # Lᵀ (unit), inside the diagonal block
        xa, la = X[a], A[a]
        for b in range(begin[a], a):
            f, xb = la[b], X[b]
            for c in range(q):
                xb[c] -= f * xa[c]
    for k in range(r - 1, -1, -1):
        p = piv[k]
        if p != k:
            for c in range(q):
                X[k, c], X[p, c] = X[p, c], X[k, c]


@nb.njit(**_FAST)
def _gather(data, slot, out) -> None:
    """``out = data[slot]`` (``0`` where ``slot < 0``), 2-D."""
    for a in range(slot.shape[0]):
        sa, oa = slot[a], out[a]
        for q in range(slot.shape[1]):
            s = sa[q]
            oa[q] = data[U64(s)] if s >= 0 else 0.0


@nb.njit(**_FAST)
def group_values(ae, g_sel, h_sel, pad, g_begin, g_end, g_outer, h_outer, M, new_rows, A, X,
                 piv) -> bool:  # fmt: skip
    """Per group ``j``: ``M_j = A_h G⁻¹`` on ``g`` selected cancelled columns (``G``: the source
    rows there, square; ``A_h``: the subtracted rows), and the new rows
    ``M_j A[sources] - A[subtract]`` on the outer columns. ``g_sel`` ``(J, g, g)``, ``h_sel``
    ``(J, r, g)``, ``g_outer`` ``(J, g, o)``, ``h_outer`` ``(J, r, o)``: slots of the entries in
    ``ae`` (``-1``: zero); a padded source row (``pad``) gets a unit pivot; ``g_begin``,
    ``g_end``: the diagonal blocks of the sources and columns in block triangular order
    (:func:`_lu`). ``A``
    ``(g, g)``, ``X`` ``(g, r)``, ``piv``: scratch. False on a breakdown."""
    ae, g_sel, h_sel, pad = borrowed(ae), borrowed(g_sel), borrowed(h_sel), borrowed(pad)
    g_outer, h_outer, M, new_rows = borrowed(g_outer), borrowed(h_outer), borrowed(M), borrowed(new_rows)  # fmt: skip
    g_begin, g_end, A, X, piv = borrowed(g_begin), borrowed(g_end), borrowed(A), borrowed(X), borrowed(piv)  # fmt: skip
    J, g = g_sel.shape[0], g_sel.shape[1]
    r, o = h_sel.shape[1], g_outer.shape[2]
    for j in range(J):
        _gather(ae, g_sel[j], A)
        for a in range(g):
            if pad[j, a]:
                A[a, a] = 1.0
        if not _lu(A, piv, g_end[j]):
            return False
        Mj, nr, hs, go = M[j], new_rows[j], h_sel[j], g_outer[j]
        for a in range(g):  # Mⱼᵀ = G⁻ᵀ A_hᵀ
            xa = X[a]
            for i in range(r):
                s = hs[i, a]
                xa[i] = ae[U64(s)] if s >= 0 else 0.0
        _lu_solve_t_rows(A, piv, X, g_begin[j])
        for i in range(r):
            for a in range(g):
                Mj[i, a] = X[a, i]
        _gather(ae, h_outer[j], nr)
        for i in range(r):
            ni = nr[i]
            for q in range(o):
                ni[q] = -ni[q]
        for a in range(g):
            xa = X[a]
            for q in range(o):
                s = go[a, q]
                if s >= 0:
                    v = ae[U64(s)]
                    for i in range(r):
                        nr[i, q] += xa[i] * v
    return True


@nb.njit(**_FAST)
def block_values(
    ae, new_rows, la_src, ln_src, lval, shape, eoff, lu_off, uoff, lu_begin, lu_end, a_ptr, a_src, a_dst, fe_ptr,
    fe_src, fe_dst, cptr, cblk, nz_ptr, nz_a, nz_p, nz_src, rmap_off, rmap, lu, piv, dinv, ebuf,
    tmp,
) -> bool:  # fmt: skip
    """The local rows' entries ``lval`` (from ``ae`` and the groups' new rows), then per block in
    plan order ``E_b = L_b[:, dep]⁻¹ (L_b[:, free] - Σ_i L_b[:, dep_i] E_i)`` over its sorted
    reach (the free columns, own and coupled, at their reach positions), the coupled blocks
    ``i = cblk[k]`` by their entries ``nz_*[nz_ptr[k]:nz_ptr[k+1]]`` (row, dependent column,
    value), summed densely over ``i``'s reach and scattered by ``rmap`` (index arrays:
    :meth:`~mbplan.solvers.kkt.reduced.symbolic.ReductionSymbolic._block_entries`). LU factors of
    ``L_b[:, dep]`` (its local rows and dependent columns in block triangular order, the
    diagonal blocks' ends in ``lu_end``) in ``lu`` / ``piv`` (at ``lu_off`` / ``uoff``) and the reciprocals of ``U``'s
    diagonal in ``dinv`` for the solves; ``tmp``: scratch of the largest reach. False on a
    breakdown."""
    ae, new_rows, la_src, ln_src = borrowed(ae), borrowed(new_rows), borrowed(la_src), borrowed(ln_src)  # fmt: skip
    lval, shape, eoff, lu_off = borrowed(lval), borrowed(shape), borrowed(eoff), borrowed(lu_off)
    uoff, a_ptr, a_src, a_dst = borrowed(uoff), borrowed(a_ptr), borrowed(a_src), borrowed(a_dst)
    lu_begin, lu_end = borrowed(lu_begin), borrowed(lu_end)
    fe_ptr, fe_src, fe_dst, cptr = borrowed(fe_ptr), borrowed(fe_src), borrowed(fe_dst), borrowed(cptr)  # fmt: skip
    cblk, nz_ptr, nz_a, nz_p = borrowed(cblk), borrowed(nz_ptr), borrowed(nz_a), borrowed(nz_p)
    nz_src, rmap_off, rmap = borrowed(nz_src), borrowed(rmap_off), borrowed(rmap)
    lu, piv, dinv = borrowed(lu), borrowed(piv), borrowed(dinv)
    ebuf, tmp = borrowed(ebuf), borrowed(tmp)
    na = la_src.shape[0]
    for t in range(na):
        lval[t] = ae[U64(la_src[t])]
    flat_new = new_rows.reshape(-1)
    for t in range(ln_src.shape[0]):
        lval[U64(na + t)] = flat_new[U64(ln_src[t])]
    for b in range(shape.shape[0]):
        r, m = shape[b, 0], shape[b, 1]
        eo = eoff[b]
        for q in range(r * m):
            ebuf[U64(eo + q)] = 0.0
        for t in range(fe_ptr[b], fe_ptr[b + 1]):
            ebuf[U64(fe_dst[t])] += lval[U64(fe_src[t])]
        for k in range(cptr[b], cptr[b + 1]):
            i = cblk[k]
            mi, ei = shape[i, 1], eoff[i]
            rm = rmap[U64(rmap_off[k]) :]
            t, t1 = nz_ptr[k], nz_ptr[k + 1]
            while t < t1:
                a = nz_a[t]
                for q in range(mi):
                    tmp[q] = 0.0
                while t < t1 and nz_a[t] == a:
                    v, ep = lval[U64(nz_src[t])], ebuf[U64(ei + nz_p[t] * mi) :]
                    for q in range(mi):
                        tmp[q] += v * ep[q]
                    t += 1
                ra = ebuf[U64(eo + a * m) :]
                for q in range(mi):
                    ra[U64(rm[q])] -= tmp[q]
        lo = lu_off[b]
        for q in range(r * r):
            lu[U64(lo + q)] = 0.0
        for t in range(a_ptr[b], a_ptr[b + 1]):
            lu[U64(a_dst[t])] = lval[U64(a_src[t])]
        A = lu[lo : lo + r * r].reshape(r, r)
        pb = piv[uoff[b] : uoff[b] + r]
        if not _lu(A, pb, lu_end[uoff[b] : uoff[b] + r]):
            return False
        _lu_solve(A, pb, ebuf[eo : eo + r * m].reshape(r, m), lu_begin[uoff[b] : uoff[b] + r])
        for a in range(r):
            dinv[U64(uoff[b] + a)] = 1.0 / A[a, a]
    return True


@nb.njit(**_FAST)
def b_solve(x, lval, shape, uoff, bc_ptr, bc_row, bc_col, bc_val, lu, lu_off, piv, dinv,
            lu_begin) -> None:  # fmt: skip
    """``x ← B⁻¹ x``, ``B`` lower block triangular (``x``: blocks' local rows / dependent
    columns at ``uoff``): per block its entries below the diagonal by row (``bc_*`` at
    ``bc_ptr[b]``: row, column and value in ``lval``), then ``L_b[:, dep]⁻¹`` (its LU factors,
    ``dinv``: the reciprocals of ``U``'s diagonal, ``L`` inside the diagonal blocks from
    ``lu_begin``)."""
    x, lval, shape, uoff, bc_ptr = borrowed(x), borrowed(lval), borrowed(shape), borrowed(uoff), borrowed(bc_ptr)  # fmt: skip
    bc_row, bc_col, bc_val, lu = borrowed(bc_row), borrowed(bc_col), borrowed(bc_val), borrowed(lu)
    lu_off, piv, dinv, lu_begin = borrowed(lu_off), borrowed(piv), borrowed(dinv), borrowed(lu_begin)  # fmt: skip
    for b in range(shape.shape[0]):
        r, ub = shape[b, 0], uoff[b]
        t, t1 = bc_ptr[b], bc_ptr[b + 1]
        while t < t1:
            row = U64(bc_row[t])
            acc = x[row]
            while t < t1 and bc_row[t] == row:
                acc -= lval[U64(bc_val[t])] * x[U64(bc_col[t])]
                t += 1
            x[row] = acc
        A, xb, pb = lu[U64(lu_off[b]) :], x[U64(ub) :], piv[U64(ub) :]
        for k in range(r):
            p = pb[k]
            if p != k:
                xb[k], xb[p] = xb[p], xb[k]
        lb = lu_begin[U64(ub) :]
        for a in range(1, r):
            la, t = A[U64(a * r) :], xb[a]
            for c in range(lb[a], a):
                t -= la[c] * xb[c]
            xb[a] = t
        for a in range(r - 1, -1, -1):
            ua, t = A[U64(a * r) :], xb[a]
            for c in range(a + 1, r):
                t -= ua[c] * xb[c]
            xb[a] = t * dinv[U64(ub + a)]


@nb.njit(**_FAST)
def bt_solve(x, lval, shape, uoff, bc_ptr, bt_row, bt_col, bt_val, lu, lu_off, piv, dinv,
             lu_end) -> None:  # fmt: skip
    """``x ← B⁻ᵀ x`` (:func:`b_solve`'s ``B``, its entries by column), blocks in reverse
    order."""
    x, lval, shape, uoff, bc_ptr = borrowed(x), borrowed(lval), borrowed(shape), borrowed(uoff), borrowed(bc_ptr)  # fmt: skip
    bt_row, bt_col, bt_val, lu = borrowed(bt_row), borrowed(bt_col), borrowed(bt_val), borrowed(lu)
    lu_off, piv, dinv, lu_end = borrowed(lu_off), borrowed(piv), borrowed(dinv), borrowed(lu_end)
    for b in range(shape.shape[0] - 1, -1, -1):
        r, ub = shape[b, 0], uoff[b]
        A, xb, pb = lu[U64(lu_off[b]) :], x[U64(ub) :], piv[U64(ub) :]
        for a in range(r):  # Uᵀ
            t = xb[a]
            for c in range(a):
                t -= A[U64(c * r + a)] * xb[c]
            xb[a] = t * dinv[U64(ub + a)]
        le = lu_end[U64(ub) :]
        for a in range(r - 2, -1, -1):  # Lᵀ (unit), inside the diagonal block
            t = xb[a]
            for c in range(a + 1, le[a]):
                t -= A[U64(c * r + a)] * xb[c]
            xb[a] = t
        for k in range(r - 1, -1, -1):
            p = pb[k]
            if p != k:
                xb[k], xb[p] = xb[p], xb[k]
        t, t1 = bc_ptr[b], bc_ptr[b + 1]
        while t < t1:
            col = U64(bt_col[t])
            acc = x[col]
            while t < t1 and bt_col[t] == col:
                acc -= lval[U64(bt_val[t])] * x[U64(bt_row[t])]
                t += 1
            x[col] = acc


@nb.njit(**_FAST)
def copy_values(hess, hl, hl_src, hd, hd_src, ae, ak, ak_src, ebuf) -> bool:
    """``hl = hess[hl_src]`` (``H``'s strictly lower part), ``hd = hess[hd_src]`` (its
    diagonal, ``-1``: zero), ``ak = ae[ak_src]`` (``A_E``'s kept rows); whether ``E``
    (``ebuf``) is finite."""
    hess, hl, hl_src, hd = borrowed(hess), borrowed(hl), borrowed(hl_src), borrowed(hd)
    hd_src, ae, ak, ak_src, ebuf = borrowed(hd_src), borrowed(ae), borrowed(ak), borrowed(ak_src), borrowed(ebuf)  # fmt: skip
    for t in range(hl_src.shape[0]):
        hl[t] = hess[U64(hl_src[t])]
    for i in range(hd_src.shape[0]):
        s = hd_src[i]
        hd[i] = hess[U64(s)] if s >= 0 else 0.0
    for t in range(ak_src.shape[0]):
        ak[t] = ae[U64(ak_src[t])]
    z = 0.0
    for e in range(ebuf.shape[0]):
        z += ebuf[e] * 0.0
    return z == 0.0


@nb.njit(cache=True)
def sigma_of(diagonal, n, me, y_rows, sigma, sigma_used) -> int:
    """``Σ = -D_I⁻¹`` into ``sigma`` from ``K``'s ``diagonal``: ``-1`` if a local row's diagonal
    is nonzero or ``D_I`` is not negative (the reduction does not apply), else ``1`` if ``Σ``
    differs from ``sigma_used``, ``0`` if not."""
    for k in range(y_rows.shape[0]):
        if diagonal[n + y_rows[k]] != 0.0:
            return -1
    changed = 0
    for r in range(sigma.shape[0]):
        d = diagonal[n + me + r]
        if not d < 0.0:
            return -1
        sigma[r] = -1.0 / d
        if sigma[r] != sigma_used[r]:
            changed = 1
    return changed
