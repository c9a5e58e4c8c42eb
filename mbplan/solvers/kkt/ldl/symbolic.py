"""Symbolic analysis of the supernodal LDLᵀ (:mod:`mbplan.solvers.kkt.system`): elimination
tree, postorder, fundamental supernodes with relaxed amalgamation, small leaves merged and
moved before their parents (:mod:`mbplan.solvers.kkt.ldl.layout`), front rows and the maps that
place every entry of ``K`` and every child's update matrix in the factor's storage.

Index conventions: ``perm[i]`` is the original index of the i-th pivot, the permuted pattern is
held as "upper CSC" (column k lists the rows i <= k of the lower triangle's row k), and L is
stored by supernodes: supernode s owns the pivot columns sfirst[s] .. sfirst[s+1]-1 and the
front rows rows[fptr[s]:fptr[s+1]] (its own columns, then the rows below, increasing); its
k x m block of L starts at lbuf[loff[s]], front column t at offset t*m.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from mbplan.solvers.kkt.ldl.layout import direct_leaves, leaves_last, update_offsets


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
    rptr = np.zeros(ns + 1, np.int64)
    for s in range(ns):
        k = sfirst[s + 1] - sfirst[s]
        m = fptr[s + 1] - fptr[s]
        loff[s + 1] = loff[s] + k * m
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
    return loff, amap, rptr, rel, cptr, child


class Analysis:
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
        self.sfirst, self.nnz_l = _supernodes(n, ptr, idx, parent)
        self.fptr, self.rows, self.sparent, snode = _front_rows(n, ptr, idx, parent, self.sfirst)
        leaves = leaves_last(perm, self.sfirst, self.fptr, self.rows, self.sparent)
        if leaves is not None:
            perm, self.sfirst = leaves
            pinv[perm] = np.arange(n)
            ptr, idx, hi, lo = _upper_csc(n, pinv, rows, cols)
            parent = _etree(n, ptr, idx)
            self.fptr, self.rows, self.sparent, snode = _front_rows(
                n, ptr, idx, parent, self.sfirst
            )
        self.n, self.perm = n, perm
        (self.loff, self.amap, self.rptr, self.rel, self.cptr, self.child) = _assembly_maps(
            n, self.sfirst, self.fptr, self.rows, self.sparent, snode, hi, lo
        )
        self.direct = direct_leaves(self.sfirst, self.cptr, self.sparent)
        self.uoff, self.zero_at = update_offsets(
            self.sfirst, self.fptr, self.sparent, self.cptr, self.child, self.direct
        )
        self.wmax = int(np.diff(self.fptr).max(initial=1))
        k, m = np.diff(self.sfirst), np.diff(self.fptr)
        below = np.repeat(m - k, k) + np.concatenate([np.arange(c)[::-1] for c in k] or [[]])
        self.flops = float(np.sum(below.astype(float) ** 2))  # multiply-adds of the numeric LDLᵀ
        self.nnz_factor = int(np.sum(below) + n)  # L's stored entries (supernodal) with D


SYMBOLIC_KERNELS = (
    _upper_csc, _etree, _postorder, _supernodes, _front_rows, _assembly_maps, update_offsets,
)  # fmt: skip
