"""A smooth motion of a mechanism with loop closures, for validating the LGVI against Pinocchio.

From rest at ``q₀`` (the closed neutral configuration with the actuated joints moved by up to
0.3 rad, the loops closed again around them), the actuated joints hold the mechanism against
gravity (:func:`~mbplan.simulation.closed_loop.closed_loop_actuation` of the static torque at
``q₀``) and push it off smoothly; passive joints take no torque:

    τ(t) = τ_hold + s ∘ sin²(ω' t),   s = 2 S (M(q₀) u),   u ~ U(-1, 1),   ω' ~ U(5, 15) rad/s

(``S`` keeps the actuated joints; pushes of ~2 rad/s² on them, :data:`PUSH`: the four-bar
reaches ~1.4 rad/s undamped, the speeds of the tree robots' scenario). The reference is RK4 on Pinocchio's constrained dynamics
(:class:`~mbplan.simulation.closed_loop.ClosedLoopDynamics`, with the damping ``-c v``) at the
step of :class:`~mbplan.benchmarks.dynamics_scenario.SmoothScenario`; the first-order baseline is
semi-implicit Euler on the same dynamics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.robots.loops import CLOSE_TOLERANCE, Loop, close_loops
from mbplan.simulation import integrate_aba
from mbplan.simulation.closed_loop import ClosedLoopDynamics, closed_loop_actuation
from mbplan.simulation.reference import damping_rate

PUSH = 2.0  # 1/s²: scale of the pushes s (module docstring)
START_TOLERANCE = 1e-14  # m or rad: q₀ closes the loops to round-off


@dataclass(frozen=True, eq=False)
class LoopScenario:
    """The motion and torques of the module docstring (arrays in Pinocchio's ``v`` order)."""

    model: pin.Model  # with the damping of the run (model.damping)
    dynamics: ClosedLoopDynamics
    q0: np.ndarray  # (nq,)
    hold: np.ndarray  # (nv,)
    push: np.ndarray  # (nv,)
    push_omega: np.ndarray  # (nv,)

    def torque(self, t: float) -> np.ndarray:
        """Joint torques ``τ(t)`` (N·m, N for prismatic joints), ``(nv,)``."""
        return self.hold + self.push * np.sin(self.push_omega * t) ** 2

    def reference_step(self, dt_min: float) -> int:
        """RK4 substeps per ``dt_min``: at least 16, and a step of at most ``0.5/λ_max`` of the
        damping."""
        return max(16, math.ceil(dt_min * damping_rate(self.model, self.q0) / 0.5))

    def reference(self, h: float, n: int, substeps: int) -> tuple[np.ndarray, np.ndarray]:
        """``q (n+1, nq)`` and ``v (n+1, nv)`` at ``t = k h`` (RK4 on the constrained
        dynamics)."""
        q, v = self.q0.copy(), np.zeros(self.model.nv)
        qs, vs = [q], [v]
        for k in range(n):
            t0 = k * h
            q, v = integrate_aba(
                self.model,
                q,
                v,
                lambda s, t0=t0: self.torque(t0 + s),
                h,
                substeps,
                acceleration=self.dynamics,
            )
            qs.append(q)
            vs.append(v)
        return np.array(qs), np.array(vs)

    def euler(self, dt: float, N: int) -> np.ndarray:
        """Baseline of order 1: ``v⁺ = v + Δt q̈(q, v, τ)``, ``q⁺ = q ⊕ Δt v⁺``; ``(N+1, nq)``."""
        q, v = self.q0.copy(), np.zeros(self.model.nv)
        qs = [q]
        for k in range(N):
            v = v + dt * self.dynamics(q, v, self.torque(k * dt))
            q = pin.integrate(self.model, q, dt * v)
            qs.append(q)
        return np.array(qs)


def loop_scenario(
    model: pin.Model, loops: Sequence[Loop], passive: Sequence[str], seed: int
) -> LoopScenario:
    """The seeded scenario of ``model`` with the closures ``loops`` and the ``passive`` joints
    (module docstring); :class:`InputError` if the loops do not close near neutral."""
    rng = np.random.default_rng(seed)
    neutral, gap = close_loops(model, loops, pin.neutral(model))
    if gap > CLOSE_TOLERANCE:
        raise InputError(f"{model.name}: the loops do not close near the neutral configuration")
    passive_v = [model.joints[model.getJointId(j)].idx_v for j in passive]
    active = np.setdiff1d(np.arange(model.nv), passive_v)
    q = neutral.copy()
    q[active] += rng.uniform(-0.3, 0.3, len(active))  # 1-dof joints: q and v indices agree
    q0, gap = close_loops(model, loops, q, fixed=active, tolerance=START_TOLERANCE)
    if gap > START_TOLERANCE:
        q0 = close_loops(model, loops, neutral, tolerance=START_TOLERANCE)[0]
    data = model.createData()
    gravity = pin.rnea(model, data, q0, np.zeros(model.nv), np.zeros(model.nv))
    hold = closed_loop_actuation(model, loops, active, q0, gravity)
    M = pin.crba(model, data, q0)
    M = np.triu(M) + np.triu(M, 1).T
    push = np.zeros(model.nv)
    push[active] = PUSH * (M @ rng.uniform(-1.0, 1.0, model.nv))[active]
    omega = rng.uniform(5.0, 15.0, model.nv)
    return LoopScenario(model, ClosedLoopDynamics(model, loops), q0, hold, push, omega)
