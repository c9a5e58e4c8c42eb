"""Single-rigid-body LGVI residuals on SO(3)×R³ (RIPM paper §V.B, eq. 30–35 and forced form 60).

State per knot: orientation ``R``, COM position ``p``, discrete pose change ``F = Rᵀ R⁺`` and
linear velocity ``v``. ``J`` is the paper's non-standard inertia ``I^b`` with
``I_b = tr(J) I₃ - J`` (eq. 33). Every function takes and returns CasADi SX expressions, for use
as the ``residual`` of a :class:`mbplan.engine.RiemannianFunction`.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from mbplan.lie import SO3


def rotational_kinematics(R0: cs.SX, R1: cs.SX, F0: cs.SX) -> cs.SX:
    """``R₁ = R₀F₀`` (eq. 30) as ``cay⁻¹(R₁ᵀ R₀ F₀) = 0``, the inverse Cayley map
    ``cay⁻¹(M) = 2 (M - Mᵀ)^∨ / (1 + tr M)``, which is ``2 tan(θ/2) a`` for ``M = exp(θ a)``.

    Table I row 1 writes the residual as ``log(R₁ᵀ R₀ F₀)`` (``θ a``). The two differ by
    ``θ³/12 a + O(θ⁵)``, so wherever the constraint holds they have the same value, Jacobian
    and Lagrangian Hessian. For ``|θ| < π`` both vanish only at ``M = I``; the skew part alone
    would also vanish at ``θ = π``. Being rational in the entries of the rotations, its
    derivatives cost about half the symbolic log's with its branches
    (measured on the drone).

    Domain: ``|θ| < π``. The residual grows like ``tan(θ/2)`` towards ``θ = π`` and a Newton
    step on it there is short (``≈ -sin θ``), so convergence from near ``π`` is slower; at
    ``θ = π`` it is ``0/0`` (rounding) and the RIPM reports a failure. Points built by the
    formulations (``F_k = R_kᵀ R_{k+1}``) have ``θ = 0``."""
    M = cs.mtimes([R1.T, R0, F0])
    return SO3.vee(M - M.T) * (2.0 / (1.0 + cs.trace(M)))


def translational_kinematics(p0: cs.SX, p1: cs.SX, v0: cs.SX, dt: cs.SX) -> cs.SX:
    """``p₁ - p₀ - v₀ Δt = 0`` (eq. 30, 32; Table I row 2)."""
    return p1 - p0 - v0 * dt


def rotational_dynamics(
    F0: cs.SX, F1: cs.SX, J: cs.SX, dt: cs.SX, torque: cs.SX | None = None
) -> cs.SX:
    """``(F₁J - JF₁ᵀ - (JF₀ - F₀ᵀJ))^∨ - τ Δt² = 0`` (eq. 34; with body torque τ, eq. 60)."""
    skew = cs.mtimes(F1, J) - cs.mtimes(J, F1.T) - cs.mtimes(J, F0) + cs.mtimes(F0.T, J)
    out = SO3.vee(skew)
    return out if torque is None else out - torque * dt**2


def translational_dynamics(
    v0: cs.SX, v1: cs.SX, mass: cs.SX, gravity: cs.SX, dt: cs.SX, force: cs.SX | None = None
) -> cs.SX:
    """``m v₁ - m v₀ - m g Δt - f Δt = 0`` (eq. 35; with world force f, eq. 60)."""
    out = mass * (v1 - v0) - mass * gravity * dt
    return out if force is None else out - force * dt


def body_kinematics(
    R0: cs.SX, R1: cs.SX, F0: cs.SX, p0: cs.SX, p1: cs.SX, v0: cs.SX, dt: cs.SX
) -> cs.SX:
    """``R₁ = R₀F₀``, ``p₁ = p₀ + v₀Δt`` (eq. 30): Table I rows 1–2, 6 residuals."""
    return cs.vertcat(rotational_kinematics(R0, R1, F0), translational_kinematics(p0, p1, v0, dt))


def body_dynamics(
    F0: cs.SX,
    F1: cs.SX,
    v0: cs.SX,
    v1: cs.SX,
    J: cs.SX,
    mass: cs.SX,
    gravity: cs.SX,
    dt: cs.SX,
    torque: cs.SX | None = None,
    force: cs.SX | None = None,
) -> cs.SX:
    """Forced LGVI (eq. 34–35, 60): Table I rows 3–4, 6 residuals; forces act at the new knot.

    The rows are divided by ``Δt²`` and ``Δt`` so that they read as torques (N·m) and forces (N):
    the same roots as eq. (34)–(35), but rows of comparable size to the joint constraints, which
    keeps the KKT systems of the interior point method well scaled for any ``Δt``.
    """
    return cs.vertcat(
        rotational_dynamics(F0, F1, J, dt, torque) / dt**2,
        translational_dynamics(v0, v1, mass, gravity, dt, force) / dt,
    )


QUADROTOR_ACTUATION = np.eye(6, 4, -2)
"""``B`` of a quadrotor (eq. 60): ``u = (u_z, τ)`` gives the body wrench ``(0, 0, u_z, τ)``."""


def quadrotor_step(
    R0: cs.SX,
    R1: cs.SX,
    F0: cs.SX,
    F1: cs.SX,
    p0: cs.SX,
    p1: cs.SX,
    v0: cs.SX,
    v1: cs.SX,
    u: cs.SX,
    J: cs.SX,
    mass: cs.SX,
    gravity: cs.SX,
    dt: cs.SX,
) -> cs.SX:
    """One LGVI step of a rigid body with thrust along body z and body torques (eq. 30–35, 60):
    :func:`free_body_step` with :data:`QUADROTOR_ACTUATION`. The 12 residuals are Table I rows
    1–4 with the forcing of eq. (60)."""
    B = cs.DM(QUADROTOR_ACTUATION)
    return free_body_step(R0, R1, F0, F1, p0, p1, v0, v1, u, J, mass, gravity, dt, B)


def free_body_step(
    R0: cs.SX,
    R1: cs.SX,
    F0: cs.SX,
    F1: cs.SX,
    p0: cs.SX,
    p1: cs.SX,
    v0: cs.SX,
    v1: cs.SX,
    u: cs.SX,
    J: cs.SX,
    mass: cs.SX,
    gravity: cs.SX,
    dt: cs.SX,
    B: cs.SX,
) -> cs.SX:
    """One LGVI step of a free body whose input ``u`` gives the body wrench ``(f, τ) = B u``
    (eq. 30–35 with the forcing of eq. 60: ``f`` rotated to the world by ``R₁``)."""
    force = cs.mtimes(R1, cs.mtimes(B[:3, :], u))
    return cs.vertcat(
        body_kinematics(R0, R1, F0, p0, p1, v0, dt),
        body_dynamics(F0, F1, v0, v1, J, mass, gravity, dt, cs.mtimes(B[3:, :], u), force),
    )
