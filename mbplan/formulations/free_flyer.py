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
Pinocchio's ``difference`` (its Jacobians ``dDifference``; Hessians by central differences of
these gradients, step :data:`FD_STEP`).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pinocchio as pin

FD_STEP = 1e-5  # central differences of the analytic gradients in the coordinates


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
        ``(K, nv)``."""
        unit = self.normalize(q)
        steps = [pin.difference(self.model, a, b) for a, b in pairwise(unit)]
        return np.array(steps) / dt - v[:-1]

    def kinematics_jacobians(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``∂/∂q_k`` and ``∂/∂q_{k+1}`` of :meth:`kinematics`, ``(K, nv, nq)`` each."""
        unit = self.normalize(q)
        C = np.array([self.tangent(qk) for qk in q])
        J = [pin.dDifference(self.model, a, b) for a, b in pairwise(unit)]
        first = np.array([j[0] for j in J]) @ C[:-1] / dt
        second = np.array([j[1] for j in J]) @ C[1:] / dt
        return first, second

    def kinematics_hessian(
        self, q0: np.ndarray, q1: np.ndarray, lam: np.ndarray, dt: float
    ) -> np.ndarray:
        """``∇²(λᵀ (q₁ ⊖ q₀)/Δt)`` over the coordinates ``(q₀, q₁)``: ``(2nq, 2nq)``; the
        joints' rows are linear, so only the bases' coordinates have second derivatives."""
        nq = self.nq

        def gradient(x: np.ndarray) -> np.ndarray:
            first, second = self.kinematics_jacobians(np.stack([x[:nq], x[nq:]]), dt)
            return np.concatenate([lam @ first[0], lam @ second[0]])

        x = np.concatenate([q0, q1])
        H = np.zeros((2 * nq, 2 * nq))
        for j in (*range(7), *range(nq, nq + 7)):  # the bases' position and quaternion
            e = np.zeros(2 * nq)
            e[j] = FD_STEP
            H[:, j] = (gradient(x + e) - gradient(x - e)) / (2.0 * FD_STEP)
        return 0.5 * (H + H.T)
