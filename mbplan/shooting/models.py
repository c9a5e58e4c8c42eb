"""Rigid-body dynamics on G × 𝔤 for shooting: forced Euler–Poincaré by forward Euler (thesis
2-27/28, 2-38/39) and the Lie group variational integrator on SO(3) × R³.

State ``x = (𝒳, ξ)`` with ``𝒳 ∈ SO(3)`` or ``SE(3)`` and body velocity ``ξ`` (mbplan's tangent
ordering: ``(v, ω)`` on SE(3)). Euler–Poincaré: ``J_b ξ̇ = ad_ξᵀ J_b ξ + f(𝒳, ξ, u)`` (for SO(3)
``ad_ξᵀ J ω = -ω × Jω``).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as cs
import numpy as np

from mbplan.lie import SO3, R
from mbplan.robots.free_body import FreeBody
from mbplan.shooting.dynamics import DiscreteDynamics
from mbplan.shooting.space import StateSpace

Forcing = Callable[[cs.SX, cs.SX, cs.SX], cs.SX]


def rigid_body_space(group) -> StateSpace:
    """``G × R^dim(G)``."""
    return StateSpace([group, R(group.dim)])


def euler_poincare_euler(
    name: str,
    group,
    inertia: np.ndarray,
    dt: float,
    nu: int,
    forcing: Forcing,
    *,
    jit: bool = True,
) -> DiscreteDynamics:
    """Forward Euler on both parts (2-38/39): ``𝒳⁺ = 𝒳 exp(hξ)``,
    ``ξ⁺ = ξ + h J_b⁻¹(ad_ξᵀ J_b ξ + f(𝒳, ξ, u))``; ``inertia`` is ``J_b`` (dim x dim)."""
    Jb = np.asarray(inertia, dtype=float)
    Jinv = cs.DM(np.linalg.inv(Jb))
    Jb = cs.DM(Jb)

    def step(parts, u):
        X, xi = parts
        mom = cs.mtimes(Jb, xi)
        rhs = cs.mtimes(group.ad(xi).T, mom) + forcing(X, xi, u)
        return [cs.mtimes(X, group.exp(dt * xi)), xi + dt * cs.mtimes(Jinv, rhs)]

    return DiscreteDynamics(name, rigid_body_space(group), nu, step, jit=jit)


def fully_actuated(X: cs.SX, xi: cs.SX, u: cs.SX) -> cs.SX:
    """Body wrench ``u`` (2-29)."""
    return u


def pendulum_forcing(mass: float, com: np.ndarray, gravity: float, down: np.ndarray) -> Forcing:
    """3-D pendulum on a moving pivot (§4-5): ``m g ρ × Rᵀe₃ + m ρ × Rᵀu``, ``u`` the pivot's
    inertial acceleration (rank 2: no torque about ρ)."""
    rho = cs.DM(np.asarray(com, dtype=float))
    e3 = cs.DM(np.asarray(down, dtype=float))

    def f(Rm, xi, u):
        return mass * gravity * cs.cross(rho, cs.mtimes(Rm.T, e3)) + mass * cs.cross(
            rho, cs.mtimes(Rm.T, u)
        )

    return f


def drone_forcing(mass: float, gravity: float, down: np.ndarray) -> Forcing:
    """Quadrotor on SE(3) (§4-6): gravity ``m g Rᵀe₃`` on the body force, ``u = (f_z, τ)``:
    collective thrust along body z and three body torques."""
    e3 = cs.DM(np.asarray(down, dtype=float))

    def f(X, xi, u):
        Rm = X[:3, :3]
        force = mass * gravity * cs.mtimes(Rm.T, e3) + cs.vertcat(0, 0, u[0])
        return cs.vertcat(force, u[1:4])

    return f


def _rotation_step_solver(Jd: np.ndarray, newton: int) -> Callable[[cs.SX, cs.SX], cs.SX]:
    """``(F_start, target) ↦ F`` solving ``(F J_d - J_d Fᵀ)^∨ = target`` (RIPM paper eq. 34) by
    ``newton`` Newton steps on SO(3), ``F ← F exp(ξ)`` with ``ξ`` from the Jacobian
    ``ξ ↦ (F ξ^ J_d + J_d ξ^ Fᵀ)^∨`` at ``ξ = 0``."""
    J = cs.DM(Jd)
    Fs, target_s = cs.SX.sym("F", 3, 3), cs.SX.sym("target", 3)
    res = SO3.vee(cs.mtimes(Fs, J) - cs.mtimes(J, Fs.T)) - target_s
    E = [cs.DM(SO3.hat(e)) for e in np.eye(3)]
    jac = cs.horzcat(*[SO3.vee(cs.mtimes([Fs, e, J]) + cs.mtimes([J, e, Fs.T])) for e in E])
    xi = -cs.solve(jac, res)
    newton_step = cs.Function("lgvi_newton", [Fs, target_s], [cs.mtimes(Fs, SO3.exp(xi))])

    def solve(F: cs.SX, target: cs.SX) -> cs.SX:
        for _ in range(newton):
            F = newton_step(F, target)
        return F

    return solve


def _rotation_lgvi_step(inertia: np.ndarray, dt: float, newton: int):
    """``(R, ω, τ, τ⁺(R⁺)) ↦ (R⁺, ω⁺)`` of the rotational LGVI (shared by both models)."""
    Ib = np.asarray(inertia, dtype=float)
    solve = _rotation_step_solver(0.5 * np.trace(Ib) * np.eye(3) - Ib, newton)
    Iinv = cs.DM(np.linalg.inv(Ib))
    Ib_dm = cs.DM(Ib)

    def rotate(Rm, w, tau, tau_next: Callable):
        Pi = cs.mtimes(Ib_dm, w)
        F = solve(SO3.exp(dt * w), dt * Pi + 0.5 * dt**2 * tau)
        R_next = cs.mtimes(Rm, F)
        Pi_next = cs.mtimes(F.T, Pi) + 0.5 * dt * (cs.mtimes(F.T, tau) + tau_next(R_next))
        return R_next, cs.mtimes(Iinv, Pi_next)

    return rotate


def rotation_lgvi(
    name: str,
    inertia: np.ndarray,
    dt: float,
    nu: int,
    torque: Forcing,
    *,
    newton: int = 8,
    jit: bool = True,
) -> DiscreteDynamics:
    """Lie group variational integrator of a rotating rigid body on SO(3) × R³ (state ``(R, ω)``).

    With ``J_d = tr(I)/2·I₃ - I`` and ``Π = Iω``: solve ``(F J_d - J_d Fᵀ)^∨ = hΠ + (h²/2)τ`` for
    ``F = exp(f)`` (``newton`` Newton iterations on ``f`` from ``hω``), then ``R⁺ = R F`` and
    ``Π⁺ = FᵀΠ + (h/2)(Fᵀτ + τ⁺)`` with ``τ⁺ = τ(R⁺, u)`` (inputs held over the step).
    """
    rotate = _rotation_lgvi_step(inertia, dt, newton)

    def step(parts, u):
        Rm, w = parts
        return list(rotate(Rm, w, torque(Rm, w, u), lambda Rn: torque(Rn, w, u)))

    return DiscreteDynamics(name, rigid_body_space(SO3), nu, step, jit=jit)


def quadrotor_lgvi(
    name: str,
    inertia: np.ndarray,
    mass: float,
    gravity: np.ndarray,
    dt: float,
    *,
    newton: int = 8,
    jit: bool = True,
) -> DiscreteDynamics:
    """Quadrotor LGVI on SO(3) × R³ × R³ × R³, state ``(R, p, ω, v)`` with world velocity ``v``,
    input ``u = (f_z, τ)`` (RIPM paper eq. 30–35 with the forcing of eq. 60: thrust ``R⁺e_z f_z``
    at the new knot): the rotational LGVI of :func:`rotation_lgvi` with body torque ``τ``,
    ``v⁺ = v + h(g + R⁺e_z f_z/m)``, ``p⁺ = p + h v``."""
    rotate = _rotation_lgvi_step(inertia, dt, newton)
    g = cs.DM(np.asarray(gravity, dtype=float))
    ez = cs.DM([0.0, 0.0, 1.0])

    def step(parts, u):
        Rm, p, w, v = parts
        tau = u[1:4]
        R_next, w_next = rotate(Rm, w, tau, lambda Rn: tau)
        v_next = v + dt * (g + cs.mtimes(R_next, ez) * u[0] / mass)
        return [R_next, p + dt * v, w_next, v_next]

    space = StateSpace([SO3, R(3), R(3), R(3)])
    return DiscreteDynamics(name, space, 4, step, jit=jit)


FREE_BODY_SPACE = StateSpace([SO3, R(3), SO3, R(3)])
"""State ``(R, p, F, v)`` of a free body's LGVI: orientation, COM position, rotation step
``F_k = R_kᵀ R_{k+1}`` and world velocity (RIPM paper eq. 30)."""


def free_body_lgvi(
    name: str, body: FreeBody, dt: float, *, newton: int = 8, jit: bool = True
) -> DiscreteDynamics:
    """The forced LGVI of a :class:`~mbplan.robots.free_body.FreeBody` as an explicit step on
    :data:`FREE_BODY_SPACE` (RIPM paper eq. 30–35, 60; the knots of its maximal formulation):
    with the body wrench ``(f, τ) = B u``, ``R⁺ = R F``, ``p⁺ = p + Δt v``, ``F⁺`` solving
    ``(F⁺J - JF⁺ᵀ)^∨ = (JF - FᵀJ)^∨ + Δt² τ`` (``newton`` Newton steps from ``F``) and
    ``v⁺ = v + Δt (g + R⁺ f / m)``."""
    J = body.nonstandard_inertia
    solve = _rotation_step_solver(J, newton)
    B, g, Jd = cs.DM(body.actuation), cs.DM(body.gravity), cs.DM(J)

    def step(parts, u):
        Rm, p, F, v = parts
        wrench = cs.mtimes(B, u)
        R_next = cs.mtimes(Rm, F)
        target = SO3.vee(cs.mtimes(Jd, F) - cs.mtimes(F.T, Jd)) + dt**2 * wrench[3:]
        v_next = v + dt * (g + cs.mtimes(R_next, wrench[:3]) / body.mass)
        return [R_next, p + dt * v, solve(F, target), v_next]

    return DiscreteDynamics(name, FREE_BODY_SPACE, body.nu, step, jit=jit)
