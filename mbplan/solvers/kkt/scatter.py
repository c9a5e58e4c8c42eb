"""Compiled scatters that assemble the reduced KKT matrix of
:class:`~mbplan.solvers.kkt.system.KKTSystem` into its fixed lower CSR pattern: the blocks'
values into their precomputed slots, the diagonal and the static regularization on top, and the
pattern check of a new block against the last one (one pass each, no temporaries)."""

from __future__ import annotations

import numba as nb

U64 = nb.uint64  # unsigned indices: no negative-index wraparound code in the scatters


@nb.njit(cache=True)
def same_arrays(a, b) -> bool:
    """``a == b`` elementwise and in length, for integer arrays (an OR of the XORs: one
    vectorized pass, no temporary)."""
    if a.shape[0] != b.shape[0]:
        return False
    diff = 0
    for i in range(a.shape[0]):
        diff |= a[i] ^ b[i]
    return diff == 0


@nb.njit(cache=True)
def same_csr_pattern(indptr_a, indices_a, indptr_b, indices_b) -> bool:
    """Equal CSR index arrays (:func:`same_arrays` of both pairs in one call)."""
    return same_arrays(indptr_a, indptr_b) and same_arrays(indices_a, indices_b)


@nb.njit(cache=True)
def scatter_blocks(base, h_data, h_src, h_slot, e_data, e_slot, i_data, i_slot) -> None:
    """``base = 0``, then ``base[h_slot] = h_data[h_src]``, ``base[e_slot] = e_data``,
    ``base[i_slot] = i_data``."""
    base[:] = 0.0
    for q in range(h_slot.shape[0]):
        base[U64(h_slot[q])] = h_data[U64(h_src[q])]
    for q in range(e_slot.shape[0]):
        base[U64(e_slot[q])] = e_data[q]
    for q in range(i_slot.shape[0]):
        base[U64(i_slot[q])] = i_data[q]


@nb.njit(cache=True)
def matrix_values(base, diag_slot, diagonal, n, static_reg, full_src, full, values) -> None:
    """``values = base`` with ``diagonal`` added on the diagonal (the matrix ``K``), then
    ``full = values[full_src]`` (``K`` in its full symmetric CSR pattern), then ``+static_reg``
    on the first ``n`` diagonal entries of ``values`` and ``-static_reg`` on the others (the
    factorized matrix)."""
    for e in range(base.shape[0]):
        values[e] = base[e]
    for i in range(diag_slot.shape[0]):
        values[U64(diag_slot[i])] += diagonal[i]
    for e in range(full_src.shape[0]):
        full[e] = values[U64(full_src[e])]
    if static_reg:
        for i in range(n):
            values[U64(diag_slot[i])] += static_reg
        for i in range(n, diag_slot.shape[0]):
            values[U64(diag_slot[i])] -= static_reg


SCATTER_KERNELS = (same_arrays, same_csr_pattern, scatter_blocks, matrix_values)
