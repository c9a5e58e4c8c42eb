"""Reference trajectories in generalized coordinates: Pinocchio's ABA with fine RK4 steps."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin


def damped_aba(
    model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, tau: np.ndarray
) -> np.ndarray:
    """``q̈ = M(q)⁻¹ (τ - D v - h(q, v))``: ABA with the model's viscous joint damping
    ``D = diag(model.damping)`` (Pinocchio's ABA ignores ``model.damping``)."""
    return pin.aba(model, data, q, v, np.asarray(tau) - model.damping * v)


def mass_matrix(model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    """``M(q)``, symmetric (Pinocchio's CRBA fills the upper triangle)."""
    M = np.triu(pin.crba(model, data, q))
    return M + np.triu(M, 1).T


def damping_rate(model: pin.Model, q: np.ndarray) -> float:
    """``λ_max(M(q)⁻¹ D)`` (1/s): the fastest decay rate of the viscous joint damping."""
    if not np.any(model.damping):
        return 0.0
    M = mass_matrix(model, model.createData(), q)
    return float(np.max(np.linalg.eigvals(np.linalg.solve(M, np.diag(model.damping))).real))


def damped_euler_velocity(
    model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float
) -> np.ndarray:
    """``v⁺`` of the Euler step ``M(q) (v⁺ - v)/Δt = τ - h(q, v) - D v⁺``: explicit in ``h``,
    implicit in the viscous damping (stable for any ``λ(M⁻¹D) Δt``; eq. 61 as
    :mod:`mbplan.formulations.generalized` writes it)."""
    a = pin.aba(model, data, q, v, tau)
    if not np.any(model.damping):
        return v + dt * a
    M = mass_matrix(model, data, q)
    return v + dt * np.linalg.solve(M + dt * np.diag(model.damping), M @ a - model.damping * v)


def integrate_aba(
    model: pin.Model,
    q0: np.ndarray,
    v0: np.ndarray,
    tau: np.ndarray | Callable[[float], np.ndarray],
    T: float,
    substeps: int,
    tau_end: np.ndarray | None = None,
    *,
    damping: bool = False,
    acceleration: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(q(T), v(T))`` by RK4 on the configuration manifold for constant ``tau``, or, with
    ``tau_end``, the torque ramping linearly from ``tau`` at 0 to ``tau_end`` at ``T``
    (first-order hold; RK4 samples it at each stage's time, so it stays fourth order), or a
    callable ``tau(t)``, ``t`` from 0 to ``T``. With ``damping``, the model's viscous
    joint damping applies (:func:`damped_aba`). ``acceleration(q, v, τ)``: the forward dynamics
    to integrate instead of ABA (e.g. :class:`~mbplan.simulation.closed_loop.ClosedLoopDynamics`;
    ``damping`` is then its own)."""
    data = model.createData()
    h = T / substeps
    q, v = np.array(q0, dtype=float), np.array(v0, dtype=float)
    if callable(tau):
        torque = tau
    else:
        tau0 = np.asarray(tau, dtype=float)
        slope = None if tau_end is None else (np.asarray(tau_end, dtype=float) - tau0) / T

        def torque(t: float) -> np.ndarray:
            return tau0 if slope is None else tau0 + t * slope

    forward = damped_aba if damping else pin.aba

    def acc(qq: np.ndarray, vv: np.ndarray, t: float) -> np.ndarray:
        if acceleration is not None:
            return acceleration(qq, vv, torque(t))
        return forward(model, data, qq, vv, torque(t))

    for i in range(substeps):
        t = i * h
        k1v, k1a = v, acc(q, v, t)
        q2 = pin.integrate(model, q, 0.5 * h * k1v)
        k2v, k2a = v + 0.5 * h * k1a, acc(q2, v + 0.5 * h * k1a, t + 0.5 * h)
        q3 = pin.integrate(model, q, 0.5 * h * k2v)
        k3v, k3a = v + 0.5 * h * k2a, acc(q3, v + 0.5 * h * k2a, t + 0.5 * h)
        q4 = pin.integrate(model, q, h * k3v)
        k4v, k4a = v + h * k3a, acc(q4, v + h * k3a, t + h)
        q = pin.integrate(model, q, h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v))
        v = v + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
    return q, v
