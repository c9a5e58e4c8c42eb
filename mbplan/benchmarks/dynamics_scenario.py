"""A smooth, non-chaotic motion for validating the LGVI against Pinocchio.

From rest at ``q₀`` (each joint in the central half of its range), joint ``i`` follows the
nominal motion ``δ_i(t) = A_i (1 - cos ω_i t)`` (``A_i`` 10 % of its range, at most 0.3 rad,
``ω_i ~ U(3, 8) rad/s``) under the open-loop torque of Pinocchio's inverse dynamics plus the
viscous damping of the model, pushed off it by a smooth random torque that starts at zero:

    τ(t) = RNEA(q_d, q̇_d, q̈_d) + c q̇_d + s ∘ sin²(ω' t),   s = 0.2 M(q₀) u,  u ~ U(-1, 1)

(pushes of ~0.2 rad/s², ``ω' ~ U(5, 15) rad/s``). A floating base is not driven: its six rows of
``τ`` are zero and the robot flies freely, its base moved by the joints' reactions and gravity;
the joints then take the pushes alone (no nominal motion: inverse dynamics on a fixed base, e.g.
gravity compensation, would spin light legs of a falling robot up to ~50 rad/s). Speeds stay of order ``A ω`` (≤ 2.4 rad/s), the
start is at rest on the motion (no initial layer in stiffly damped joints), and the torques are
smooth, so the error of a method of order ``p`` behaves as ``C Δt^p`` — unlike a free fall from a
random pose, where light arms reach 100+ rad/s and errors of right and wrong integrators agree.

The reference is RK4 on Pinocchio's ABA with the damping force ``-c v``, at a step of at most
``Δt_min/16`` and ``0.5/λ_max`` (``λ_max`` the largest eigenvalue of ``M(q₀)⁻¹ diag(c)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from mbplan.multibody import MaximalModel
from mbplan.simulation import integrate_aba


@dataclass(frozen=True, eq=False)
class SmoothScenario:
    """The motion and torques of the module docstring (arrays in Pinocchio's ``v`` order)."""

    model: pin.Model  # with the damping of the run (model.damping)
    q0: np.ndarray  # (nq,)
    amplitude: np.ndarray  # (nv,)
    omega: np.ndarray  # (nv,)
    push: np.ndarray  # (nv,)
    push_omega: np.ndarray  # (nv,)
    driven: np.ndarray  # (nv,) bool: the actuated coordinates (all but a floating base's)

    def motion(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nominal ``(q_d, q̇_d, q̈_d)`` at time ``t``."""
        A, w = self.amplitude, self.omega
        q = pin.integrate(self.model, self.q0, A * (1.0 - np.cos(w * t)))
        return q, A * w * np.sin(w * t), A * w**2 * np.cos(w * t)

    def torque(self, t: float) -> np.ndarray:
        """Joint torques ``τ(t)`` (N·m, N for prismatic joints), ``(nv,)``."""
        q, v, a = self.motion(t)
        data = self.model.createData()
        push = self.push * np.sin(self.push_omega * t) ** 2
        if not self.driven.all():  # a floating base (module docstring)
            return np.where(self.driven, push, 0.0)
        return pin.rnea(self.model, data, q, v, a) + np.asarray(self.model.damping) * v + push

    def reference_step(self, dt_min: float) -> int:
        """RK4 substeps per ``dt_min`` (module docstring)."""
        data = self.model.createData()
        M = pin.crba(self.model, data, self.q0)
        M = np.triu(M) + np.triu(M, 1).T
        lam = np.linalg.eigvals(np.linalg.solve(M, np.diag(self.model.damping))).real.max()
        return max(16, math.ceil(dt_min * lam / 0.5))

    def reference(self, h: float, n: int, substeps: int) -> tuple[np.ndarray, np.ndarray]:
        """``q (n+1, nq)`` and ``v (n+1, nv)`` at ``t = k h`` (RK4 on ABA, damped)."""
        q, v = self.q0.copy(), np.zeros(self.model.nv)
        qs, vs = [q], [v]
        for k in range(n):
            t0 = k * h
            q, v = integrate_aba(
                self.model, q, v, lambda s, t0=t0: self.torque(t0 + s), h, substeps, damping=True
            )
            qs.append(q)
            vs.append(v)
        return np.array(qs), np.array(vs)

    def euler(self, dt: float, N: int) -> np.ndarray:
        """Baseline of order 1: semi-implicit Euler on ABA, damping implicit (stable for stiff
        damping): ``(M + Δt C) v⁺ = M (v + Δt ABA(q, v, τ))``, ``q⁺ = q ⊕ Δt v⁺``; ``(N+1, nq)``."""
        data = self.model.createData()
        C = np.diag(self.model.damping)
        q, v = self.q0.copy(), np.zeros(self.model.nv)
        qs = [q]
        for k in range(N):
            M = pin.crba(self.model, data, q)
            M = np.triu(M) + np.triu(M, 1).T
            a = pin.aba(self.model, data, q, v, self.torque(k * dt))
            v = np.linalg.solve(M + dt * C, M @ (v + dt * a))
            q = pin.integrate(self.model, q, dt * v)
            qs.append(q)
        return np.array(qs)


def smooth_scenario(mm: MaximalModel, seed: int) -> SmoothScenario:
    """The seeded scenario of ``mm.model`` (module docstring)."""
    model = mm.model
    rng = np.random.default_rng(seed)
    lo, hi = np.full(model.nv, -np.pi), np.full(model.nv, np.pi)
    bounded = np.isfinite(mm.lower_position_limit) & np.isfinite(mm.upper_position_limit)
    bounded &= mm.upper_position_limit > mm.lower_position_limit
    lo[mm.idx_v[bounded]] = mm.lower_position_limit[bounded]
    hi[mm.idx_v[bounded]] = mm.upper_position_limit[bounded]
    span, mid = hi - lo, 0.5 * (lo + hi)
    revolute = np.zeros(model.nv, dtype=bool)
    revolute[mm.idx_v] = mm.revolute
    q0 = pin.integrate(model, pin.neutral(model), mid + span * rng.uniform(-0.25, 0.25, model.nv))
    driven = np.ones(model.nv, dtype=bool)
    for b in np.flatnonzero(mm.free):
        driven[mm.idx_v[b] : mm.idx_v[b] + 6] = False
    amplitude = 0.1 * span * rng.uniform(0.5, 1.0, model.nv)
    amplitude = np.where(revolute, np.minimum(amplitude, 0.3), amplitude) * driven.all()
    omega = rng.uniform(3.0, 8.0, model.nv)
    M = pin.crba(model, model.createData(), q0)
    M = np.triu(M) + np.triu(M, 1).T
    push = 0.2 * M @ rng.uniform(-1.0, 1.0, model.nv)
    push_omega = rng.uniform(5.0, 15.0, model.nv)
    return SmoothScenario(model, q0, amplitude, omega, push, push_omega, driven)


def joint_errors(mm: MaximalModel, q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Joint differences ``(K, nb)`` in rad or m (continuous joints via their (cos, sin) pair; a
    floating base: the larger of its position error and its rotation angle error)."""
    plain = ~mm.continuous & ~mm.free
    err = np.zeros((len(q), mm.nb))
    err[:, plain] = q[:, mm.idx_q[plain]] - q_ref[:, mm.idx_q[plain]]
    for b in np.flatnonzero(mm.free):
        i = mm.idx_q[b]
        position = np.linalg.norm(q[:, i : i + 3] - q_ref[:, i : i + 3], axis=1)
        a, c = q_ref[:, i + 3 : i + 7], q[:, i + 3 : i + 7]  # (x, y, z, w)
        cos_half = np.einsum("ki,ki->k", a, c)  # the angle of a⁻¹c, without arccos's round-off
        sin_half = a[:, 3:] * c[:, :3] - c[:, 3:] * a[:, :3] - np.cross(a[:, :3], c[:, :3])
        angle = 2.0 * np.arctan2(np.linalg.norm(sin_half, axis=1), np.abs(cos_half))
        err[:, b] = np.maximum(position, angle)
    c = mm.idx_q[mm.continuous]
    err[:, mm.continuous] = np.arctan2(
        q[:, c + 1] * q_ref[:, c] - q[:, c] * q_ref[:, c + 1],
        q[:, c] * q_ref[:, c] + q[:, c + 1] * q_ref[:, c + 1],
    )
    return err
