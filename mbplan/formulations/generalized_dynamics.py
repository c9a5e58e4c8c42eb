"""Second derivatives of the generalized dynamics rows ``RNEA(q, v, a) - τ`` (eq. 61).

Pinocchio gives the analytic first derivatives (``computeRNEADerivatives``) but no second ones:
``∇²(λᵀ RNEA)`` takes central differences in ``q`` of the analytic first derivatives (step
:data:`FD_STEP_Q`), a unit forward difference in ``v`` (exact: ``∂τ/∂v`` is affine in ``v``), and
``∂²τ/∂a² = ∂²τ/∂a∂v = 0``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mbplan.formulations.free_flyer import FreeFlyerChart

FD_STEP_Q = 1e-5  # rad: central differences of the analytic RNEA derivatives in q


def rnea_hessian(
    model: pin.Model,
    data: pin.Data,
    chart: FreeFlyerChart | None,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    lam: np.ndarray,
) -> np.ndarray:
    """``∇²(λᵀ RNEA(q, v, a))`` over ``(q, v, a)``, ``(nq + 2nv)²`` (a floating base, ``chart``:
    over its coordinates ``q``, RNEA at the normalized ones)."""
    nq, nv = model.nq, model.nv
    at_q = None if chart is None else chart.tangent(q)

    def gradient(qq: np.ndarray, vv: np.ndarray, j: int = -1) -> np.ndarray:
        """At ``qq``, ``q`` moved along coordinate ``j`` (-1: not moved)."""
        unit = qq if chart is None else chart.normalize(qq)
        dq, dv, M = pin.computeRNEADerivatives(model, data, unit, vv, a)
        if chart is not None:  # C depends on the base's coordinates alone
            dq = dq @ (chart.tangent(qq) if 0 <= j < 7 else at_q)
        return np.concatenate([lam @ dq, lam @ dv, lam @ M])

    H = np.zeros((nq + 2 * nv, nq + 2 * nv))
    for j in range(nq):
        hq = np.zeros(nq)
        hq[j] = FD_STEP_Q
        H[:, j] = (gradient(q + hq, v, j) - gradient(q - hq, v, j)) / (2.0 * FD_STEP_Q)
    vv = slice(nq, nq + nv)
    base = gradient(q, v)[vv]
    step = np.eye(nv)
    for j in range(nv):
        H[vv, nq + j] = gradient(q, v + step[j])[vv] - base
    H[:nq, :nq] = 0.5 * (H[:nq, :nq] + H[:nq, :nq].T)
    H[vv, vv] = 0.5 * (H[vv, vv] + H[vv, vv].T)
    H[:nq, nq:] = H[nq:, :nq].T
    return H
