"""A floating base in generalized coordinates: the free flyer's configuration as decision
variables of the generalized NLP (eq. 61), with derivatives in those coordinates.

Each knot's ``q`` holds Pinocchio's free-flyer coordinates: the base position and a quaternion
in R⁴ (as the quaternion drone formulation holds a free body's, :mod:`.quaternion`), kept on
the unit sphere by one equality row ``|quat|² - 1 = 0`` per knot. Every function reads the
configuration through :meth:`FreeFlyerChart.normalize` (the quaternion divided by its norm), so
it is defined off the sphere and its derivative in the coordinates is the Pinocchio derivative
in the tangent space (``δ`` of ``q ⊕ δ``) times ``C = ∂δ/∂q``
(:meth:`FreeFlyerChart.tangent`): the pseudo-inverse of Pinocchio's ``tangentMap`` at the
normalized ``q``, times the normalization's Jacobian; a radial change of the quaternion moves
nothing.

Explicit Euler's position step of eq. (61) becomes ``(q_{k+1} ⊖ q_k)/Δt - v_k = 0`` with
Pinocchio's ``difference``: the base's ``log6(M_k⁻¹ M_{k+1})`` as a CasADi expression of the
coordinates (exact Jacobian and Hessian), the joints' plain differences.
"""

from __future__ import annotations

from functools import cache

import casadi as cs
import numpy as np
import pinocchio as pin

from mbplan.lie import SE3


def quaternion_matrix(quat: cs.SX) -> cs.SX:
    """The rotation of the quaternion ``(x, y, z, w)``, normalized: ``I + 2w[u]× + 2[u]×²``
    (a generalized NLP's quaternion coordinates leave the unit sphere between iterates)."""
    unit = quat / cs.norm_2(quat)
    u, w = unit[:3], unit[3]
    K = cs.skew(u)
    return cs.SX.eye(3) + 2.0 * w * K + 2.0 * cs.mtimes(K, K)


class FreeFlyerChart:
    """The coordinates of a model whose joint 1 is a free flyer (module docstring)."""

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.nq, self.nv = model.nq, model.nv
        self.quaternion = slice(3, 7)

    def normalize(self, q: np.ndarray) -> np.ndarray:
        """``q (..., nq)`` with each quaternion divided by its norm."""
        out = np.array(q, dtype=float)
        quat = out[..., self.quaternion]
        out[..., self.quaternion] = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
        return out

    def tangent(self, q: np.ndarray) -> np.ndarray:
        """``C = ∂δ/∂q`` ``(nv, nq)`` at the coordinates ``q``: a coordinate change ``dq`` moves
        the normalized configuration by ``⊕ C dq`` to first order."""
        unit = self.normalize(q)
        # tangentMap = diag(R, ½E(quat), I): its pseudo-inverse diag(Rᵀ, 2E(quat)ᵀ, I)
        C = pin.tangentMap(self.model, unit).T
        C[3:6, self.quaternion] *= 4.0 / np.linalg.norm(q[self.quaternion])
        return C

    def norm_rows(self, q: np.ndarray) -> np.ndarray:
        """``|quat_k|² - 1`` of the knots ``q (K, nq)``: ``(K,)``."""
        return np.sum(q[:, self.quaternion] ** 2, axis=1) - 1.0

    def kinematics(self, q: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """``(q_{k+1} ⊖ q_k)/Δt - v_k`` for the knots ``q (K+1, nq)``, ``v (K+1, nv)``:
        ``(K, nv)`` (the base's ``log6(M_k⁻¹ M_{k+1})``, the joints' differences)."""
        step = np.empty((len(q) - 1, self.nv))
        step[:, :6] = np.array(_base_step()[0].map(len(q) - 1)(q[:-1, :7].T, q[1:, :7].T)).T
        step[:, 6:] = q[1:, 7:] - q[:-1, 7:]
        return step / dt - v[:-1]

    def kinematics_jacobians(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``∂/∂q_k`` and ``∂/∂q_{k+1}`` of :meth:`kinematics`, ``(K, nv, nq)`` each."""
        K = len(q) - 1
        J = np.array(_base_step()[1].map(K)(q[:-1, :7].T, q[1:, :7].T)).reshape(6, K, 14)
        J = J.transpose(1, 0, 2)
        first, second = np.zeros((K, self.nv, self.nq)), np.zeros((K, self.nv, self.nq))
        first[:, :6, :7], second[:, :6, :7] = J[..., :7], J[..., 7:]
        joints = np.arange(6, self.nv)
        first[:, joints, joints + 1], second[:, joints, joints + 1] = -1.0, 1.0
        return first / dt, second / dt

    def kinematics_hessians(self, q: np.ndarray, lam: np.ndarray, dt: float) -> np.ndarray:
        """``∇²(λ_kᵀ (q_{k+1} ⊖ q_k)/Δt)`` over the bases' coordinates ``(q_k[:7],
        q_{k+1}[:7])`` (the joints' rows are linear): ``(K, 14, 14)``, for ``lam (K, nv)``."""
        K = len(q) - 1
        H = _base_step()[2].map(K)(q[:-1, :7].T, q[1:, :7].T, lam[:, :6].T / dt)
        return np.array(H).reshape(14, K, 14).transpose(1, 0, 2)


# process-wide cache, result-neutral: a CasADi function of nothing but its own symbols
@cache
def _base_step() -> tuple[cs.Function, cs.Function, cs.Function]:
    """``log6(M(a)⁻¹ M(b))`` of two free-flyer configurations ``a, b`` (position, quaternion
    ``x y z w`` normalized where read; Pinocchio's ``difference``), its Jacobian ``(6, 14)``
    and the Hessian of ``μᵀ log6`` ``(14, 14)``."""
    a, b, mu = cs.SX.sym("a", 7), cs.SX.sym("b", 7), cs.SX.sym("mu", 6)

    def placement(x: cs.SX) -> cs.SX:
        return cs.vertcat(cs.horzcat(quaternion_matrix(x[3:7]), x[:3]), cs.DM([[0, 0, 0, 1]]))

    step = SE3.log(cs.mtimes(SE3.inverse(placement(a)), placement(b)))
    x = cs.vertcat(a, b)
    return (
        cs.Function("base_step", [a, b], [step]),
        cs.Function("base_step_jacobian", [a, b], [cs.densify(cs.jacobian(step, x))]),
        cs.Function(
            "base_step_hessian", [a, b, mu], [cs.densify(cs.hessian(cs.dot(mu, step), x)[0])]
        ),
    )
