"""Where the supernodal LDLᵀ of :mod:`mbplan.solvers.kkt.ldl.symbolic` keeps its small leaves and
its update matrices.

Leaves with at most ``DIRECT_COLUMNS`` columns subtract their Schur update straight from their
parent's front (:func:`~mbplan.solvers.kkt.ldl.kernels.ldl_factor`); sibling leaves with the same
rows below their columns become one such supernode (siblings share no entry of L, so the merged
front adds only the zeros between their columns), and every such leaf is eliminated right
before its parent (any topological order of the elimination tree has the same fill). Update
matrices live in one buffer, each from the step that starts it (zeroed) to its parent's
step; offsets are assigned first-fit over these lifetimes, so the buffer is the largest set of
update matrices alive at once instead of all of them, and recently freed (cached) memory is
reused first.
"""

from __future__ import annotations

import numba as nb
import numpy as np

DIRECT_COLUMNS = 4
"""Leaf supernodes with at most this many columns update their parent's front directly (no
update matrix of their own unless they need pivoting; the kernels handle 1 to 4)."""


def leaves_last(
    perm: np.ndarray, sfirst: np.ndarray, fptr: np.ndarray, rows: np.ndarray, sparent: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The elimination order and supernode partition with sibling leaves of equal rows merged
    (up to ``DIRECT_COLUMNS`` columns) and every leaf of at most ``DIRECT_COLUMNS`` columns
    moved right before its parent; ``None`` when there is no such leaf."""
    ns = len(sfirst) - 1
    k = np.diff(sfirst)
    leaf = (np.bincount(sparent[sparent >= 0], minlength=ns) == 0) & (sparent >= 0)
    small = np.flatnonzero(leaf & (k <= DIRECT_COLUMNS))
    if small.size == 0:
        return None
    groups: dict[tuple[int, bytes], list[int]] = {}
    for s in small:
        key = (int(sparent[s]), rows[fptr[s] + k[s] : fptr[s + 1]].tobytes())
        groups.setdefault(key, []).append(int(s))
    group = np.arange(ns)  # each supernode's new supernode (a merged group: its first member)
    for members in groups.values():
        start, cols = 0, 0
        for q, s in enumerate([*members, -1]):
            if s == -1 or cols + k[s] > DIRECT_COLUMNS:  # close the group members[start:q]
                group[members[start:q]] = members[start]
                start, cols = q, 0
            if s != -1:
                cols += k[s]
    position = 2 * np.arange(ns)  # small leaves right before their parent, groups together
    position[small] = 2 * sparent[small] - 1
    order = np.lexsort((np.arange(ns), group, position))
    cols = np.concatenate([np.arange(sfirst[s], sfirst[s + 1]) for s in order])
    first = np.r_[True, group[order][1:] != group[order][:-1]]
    new_first = np.r_[np.cumsum(np.r_[0, k[order]])[:-1][first], len(perm)]
    return perm[cols], new_first.astype(np.int64)


def direct_leaves(sfirst: np.ndarray, cptr: np.ndarray, sparent: np.ndarray) -> np.ndarray:
    """Which supernodes update their parent's front directly: leaves with a parent and at most
    ``DIRECT_COLUMNS`` columns."""
    return (np.diff(sfirst) <= DIRECT_COLUMNS) & (np.diff(cptr) == 0) & (sparent != -1)


@nb.njit(cache=True)
def update_offsets(sfirst, fptr, sparent, cptr, child, direct):
    """Offsets of the update matrices (``r × r`` for a front with ``r`` rows below its pivots)
    in a reused buffer, the buffer's size, and ``zero_at[s]``: the supernode whose update
    matrix is zeroed when step ``s`` starts (-1: none). A supernode's update matrix lives from
    its first direct child's step (they write into it), or its own, to its parent's step;
    a direct leaf's (needed only when it pivots) from its own step."""
    ns = sfirst.shape[0] - 1
    size = np.empty(ns, np.int64)
    start = np.arange(ns)
    for s in range(ns):
        r = fptr[s + 1] - fptr[s] - sfirst[s + 1] + sfirst[s]
        size[s] = r * r
    for s in range(ns - 1, -1, -1):  # the first direct child of each parent
        p = sparent[s]
        if direct[s] and p != -1:
            start[p] = min(start[p], s)
    zero_at = np.full(ns, -1, np.int64)
    for s in range(ns):
        if not direct[s]:
            zero_at[start[s]] = s
    order = np.argsort(start, kind="mergesort")
    free_off = np.empty(ns + 1, np.int64)  # free blocks below the top, by offset
    free_len = np.empty(ns + 1, np.int64)
    nfree = top = peak = 0
    off = np.zeros(ns + 1, np.int64)
    q = 0
    for t in range(ns):
        while q < ns and start[order[q]] == t:  # allocate first fit
            s = order[q]
            q += 1
            need = size[s]
            if need == 0:
                continue
            j = 0
            while j < nfree and free_len[j] < need:
                j += 1
            if j == nfree:
                off[s] = top
                top += need
                peak = max(peak, top)
                continue
            off[s] = free_off[j]
            free_off[j] += need
            free_len[j] -= need
            if free_len[j] == 0:
                nfree -= 1
                free_off[j:nfree] = free_off[j + 1 : nfree + 1].copy()
                free_len[j:nfree] = free_len[j + 1 : nfree + 1].copy()
        for c in child[cptr[t] : cptr[t + 1]]:  # then free those read for the last time
            if size[c] == 0:
                continue
            j = 0
            while j < nfree and free_off[j] < off[c]:
                j += 1
            free_off[j + 1 : nfree + 1] = free_off[j:nfree].copy()
            free_len[j + 1 : nfree + 1] = free_len[j:nfree].copy()
            free_off[j], free_len[j] = off[c], size[c]
            nfree += 1
            if j + 1 < nfree and free_off[j] + free_len[j] == free_off[j + 1]:  # merge up
                free_len[j] += free_len[j + 1]
                nfree -= 1
                free_off[j + 1 : nfree] = free_off[j + 2 : nfree + 1].copy()
                free_len[j + 1 : nfree] = free_len[j + 2 : nfree + 1].copy()
            if j > 0 and free_off[j - 1] + free_len[j - 1] == free_off[j]:  # merge down
                free_len[j - 1] += free_len[j]
                nfree -= 1
                free_off[j:nfree] = free_off[j + 1 : nfree + 1].copy()
                free_len[j:nfree] = free_len[j + 1 : nfree + 1].copy()
            if nfree and free_off[nfree - 1] + free_len[nfree - 1] == top:  # back to the top
                nfree -= 1
                top = free_off[nfree]
    off[ns] = peak
    return off, zero_at
