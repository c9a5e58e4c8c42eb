"""Compiled products of :class:`~mbplan.solvers.kkt.reduced.reduction.Reduction` with the variable reduction
``T`` (identity on the kept columns, ``-E_b`` on block ``b``'s dependent rows over its sorted
reach ``R_b``), all by blocks of ``E`` (no ``T`` matrix): ``X T`` for a sparse ``X``,
``tril(Tᵀ W)``, ``tril(Tᵀ D T)``, ``T x`` and ``Tᵀ v``. Entry kernels borrow their arguments
(:mod:`mbplan.solvers.kkt.borrow`)."""

from __future__ import annotations

import numba as nb

from mbplan.solvers.kkt.borrow import borrowed
from mbplan.solvers.kkt.reduced.kernels import U64

_FAST = {"cache": True, "fastmath": {"contract", "reassoc"}, "error_model": "numpy"}


@nb.njit(**_FAST)
def _segments_into(x, s0, s1, off, seg_ptr, seg_block, seg_e, seg_arg, seg_out, seg_map, pos,
                   seg_len, ebuf, eoff, shape, out, acc) -> None:  # fmt: skip
    """Segments ``s0 … s1`` of ``X T`` added into ``out`` (rows' results at ``seg_out - off``):
    a segment of a row's entries on one block's dependent columns is summed densely over the
    first ``seg_len`` of the block's reach (contiguous rows of ``E_b``, ``seg_arg`` the row) and
    added at
    ``pos[seg_map[s]:]`` relative to its row's result; a kept column's entry at ``seg_arg``
    (:meth:`~mbplan.solvers.kkt.reduced.layout.ReductionLayout._segments`)."""
    for s in range(s0, s1):
        b, t0, t1 = seg_block[s], seg_ptr[s], seg_ptr[s + 1]
        ov = out[U64(seg_out[s] - off) :]
        if b < 0:
            for t in range(t0, t1):
                ov[U64(seg_arg[t])] += x[U64(seg_e[t])]
            continue
        m, eo, ml = shape[b, 1], eoff[b], seg_len[s]
        a = x[U64(seg_e[t0])]
        ep = ebuf[U64(eo + seg_arg[t0] * m) :]
        for q in range(ml):
            acc[q] = a * ep[q]
        for t in range(t0 + 1, t1):
            a = x[U64(seg_e[t])]
            ep = ebuf[U64(eo + seg_arg[t] * m) :]
            for q in range(ml):
                acc[q] += a * ep[q]
        pm = pos[U64(seg_map[s]) :]
        for q in range(ml):
            ov[U64(pm[q])] -= acc[q]


@nb.njit(**_FAST)
def times_t(x, seg_ptr, seg_block, seg_e, seg_arg, seg_out, seg_map, pos, seg_len, ebuf, eoff,
            shape, out, acc) -> None:  # fmt: skip
    """``out = X T`` in its rows' result layouts (:func:`_segments_into`)."""
    x, seg_ptr, seg_block, seg_e = borrowed(x), borrowed(seg_ptr), borrowed(seg_block), borrowed(seg_e)  # fmt: skip
    seg_arg, seg_out, seg_map, pos = borrowed(seg_arg), borrowed(seg_out), borrowed(seg_map), borrowed(pos)  # fmt: skip
    ebuf, eoff, shape, out, acc = borrowed(ebuf), borrowed(eoff), borrowed(shape), borrowed(out), borrowed(acc)  # fmt: skip
    seg_len = borrowed(seg_len)
    for e in range(out.shape[0]):
        out[e] = 0.0
    _segments_into(x, 0, seg_block.shape[0], 0, seg_ptr, seg_block, seg_e, seg_arg, seg_out,
                   seg_map, pos, seg_len, ebuf, eoff, shape, out, acc)  # fmt: skip


@nb.njit(**_FAST)
def _tp_lower(hr, panel, b, ebuf, eoff, shape, pwidth, reach_ptr, lo_ptr, lo_slot, acc) -> None:
    """``hr += tril(-E_bᵀ P_b)``, ``P_b`` (``panel``: ``W``'s dependent rows of block ``b``,
    dense ``r × pwidth[b]`` over the sorted union of their columns), row ``q`` over the prefix
    of the union below the diagonal (slots ``lo_slot[lo_ptr[g]:lo_ptr[g+1]]``,
    ``g = reach_ptr[b] + q``), four rows at a time over the longest of their prefixes (the
    reach is sorted: the last one's; ``acc``: scratch of four times the widest panel)."""
    r, m, eo, u, rp = shape[b, 0], shape[b, 1], eoff[b], pwidth[b], reach_ptr[b]
    for q0 in range(0, m, 4):
        nq = min(4, m - q0)
        w = lo_ptr[rp + q0 + nq] - lo_ptr[rp + q0 + nq - 1]
        c0, c1, c2, c3 = acc[:w], acc[w : 2 * w], acc[2 * w : 3 * w], acc[3 * w : 4 * w]
        for t in range(w):
            c0[t] = c1[t] = c2[t] = c3[t] = 0.0
        for p in range(r):
            pp, ep = panel[U64(p * u) :], ebuf[U64(eo + p * m + q0) :]
            e0 = ep[0]
            e1 = ep[1] if nq > 1 else 0.0
            e2 = ep[2] if nq > 2 else 0.0
            e3 = ep[3] if nq > 3 else 0.0
            for t in range(w):
                v = pp[t]
                c0[t] += e0 * v
                c1[t] += e1 * v
                c2[t] += e2 * v
                c3[t] += e3 * v
        for k in range(nq):
            s0 = lo_ptr[rp + q0 + k]
            ls, ck = lo_slot[U64(s0) :], acc[U64(k * w) :]
            for t in range(lo_ptr[rp + q0 + k + 1] - s0):
                hr[U64(ls[t])] -= ck[t]


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
def hr_values(hl, hl_lo, hl_up, hd, hd_slot, hf, fold_slot, ai_p, ai, sigma, seg_ptr, seg_block, seg_e, seg_arg, seg_out,
              seg_map, pos, seg_len, bseg_ptr, ebuf, eoff, shape, reach_ptr, panel_off, pwidth, pbuf, kbuf,
              kw_pos, kw_slot, lo_ptr, lo_slot, hr, acc) -> bool:  # fmt: skip
    """``hr = tril(Tᵀ H_f T)``, ``H_f = H + A_Iᵀ diag(σ) A_I`` (``H``: strictly lower ``hl`` at
    slots ``hl_lo`` and ``hl_up`` of ``H_f``, diagonal ``hd`` at ``hd_slot``; the fold row by row of ``A_I`` (CSR ``ai_p``, ``ai``), pair by pair of its
    entries into ``fold_slot``): ``W = H_f T`` block by block (:func:`_segments_into`, its
    segments from ``bseg_ptr[b]``), each panel into ``hr`` while in cache (:func:`_tp_lower`),
    then ``W``'s kept rows (``kbuf``: entries ``kw_pos`` → slots ``kw_slot``). False if a value
    is not finite."""
    hl, hl_lo, hl_up, hd = borrowed(hl), borrowed(hl_lo), borrowed(hl_up), borrowed(hd)
    hd_slot, hf, fold_slot = borrowed(hd_slot), borrowed(hf), borrowed(fold_slot)
    ai_p, ai, sigma = borrowed(ai_p), borrowed(ai), borrowed(sigma)
    seg_ptr, seg_block, seg_e = borrowed(seg_ptr), borrowed(seg_block), borrowed(seg_e)
    seg_arg, seg_out, seg_map, pos = borrowed(seg_arg), borrowed(seg_out), borrowed(seg_map), borrowed(pos)  # fmt: skip
    seg_len = borrowed(seg_len)
    bseg_ptr, ebuf, eoff, shape = borrowed(bseg_ptr), borrowed(ebuf), borrowed(eoff), borrowed(shape)  # fmt: skip
    reach_ptr, panel_off, pwidth = borrowed(reach_ptr), borrowed(panel_off), borrowed(pwidth)
    pbuf, kbuf, kw_pos, kw_slot = borrowed(pbuf), borrowed(kbuf), borrowed(kw_pos), borrowed(kw_slot)  # fmt: skip
    lo_ptr, lo_slot, hr, acc = borrowed(lo_ptr), borrowed(lo_slot), borrowed(hr), borrowed(acc)
    for e in range(hf.shape[0]):
        hf[e] = 0.0
    for t in range(hl.shape[0]):
        hf[U64(hl_lo[t])] = hl[t]
        hf[U64(hl_up[t])] = hl[t]
    for i in range(hd.shape[0]):
        hf[U64(hd_slot[i])] = hd[i]
    t = 0
    for r in range(ai_p.shape[0] - 1):  # A_Iᵀ Σ A_I row by row, entry pairs in fold_slot order
        p0, p1 = ai_p[r], ai_p[r + 1]
        for e in range(p0, p1):
            ve = sigma[r] * ai[e]
            for f in range(p0, p1):
                hf[U64(fold_slot[t])] += ve * ai[f]
                t += 1
    for e in range(hr.shape[0]):
        hr[e] = 0.0
    B = shape.shape[0]
    for b in range(B):
        for e in range(shape[b, 0] * pwidth[b]):
            pbuf[e] = 0.0
        _segments_into(hf, bseg_ptr[b], bseg_ptr[b + 1], panel_off[b], seg_ptr, seg_block, seg_e,
                       seg_arg, seg_out, seg_map, pos, seg_len, ebuf, eoff, shape, pbuf, acc)  # fmt: skip
        _tp_lower(hr, pbuf, b, ebuf, eoff, shape, pwidth, reach_ptr, lo_ptr, lo_slot, acc)
    for e in range(kbuf.shape[0]):
        kbuf[e] = 0.0
    _segments_into(hf, bseg_ptr[B], bseg_ptr[B + 1], panel_off[B], seg_ptr, seg_block, seg_e,
                   seg_arg, seg_out, seg_map, pos, seg_len, ebuf, eoff, shape, kbuf, acc)  # fmt: skip
    for t in range(kw_pos.shape[0]):
        hr[U64(kw_slot[t])] += kbuf[U64(kw_pos[t])]
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
    xr, y, red_cols, dep, ebuf = borrowed(xr), borrowed(y), borrowed(red_cols), borrowed(dep), borrowed(ebuf)  # fmt: skip
    eoff, shape, reach_red, reach_ptr = borrowed(eoff), borrowed(shape), borrowed(reach_red), borrowed(reach_ptr)  # fmt: skip
    uoff, tmp = borrowed(uoff), borrowed(tmp)
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
    v, out, red_cols, dep, ebuf = borrowed(v), borrowed(out), borrowed(red_cols), borrowed(dep), borrowed(ebuf)  # fmt: skip
    eoff, shape, reach_red, reach_ptr = borrowed(eoff), borrowed(shape), borrowed(reach_red), borrowed(reach_ptr)  # fmt: skip
    uoff, tmp = borrowed(uoff), borrowed(tmp)
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
