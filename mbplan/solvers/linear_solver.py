"""The reduced KKT matrix of the RIPM and its inertia-revealing sparse LDLᵀ factorization.

Eliminating ``ds`` from the Newton system (53) (see :mod:`mbplan.solvers.ripm`) leaves the
symmetric quasi-definite-shaped matrix, unknowns ordered ``(dx, dy, dz)``::

    K = [[H + D_x,  A_Eᵀ,  A_Iᵀ],
         [A_E,      D_y,   0   ],
         [A_I,      0,     D_z ]]

with diagonal blocks ``D_*`` chosen by the caller (``δ_w I``, ``-δ_c I``, ``-(Σ⁻¹ + δ_c I)``).
The pattern (the union of ``H``'s lower triangle, the Jacobians and the full diagonal) is built
once by index arrays; each new matrix with the same pattern is a scatter of its values.

The factorization is a supernodal multifrontal ``P K Pᵀ = (I + L) D (I + L)ᵀ`` with a diagonal
``D`` and no pivoting, compiled with numba. Its symbolic analysis takes the approximate minimum
degree ordering qdldl computes (SuiteSparse AMD), postorders the elimination tree, groups
columns into fundamental supernodes merged by CHOLMOD's relaxed amalgamation rule, and
precomputes where every entry of ``K`` and every child's update matrix lands; it is memoized per
process for the last few patterns (the KKT systems of one task family share theirs). The numeric
factorization works on small dense fronts with register-blocked loops: on trajectory-optimization
KKT matrices, whose elimination ends in a chain of dense knot-to-knot blocks, it is about twice
as fast as qdldl's column-by-column up-looking LDLᵀ with the same ordering, and it counts the
pivot signs as it goes (qdldl's Python binding returns ``D`` only with a copy of ``L``).
Compiled kernels are cached on disk by numba; the first use in a fresh environment compiles
them (seconds).

By Sylvester's law of inertia the signs of ``D`` are the inertia of ``K``. Without pivoting the
factorization breaks down on a zero pivot, which a structurally zero diagonal (a variable
entering the Lagrangian linearly, an equality row) produces whenever the ordering eliminates it
first. A tiny static regularization (``+ε`` on the primal, ``-ε`` on the dual diagonal, as in
QDLDL-based solvers such as OSQP and Clarabel) avoids that; every solve is then followed by
iterative refinement against the unregularized matrix, and a residual that refinement cannot
reduce is reported to the caller, who treats the matrix as singular (IPOPT's
``PDFullSpaceSolver``). The regularization does not change the inertia of a nonsingular matrix
whose smallest eigenvalue magnitude exceeds ``ε``.
"""

from __future__ import annotations

import itertools
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numba as nb
import numpy as np
import scipy.sparse as sp

from mbplan.engine.jit import announce_uncached_numba, numba_cached
from mbplan.errors import InputError
from mbplan.solvers.ordering import amd_order, nested_dissection_order


@dataclass(frozen=True)
class Inertia:
    """Numbers of positive, negative and zero pivots of the LDLᵀ factorization."""

    positive: int
    negative: int
    zero: int


def _csr(a: sp.spmatrix | sp.sparray | None, shape: tuple[int, int]) -> sp.csr_matrix:
    if a is None:
        return sp.csr_matrix(shape)
    if type(a) is sp.csr_matrix and a.shape == shape and a.has_canonical_format:
        return a  # read only: no copy needed
    out = sp.csr_matrix(a)
    if out.shape != shape:
        raise InputError(f"KKT block has shape {out.shape}, expected {shape}")
    if not out.has_canonical_format:
        out = out.copy()
        out.sum_duplicates()
    return out


def _same_pattern(a: sp.csr_matrix, b: sp.csr_matrix | None) -> bool:
    return (
        b is not None
        and a.shape == b.shape
        and a.nnz == b.nnz
        and np.array_equal(a.indptr, b.indptr)
        and np.array_equal(a.indices, b.indices)
    )


# ---------------------------------------------------------------------------- symbolic analysis
# Index conventions: ``perm[i]`` is the original index of the i-th pivot, the permuted pattern is
# held as "upper CSC" (column k lists the rows i <= k of the lower triangle's row k), and L is
# stored by supernodes: supernode s owns the pivot columns sfirst[s] .. sfirst[s+1]-1 and the
# front rows rows[fptr[s]:fptr[s+1]] (its own columns, then the rows below, increasing); its
# k x m block of L starts at lbuf[loff[s]], front column t at offset t*m.


@nb.njit(cache=True)
def _upper_csc(n, pinv, rows, cols):
    """The permuted pattern as upper CSC; ``hi``/``lo`` are each entry's permuted row/column."""
    ne = rows.shape[0]
    hi = np.empty(ne, np.int64)
    lo = np.empty(ne, np.int64)
    ptr = np.zeros(n + 1, np.int64)
    for e in range(ne):
        a, b = pinv[rows[e]], pinv[cols[e]]
        hi[e], lo[e] = max(a, b), min(a, b)
        ptr[hi[e] + 1] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    idx = np.empty(ne, np.int64)
    fill = ptr[:n].copy()
    for e in range(ne):
        idx[fill[hi[e]]] = lo[e]
        fill[hi[e]] += 1
    return ptr, idx, hi, lo


@nb.njit(cache=True)
def _etree(n, ptr, idx):
    """Elimination tree (Liu's algorithm with path compression); -1 marks a root."""
    parent = np.full(n, -1, np.int64)
    ancestor = np.full(n, -1, np.int64)
    for k in range(n):
        for q in range(ptr[k], ptr[k + 1]):
            i = idx[q]
            while i != -1 and i < k:
                nxt = ancestor[i]
                ancestor[i] = k
                if nxt == -1:
                    parent[i] = k
                i = nxt
    return parent


@nb.njit(cache=True)
def _postorder(n, parent):
    head = np.full(n, -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    for j in range(n - 1, -1, -1):
        if parent[j] != -1:
            nxt[j] = head[parent[j]]
            head[parent[j]] = j
    post = np.empty(n, np.int64)
    stack = np.empty(n, np.int64)
    k = 0
    for root in range(n):
        if parent[root] != -1:
            continue
        top = 0
        stack[0] = root
        while top >= 0:
            p = stack[top]
            c = head[p]
            if c == -1:
                top -= 1
                post[k] = p
                k += 1
            else:
                head[p] = nxt[c]
                top += 1
                stack[top] = c
    return post


@nb.njit(cache=True)
def _supernodes(n, ptr, idx, parent):
    """Fundamental supernodes (column j+1 joins j's when it is j's parent and L's column j is
    ``{j+1} ∪`` column j+1), then relaxed amalgamation of a supernode into its parent when they
    are adjacent (CHOLMOD's default rule: few columns, or few explicit zeros added)."""
    cc = np.zeros(n, np.int64)  # strictly-lower column counts of L (row-subtree traversal)
    mark = np.full(n, -1, np.int64)
    for k in range(n):
        mark[k] = k
        for q in range(ptr[k], ptr[k + 1]):
            i = idx[q]
            while i < k and mark[i] != k:
                cc[i] += 1
                mark[i] = k
                i = parent[i]
    fund = np.ones(n + 1, np.bool_)
    for j in range(n - 1):
        if parent[j] == j + 1 and cc[j] == cc[j + 1] + 1:
            fund[j + 1] = False
    first = np.flatnonzero(fund)
    ns = first.shape[0] - 1
    snode = np.empty(n, np.int64)
    for s in range(ns):
        snode[first[s] : first[s + 1]] = s
    gfirst = first[:ns].copy()  # first column of the group whose top supernode is s
    gnnz = np.zeros(ns)  # nonzeros of L in that group
    for j in range(n):
        gnnz[snode[j]] += cc[j] + 1
    keep = np.ones(ns + 1, np.bool_)
    for s in range(ns - 1):
        last = first[s + 1] - 1
        if parent[last] == -1 or snode[parent[last]] != s + 1:
            continue
        k = first[s + 2] - gfirst[s]
        r = cc[first[s + 2] - 1]
        dense = k * (k + 1) / 2.0 + k * r
        z = (dense - gnnz[s] - gnnz[s + 1]) / dense
        if k <= 4 or (k <= 16 and z < 0.8) or (k <= 48 and z < 0.1) or z < 0.05:
            keep[s] = False
            gfirst[s + 1] = gfirst[s]
            gnnz[s + 1] += gnnz[s]
    out = np.empty(int(keep.sum()), np.int64)
    out[:-1] = gfirst[keep[:ns]]
    out[-1] = n
    return out, int(cc.sum())


@nb.njit(cache=True)
def _front_rows(n, ptr, idx, parent, sfirst):
    """Front row lists and the supernodal elimination tree."""
    ns = sfirst.shape[0] - 1
    snode = np.empty(n, np.int64)
    for s in range(ns):
        snode[sfirst[s] : sfirst[s + 1]] = s
    fptr = np.zeros(ns + 1, np.int64)
    for s in range(ns):
        fptr[s + 1] = sfirst[s + 1] - sfirst[s]
    rows = np.empty(0, np.int64)
    fill = np.empty(ns, np.int64)
    for sweep in range(2):  # count the rows below each supernode, then store them
        if sweep == 1:
            for s in range(ns):
                fptr[s + 1] += fptr[s]
            rows = np.empty(fptr[ns], np.int64)
            for s in range(ns):
                k = sfirst[s + 1] - sfirst[s]
                rows[fptr[s] : fptr[s] + k] = np.arange(sfirst[s], sfirst[s + 1])
                fill[s] = fptr[s] + k
        smark = np.full(ns, -1, np.int64)
        mark = np.full(n, -1, np.int64)
        for k in range(n):  # row k of L: the etree paths from A's row k (row-subtree)
            mark[k] = k
            sk = snode[k]
            for q in range(ptr[k], ptr[k + 1]):
                i = idx[q]
                while i < k and mark[i] != k:
                    mark[i] = k
                    s = snode[i]
                    if s != sk and smark[s] != k:
                        smark[s] = k
                        if sweep == 0:
                            fptr[s + 1] += 1
                        else:
                            rows[fill[s]] = k
                            fill[s] += 1
                    i = parent[i]
    sparent = np.full(ns, -1, np.int64)
    for s in range(ns):
        k = sfirst[s + 1] - sfirst[s]
        if fptr[s + 1] - fptr[s] > k:
            sparent[s] = snode[rows[fptr[s] + k]]
    return fptr, rows, sparent, snode


@nb.njit(cache=True)
def _assembly_maps(n, sfirst, fptr, rows, sparent, snode, hi, lo):
    """Storage offsets, where each entry of K lands in L's storage, the children of each
    supernode and the positions of a child's update rows in its parent's front."""
    ns = sfirst.shape[0] - 1
    loff = np.zeros(ns + 1, np.int64)
    uoff = np.zeros(ns + 1, np.int64)
    rptr = np.zeros(ns + 1, np.int64)
    for s in range(ns):
        k = sfirst[s + 1] - sfirst[s]
        m = fptr[s + 1] - fptr[s]
        loff[s + 1] = loff[s] + k * m
        uoff[s + 1] = uoff[s] + (m - k) * (m - k)
        rptr[s + 1] = rptr[s] + m - k
    pos = np.full(n, -1, np.int64)
    amap = np.empty(hi.shape[0], np.int64)
    order = np.argsort(snode[lo], kind="mergesort")
    cur = -1
    for e in order:
        s = snode[lo[e]]
        if s != cur:
            for q in range(fptr[s], fptr[s + 1]):
                pos[rows[q]] = q - fptr[s]
            cur = s
        amap[e] = loff[s] + (lo[e] - sfirst[s]) * (fptr[s + 1] - fptr[s]) + pos[hi[e]]
    cptr = np.zeros(ns + 1, np.int64)
    for s in range(ns):
        if sparent[s] != -1:
            cptr[sparent[s] + 1] += 1
    for s in range(ns):
        cptr[s + 1] += cptr[s]
    child = np.empty(cptr[ns], np.int64)
    cfill = cptr[:ns].copy()
    for s in range(ns):
        if sparent[s] != -1:
            child[cfill[sparent[s]]] = s
            cfill[sparent[s]] += 1
    rel = np.empty(rptr[ns], np.int64)
    for p in range(ns):
        for q in range(fptr[p], fptr[p + 1]):
            pos[rows[q]] = q - fptr[p]
        for c in child[cptr[p] : cptr[p + 1]]:
            k = sfirst[c + 1] - sfirst[c]
            for q in range(rptr[c + 1] - rptr[c]):
                rel[rptr[c] + q] = pos[rows[fptr[c] + k + q]]
    return loff, uoff, amap, rptr, rel, cptr, child


# ---------------------------------------------------------------------------- numeric kernels
_SMALL = 4  # supernodes with at most this many columns are solved without a gathered copy


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _schur_update(L, d, k, U):
    """``U[b, a] -= Σ_t L[t, k+b] d_t L[t, k+a]`` for ``a >= b``: two rows of ``U`` and four
    pivot columns at a time (``L[t]`` is front column ``t``, ``d`` its pivots)."""
    r = U.shape[0]
    k4 = k - k % 4
    for b in range(0, r - 1, 2):
        u0 = U[b]
        u1 = U[b + 1]
        for t in range(0, k4, 4):
            l0 = L[t, k:]
            l1 = L[t + 1, k:]
            l2 = L[t + 2, k:]
            l3 = L[t + 3, k:]
            a0, a1, a2, a3 = l0[b] * d[t], l1[b] * d[t + 1], l2[b] * d[t + 2], l3[b] * d[t + 3]
            b0, b1 = l0[b + 1] * d[t], l1[b + 1] * d[t + 1]
            b2, b3 = l2[b + 1] * d[t + 2], l3[b + 1] * d[t + 3]
            if a0 == 0.0 and a1 == 0.0 and a2 == 0.0 and a3 == 0.0:
                if b0 == 0.0 and b1 == 0.0 and b2 == 0.0 and b3 == 0.0:
                    continue
            for a in range(b, r):
                x0, x1, x2, x3 = l0[a], l1[a], l2[a], l3[a]
                u0[a] -= a0 * x0 + a1 * x1 + a2 * x2 + a3 * x3
                u1[a] -= b0 * x0 + b1 * x1 + b2 * x2 + b3 * x3
        for t in range(k4, k):
            lt = L[t, k:]
            a0, b0 = lt[b] * d[t], lt[b + 1] * d[t]
            for a in range(b, r):
                u0[a] -= a0 * lt[a]
                u1[a] -= b0 * lt[a]
    if r % 2 == 1:
        for t in range(k):
            x = L[t, k + r - 1]
            U[r - 1, r - 1] -= x * d[t] * x


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
def _factor(vals, amap, sfirst, fptr, loff, uoff, rptr, rel, cptr, child, lbuf, ubuf, d):
    """Multifrontal ``LDLᵀ`` without pivoting. Returns the numbers of positive and negative
    pivots and ``False`` on a breakdown (a zero or non-finite pivot)."""
    lbuf[:] = 0.0
    for e in range(vals.shape[0]):
        lbuf[amap[e]] += vals[e]
    npos = nneg = 0
    for s in range(sfirst.shape[0] - 1):
        f = sfirst[s]
        k = sfirst[s + 1] - f
        m = fptr[s + 1] - fptr[s]
        r = m - k
        lo, uo = loff[s], uoff[s]
        for i in range(uo, uo + r * r):
            ubuf[i] = 0.0
        for ci in range(cptr[s], cptr[s + 1]):  # extend-add the children's update matrices
            c = child[ci]
            rc, uc, rp = rptr[c + 1] - rptr[c], uoff[c], rptr[c]
            for bb in range(rc):
                col = rel[rp + bb]
                src = uc + bb * rc
                if col < k:  # into a pivot column of the front
                    dst = lo + col * m
                    for aa in range(bb, rc):
                        lbuf[dst + rel[rp + aa]] += ubuf[src + aa]
                else:  # into the front's own update matrix
                    dst = uo + (col - k) * r - k
                    for aa in range(bb, rc):
                        ubuf[dst + rel[rp + aa]] += ubuf[src + aa]
        if k <= _SMALL:  # few pivot columns: plain loops on flat indices (no array views)
            for t in range(k):
                ct = lo + t * m
                for p in range(t):
                    cp = lo + p * m
                    coef = lbuf[cp + t] * d[f + p]
                    if coef != 0.0:
                        for i in range(t, m):
                            lbuf[ct + i] -= coef * lbuf[cp + i]
                dt = lbuf[ct + t]
                if dt == 0.0 or not np.isfinite(dt):
                    return npos, nneg, False
                d[f + t] = dt
                if dt > 0.0:
                    npos += 1
                else:
                    nneg += 1
                inv = 1.0 / dt
                for i in range(t + 1, m):
                    lbuf[ct + i] *= inv
                for b in range(r):
                    coef = lbuf[ct + k + b] * dt
                    if coef != 0.0:
                        ub = uo + b * r
                        for a in range(b, r):
                            ubuf[ub + a] -= coef * lbuf[ct + k + a]
            continue
        L = lbuf[lo : lo + k * m].reshape(k, m)
        df = d[f : f + k]
        t = 0
        while t < k:  # the k pivot columns, two at a time
            two = t + 1 < k
            _apply_previous(L, df, t, two)
            for step in range(2 if two else 1):
                col = L[t + step]
                dt = col[t + step]
                if dt == 0.0 or not np.isfinite(dt):
                    return npos, nneg, False
                df[t + step] = dt
                if dt > 0.0:
                    npos += 1
                else:
                    nneg += 1
                inv = 1.0 / dt
                for i in range(t + step + 1, m):
                    col[i] *= inv
                if step == 0 and two:
                    coef = col[t + 1] * dt
                    nxt = L[t + 1]
                    for i in range(t + 1, m):
                        nxt[i] -= coef * col[i]
            t += 2
        if r > 0:
            _schur_update(L, df, k, ubuf[uo : uo + r * r].reshape(r, r))
    return npos, nneg, True


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def _forward_front(L, w, k, m):
    """``w ← (I + L_front)⁻¹ w`` on a gathered front (``L[t]`` is front column ``t``), four
    columns at a time."""
    k4 = k - k % 4
    for t in range(0, k4, 4):
        l0, l1, l2, l3 = L[t], L[t + 1], L[t + 2], L[t + 3]
        a0 = w[t]
        a1 = w[t + 1] - l0[t + 1] * a0
        a2 = w[t + 2] - l0[t + 2] * a0 - l1[t + 2] * a1
        a3 = w[t + 3] - l0[t + 3] * a0 - l1[t + 3] * a1 - l2[t + 3] * a2
        w[t + 1], w[t + 2], w[t + 3] = a1, a2, a3
        for i in range(t + 4, m):
            w[i] -= a0 * l0[i] + a1 * l1[i] + a2 * l2[i] + a3 * l3[i]
    for t in range(k4, k):
        lt, a0 = L[t], w[t]
        for i in range(t + 1, m):
            w[i] -= a0 * lt[i]


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def _backward_front(L, w, k, m):
    """``w[:k] ← w[:k] - L_frontᵀ w`` solved backwards (``(I + L)ᵀ``), four columns at a time."""
    k4 = k - k % 4
    for t in range(k - 1, k4 - 1, -1):
        lt = L[t]
        acc = 0.0
        for i in range(t + 1, m):
            acc += lt[i] * w[i]
        w[t] -= acc
    for t in range(k4 - 4, -1, -4):
        l0, l1, l2, l3 = L[t], L[t + 1], L[t + 2], L[t + 3]
        a0 = a1 = a2 = a3 = 0.0
        for i in range(t + 4, m):
            x = w[i]
            a0 += l0[i] * x
            a1 += l1[i] * x
            a2 += l2[i] * x
            a3 += l3[i] * x
        x3 = w[t + 3] - a3
        x2 = w[t + 2] - a2 - l2[t + 3] * x3
        x1 = w[t + 1] - a1 - l1[t + 2] * x2 - l1[t + 3] * x3
        w[t] -= a0 + l0[t + 1] * x1 + l0[t + 2] * x2 + l0[t + 3] * x3
        w[t + 1], w[t + 2], w[t + 3] = x1, x2, x3


@nb.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def _solve(b, perm, sfirst, fptr, rows, loff, lbuf, d, wmax):
    """``x = K⁻¹ b`` with the factorization: forward, diagonal and backward substitution (a
    supernode with many columns works on a gathered copy of its rows of the right-hand side)."""
    n = b.shape[0]
    ns = sfirst.shape[0] - 1
    y = np.empty(n)
    w = np.empty(wmax)
    for i in range(n):
        y[i] = b[perm[i]]
    for s in range(ns):
        f, fp, lo = sfirst[s], fptr[s], loff[s]
        k = sfirst[s + 1] - f
        m = fptr[s + 1] - fp
        if k <= _SMALL:  # flat indexing: no array views for the many small supernodes
            for t in range(k):
                yt = y[f + t]
                if yt != 0.0:
                    c = lo + t * m
                    for i in range(t + 1, m):
                        y[rows[fp + i]] -= lbuf[c + i] * yt
            continue
        L = lbuf[lo : lo + k * m].reshape(k, m)
        R = rows[fp : fp + m]
        w[:k] = y[f : f + k]
        w[k:m] = 0.0
        _forward_front(L, w, k, m)
        y[f : f + k] = w[:k]
        for i in range(k, m):
            y[R[i]] += w[i]
    for i in range(n):
        y[i] /= d[i]
    for s in range(ns - 1, -1, -1):
        f, fp, lo = sfirst[s], fptr[s], loff[s]
        k = sfirst[s + 1] - f
        m = fptr[s + 1] - fp
        if k <= _SMALL:
            for t in range(k - 1, -1, -1):
                c = lo + t * m
                acc = 0.0
                for i in range(t + 1, m):
                    acc += lbuf[c + i] * y[rows[fp + i]]
                y[f + t] -= acc
            continue
        L = lbuf[lo : lo + k * m].reshape(k, m)
        R = rows[fp : fp + m]
        w[:k] = y[f : f + k]
        for i in range(k, m):
            w[i] = y[R[i]]
        _backward_front(L, w, k, m)
        y[f : f + k] = w[:k]
    x = np.empty(n)
    for i in range(n):
        x[perm[i]] = y[i]
    return x


class _Analysis:
    """Symbolic analysis of a pattern (lower entries ``rows >= cols``, full diagonal) for the
    elimination order ``perm``: read-only arrays shared by every factorization of the pattern."""

    def __init__(self, n: int, rows: np.ndarray, cols: np.ndarray, perm: np.ndarray) -> None:
        rows = rows.astype(np.int64)
        cols = cols.astype(np.int64)
        pinv = np.empty(n, np.int64)
        pinv[perm] = np.arange(n)
        ptr, idx, _, _ = _upper_csc(n, pinv, rows, cols)
        perm = perm[_postorder(n, _etree(n, ptr, idx))]  # same fill, supernodes contiguous
        pinv[perm] = np.arange(n)
        ptr, idx, hi, lo = _upper_csc(n, pinv, rows, cols)
        parent = _etree(n, ptr, idx)
        self.n, self.perm = n, perm
        self.sfirst, self.nnz_l = _supernodes(n, ptr, idx, parent)
        self.fptr, self.rows, sparent, snode = _front_rows(n, ptr, idx, parent, self.sfirst)
        (self.loff, self.uoff, self.amap, self.rptr, self.rel, self.cptr, self.child) = (
            _assembly_maps(n, self.sfirst, self.fptr, self.rows, sparent, snode, hi, lo)
        )
        self.wmax = int(np.diff(self.fptr).max(initial=1))
        k, m = np.diff(self.sfirst), np.diff(self.fptr)
        below = np.repeat(m - k, k) + np.concatenate([np.arange(c)[::-1] for c in k] or [[]])
        self.flops = float(np.sum(below.astype(float) ** 2))  # multiply-adds of the numeric LDLᵀ
        self.nnz_factor = int(np.sum(below) + n)  # L's stored entries (supernodal) with D


_ANALYSES: OrderedDict[tuple[int, bytes, bytes, str], _Analysis] = OrderedDict()
_ANALYSES_KEPT = 8
_ANALYSES_LOCK = threading.Lock()
ORDERINGS = ("amd", "nested")


def analysis(indptr: np.ndarray, indices: np.ndarray, ordering: str = "amd") -> _Analysis:
    """The analysis of the pattern given as lower CSR arrays, memoized per process for the last
    few patterns: the KKT systems of one task family (every case of a benchmark, every solve of
    a receding-horizon loop) share their pattern, and its ordering and symbolic factorization
    cost as much as a few numeric factorizations. ``ordering``: ``"amd"`` or ``"nested"``
    (:mod:`mbplan.solvers.ordering`)."""
    if ordering not in ORDERINGS:
        raise InputError(f"ordering: expected one of {ORDERINGS}, got {ordering!r}")
    key = (len(indptr) - 1, indptr.tobytes(), indices.tobytes(), ordering)
    with _ANALYSES_LOCK:
        hit = _ANALYSES.get(key)
        if hit is not None:
            _ANALYSES.move_to_end(key)
            return hit
    announce_uncached_numba(*_ENTRY_KERNELS)  # first run only
    n = key[0]
    rows = np.repeat(np.arange(n), np.diff(indptr))
    order = amd_order if ordering == "amd" else nested_dissection_order
    hit = _Analysis(n, rows, indices, order(indptr, indices))
    with _ANALYSES_LOCK:
        _ANALYSES[key] = hit
        while len(_ANALYSES) > _ANALYSES_KEPT:
            _ANALYSES.popitem(last=False)
    return hit


class _SupernodalLDL:
    """Numeric factorization and solves for an :class:`_Analysis` (own work arrays)."""

    def __init__(self, analysis: _Analysis) -> None:
        self.a = analysis
        self.lbuf = np.empty(analysis.loff[-1])
        self.ubuf = np.empty(analysis.uoff[-1])
        self.d = np.empty(analysis.n)

    def factor(self, vals: np.ndarray) -> tuple[int, int, bool]:
        a = self.a
        return _factor(
            vals, a.amap, a.sfirst, a.fptr, a.loff, a.uoff, a.rptr, a.rel, a.cptr, a.child,
            self.lbuf, self.ubuf, self.d,
        )  # fmt: skip

    def solve(self, b: np.ndarray) -> np.ndarray:
        a = self.a
        return _solve(
            np.ascontiguousarray(b, dtype=np.float64), a.perm, a.sfirst, a.fptr, a.rows,
            a.loff, self.lbuf, self.d, a.wmax,
        )  # fmt: skip


@dataclass(frozen=True)
class _KKTPattern:
    """Where the blocks of ``K`` land in its lower CSR pattern, the full symmetric pattern for
    refinement residuals and the symbolic analysis: read-only, shared by every KKTSystem of the
    same block patterns."""

    h_mask: np.ndarray
    h_slot: np.ndarray
    e_slot: np.ndarray
    i_slot: np.ndarray
    diag_slot: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    full_src: np.ndarray
    full_indptr: np.ndarray
    full_indices: np.ndarray
    analysis: _Analysis


_PATTERNS: OrderedDict[tuple, _KKTPattern] = OrderedDict()


def _kkt_pattern(
    n: int,
    n_eq: int,
    n_ineq: int,
    hess: sp.csr_matrix,
    jac_eq: sp.csr_matrix,
    jac_in: sp.csr_matrix,
    ordering: str,
) -> _KKTPattern:
    """The pattern of ``K`` for the blocks' patterns, memoized like :func:`analysis` (a solve
    builds it once, a benchmark of many cases once per process)."""
    key = (
        n,
        n_eq,
        n_ineq,
        ordering,
        *tuple(a.tobytes() for m in (hess, jac_eq, jac_in) for a in (m.indptr, m.indices)),
    )
    with _ANALYSES_LOCK:
        hit = _PATTERNS.get(key)
        if hit is not None:
            _PATTERNS.move_to_end(key)
            return hit
    N = n + n_eq + n_ineq
    h_rows = np.repeat(np.arange(n), np.diff(hess.indptr))
    h_mask = h_rows >= hess.indices
    sources = [
        (h_rows[h_mask], hess.indices[h_mask]),
        (n + np.repeat(np.arange(n_eq), np.diff(jac_eq.indptr)), jac_eq.indices),
        (n + n_eq + np.repeat(np.arange(n_ineq), np.diff(jac_in.indptr)), jac_in.indices),
        (np.arange(N), np.arange(N)),
    ]
    keys = np.concatenate([r.astype(np.int64) * N + c for r, c in sources])
    unique, slot = np.unique(keys, return_inverse=True)
    sizes = np.cumsum([0] + [len(r) for r, _ in sources])
    h_slot, e_slot, i_slot, diag_slot = (slot[a:b] for a, b in itertools.pairwise(sizes))
    rows = unique // N
    cols = unique % N
    indices = cols.astype(np.int32)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=N))]).astype(np.int32)
    # the full symmetric matrix for refinement residuals (one SpMV): entry e of the lower
    # triangle lands in its own slot and, off the diagonal, in the mirrored one
    off = rows != cols
    f_rows = np.concatenate([rows, cols[off]])
    f_cols = np.concatenate([cols, rows[off]])
    order = np.lexsort((f_cols, f_rows))
    hit = _KKTPattern(
        h_mask=h_mask,
        h_slot=h_slot,
        e_slot=e_slot,
        i_slot=i_slot,
        diag_slot=diag_slot,
        indptr=indptr,
        indices=indices,
        full_src=np.concatenate([np.arange(len(unique)), np.flatnonzero(off)])[order],
        full_indptr=np.concatenate([[0], np.cumsum(np.bincount(f_rows, minlength=N))]).astype(
            np.int32
        ),
        full_indices=f_cols[order].astype(np.int32),
        analysis=analysis(indptr, indices, ordering),
    )
    with _ANALYSES_LOCK:
        _PATTERNS[key] = hit
        while len(_PATTERNS) > _ANALYSES_KEPT:
            _PATTERNS.popitem(last=False)
    return hit


class KKTSystem:
    """Assembles ``K`` for a fixed pattern, factorizes it (supernodal LDLᵀ) and solves with
    refinement.

    Typical use per Newton step: :meth:`set_matrices` once, then :meth:`factorize` for each trial
    perturbation of the diagonal (inertia correction) and :meth:`solve` for each right-hand side.
    ``ordering`` selects the elimination order (:func:`analysis`).
    """

    def __init__(self, n: int, n_eq: int, n_ineq: int, *, ordering: str = "amd") -> None:
        if ordering not in ORDERINGS:
            raise InputError(f"ordering: expected one of {ORDERINGS}, got {ordering!r}")
        self.ordering = ordering
        self.n, self.n_eq, self.n_ineq = n, n_eq, n_ineq
        self.dim = n + n_eq + n_ineq
        self._patterns: tuple[sp.csr_matrix | None, ...] = (None, None, None)
        self._solver: _SupernodalLDL | None = None
        self._matrix: sp.csr_matrix | None = None
        self.n_factorizations = 0
        self.n_analyses = 0

    # ------------------------------------------------------------------ pattern
    def _build_pattern(self, hess: sp.csr_matrix, jac_eq: sp.csr_matrix, jac_in: sp.csr_matrix):
        pat = _kkt_pattern(self.n, self.n_eq, self.n_ineq, hess, jac_eq, jac_in, self.ordering)
        self._pattern = pat
        self._h_mask, self._h_slot, self._e_slot = pat.h_mask, pat.h_slot, pat.e_slot
        self._i_slot, self._diag_slot, self._full_src = pat.i_slot, pat.diag_slot, pat.full_src
        self._indptr, self._indices = pat.indptr, pat.indices
        nnz = len(pat.indices)
        self._base = np.zeros(nnz)
        self._data = np.zeros(nnz)
        # the factorized values, entry by entry of the lower CSR arrays (= upper CSC arrays)
        self._factor_data = np.zeros(nnz)
        self._full = sp.csr_matrix(
            (np.zeros(len(pat.full_src)), pat.full_indices, pat.full_indptr),
            shape=(self.dim, self.dim),
        )
        self._solver = _SupernodalLDL(pat.analysis)
        self.n_analyses += 1

    def set_matrices(
        self,
        hessian: sp.spmatrix | sp.sparray | None,
        jac_eq: sp.spmatrix | sp.sparray | None,
        jac_ineq: sp.spmatrix | sp.sparray | None,
    ) -> None:
        """New ``H`` (lower triangle read), ``A_E``, ``A_I``; ``hessian=None`` means ``H = 0``
        (the pattern of the previous Hessian is kept)."""
        n = self.n
        jac_eq = _csr(jac_eq, (self.n_eq, n))
        jac_ineq = _csr(jac_ineq, (self.n_ineq, n))
        zero_hessian = hessian is None
        hess = self._patterns[0] if zero_hessian else _csr(hessian, (n, n))
        if hess is None:
            hess = sp.csr_matrix((n, n))
        new = (hess, jac_eq, jac_ineq)
        if not all(_same_pattern(a, b) for a, b in zip(new, self._patterns, strict=True)):
            self._build_pattern(*new)
            self._patterns = tuple(
                sp.csr_matrix((np.zeros(a.nnz), a.indices.copy(), a.indptr.copy()), shape=a.shape)
                for a in new
            )
        base = self._base
        base[:] = 0.0
        if not zero_hessian:
            base[self._h_slot] = hess.data[self._h_mask]
        base[self._e_slot] = jac_eq.data
        base[self._i_slot] = jac_ineq.data

    # ------------------------------------------------------------------ factorization
    def factorize(self, diagonal: np.ndarray, static_reg: float = 0.0) -> Inertia | None:
        """Factorize ``K`` with ``diagonal`` (length ``dim``) added to its diagonal.

        ``static_reg`` is added to the primal and subtracted from the dual diagonal of the
        *factorized* matrix only (not of ``K``): it keeps the LDLᵀ away from zero pivots of a
        structurally zero diagonal, and :meth:`solve` removes its effect by iterative refinement
        against ``K``. Returns the inertia, or ``None`` when the factorization broke down."""
        data = self._data
        np.copyto(data, self._base)
        data[self._diag_slot] += diagonal
        self._full.data[:] = data[self._full_src]
        values = self._factor_data
        np.copyto(values, data)
        if static_reg:
            values[self._diag_slot[: self.n]] += static_reg
            values[self._diag_slot[self.n :]] -= static_reg
        self.n_factorizations += 1
        positive, negative, ok = self._solver.factor(values)
        if not ok:  # a zero or non-finite pivot
            return None
        return Inertia(positive, negative, 0)

    @property
    def analysis(self) -> _Analysis:
        """The symbolic analysis in use (elimination order, supernodes, ``flops``,
        ``nnz_factor``); available after the first :meth:`set_matrices`."""
        if self._solver is None:
            raise InputError("KKTSystem.analysis: call set_matrices first")
        return self._solver.a

    def matrix(self) -> sp.csc_matrix:
        """The last factorized ``K`` (diagonal included, static regularization excluded), full,
        with the fixed pattern (explicit zeros kept)."""
        return self._full.tocsc(copy=True)

    def matvec(self, v: np.ndarray) -> np.ndarray:
        """``K v`` with the last factorized matrix (one SpMV with the full symmetric pattern)."""
        return self._full @ v

    def solve(
        self, rhs: np.ndarray, max_refinement: int = 10, ratio_max: float = 1e-10
    ) -> tuple[np.ndarray, float]:
        """Solve ``K x = rhs`` with iterative refinement (at least one step, IPOPT's default).

        Returns ``x`` and IPOPT's residual ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``."""
        sol = self._solver.solve(rhs)
        nrm_b = np.max(np.abs(rhs), initial=0.0)
        resid, ratio = self._residual(rhs, sol, nrm_b)
        for step in range(max_refinement):
            if step >= 1 and ratio <= ratio_max:
                break
            cand = sol + self._solver.solve(resid)
            cand_resid, cand_ratio = self._residual(rhs, cand, nrm_b)
            if not cand_ratio < ratio:
                break
            sol, resid, ratio = cand, cand_resid, cand_ratio
        return sol, ratio

    def _residual(self, rhs: np.ndarray, sol: np.ndarray, nrm_b: float) -> tuple[np.ndarray, float]:
        resid = rhs - self.matvec(sol)
        denom = min(np.max(np.abs(sol), initial=0.0), 1e6 * nrm_b) + nrm_b
        nrm_r = np.max(np.abs(resid), initial=0.0)
        ratio = nrm_r / denom if denom > 0 else nrm_r
        return resid, float(ratio) if np.isfinite(ratio) else np.inf


_ENTRY_KERNELS = (_upper_csc, _etree, _postorder, _supernodes, _front_rows, _assembly_maps)
_ENTRY_KERNELS += (_factor, _solve)


def compile_kernels_in_background() -> threading.Thread | None:
    """If the numba kernels are not cached yet, compile them in a daemon thread (a tiny KKT
    system through the public path, so with the dtypes of real use) and return it: a caller
    that then spends its time in a C compiler (the CasADi JIT) gets them for free."""
    if all(numba_cached(k) for k in _ENTRY_KERNELS):
        return None

    def tiny_solve() -> None:
        kkt = KKTSystem(2, 1, 1)
        one = sp.csr_matrix(np.ones((1, 2)))
        kkt.set_matrices(sp.eye(2, format="csr"), one, one)
        kkt.factorize(np.array([0.0, 0.0, -1.0, -1.0]), 1e-9)
        kkt.solve(np.ones(4))

    thread = threading.Thread(target=tiny_solve, name="mbplan-numba-compile", daemon=True)
    thread.start()
    return thread
