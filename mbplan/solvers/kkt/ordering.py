"""Fill-reducing elimination orders for the KKT matrix: approximate minimum degree (qdldl's
SuiteSparse AMD), METIS's multilevel nested dissection and a nested dissection that follows the
trajectory's structure.

The KKT graph of a trajectory NLP is a time × body grid of small dense blocks: every knot is
coupled to its neighbours in time, every body to its neighbours in the kinematic tree. Nested
dissection cuts such a grid recursively by small separators (George 1973): a breadth-first level
structure from a pseudo-peripheral vertex (Gibbs-Poole-Stockmeyer) sweeps the graph along its
longest extent, the thinnest level near the middle (shrunk to the vertices that touch the next
level) separates the two halves, which are ordered first, the separator last. Pieces below
``leaf`` vertices are ordered by AMD. No coordinates are needed: the level structure finds the
time (or body) direction by itself. :func:`coordinate_dissection_order` cuts by given
coordinates (knot, body) instead. :func:`metis_order` is Karypis & Kumar's (1998)
``METIS_NodeND`` through pymetis (multilevel vertex separators, supervariable compression,
minimum degree on the small pieces). Their flop counts against AMD: ``mbplan bench speed``.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import pymetis
import qdldl
import scipy.sparse as sp


def amd_order(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """qdldl's approximate minimum degree order (SuiteSparse AMD) of the pattern given as upper
    CSC arrays: ``order[k]`` is the index of the k-th pivot. qdldl orders and factorizes on
    construction, so it gets a matrix it factorizes without breakdown (``1`` on the diagonal,
    explicit zeros elsewhere)."""
    n = len(indptr) - 1
    if n == 0:
        return np.zeros(0, np.int64)
    cols = np.repeat(np.arange(n), np.diff(indptr))
    upper = sp.csc_matrix(((indices == cols).astype(float), indices, indptr), shape=(n, n))
    return np.asarray(qdldl.Solver(upper, upper=True).factors()[2], dtype=np.int64)


def metis_order(indptr: np.ndarray, indices: np.ndarray, seed: int = 0) -> np.ndarray:
    """METIS's nested dissection order (``METIS_NodeND`` with its defaults: vertices of identical
    adjacency compressed into one, one separator per bisection, a fixed random ``seed``) of the
    symmetric pattern given by its lower (or upper) CSR/CSC arrays: ``order[k]`` is the index
    of the k-th pivot."""
    n = len(indptr) - 1
    if n <= 1:
        return np.arange(n, dtype=np.int64)
    a = _adjacency(indptr, indices)
    graph = pymetis.CSRAdjacency(a.indptr.astype(np.int32), a.indices.astype(np.int32))
    order, _ = pymetis.nested_dissection(graph, options=pymetis.Options(seed=seed))
    return np.asarray(order, dtype=np.int64)


@nb.njit(cache=True)
def _bfs(adj_ptr, adj, start, member, tag, level):
    """Breadth-first levels from ``start`` over vertices with ``member == tag``; returns the
    visit order (``level`` holds each visited vertex's level, others keep -1)."""
    order = np.empty(adj_ptr.shape[0] - 1, np.int64)
    order[0] = start
    level[start] = 0
    head, tail = 0, 1
    while head < tail:
        v = order[head]
        head += 1
        for q in range(adj_ptr[v], adj_ptr[v + 1]):
            w = adj[q]
            if member[w] == tag and level[w] < 0:
                level[w] = level[v] + 1
                order[tail] = w
                tail += 1
    return order[:tail]


@nb.njit(cache=True)
def _split(adj_ptr, adj, nodes, member, tag, level):
    """One dissection step on ``nodes`` (all with ``member == tag``): returns a label per node,
    0 / 1 for the two parts and 2 for the separator (or only 0 / 1 when ``nodes`` is not
    connected: the component of the first vertex and the rest)."""
    for v in nodes:
        level[v] = -1
    start = nodes[0]
    order = _bfs(adj_ptr, adj, start, member, tag, level)
    for _sweep in range(3):  # pseudo-peripheral vertex: restart from a vertex of the last level
        if order.shape[0] < nodes.shape[0]:
            break
        far = order[-1]
        depth = level[far]
        for v in nodes:
            level[v] = -1
        order2 = _bfs(adj_ptr, adj, far, member, tag, level)
        if level[order2[-1]] <= depth:
            order = order2
            break
        order = order2
    label = np.zeros(nodes.shape[0], np.int64)
    if order.shape[0] < nodes.shape[0]:  # disconnected: the reached component, then the rest
        for i in range(nodes.shape[0]):
            label[i] = 0 if level[nodes[i]] >= 0 else 1
        return label
    nlev = level[order[-1]] + 1
    size = np.zeros(nlev + 1, np.int64)
    for v in nodes:
        size[level[v]] += 1
    # separator level: the thinnest (after shrinking) with 30-70 % of the vertices before it
    n = nodes.shape[0]
    best, best_size, before = -1, n + 1, 0
    sep_mark = np.zeros(nlev + 1, np.int64)
    for lv in range(nlev):
        if 0.3 * n <= before <= 0.7 * n and lv + 1 < nlev:
            # vertices of level lv that touch level lv + 1
            cnt = 0
            for v in order:
                if level[v] == lv:
                    for q in range(adj_ptr[v], adj_ptr[v + 1]):
                        w = adj[q]
                        if member[w] == tag and level[w] == lv + 1:
                            cnt += 1
                            break
            sep_mark[lv] = cnt
            if cnt < best_size:
                best, best_size = lv, cnt
        before += size[lv]
    if best < 0:  # too shallow to cut: halve by level order
        for i in range(n):
            label[i] = 0
        half = n // 2
        pos = 0
        for v in order:
            if pos >= half:
                level[v] = -2
            pos += 1
        for i in range(n):
            label[i] = 1 if level[nodes[i]] == -2 else 0
        return label
    for i in range(n):
        v = nodes[i]
        lv = level[v]
        if lv < best:
            label[i] = 0
        elif lv > best:
            label[i] = 1
        else:
            touches = False
            for q in range(adj_ptr[v], adj_ptr[v + 1]):
                w = adj[q]
                if member[w] == tag and level[w] == best + 1:
                    touches = True
                    break
            label[i] = 2 if touches else 0
    return label


def _adjacency(indptr: np.ndarray, indices: np.ndarray) -> sp.csr_matrix:
    n = len(indptr) - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    off = rows != indices
    a = sp.csr_matrix(
        (np.ones(int(off.sum())), (rows[off], np.asarray(indices)[off])), shape=(n, n)
    )
    return (a + a.T).tocsr()


def _leaf_order(a: sp.csr_matrix, nodes: np.ndarray) -> np.ndarray:
    sub = a[nodes][:, nodes]
    up = sp.triu(sub + sp.eye(nodes.shape[0]), format="csc")
    return nodes[amd_order(up.indptr, up.indices)]


def coordinate_dissection_order(
    indptr: np.ndarray, indices: np.ndarray, coords: np.ndarray, leaf: int = 200
) -> np.ndarray:
    """Nested dissection by coordinates (e.g. the knot and body of every unknown, ``coords``
    of shape ``(n, d)``): halve the box along its longest axis at the median, separate the
    halves by the smaller of the two sets of vertices with a neighbour across, recurse; pieces
    below ``leaf`` vertices by AMD."""
    n = len(indptr) - 1
    a = _adjacency(indptr, indices)
    out: list[np.ndarray] = []
    stack: list[tuple[np.ndarray, bool]] = [(np.arange(n, dtype=np.int64), False)]
    side = np.zeros(n, np.int8)
    while stack:
        nodes, emit = stack.pop()
        if emit:
            out.append(nodes)
            continue
        c = coords[nodes]
        extent = [np.unique(c[:, i]).size for i in range(c.shape[1])]
        axis = int(np.argmax(extent))
        if nodes.shape[0] <= leaf or extent[axis] < 2:
            out.append(_leaf_order(a, nodes))
            continue
        values = np.unique(c[:, axis])
        split = values[values.size // 2]
        upper = c[:, axis] >= split
        side[nodes] = 0
        side[nodes[upper]] = 2
        side[nodes[~upper]] = 1
        sub = a[nodes]
        cross_lo = (sub @ (side == 2).astype(float) > 0) & ~upper
        cross_hi = (sub @ (side == 1).astype(float) > 0) & upper
        sep = cross_lo if cross_lo.sum() <= cross_hi.sum() else cross_hi
        side[nodes] = 0
        stack.append((nodes[sep], True))
        stack.append((nodes[upper & ~sep], False))
        stack.append((nodes[~upper & ~sep], False))
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def nested_dissection_order(indptr: np.ndarray, indices: np.ndarray, leaf: int = 200) -> np.ndarray:
    """Nested dissection order (module docstring) of the symmetric pattern given by its lower
    (or upper) CSR/CSC arrays: ``order[k]`` is the index of the k-th pivot."""
    n = len(indptr) - 1
    a = _adjacency(indptr, indices)
    adj_ptr, adj = a.indptr.astype(np.int64), a.indices.astype(np.int64)
    member = np.zeros(n, np.int64)
    level = np.full(n, -1, np.int64)
    out: list[np.ndarray] = []
    tags = iter(range(1, 4 * n + 2))
    stack: list[tuple[np.ndarray, bool]] = [(np.arange(n, dtype=np.int64), False)]
    while stack:  # depth first; a separator is emitted after both of its parts
        nodes, emit = stack.pop()
        if emit:
            out.append(nodes)
            continue
        if nodes.shape[0] <= leaf:
            out.append(_leaf_order(a, nodes))
            continue
        tag = next(tags)
        member[nodes] = tag
        label = _split(adj_ptr, adj, nodes, member, tag, level)
        member[nodes] = 0
        sep = nodes[label == 2]
        if sep.size:
            stack.append((sep, True))
        stack.append((nodes[label == 1], False))
        stack.append((nodes[label == 0], False))
    return np.concatenate(out) if out else np.zeros(0, np.int64)
