"""Compiled (numba) Riccati backward pass, adjoint gradient and linear rollout of iLQR.

Backward pass (thesis 3-35…3-39; with defects, 3-61, using ``d_k``):
``Q_x = l_x + Aᵀ(V'_x + V'_xx d)``, ``Q_u = l_u + Bᵀ(V'_x + V'_xx d)``, ``Q_xx = l_xx + AᵀV'_xxA``,
``Q_ux = BᵀV'_xxA``, ``Q_uu = l_uu + BᵀV'_xxB + μI`` (``l_ux = 0``); gains ``k = -Q_uu⁻¹Q_u``,
``K = -Q_uu⁻¹Q_ux``; value ``V_x = Q_x + Q_uxᵀk``, ``V_xx = Q_xx + Q_uxᵀK``.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _cholesky(M: np.ndarray, L: np.ndarray) -> bool:
    n = M.shape[0]
    for j in range(n):
        s = M[j, j]
        for p in range(j):
            s -= L[j, p] * L[j, p]
        if not s > 0.0:
            return False
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            t = M[i, j]
            for p in range(j):
                t -= L[i, p] * L[j, p]
            L[i, j] = t / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    return True


@numba.njit(cache=True)
def _cho_solve(L: np.ndarray, X: np.ndarray) -> None:
    """Solve ``L Lᵀ Y = X`` in place for a matrix right-hand side ``X`` (n, m)."""
    n, m = X.shape
    for c in range(m):
        for i in range(n):
            s = X[i, c]
            for p in range(i):
                s -= L[i, p] * X[p, c]
            X[i, c] = s / L[i, i]
        for i in range(n - 1, -1, -1):
            s = X[i, c]
            for p in range(i + 1, n):
                s -= L[p, i] * X[p, c]
            X[i, c] = s / L[i, i]


@numba.njit(cache=True)
def backward_pass(A, B, lx, lxx, lu, luu, d, mu, K, k, H, second_order):
    """Fill ``K (N, nu, nx)`` and ``k (N, nu)``; return -1 on success, else the knot where
    ``Q_uu`` is not positive definite (or not finite).

    With ``second_order`` (DDP), ``Q_zz += Σᵢ (V'_x + V'_xx d)ᵢ Hᵢ`` with the dynamics' second
    derivatives ``H (N, nx, nx+nu, nx+nu)`` (the terms iLQR drops, thesis 3-35).

    The gains solve with the regularised ``Q_uu``, so ``V_x = Q_x + Q_uxᵀk`` and
    ``V_xx = Q_xx + Q_uxᵀK`` exactly. Explicit loops: no temporaries per knot.
    """
    N, nx, nu = B.shape
    Vx = lx[N].copy()
    Vxx = lxx[N].copy()
    vx = np.empty(nx)
    Qx = np.empty(nx)
    Qu = np.empty(nu)
    VA = np.empty((nx, nx))
    VB = np.empty((nx, nu))
    Qxx = np.empty((nx, nx))
    Qux = np.empty((nu, nx))
    Quu = np.empty((nu, nu))
    L = np.zeros((nu, nu))
    rhs = np.empty((nu, nx + 1))
    for t in range(N - 1, -1, -1):
        At, Bt, dt = A[t], B[t], d[t]
        for i in range(nx):
            acc = Vx[i]
            for j in range(nx):
                acc += Vxx[i, j] * dt[j]
            vx[i] = acc
        for i in range(nx):
            acc = lx[t, i]
            for j in range(nx):
                acc += At[j, i] * vx[j]
            Qx[i] = acc
        for i in range(nu):
            acc = lu[t, i]
            for j in range(nx):
                acc += Bt[j, i] * vx[j]
            Qu[i] = acc
        for i in range(nx):
            for j in range(nx):
                acc = 0.0
                for p in range(nx):
                    acc += Vxx[i, p] * At[p, j]
                VA[i, j] = acc
            for j in range(nu):
                acc = 0.0
                for p in range(nx):
                    acc += Vxx[i, p] * Bt[p, j]
                VB[i, j] = acc
        for i in range(nx):
            for j in range(i, nx):
                acc = lxx[t, i, j]
                for p in range(nx):
                    acc += At[p, i] * VA[p, j]
                Qxx[i, j] = acc
        for i in range(nx):
            for j in range(i):
                Qxx[i, j] = Qxx[j, i]
        for i in range(nu):
            for j in range(nx):
                acc = 0.0
                for p in range(nx):
                    acc += Bt[p, i] * VA[p, j]
                Qux[i, j] = acc
            for j in range(nu):
                acc = luu[t, i, j]
                for p in range(nx):
                    acc += Bt[p, i] * VB[p, j]
                Quu[i, j] = acc
        if second_order:
            Ht = H[t]
            for p in range(nx):
                w = vx[p]
                for i in range(nx):
                    for j in range(nx):
                        Qxx[i, j] += w * Ht[p, i, j]
                for i in range(nu):
                    for j in range(nx):
                        Qux[i, j] += w * Ht[p, nx + i, j]
                    for j in range(nu):
                        Quu[i, j] += w * Ht[p, nx + i, nx + j]
        finite = True
        for i in range(nu):
            Quu[i, i] += mu
            for j in range(i):
                Quu[i, j] = Quu[j, i] = 0.5 * (Quu[i, j] + Quu[j, i])
            for j in range(nu):
                finite = finite and np.isfinite(Quu[i, j])
        if not finite or not _cholesky(Quu, L):
            return t
        for i in range(nu):
            for j in range(nx):
                rhs[i, j] = Qux[i, j]
            rhs[i, nx] = Qu[i]
        _cho_solve(L, rhs)
        for i in range(nu):
            for j in range(nx):
                K[t, i, j] = -rhs[i, j]
            k[t, i] = -rhs[i, nx]
        for i in range(nx):
            acc = Qx[i]
            for p in range(nu):
                acc += Qux[p, i] * k[t, p]
            Vx[i] = acc
        for i in range(nx):
            for j in range(i, nx):
                acc = Qxx[i, j]
                for p in range(nu):
                    acc += Qux[p, i] * K[t, p, j]
                Vxx[i, j] = acc
        for i in range(nx):
            for j in range(i):
                Vxx[i, j] = Vxx[j, i]
    return -1


@numba.njit(cache=True)
def adjoint_gradient(A, B, lx, lu):
    """``∂J/∂u_k = l_u + Bᵀλ_{k+1}``, ``λ_k = l_x + Aᵀλ_{k+1}``, ``λ_N = l_{N,x}`` (3-49/50)."""
    N, nx, nu = B.shape
    g = np.empty((N, nu))
    lam = lx[N].copy()
    new = np.empty(nx)
    for t in range(N - 1, -1, -1):
        for i in range(nu):
            acc = lu[t, i]
            for j in range(nx):
                acc += B[t, j, i] * lam[j]
            g[t, i] = acc
        for i in range(nx):
            acc = lx[t, i]
            for j in range(nx):
                acc += A[t, j, i] * lam[j]
            new[i] = acc
        lam[:] = new
    return g


@numba.njit(cache=True)
def row_norms(a):
    """``(mean_k ‖a_k‖₂, max_k ‖a_k‖₂, ‖a‖₂)`` of a ``(K, n)`` array (inf if not finite)."""
    total, worst, sq = 0.0, 0.0, 0.0
    for t in range(a.shape[0]):
        s = 0.0
        for j in range(a.shape[1]):
            s += a[t, j] * a[t, j]
        r = np.sqrt(s)
        total += r
        worst = max(worst, r)
        sq += s
    if a.shape[0] == 0:
        return 0.0, 0.0, 0.0
    return total / a.shape[0], worst, np.sqrt(sq)


@numba.njit(cache=True)
def expected_change(A, B, lx, lxx, lu, luu, d, K, k):
    """``(Δ₁, Δ₂)`` of the quadratic model along the α = 1 linear rollout
    ``δu = Kδx + k``, ``δx⁺ = Aδx + Bδu + d``; the model predicts ``αΔ₁ + ½α²Δ₂``."""
    N, nx = B.shape[0], B.shape[1]
    dx = np.zeros(nx)
    d1 = 0.0
    d2 = 0.0
    for t in range(N):
        du = K[t] @ dx + k[t]
        d1 += lx[t] @ dx + lu[t] @ du
        d2 += dx @ (lxx[t] @ dx) + du @ (luu[t] @ du)
        dx = A[t] @ dx + B[t] @ du + d[t]
    d1 += lx[N] @ dx
    d2 += dx @ (lxx[N] @ dx)
    return d1, d2
