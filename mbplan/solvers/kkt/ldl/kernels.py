"""Numeric kernels of the supernodal LDLᵀ (:mod:`mbplan.solvers.kkt.system`): the multifrontal
factorization (counting the pivot signs), unpivoted or with threshold pivoting inside each
supernode (:mod:`mbplan.solvers.kkt.ldl.pivot`), compiled with numba: the loop over the fronts,
the small fronts' flat kernels and the direct updates of small leaves
(:mod:`mbplan.solvers.kkt.ldl.layout`); the large fronts' dense kernels are in
:mod:`mbplan.solvers.kkt.ldl.dense`, the solves in :mod:`mbplan.solvers.kkt.ldl.solve`; storage as
described in :mod:`mbplan.solvers.kkt.ldl.symbolic`. Every kernel works on borrowed arrays
(:mod:`mbplan.solvers.kkt.borrow`) and flat indices cast to unsigned (no wraparound code).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from mbplan.solvers.kkt.borrow import borrowed
from mbplan.solvers.kkt.ldl.dense import _WIDE, _front_columns, _scale_checked, _schur  # noqa: F401
from mbplan.solvers.kkt.ldl.pivot import pivoted_front, rotate_pairs

U64 = nb.uint64  # unsigned flat indices: no negative-index wraparound code in the loops
SMALL_COLUMNS = 4  # supernodes with at most this many columns are solved without a gathered copy


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
    :func:`~mbplan.solvers.kkt.ldl.pivot.pivoted_front`: 1 × 1 / 2 × 2 pivots among its own columns
    (``piv``: local order, ``e``: 2 × 2 off-diagonals, ``spiv[s]``: supernode s pivoted), tiny
    pivots perturbed to ``sign · delta`` (``sign``: expected pivot signs, pivot order). ``stats``: pivoted fronts, 2 × 2 pivots, perturbed pivots,
    pivots accepted below the threshold. A leaf front flagged ``direct`` (parent ``sparent``)
    subtracts its Schur update from its parent's front itself (``sent``: it did). Returns the
    numbers of positive, negative and perturbed pivots and ``False`` on a breakdown."""
    vals, amap, sfirst, fptr, loff = borrowed(vals), borrowed(amap), borrowed(sfirst), borrowed(fptr), borrowed(loff)  # fmt: skip
    uoff, zero_at, rptr, rel = borrowed(uoff), borrowed(zero_at), borrowed(rptr), borrowed(rel)
    cptr, child, sparent, direct = borrowed(cptr), borrowed(child), borrowed(sparent), borrowed(direct)  # fmt: skip
    sent, lbuf, ubuf, d, sign = borrowed(sent), borrowed(lbuf), borrowed(ubuf), borrowed(d), borrowed(sign)  # fmt: skip
    piv, e, spiv, eptr = borrowed(piv), borrowed(e), borrowed(spiv), borrowed(eptr)
    eidx, save, stats = borrowed(eidx), borrowed(save), borrowed(stats)
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
