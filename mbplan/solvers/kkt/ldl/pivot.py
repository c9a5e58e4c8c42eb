"""Pivoted factorization of one front's fully-summed block (:mod:`mbplan.solvers.kkt.ldl.kernels`):
threshold 1 × 1 and 2 × 2 pivots chosen among the supernode's own columns only (no delayed
pivots, so the symbolic structure is unchanged), and a static perturbation of a tiny pivot
where the supernode offers no acceptable one.

The front's k pivot columns are stored as in :mod:`mbplan.solvers.kkt.ldl.symbolic`: ``L[j, i]``
(``i >= j``) is entry ``(i, j)`` of the symmetric front; an entry of two pivot columns is kept
once, at ``L[min, max]``. A 1 × 1 pivot ``c`` is accepted when ``|F_cc| >= u max_i |F_ic|``
over the front's remaining rows, a 2 × 2 pivot ``(c, p)`` when ``|D⁻¹| [γ_c, γ_p]ᵀ <= 1/u``
elementwise (``γ``: the largest entries of the two columns outside the pivot block), the
tests of Duff & Reid's MA27/MA57.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def _at(L, k, i, j):
    """Front entry ``(i, j)``, ``j`` a pivot column (``j < k``)."""
    if i >= k:
        return L[j, i]
    return L[min(i, j), max(i, j)]


@nb.njit(cache=True, inline="always")
def _put(L, k, i, j, x):
    if i >= k:
        L[j, i] = x
    else:
        L[min(i, j), max(i, j)] = x


@nb.njit(cache=True)
def _column_max(L, k, m, done, c, skip):
    """``max |F_ic|`` over the remaining rows ``i ∉ {c, skip}`` and the row where it is
    attained among the remaining pivot columns (-1 if none)."""
    best, arg, where = 0.0, 0.0, -1
    for i in range(k):
        if done[i] or i == c or i == skip:
            continue
        a = abs(_at(L, k, i, c))
        if a > best:
            best = a
        if a > arg:
            arg, where = a, i
    lc = L[c]
    for i in range(k, m):
        a = abs(lc[i])
        if a > best:
            best = a
    return best, where


@nb.njit(cache=True)
def _choose(L, k, m, done, u):
    """Pivot columns ``(c, p)`` (``p = -1``: a 1 × 1 pivot) and whether they pass the
    threshold tests, by a bounded search: the first remaining column ``c`` as a 1 × 1 pivot,
    else ``(c, p)`` as a 2 × 2 pivot with ``p`` its largest entry among the remaining pivot
    columns, else ``p`` as a 1 × 1 pivot; without an acceptable one, ``c`` and ``False``."""
    c = np.argmin(done)
    a = _at(L, k, c, c)
    gamma, p = _column_max(L, k, m, done, c, -1)
    if abs(a) >= u * gamma and (a != 0.0 or gamma == 0.0):
        return c, -1, True
    if p < 0:
        return c, -1, False
    b, e = _at(L, k, p, c), _at(L, k, p, p)
    det = a * e - b * b
    if det != 0.0 and np.isfinite(det):
        gc = _column_max(L, k, m, done, c, p)[0]
        gp = _column_max(L, k, m, done, p, c)[0]
        if (abs(e) * gc + abs(b) * gp) * u <= abs(det) and (abs(b) * gc + abs(a) * gp) * u <= abs(
            det
        ):
            return c, p, True
    if abs(e) >= u * _column_max(L, k, m, done, p, -1)[0] and e != 0.0:
        return p, -1, True
    return c, -1, False


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def pivoted_front(L, k, m, u, delta, sign, out, rest, v1, v2, piv, dd, ee):
    """Factorize the ``k`` pivot columns of the front ``L`` (``k × m``) with threshold pivoting
    (``u``) inside the block; a 1 × 1 pivot ``|F_cc| <= delta`` is replaced by
    ``sign[c] · delta`` (``sign``: the expected sign of each column's pivot). Writes the
    permuted unit-triangular columns back into ``L`` (``out``: ``k × m`` work array; ``rest``,
    ``v1``, ``v2``: length ``k``), ``piv[q]`` the local column of the q-th pivot, ``dd``/``ee``
    the block-diagonal ``D`` (``ee[q] != 0``: ``(q, q+1)`` is a 2 × 2 block). Returns the
    numbers of positive and negative pivots (a perturbed one counted with its ``sign``), of
    perturbed pivots and of 1 × 1 pivots accepted below the threshold, and ``False`` on a non-finite pivot."""
    done = np.zeros(k, np.bool_)
    npos = nneg = npert = nweak = 0
    q = 0
    while q < k:
        c, p, ok = _choose(L, k, m, done, u)
        nr = 0
        for i in range(k):
            if not done[i] and i != c and i != p:
                rest[nr] = i
                nr += 1
        lc = L[c]
        if p < 0:
            a = _at(L, k, c, c)
            if not np.isfinite(a):
                return npos, nneg, npert, nweak, False
            if abs(a) <= delta:
                a = sign[c] * delta
                npert += 1
            elif not ok:
                nweak += 1
            if a > 0.0:
                npos += 1
            else:
                nneg += 1
            for jj in range(nr):
                v1[jj] = _at(L, k, rest[jj], c)
            inv = 1.0 / a
            for jj in range(nr):  # the remaining block, each entry once
                j = rest[jj]
                coef = v1[jj] * inv
                for ii in range(jj, nr):
                    i = rest[ii]
                    _put(L, k, i, j, _at(L, k, i, j) - coef * v1[ii])
            for jj in range(nr):
                _put(L, k, rest[jj], c, v1[jj] * inv)
            for i in range(k, m):
                lc[i] *= inv
            for jj in range(nr):
                lj, coef = L[rest[jj]], v1[jj]
                for i in range(k, m):
                    lj[i] -= coef * lc[i]
            piv[q], dd[q], ee[q] = c, a, 0.0
            done[c] = True
            q += 1
            continue
        a, b, e = _at(L, k, c, c), _at(L, k, p, c), _at(L, k, p, p)
        det = a * e - b * b
        if det < 0.0:
            npos += 1
            nneg += 1
        elif a > 0.0:
            npos += 2
        else:
            nneg += 2
        i00, i01, i11 = e / det, -b / det, a / det  # D⁻¹
        for jj in range(nr):
            v1[jj] = _at(L, k, rest[jj], c)
            v2[jj] = _at(L, k, rest[jj], p)
        for jj in range(nr):
            j = rest[jj]
            w1 = i00 * v1[jj] + i01 * v2[jj]
            w2 = i01 * v1[jj] + i11 * v2[jj]
            for ii in range(jj, nr):
                i = rest[ii]
                _put(L, k, i, j, _at(L, k, i, j) - w1 * v1[ii] - w2 * v2[ii])
        for jj in range(nr):
            j = rest[jj]
            _put(L, k, j, c, i00 * v1[jj] + i01 * v2[jj])
            _put(L, k, j, p, i01 * v1[jj] + i11 * v2[jj])
        lp = L[p]
        for i in range(k, m):
            x1, x2 = lc[i], lp[i]
            lc[i] = i00 * x1 + i01 * x2
            lp[i] = i01 * x1 + i11 * x2
        for jj in range(nr):
            lj, c1, c2 = L[rest[jj]], v1[jj], v2[jj]
            for i in range(k, m):
                lj[i] -= c1 * lc[i] + c2 * lp[i]
        piv[q], dd[q], ee[q] = c, a, b
        piv[q + 1], dd[q + 1], ee[q + 1] = p, e, 0.0
        done[c] = done[p] = True
        q += 2
    for q in range(k):  # column q of the factor: pivot piv[q], rows in pivot order
        oq = out[q]
        c = piv[q]
        for t in range(q):
            oq[t] = 0.0
        oq[q] = dd[q]
        for t in range(q + 1, k):
            oq[t] = _at(L, k, piv[t], c)
        if ee[q] != 0.0:
            oq[q + 1] = 0.0  # the 2 × 2 block's off-diagonal lives in D
        lc = L[c]
        for i in range(k, m):
            oq[i] = lc[i]
    L[:, :] = out
    return npos, nneg, npert, nweak, True


@nb.njit(cache=True)
def rotate_pairs(L, k, m, dd, ee, out, lam):
    """``out``/``lam``: the front's update columns with each 2 × 2 block ``D_b = Q Λ Qᵀ``
    rotated (``Qᵀ`` applied to the pair of columns, rows ``k..``), so that the Schur update
    ``Σ_b L_bᵀ D_b L_b`` is the diagonal kernels' ``Σ_t λ_t l_t l_tᵀ``."""
    q = 0
    while q < k:
        if ee[q] == 0.0:
            lam[q] = dd[q]
            out[q, k:m] = L[q, k:m]
            q += 1
            continue
        a, b, e = dd[q], ee[q], dd[q + 1]
        # Jacobi rotation diagonalizing [[a, b], [b, e]] (Golub & Van Loan, Alg. 8.4.1)
        tau = (e - a) / (2.0 * b)
        t = (1.0 if tau >= 0.0 else -1.0) / (abs(tau) + np.sqrt(1.0 + tau * tau))
        cs = 1.0 / np.sqrt(1.0 + t * t)
        sn = t * cs
        lam[q], lam[q + 1] = a - t * b, e + t * b
        l0, l1 = L[q], L[q + 1]
        o0, o1 = out[q], out[q + 1]
        for i in range(k, m):
            o0[i] = cs * l0[i] - sn * l1[i]
            o1[i] = sn * l0[i] + cs * l1[i]
        q += 2
