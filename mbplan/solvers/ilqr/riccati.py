"""Compiled (numba) Riccati backward pass, adjoint gradient and linear rollout of iLQR.

Backward pass (thesis 3-35…3-39; with defects, 3-61, using ``d_k``):
``Q_x = l_x + Aᵀ(V'_x + V'_xx d)``, ``Q_u = l_u + Bᵀ(V'_x + V'_xx d)``, ``Q_xx = l_xx + AᵀV'_xxA``,
``Q_ux = BᵀV'_xxA``, ``Q_uu = l_uu + BᵀV'_xxB + μI`` (``l_ux = 0``); gains ``k = -Q_uu⁻¹Q_u``,
``K = -Q_uu⁻¹Q_ux``; value ``V_x = Q_x + KᵀQ_uu k + KᵀQ_u + Q_uxᵀk`` and
``V_xx = Q_xx + KᵀQ_uu K + KᵀQ_ux + Q_uxᵀK``.
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
def _cho_solve(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``L Lᵀ X = b`` for a matrix right-hand side ``b`` (n, m)."""
    n, m = b.shape
    X = b.copy()
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
    return X


@numba.njit(cache=True)
def backward_pass(A, B, lx, lxx, lu, luu, d, mu, K, k):
    """Fill ``K (N, nu, nx)`` and ``k (N, nu)``; return -1 on success, else the knot where
    ``Q_uu`` is not positive definite (or not finite)."""
    N, nx, nu = B.shape
    Vx = lx[N].copy()
    Vxx = lxx[N].copy()
    L = np.zeros((nu, nu))
    rhs = np.empty((nu, nx + 1))
    for t in range(N - 1, -1, -1):
        At = A[t]
        Bt = B[t]
        vx = Vx + Vxx @ d[t]
        Qx = lx[t] + At.T @ vx
        Qu = lu[t] + Bt.T @ vx
        VA = Vxx @ At
        VB = Vxx @ Bt
        Qxx = lxx[t] + At.T @ VA
        Qux = Bt.T @ VA
        Quu = luu[t] + Bt.T @ VB
        for i in range(nu):
            Quu[i, i] += mu
        Quu = 0.5 * (Quu + Quu.T)
        if not np.all(np.isfinite(Quu)) or not _cholesky(Quu, L):
            return t
        rhs[:, :nx] = Qux
        rhs[:, nx] = Qu
        sol = _cho_solve(L, rhs)
        Kt = -sol[:, :nx]
        kt = -sol[:, nx]
        K[t] = Kt
        k[t] = kt
        Vx = Qx + Kt.T @ (Quu @ kt) + Kt.T @ Qu + Qux.T @ kt
        Vxx = Qxx + Kt.T @ (Quu @ Kt) + Kt.T @ Qux + Qux.T @ Kt
        Vxx = 0.5 * (Vxx + Vxx.T)
    return -1


@numba.njit(cache=True)
def adjoint_gradient(A, B, lx, lu):
    """``∂J/∂u_k = l_u + Bᵀλ_{k+1}``, ``λ_k = l_x + Aᵀλ_{k+1}``, ``λ_N = l_{N,x}`` (3-49/50)."""
    N, nu = B.shape[0], B.shape[2]
    g = np.empty((N, nu))
    lam = lx[N].copy()
    for t in range(N - 1, -1, -1):
        g[t] = lu[t] + B[t].T @ lam
        lam = lx[t] + A[t].T @ lam
    return g


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
