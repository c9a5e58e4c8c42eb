"""Compiled vector arithmetic of one RIPM iteration: the residuals of eq. (50), the diagonal and
right-hand side of the reduced Newton system (eq. 53), the slack step, the fraction to the
boundary (WB eq. 15), trial constraint values and the bound-multiplier safeguard (WB eq. 16).

Each kernel replaces a sequence of NumPy calls of a few µs each on the small vectors of the
drone-sized tasks. They keep NumPy's arithmetic: the same elementwise operations in the same
order, and sums in NumPy's pairwise order (:func:`pairwise_sum`), so the iterates are bitwise
those of the NumPy expressions (the logarithms of ``φ_μ`` and the dot products stay NumPy's).
"""

from __future__ import annotations

import numba as nb
import numpy as np

_BLOCK = 128  # NumPy's PW_BLOCKSIZE
U64 = nb.uint64  # unsigned indices: no negative-index wraparound code in the scattered loops


@nb.njit(cache=True, error_model="numpy")
def _block_sum(a, lo, n):  # pragma: no cover - numba
    """NumPy's ``pairwise_sum`` of ``a[lo : lo + n]`` for ``n ≤ 128``: eight running sums."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    stop = lo + n - n % 8
    i = lo + 8
    while i < stop:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < lo + n:
        res += a[i]
        i += 1
    return res


@nb.njit(cache=True, error_model="numpy")
def pairwise_sum(a: np.ndarray) -> float:
    """``np.sum(a)`` of a contiguous 1-D float array, bitwise: NumPy's pairwise summation
    (halves rounded down to a multiple of 8 until a piece has ≤ 128 entries, added to the
    identity 0), without recursion (numba's cache does not keep recursive functions)."""
    n = a.shape[0]
    if n <= _BLOCK:
        return 0.0 + _block_sum(a, 0, n)
    # explicit stack of pieces: start, length, phase (0 new, 1 left done, 2 right done)
    lo = np.empty(64, np.int64)
    size = np.empty(64, np.int64)
    phase = np.zeros(64, np.int64)
    left = np.empty(64)
    right = np.empty(64)
    lo[0], size[0], depth, total = 0, n, 1, 0.0
    while depth:
        top = depth - 1
        m = size[top]
        if m <= _BLOCK or phase[top] == 2:
            value = _block_sum(a, lo[top], m) if m <= _BLOCK else left[top] + right[top]
            depth -= 1
            if depth == 0:
                total = value
            elif phase[depth - 1] == 0:
                left[depth - 1] = value
                phase[depth - 1] = 1
            else:
                right[depth - 1] = value
                phase[depth - 1] = 2
            continue
        half = m // 2
        half -= half % 8
        if phase[top] == 0:
            lo[depth], size[depth] = lo[top], half
        else:
            lo[depth], size[depth] = lo[top] + half, m - half
        phase[depth] = 0
        depth += 1
    return 0.0 + total


@nb.njit(cache=True, error_model="numpy")
def abs_sum(a: np.ndarray) -> float:
    """``np.sum(np.abs(a))`` (bitwise)."""
    return pairwise_sum(np.abs(a))


@nb.njit(cache=True, error_model="numpy")
def abs_max(a: np.ndarray) -> float:
    """``‖a‖∞``: 0 for an empty ``a``, NaN if some entry is NaN (as ``np.abs(a).max()``)."""
    out = 0.0
    for v in a:
        av = abs(v)
        if np.isnan(av):
            return av
        out = max(out, av)
    return out


@nb.njit(cache=True, error_model="numpy")
def _add_transpose_times(indptr, indices, data, x, out) -> None:  # pragma: no cover - numba
    """``out += aᵀx`` for a CSR ``a``, row by row (the order of scipy's ``a.T @ x``)."""
    for i in range(indptr.shape[0] - 1):
        xi = x[i]
        for k in range(indptr[i], indptr[i + 1]):
            out[U64(indices[U64(k)])] += data[U64(k)] * xi


@nb.njit(cache=True, error_model="numpy")
def csr_transpose_times(indptr, indices, data, x, n) -> np.ndarray:  # pragma: no cover - numba
    """``aᵀx`` for the CSR arrays of an ``(len(x), n)`` matrix ``a``."""
    out = np.zeros(n)
    _add_transpose_times(indptr, indices, data, x, out)
    return out


@nb.njit(cache=True, error_model="numpy")
def residuals(
    grad, sigma, e_ptr, e_idx, e_val, y, i_ptr, i_idx, i_val, z, h, g, s, r_d, r_c
) -> tuple[float, float]:  # pragma: no cover - numba
    """``r_d = σ∇f + A_Eᵀy + A_Iᵀz`` and ``r_c = (h, g + s)`` (eq. 50) into the given arrays;
    returns ``‖r_d‖∞, ‖r_c‖∞``. ``σ∇f`` is ``∇f`` itself for ``σ = 1``."""
    n = grad.shape[0]
    work = csr_transpose_times(e_ptr, e_idx, e_val, y, n)
    for j in range(n):
        r_d[j] = (grad[j] if sigma == 1.0 else sigma * grad[j]) + work[j]
    work[:] = 0.0
    _add_transpose_times(i_ptr, i_idx, i_val, z, work)
    for j in range(n):
        r_d[j] += work[j]
    me = h.shape[0]
    r_c[:me] = h
    for i in range(g.shape[0]):
        r_c[me + i] = g[i] + s[i]
    return abs_max(r_d), abs_max(r_c)


@nb.njit(cache=True, error_model="numpy")
def complementarity_error(s, z, mu) -> float:  # pragma: no cover - numba
    """``‖s∘z - μ‖∞`` (NaN propagated like :func:`abs_max`)."""
    out = 0.0
    for i in range(s.shape[0]):
        av = abs(s[i] * z[i] - mu)
        if np.isnan(av):
            return av
        out = max(out, av)
    return out


@nb.njit(cache=True, error_model="numpy")
def measures(
    grad, sigma, e_ptr, e_idx, e_val, y, i_ptr, i_idx, i_val, z, h, g, s, r_d, r_c
) -> tuple[float, float, float, float, float]:  # pragma: no cover - numba
    """:func:`residuals` (same arguments) with what the KKT error needs besides:
    ``‖r_d‖∞, ‖r_c‖∞, Σ|y|, Σ|z|`` and ``‖s∘z‖∞``."""
    inf_du, inf_pr = residuals(
        grad, sigma, e_ptr, e_idx, e_val, y, i_ptr, i_idx, i_val, z, h, g, s, r_d, r_c
    )
    return inf_du, inf_pr, abs_sum(y), abs_sum(z), complementarity_error(s, z, 0.0)


@nb.njit(cache=True, error_model="numpy")
def newton_diagonal(n, me, primal, dc, s, z, out) -> None:  # pragma: no cover - numba
    """The diagonal added to ``K`` (eq. 53 reduced): ``primal`` on the ``n`` primal rows,
    ``-δ_c`` on the equality rows and ``-δ_c - s/z`` on the inequality rows."""
    out[:n] = primal
    out[n : n + me] = -dc
    for i in range(s.shape[0]):
        out[n + me + i] = -dc - s[i] / z[i]


@nb.njit(cache=True, error_model="numpy")
def newton_rhs(r_d, c, me, s, z, mu, shift, out) -> None:  # pragma: no cover - numba
    """The right-hand side ``-(r_d, c - (0, s - μ/z))`` for constraint values ``c``, with
    Mehrotra's corrector ``shift`` (empty: none) as ``+ shift/z`` on the inequality rows (the
    complementarity row's ``μe - shift``)."""
    n = r_d.shape[0]
    for j in range(n):
        out[j] = -r_d[j]
    for i in range(me):
        out[n + i] = -c[i]
    shifted = shift.shape[0] > 0
    for i in range(s.shape[0]):
        v = -c[me + i] + (s[i] - mu / z[i])
        if shifted:
            v += shift[i] / z[i]
        out[n + me + i] = v


@nb.njit(cache=True, error_model="numpy")
def slack_step(s, z, dz, mu, shift) -> np.ndarray:  # pragma: no cover - numba
    """``ds = -s + μ/z - s∘dz/z`` (the last row of eq. 53), ``- shift/z`` with Mehrotra's
    corrector ``shift`` (empty: none)."""
    ds = np.empty(s.shape[0])
    shifted = shift.shape[0] > 0
    for i in range(s.shape[0]):
        v = -s[i] + mu / z[i] - s[i] * dz[i] / z[i]
        if shifted:
            v -= shift[i] / z[i]
        ds[i] = v
    return ds


@nb.njit(cache=True, error_model="numpy")
def frac_to_boundary(v, dv, tau) -> float:  # pragma: no cover - numba
    """Largest ``α ∈ (0, 1]`` with ``v + α dv ≥ (1 - τ) v`` (WB eq. 15)."""
    out = np.inf
    for i in range(v.shape[0]):
        if dv[i] < 0:
            out = min(out, -tau * v[i] / dv[i])
    return min(1.0, out)


@nb.njit(cache=True, error_model="numpy")
def mean_product(a, b) -> float:  # pragma: no cover - numba
    """``np.mean(a * b)`` (bitwise) of two equally long, non-empty vectors."""
    return pairwise_sum(a * b) / a.shape[0]


@nb.njit(cache=True, error_model="numpy")
def affine_complementarity(s, ds, z, dz, tau) -> float:  # pragma: no cover - numba
    """Mehrotra's ``μ_aff``: the average complementarity ``mean((s + α_p ds)(z + α_d dz))``
    after the affine step's fraction-to-boundary steps ``α_p``, ``α_d`` (WB eq. 15)."""
    a_p = frac_to_boundary(s, ds, tau)
    a_d = frac_to_boundary(z, dz, tau)
    prod = np.empty(s.shape[0])
    for i in range(s.shape[0]):
        prod[i] = (s[i] + a_p * ds[i]) * (z[i] + a_d * dz[i])
    return pairwise_sum(prod) / s.shape[0]


@nb.njit(cache=True, error_model="numpy")
def corrector_shift(s, ds, z, dz, tau) -> tuple[np.ndarray, float]:  # pragma: no cover - numba
    """Mehrotra's second-order term ``(α_p Δs_aff)(α_d Δz_aff)`` with the affine step's
    fraction-to-boundary step lengths (a long affine step corrects fully, a cut one little: the
    unscaled term lost iterations on the iiwa), and the affine
    step's reach ``min(α_p, α_d)``."""
    a_p = frac_to_boundary(s, ds, tau)
    a_d = frac_to_boundary(z, dz, tau)
    scale = a_p * a_d
    out = np.empty(s.shape[0])
    for i in range(s.shape[0]):
        out[i] = scale * (ds[i] * dz[i])
    return out, min(a_p, a_d)


@nb.njit(cache=True, error_model="numpy")
def ratio_sum(a, b) -> float:  # pragma: no cover - numba
    """``np.sum(a / b)`` (bitwise)."""
    return pairwise_sum(a / b)


@nb.njit(cache=True, error_model="numpy")
def constraint_values(h, g, s, c) -> float:  # pragma: no cover - numba
    """``c = (h, g + s)`` into ``c``; returns ``θ = ‖c‖₁``."""
    me = h.shape[0]
    c[:me] = h
    for i in range(g.shape[0]):
        c[me + i] = g[i] + s[i]
    return abs_sum(c)


@nb.njit(cache=True, error_model="numpy")
def safeguarded_duals(z, dz, alpha, s, mu, kappa) -> np.ndarray:  # pragma: no cover - numba
    """``z + α dz`` clipped to ``[μ/(κ s), κ μ/s]`` (WB eq. 16)."""
    out = np.empty(z.shape[0])
    kmu = kappa * mu
    for i in range(z.shape[0]):
        out[i] = min(max(z[i] + alpha * dz[i], mu / (kappa * s[i])), kmu / s[i])
    return out
