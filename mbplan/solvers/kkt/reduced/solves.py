"""Compiled solve of :class:`~mbplan.solvers.kkt.reduced.reduction.Reduction` (the module docstring of
:mod:`mbplan.solvers.kkt.reduced.system`): the right-hand side of ``K_r`` and the recovered step
around ``K_r``'s own solve, and ``K``'s residual with IPOPT's ratio. The arrays come in tuples
of one meaning each (``h``: ``H``'s strictly lower CSR arrays and diagonal; ``ai``, ``ak``: CSR
arrays of ``A_I``, ``A_E,kept``; ``grp``: the row groups; ``bf``, ``bb``: the arguments of
:func:`~mbplan.solvers.kkt.reduced.kernels.b_solve` and ``bt_solve`` after the vector; ``tr``: of
:func:`~mbplan.solvers.kkt.reduced.products.t_apply` after the two vectors)."""

from __future__ import annotations

import numba as nb
import numpy as np

from mbplan.solvers.kkt.borrow import borrowed
from mbplan.solvers.kkt.reduced.kernels import U64, b_solve, bt_solve
from mbplan.solvers.kkt.reduced.products import t_apply, tt_apply

_FAST = {"cache": True, "fastmath": {"contract", "reassoc"}, "error_model": "numpy"}


@nb.njit(**_FAST)
def _group_rows(b, out, tgt, src, sub, M) -> None:
    """``out[tgt[j, i]] = Σ_g M[j, i, g] b[src[j, g]] - b[sub[j, i]]`` (``S b`` on the replaced
    rows)."""
    J, r, g = M.shape
    for j in range(J):
        for i in range(r):
            t = -b[U64(sub[j, i])]
            for q in range(g):
                s = src[j, q]
                if s >= 0:
                    t += M[j, i, q] * b[U64(s)]
            out[U64(tgt[j, i])] = t


@nb.njit(**_FAST)
def _group_rows_t(v, tgt, src, sub, M, vt) -> None:
    """``v ← Sᵀ v`` in place (``vt``: scratch of ``J r``: the replaced rows' values, read
    before any is changed)."""
    J, r, g = M.shape
    for j in range(J):
        for i in range(r):
            t = U64(tgt[j, i])
            vt[j * r + i] = v[t]
            v[t] = 0.0
    for j in range(J):
        for i in range(r):
            x = vt[j * r + i]
            v[U64(sub[j, i])] -= x
            for q in range(g):
                s = src[j, q]
                if s >= 0:
                    v[U64(s)] += M[j, i, q] * x


@nb.njit(**_FAST)
def _sym_lower_sub(hp, hi, hx, hd, x, y) -> None:
    """``y -= H x``, ``H`` from its strictly lower CSR part and its diagonal ``hd``."""
    hp, hi, hx, hd, x, y = borrowed(hp), borrowed(hi), borrowed(hx), borrowed(hd), borrowed(x), borrowed(y)  # fmt: skip
    for i in range(hp.shape[0] - 1):
        xi, t = x[i], hd[i] * x[i]
        for e in range(hp[i], hp[i + 1]):
            j = U64(hi[e])
            t += hx[e] * x[j]
            y[j] -= hx[e] * xi
        y[i] -= t


@nb.njit(**_FAST)
def reduce_rhs(b, diag, sigma, n, me, y_rows, kept, h, ai, ak, grp, bf, bb, tr, xu, rz, rhs_r, vx,
               kv, se) -> None:  # fmt: skip
    """``x_U = B⁻¹ (S b_E)[Y]`` into ``xu``; ``r_z = b_I - A_I x_U`` into ``rz``; ``K_r``'s
    right-hand side ``[Tᵀ (b_x - (H + D_x) [x_U; 0] - A_Iᵀ Σ r_z); b_E,kept - A_E,kept x_U]``
    into ``rhs_r``. ``vx``, ``kv`` (length ``n``), ``se`` (``m_E``): scratch."""
    b, diag, sigma, y_rows = borrowed(b), borrowed(diag), borrowed(sigma), borrowed(y_rows)
    kept, xu, rz, rhs_r = borrowed(kept), borrowed(xu), borrowed(rz), borrowed(rhs_r)
    vx, kv, se, dep = borrowed(vx), borrowed(kv), borrowed(se), borrowed(tr[1])
    ip, ii, ix = borrowed(ai[0]), borrowed(ai[1]), borrowed(ai[2])
    kp, ki, kx = borrowed(ak[0]), borrowed(ak[1]), borrowed(ak[2])
    be = b[n : n + me]
    for i in range(me):
        se[i] = be[i]
    _group_rows(be, se, *grp)
    for k in range(y_rows.shape[0]):
        xu[k] = se[U64(y_rows[k])]
    b_solve(xu, *bf)
    for i in range(n):
        vx[i] = 0.0
        kv[i] = b[i]
    for k in range(dep.shape[0]):  # kv = b_x - (H + D_x) [x_U; 0]
        j, v = U64(dep[k]), xu[k]
        vx[j] = v
        kv[j] -= diag[j] * v
    _sym_lower_sub(*h, vx, kv)
    for r in range(rz.shape[0]):  # r_z, and kv += A_Iᵀ Σ r_z
        t = 0.0
        for e in range(ip[r], ip[r + 1]):
            t += ix[e] * vx[U64(ii[e])]
        rz[r] = b[U64(n + me + r)] - t
        s = sigma[r] * rz[r]
        for e in range(ip[r], ip[r + 1]):
            kv[U64(ii[e])] += ix[e] * s
    tt_apply(kv, rhs_r, *tr)
    nr = tr[0].shape[0]
    for r in range(kept.shape[0]):
        t = 0.0
        for e in range(kp[r], kp[r + 1]):
            t += kx[e] * vx[U64(ki[e])]
        rhs_r[U64(nr + r)] = be[U64(kept[r])] - t


@nb.njit(**_FAST)
def expand_solution(b, xr, diag, sigma, n, me, y_rows, kept, h, ai, ak, grp, bf, bb, tr, xu, rz,
                    w, atw, yv, hw) -> None:  # fmt: skip
    """The step ``w`` from ``K_r``'s solution ``xr`` and :func:`reduce_rhs`'s ``xu``, ``rz``:
    ``w_x = T xr_x + [x_U]``, ``w_E,kept = xr_E``, ``w_I = Σ (A_I T xr_x - r_z)``,
    ``w_Y = B⁻ᵀ (b_U - ((H + D_x) w_x)_U - (A_E,keptᵀ w_E,kept + A_Iᵀ w_I)_U)``, then ``Sᵀ`` on
    ``w_E``. ``atw``, ``hw``, ``yv``: scratch of lengths ``n``, ``n`` and ``|U|`` (``≥ J r``)."""
    b, xr, diag, sigma, y_rows = borrowed(b), borrowed(xr), borrowed(diag), borrowed(sigma), borrowed(y_rows)  # fmt: skip
    kept, xu, rz, w = borrowed(kept), borrowed(xu), borrowed(rz), borrowed(w)
    atw, yv, hw, dep = borrowed(atw), borrowed(yv), borrowed(hw), borrowed(tr[1])
    ip, ii, ix = borrowed(ai[0]), borrowed(ai[1]), borrowed(ai[2])
    kp, ki, kx = borrowed(ak[0]), borrowed(ak[1]), borrowed(ak[2])
    nr = tr[0].shape[0]
    t_apply(xr, w, *tr)
    for i in range(n):
        atw[i] = 0.0
    for r in range(kept.shape[0]):
        v = xr[U64(nr + r)]
        w[U64(n + kept[r])] = v
        for e in range(kp[r], kp[r + 1]):
            atw[U64(ki[e])] += kx[e] * v
    for r in range(rz.shape[0]):
        t = 0.0
        for e in range(ip[r], ip[r + 1]):
            t += ix[e] * w[U64(ii[e])]
        wz = sigma[r] * (t - rz[r])
        w[U64(n + me + r)] = wz
        for e in range(ip[r], ip[r + 1]):
            atw[U64(ii[e])] += ix[e] * wz
    for k in range(dep.shape[0]):  # w_x = T xr_x + [x_U] (after A_I T xr_x: r_z holds A_I x_U)
        w[U64(dep[k])] += xu[k]
    for i in range(n):
        hw[i] = b[i] - atw[i] - diag[i] * w[i]
    _sym_lower_sub(*h, w, hw)  # b_x - A_E,keptᵀ w_E - A_Iᵀ w_I - (H + D_x) w_x
    for k in range(dep.shape[0]):
        yv[k] = hw[U64(dep[k])]
    bt_solve(yv, *bb)
    for k in range(y_rows.shape[0]):
        w[U64(n + y_rows[k])] = yv[k]
    _group_rows_t(w[n : n + me], *grp, yv)


@nb.njit(**_FAST)
def _jacobian_residual(off, p, idx, v, x, res) -> None:
    """``res -= [Aᵀ x[off:]; A x]`` for a Jacobian block at row offset ``off``."""
    for r in range(p.shape[0] - 1):
        t, xr = 0.0, x[U64(off + r)]
        for e in range(p[r], p[r + 1]):
            c = U64(idx[e])
            t += v[e] * x[c]
            res[c] -= v[e] * xr
        res[U64(off + r)] -= t


@nb.njit(**_FAST)
def residual(hp, hi, hx, hd, ep, ei, ex, ip, ii, ix, diag, x, b, res) -> float:
    """``res = b - K x`` (``K`` from its blocks: ``H`` as strictly lower CSR and diagonal
    ``hd``, ``A_E``, ``A_I``, the diagonal) and IPOPT's ratio
    ``‖res‖∞ / (min(‖x‖∞, 1e6 ‖b‖∞) + ‖b‖∞)``."""
    hp, hi, hx, hd, ep = borrowed(hp), borrowed(hi), borrowed(hx), borrowed(hd), borrowed(ep)
    ei, ex, ip, ii = borrowed(ei), borrowed(ex), borrowed(ip), borrowed(ii)
    ix, diag, x, b, res = borrowed(ix), borrowed(diag), borrowed(x), borrowed(b), borrowed(res)
    n, me = hp.shape[0] - 1, ep.shape[0] - 1
    for i in range(x.shape[0]):
        res[i] = b[i] - diag[i] * x[i]
    _sym_lower_sub(hp, hi, hx, hd, x, res)
    _jacobian_residual(n, ep, ei, ex, x, res)
    _jacobian_residual(n + me, ip, ii, ix, x, res)
    nr = nx = nb_ = 0.0
    for i in range(x.shape[0]):
        nr = max(nr, abs(res[i]))
        nx = max(nx, abs(x[i]))
        nb_ = max(nb_, abs(b[i]))
    den = min(nx, 1e6 * nb_) + nb_
    if den > 0:
        return nr / den
    return 0.0 if nr == 0 else np.inf
