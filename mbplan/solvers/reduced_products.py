"""Compiled products of :class:`~mbplan.solvers.reduction.Reduction` with the variable reduction
``T`` (identity on the kept columns, ``-E_b`` on block ``b``'s dependent rows over its sorted
reach ``R_b``), all by blocks of ``E`` (no ``T`` matrix): ``X T`` for a sparse ``X``,
``tril(Tᵀ W)``, ``tril(Tᵀ D T)``, ``T x`` and ``Tᵀ v``. Entry kernels borrow their arguments
(:mod:`mbplan.solvers.numba_borrow`)."""

from __future__ import annotations

import numba as nb

from mbplan.solvers.numba_borrow import borrowed
from mbplan.solvers.reduced_kernels import U64

_FAST = {"cache": True, "fastmath": {"contract", "reassoc"}, "error_model": "numpy"}


@nb.njit(**_FAST)
def _times_t(x, row_seg, seg_ptr, seg_block, seg_e, seg_arg, ebuf, eoff, shape, reach_red,
             reach_ptr, ostart, olen, ocol, out, work, acc) -> None:  # fmt: skip
    """``X T`` row by row: each segment of ``X``'s row on one block's dependent columns
    (``seg_block < 0``: on kept columns, ``seg_arg`` their reduced index) is summed densely over
    the block's reach (contiguous rows of ``E_b``, ``seg_arg`` the row) and scattered once into
    ``work`` (zeros of length ``n_r``, left zero); row ``i``'s result is gathered at
    ``ocol[ostart[i] : ostart[i] + olen[i]]`` into the same positions of ``out``."""
    for i in range(row_seg.shape[0] - 1):
        for s in range(row_seg[i], row_seg[i + 1]):
            b, t0, t1 = seg_block[s], seg_ptr[s], seg_ptr[s + 1]
            if b < 0:
                for t in range(t0, t1):
                    work[U64(seg_arg[t])] += x[U64(seg_e[t])]
                continue
            m, eo = shape[b, 1], eoff[b]
            a = x[U64(seg_e[t0])]
            ep = ebuf[U64(eo + seg_arg[t0] * m) :]
            for q in range(m):
                acc[q] = a * ep[q]
            for t in range(t0 + 1, t1):
                a = x[U64(seg_e[t])]
                ep = ebuf[U64(eo + seg_arg[t] * m) :]
                for q in range(m):
                    acc[q] += a * ep[q]
            rr = reach_red[U64(reach_ptr[b]) :]
            for q in range(m):
                work[U64(rr[q])] -= acc[q]
        o0 = ostart[i]
        oc, ov = ocol[U64(o0) :], out[U64(o0) :]
        for t in range(olen[i]):
            c = U64(oc[t])
            ov[t] = work[c]
            work[c] = 0.0


@nb.njit(**_FAST)
def times_t(x, row_seg, seg_ptr, seg_block, seg_e, seg_arg, ebuf, eoff, shape, reach_red,
            reach_ptr, ostart, olen, ocol, out, work, acc) -> None:  # fmt: skip
    """:func:`_times_t` on borrowed arguments."""
    _times_t(
        borrowed(x), borrowed(row_seg), borrowed(seg_ptr), borrowed(seg_block), borrowed(seg_e),
        borrowed(seg_arg), borrowed(ebuf), borrowed(eoff), borrowed(shape), borrowed(reach_red),
        borrowed(reach_ptr), borrowed(ostart), borrowed(olen), borrowed(ocol), borrowed(out),
        borrowed(work), borrowed(acc),
    )  # fmt: skip


@nb.njit(**_FAST)
def _tw_lower(hr, wbuf, kw_pos, kw_slot, panel_off, pwidth, ebuf, eoff, shape, reach_ptr, lo_ptr,
              lo_slot, acc) -> None:  # fmt: skip
    """``hr += tril(Tᵀ W)``: the kept rows of ``W`` (entries ``kw_pos`` → slots ``kw_slot``),
    then per block ``-E_bᵀ P_b`` (``P_b``: ``W``'s dependent rows of the block, dense
    ``r × pwidth[b]`` at ``panel_off[b]`` over the sorted union of their columns), row ``q`` of
    it over the prefix of the union below the diagonal (slots ``lo_slot[lo_ptr[g]:lo_ptr[g+1]]``,
    ``g = reach_ptr[b] + q``)."""
    for t in range(kw_pos.shape[0]):
        hr[U64(kw_slot[t])] += wbuf[U64(kw_pos[t])]
    for b in range(shape.shape[0]):
        r, m, eo = shape[b, 0], shape[b, 1], eoff[b]
        u, po = pwidth[b], panel_off[b]
        for q in range(m):
            g = reach_ptr[b] + q
            s0 = lo_ptr[g]
            end = lo_ptr[g + 1] - s0
            for t in range(end):
                acc[t] = 0.0
            for p in range(r):
                e = ebuf[U64(eo + p * m + q)]
                if e != 0.0:
                    pp = wbuf[U64(po + p * u) :]
                    for t in range(end):
                        acc[t] += e * pp[t]
            ls = lo_slot[U64(s0) :]
            for t in range(end):
                hr[U64(ls[t])] -= acc[t]


@nb.njit(**_FAST)
def _tdt_lower(hr, d, dep, red_cols, ebuf, eoff, shape, uoff, tt_off, tt_slot, diag_slot,
               acc) -> None:  # fmt: skip
    """``hr += tril(Tᵀ diag(d) T)``: ``d`` on the kept columns' diagonal slots, then per block
    ``E_bᵀ diag(d_dep) E_b``, row ``q`` over ``q' ≤ q`` (the reach is sorted), slots
    ``tt_slot[tt_off[b] + q (q + 1) / 2 ...]``."""
    for i in range(red_cols.shape[0]):
        hr[U64(diag_slot[i])] += d[U64(red_cols[i])]
    for b in range(shape.shape[0]):
        r, m, eo, ub = shape[b, 0], shape[b, 1], eoff[b], uoff[b]
        for q in range(m):
            for t in range(q + 1):
                acc[t] = 0.0
            for p in range(r):
                ep = ebuf[U64(eo + p * m) :]
                e = d[U64(dep[U64(ub + p)])] * ep[q]
                if e != 0.0:
                    for t in range(q + 1):
                        acc[t] += e * ep[t]
            ts = tt_slot[U64(tt_off[b] + q * (q + 1) // 2) :]
            for t in range(q + 1):
                hr[U64(ts[t])] += acc[t]


@nb.njit(**_FAST)
def hr_values(hs, hf, fold_slot, fold_e, fold_f, fold_row, ai, sigma, row_seg, seg_ptr,
              seg_block, seg_e, seg_arg, ebuf, eoff, shape, reach_red, reach_ptr, ostart, olen,
              ocol, wbuf, kw_pos, kw_slot, panel_off, pwidth, lo_ptr, lo_slot, hr, work,
              acc) -> bool:  # fmt: skip
    """``hr = tril(Tᵀ H_f T)``, ``H_f = H + A_Iᵀ diag(σ) A_I`` (``hs``: ``H``'s values in
    ``H_f``'s pattern; the fold term by term, ``hf[slot] += σ[row] ai[e] ai[f]``); ``W = H_f T``
    in ``wbuf`` (:func:`_times_t`, :func:`_tw_lower`). False if a value is not finite."""
    hs, hf, fold_slot, fold_e = borrowed(hs), borrowed(hf), borrowed(fold_slot), borrowed(fold_e)
    fold_f, fold_row, ai, sigma = borrowed(fold_f), borrowed(fold_row), borrowed(ai), borrowed(sigma)  # fmt: skip
    row_seg, seg_ptr, seg_block = borrowed(row_seg), borrowed(seg_ptr), borrowed(seg_block)
    seg_e, seg_arg, ebuf, eoff = borrowed(seg_e), borrowed(seg_arg), borrowed(ebuf), borrowed(eoff)
    shape, reach_red, reach_ptr = borrowed(shape), borrowed(reach_red), borrowed(reach_ptr)
    ostart, olen, ocol, wbuf = borrowed(ostart), borrowed(olen), borrowed(ocol), borrowed(wbuf)
    kw_pos, kw_slot, panel_off = borrowed(kw_pos), borrowed(kw_slot), borrowed(panel_off)
    pwidth, lo_ptr, lo_slot = borrowed(pwidth), borrowed(lo_ptr), borrowed(lo_slot)
    hr, work, acc = borrowed(hr), borrowed(work), borrowed(acc)
    for e in range(hs.shape[0]):
        hf[e] = hs[e]
    for t in range(fold_slot.shape[0]):
        hf[U64(fold_slot[t])] += sigma[U64(fold_row[t])] * ai[U64(fold_e[t])] * ai[U64(fold_f[t])]
    _times_t(hf, row_seg, seg_ptr, seg_block, seg_e, seg_arg, ebuf, eoff, shape, reach_red,
             reach_ptr, ostart, olen, ocol, wbuf, work, acc)  # fmt: skip
    for e in range(hr.shape[0]):
        hr[e] = 0.0
    _tw_lower(hr, wbuf, kw_pos, kw_slot, panel_off, pwidth, ebuf, eoff, shape, reach_ptr, lo_ptr,
              lo_slot, acc)  # fmt: skip
    ok = 0.0
    for e in range(hr.shape[0]):
        ok += hr[e] * 0.0
    return ok == 0.0


@nb.njit(**_FAST)
def tdt_values(hr, base, d, dep, red_cols, ebuf, eoff, shape, uoff, tt_off, tt_slot, diag_slot,
               acc) -> None:  # fmt: skip
    """``hr = base + tril(Tᵀ diag(d) T)`` (:func:`_tdt_lower`)."""
    hr, base, d, dep = borrowed(hr), borrowed(base), borrowed(d), borrowed(dep)
    red_cols, ebuf, eoff, shape = borrowed(red_cols), borrowed(ebuf), borrowed(eoff), borrowed(shape)  # fmt: skip
    uoff, tt_off, tt_slot = borrowed(uoff), borrowed(tt_off), borrowed(tt_slot)
    diag_slot, acc = borrowed(diag_slot), borrowed(acc)
    for e in range(hr.shape[0]):
        hr[e] = base[e]
    _tdt_lower(hr, d, dep, red_cols, ebuf, eoff, shape, uoff, tt_off, tt_slot, diag_slot, acc)


@nb.njit(**_FAST)
def t_apply(xr, y, red_cols, dep, ebuf, eoff, shape, reach_red, reach_ptr, uoff, tmp) -> None:
    """``y = T xr`` (length ``n``): ``xr`` on the kept columns, ``-E_b xr[R_b]`` on the
    dependent ones."""
    for i in range(red_cols.shape[0]):
        y[U64(red_cols[i])] = xr[i]
    for b in range(shape.shape[0]):
        r, m, eo, ub = shape[b, 0], shape[b, 1], eoff[b], uoff[b]
        rr = reach_red[U64(reach_ptr[b]) :]
        for q in range(m):
            tmp[q] = xr[U64(rr[q])]
        for p in range(r):
            ep = ebuf[U64(eo + p * m) :]
            t = 0.0
            for q in range(m):
                t += ep[q] * tmp[q]
            y[U64(dep[U64(ub + p)])] = -t


@nb.njit(**_FAST)
def tt_apply(v, out, red_cols, dep, ebuf, eoff, shape, reach_red, reach_ptr, uoff, tmp) -> None:
    """``out = Tᵀ v`` (length ``n_r``)."""
    for i in range(red_cols.shape[0]):
        out[i] = v[U64(red_cols[i])]
    for b in range(shape.shape[0]):
        r, m, eo, ub = shape[b, 0], shape[b, 1], eoff[b], uoff[b]
        for q in range(m):
            tmp[q] = 0.0
        for p in range(r):
            vp = v[U64(dep[U64(ub + p)])]
            if vp != 0.0:
                ep = ebuf[U64(eo + p * m) :]
                for q in range(m):
                    tmp[q] += vp * ep[q]
        rr = reach_red[U64(reach_ptr[b]) :]
        for q in range(m):
            out[U64(rr[q])] -= tmp[q]


PRODUCT_KERNELS = (times_t, hr_values, tdt_values)
