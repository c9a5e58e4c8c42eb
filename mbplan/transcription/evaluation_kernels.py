"""Compiled passes of :class:`~mbplan.transcription.trajectory.TrajectoryProblem`'s evaluation:
every term's inputs gathered from the packed point and the multipliers before the terms' calls,
every output summed into the NLP's vectors and matrix nonzeros after them, one call each. The
sums are NumPy's ``bincount`` (:func:`~mbplan.transcription.sparse.accumulate`): the same
additions in the same order as per-term ``take`` and ``bincount`` calls."""

from __future__ import annotations

import numba as nb
import numpy as np

from mbplan.transcription.sparse import accumulate


@nb.njit(cache=True)
def gather_inputs(packed, z_gather, z_flat, obj_factor, y, z, lam_source, lam_flat):
    """``z_flat = packed[z_gather]``; ``lam_flat[i]`` is ``obj_factor`` where
    ``lam_source[i] < 0`` (a cost), else entry ``lam_source[i]`` of ``(y, z)``. An empty
    ``lam_flat`` skips the multipliers."""
    for i in range(z_gather.shape[0]):
        z_flat[i] = packed[z_gather[i]]
    if lam_flat.shape[0] == 0:
        return
    n_eq = y.shape[0]
    for i in range(lam_source.shape[0]):
        j = lam_source[i]
        if j < 0:
            lam_flat[i] = obj_factor
        elif j < n_eq:
            lam_flat[i] = y[j]
        else:
            lam_flat[i] = z[j - n_eq]


@nb.njit(cache=True)
def collect_values(eq_res, eq_rows, n_eq, ineq_res, ineq_rows, n_ineq):
    """The equality and inequality residual vectors from the terms' residuals."""
    return accumulate(eq_rows, eq_res, n_eq), accumulate(ineq_rows, ineq_res, n_ineq)


@nb.njit(cache=True)
def collect_derivatives(
    cost_jac, grad_cols, n, eq_res, eq_rows, n_eq, ineq_res, ineq_rows, n_ineq,
    eq_jac, eq_slot, eq_nnz, ineq_jac, ineq_slot, ineq_nnz, hess, hess_slot, hess_nnz,
):  # fmt: skip
    """Gradient, residual vectors and the nonzeros of the two Jacobians and of the Hessian's
    lower triangle (empty if ``hess_slot`` is) from the terms' outputs; entries at a fixed
    coordinate go to the extra last bin, cut off."""
    grad = accumulate(grad_cols, cost_jac, n + 1)[:n]
    eq, ineq = collect_values(eq_res, eq_rows, n_eq, ineq_res, ineq_rows, n_ineq)
    eq_data = accumulate(eq_slot, eq_jac, eq_nnz + 1)[:eq_nnz]
    ineq_data = accumulate(ineq_slot, ineq_jac, ineq_nnz + 1)[:ineq_nnz]
    if hess_slot.shape[0] == 0:
        return grad, eq, ineq, eq_data, ineq_data, np.zeros(0)
    return grad, eq, ineq, eq_data, ineq_data, accumulate(hess_slot, hess, hess_nnz + 1)[:hess_nnz]
