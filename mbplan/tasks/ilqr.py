"""The thesis' iLQR experiments (Lin 2025, §4) as :class:`~mbplan.shooting.ShootingProblem` s.

Values from ``/work/shared/specs/lie-ilqr-thesis.md`` §2.6: inertia ``J = diag(0.5, 0.7, 0.9)``
(SE(3): ``m = 1``), terminal weights 1.5x the stage weights, horizons, time steps and iteration
caps of the thesis' scripts. SE(3) tangents are in mbplan's ``(v, ω)`` order, so the thesis'
``diag(Q_rot, Q_trans, Q_ω, Q_v)`` appears as ``(Q_trans, Q_rot, Q_v, Q_ω)``.

References are generated here (no thesis data files):

* ``so3-tracking`` (A): ``R_ref(t) = R_y(θ_y) R_x(θ_x)``, ``θ_x = (π/3) sin(πt/5)``,
  ``θ_y = (π/2) sin(2πt/5)``, and ``ω_ref,k = log(R_kᵀR_{k+1})/h`` so that the reference is
  exactly Euler-consistent, as the thesis' data file is.
* ``se3-tracking`` (B2): forward Euler ``X_{k+1} = X_k exp(h ξ(t_k))`` from ``X_0 = I`` with
  ``ω = (2 sin t, 0, 1)``, ``v = (2, cos √20 t, sin √20 t)`` (each sample's own velocity; the
  thesis' file uses the next sample's).
* ``pendulum`` (C): fixed upright target ``R_ref = diag(1, -1, -1)``, ``ω_ref = 0``.
* ``drone`` (in the spirit of B1/D; the racing data is not ours): a differentially flat
  figure-eight entered from hover, ``p = (4 sin θ, 2 sin 2θ, 1.5 + 0.5 sin θ)``, ``θ = 1.25t²/2``,
  yaw ``0.3t``, attitude with body z along ``p̈ + g e_z``; twists ``log(X_k⁻¹X_{k+1})/h``; 150
  steps at ``h = 0.004`` s as in D. ``drone`` with the LGVI is the maximal-coordinate version
  on SO(3) × R³ × R³ × R³ (world velocity), tracking the same poses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mbplan.lie import SE3, SO3
from mbplan.shooting import (
    ShootingProblem,
    TrackingCost,
    drone_forcing,
    euler_poincare_euler,
    fully_actuated,
    pendulum_forcing,
    quadrotor_lgvi,
    rotation_lgvi,
)

INERTIA = np.diag([0.5, 0.7, 0.9])
GRAVITY = 9.8
DOWN = np.array([0.0, 0.0, -1.0])
HESSIAN = "exact"
SCENARIOS = ("so3-tracking", "se3-tracking", "pendulum", "drone")


def rot_x(a: float) -> np.ndarray:
    return SO3.exp([a, 0.0, 0.0])


def rot_y(a: float) -> np.ndarray:
    return SO3.exp([0.0, a, 0.0])


def rot_z(a: float) -> np.ndarray:
    return SO3.exp([0.0, 0.0, a])


def thesis_initial_rotation(z_deg: float, x_deg: float, y_deg: float) -> np.ndarray:
    """``R_y R_x R_z`` (§4-3)."""
    z, x, y = np.deg2rad([z_deg, x_deg, y_deg])
    return rot_y(y) @ rot_x(x) @ rot_z(z)


@dataclass(frozen=True)
class Scenario:
    """A thesis experiment: its shooting problem and the data the baselines need."""

    name: str
    problem: ShootingProblem
    group: object
    dt: float
    max_iter: int
    inertia: np.ndarray
    """``J_b`` in mbplan's tangent order."""
    integrator: str
    """``euler`` (thesis 2-38/39) or ``lgvi``."""
    forcing: str
    """``wrench``, ``pendulum`` or ``drone``."""
    baseline_weights: dict
    """Weights of the embedded IPOPT formulations (α_q, α_X, Q_P, ...; thesis §2.5/2.6)."""


def _twists_between(group, X: np.ndarray, dt: float) -> np.ndarray:
    xi = group.log(group.compose(group.inverse(X[:-1]), X[1:])) / dt
    return np.vstack([xi, xi[-1:]])


def _rigid_body_problem(dyn, x0_parts, Xref, xiref, uref, wq, wu, jit) -> ShootingProblem:
    space = dyn.space
    return ShootingProblem(
        dynamics=dyn,
        cost=TrackingCost(space, dyn.nu, hessian=HESSIAN, jit=jit),
        x0=space.pack(x0_parts),
        x_ref=space.pack([Xref, xiref]),
        u_ref=uref,
        state_weights=wq,
        input_weights=wu,
        terminal_weights=1.5 * np.asarray(wq),
    )


def so3_tracking(integrator: str = "euler", *, jit: bool = True) -> Scenario:
    """Scenario A: fully actuated SO(3) tracking of the 8-shape (§4-3)."""
    dt, N = 0.04, 249
    t = dt * np.arange(N + 1)
    Xref = np.stack(
        [
            rot_y(np.pi / 2 * np.sin(2 * np.pi * s / 5)) @ rot_x(np.pi / 3 * np.sin(np.pi * s / 5))
            for s in t
        ]
    )
    wref = _twists_between(SO3, Xref, dt)
    dyn = _rotation_dynamics("so3_wrench", integrator, dt, fully_actuated, jit)
    problem = _rigid_body_problem(
        dyn,
        [thesis_initial_rotation(90, 10, 45), np.full(3, 0.15)],
        Xref,
        wref,
        np.zeros((N, 3)),
        [10.0] * 3 + [1.0] * 3,
        [1e-3] * 3,
        jit,
    )
    return Scenario(
        "so3-tracking",
        problem,
        SO3,
        dt,
        50,
        INERTIA,
        integrator,
        "wrench",
        {"alpha_q": 250.0, "alpha_X": 10.0, "Q_w": 1.0, "R": 1e-3},
    )


def pendulum(integrator: str = "euler", *, jit: bool = True) -> Scenario:
    """Scenario C: swing-up of a 3-D pendulum driven by its pivot acceleration (§4-5)."""
    dt, N = 0.025, 80
    forcing = pendulum_forcing(1.0, np.array([0.0, 0.0, -0.25]), GRAVITY, DOWN)
    dyn = _rotation_dynamics("pendulum", integrator, dt, forcing, jit)
    Xref = np.broadcast_to(np.diag([1.0, -1.0, -1.0]), (N + 1, 3, 3))
    problem = _rigid_body_problem(
        dyn,
        [thesis_initial_rotation(0, 10, 45), np.array([1.0, 1.0, 0.0])],
        Xref,
        np.zeros((N + 1, 3)),
        np.zeros((N, 3)),
        [10.0] * 3 + [1.0] * 3,
        [1e-2] * 3,
        jit,
    )
    return Scenario(
        "pendulum",
        problem,
        SO3,
        dt,
        100,
        INERTIA,
        integrator,
        "pendulum",
        {"alpha_q": 10.0, "alpha_X": 10.0, "Q_w": 1.0, "R": 1e-2},
    )


def _rotation_dynamics(name: str, integrator: str, dt: float, forcing: Callable, jit: bool):
    if integrator == "euler":
        return euler_poincare_euler(f"{name}_euler", SO3, INERTIA, dt, 3, forcing, jit=jit)
    if integrator == "lgvi":
        return rotation_lgvi(
            f"{name}_lgvi", INERTIA, dt, 3, lambda R, w, u: forcing(R, w, u), jit=jit
        )
    raise ValueError(f"unknown integrator {integrator!r} (euler or lgvi)")


SE3_INERTIA = np.diag([1.0, 1.0, 1.0, 0.5, 0.7, 0.9])  # (m I₃, J) in (v, ω) order
SE3_WEIGHTS = [10.0] * 3 + [25.0] * 3 + [1.0] * 6  # thesis Q = diag(25 rot, 10 trans, I, I)


def se3_tracking(*, jit: bool = True) -> Scenario:
    """Scenario B2: fully actuated SE(3) tracking of the generated sine reference (§4-4-2)."""
    dt, N = 0.05, 200
    t = dt * np.arange(N + 1)
    r20 = np.sqrt(20.0)
    xi = np.column_stack(
        [np.full_like(t, 2.0), np.cos(r20 * t), np.sin(r20 * t), 2 * np.sin(t), 0 * t, 0 * t + 1]
    )
    Xref = [np.eye(4)]
    for k in range(N):
        Xref.append(Xref[-1] @ SE3.exp(dt * xi[k]))
    Xref = np.stack(Xref)
    X0 = np.eye(4)
    X0[:3, :3] = thesis_initial_rotation(90, 10, 45)
    X0[:3, 3] = Xref[0, :3, 3] - 1.0
    dyn = euler_poincare_euler("se3_wrench_euler", SE3, SE3_INERTIA, dt, 6, fully_actuated, jit=jit)
    problem = _rigid_body_problem(
        dyn, [X0, np.full(6, 0.1)], Xref, xi, np.zeros((N, 6)), SE3_WEIGHTS, [1e-3] * 6, jit
    )
    return Scenario(
        "se3-tracking",
        problem,
        SE3,
        dt,
        200,
        SE3_INERTIA,
        "euler",
        "wrench",
        {"alpha_q": 250.0, "alpha_X": 25.0, "Q_P": 250.0, "Q_w": 1.0, "R": 1e-3},
    )


def figure_eight_reference(dt: float, N: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat-output drone reference from hover: poses ``(N+1, 4, 4)`` and Euler-consistent twists.

    ``p = (4 sin θ, 2 sin 2θ, 1.5 + 0.5 sin θ)`` with ``θ(t) = βt²/2`` (``β = 1.25``: 0 to
    ≈ 3 m/s over 0.6 s), yaw ``0.3t``, body z along ``p̈ + g e_z``.
    """
    beta = 1.25
    t = dt * np.arange(N + 1)
    th, thd, thdd = 0.5 * beta * t**2, beta * t, beta + 0 * t

    def f(a, w):  # a sin(wθ) and its second time derivative
        return a * np.sin(w * th), a * (
            -(w**2) * np.sin(w * th) * thd**2 + w * np.cos(w * th) * thdd
        )

    (px, ax), (py, ay), (pz, az) = f(4, 1), f(2, 2), f(0.5, 1)
    p = np.column_stack([px, py, 1.5 + pz])
    acc = np.column_stack([ax, ay, az])
    X = np.zeros((N + 1, 4, 4))
    for k in range(N + 1):
        b3 = acc[k] + np.array([0.0, 0.0, GRAVITY])
        b3 /= np.linalg.norm(b3)
        heading = np.array([np.cos(0.3 * t[k]), np.sin(0.3 * t[k]), 0.0])
        b2 = np.cross(b3, heading)
        b2 /= np.linalg.norm(b2)
        X[k, :3, :3] = np.column_stack([np.cross(b2, b3), b2, b3])
        X[k, :3, 3] = p[k]
        X[k, 3, 3] = 1.0
    return X, _twists_between(SE3, X, dt)


def drone(*, jit: bool = True) -> Scenario:
    """Quadrotor on SE(3) tracking the generated figure-eight (in the spirit of §4-4-1/§4-6)."""
    dt, N = 0.004, 150
    Xref, xiref = figure_eight_reference(dt, N)
    X0 = np.eye(4)
    X0[:3, 3] = Xref[0, :3, 3] - 0.1
    dyn = euler_poincare_euler(
        "drone_euler", SE3, SE3_INERTIA, dt, 4, drone_forcing(1.0, GRAVITY, DOWN), jit=jit
    )
    uref = np.zeros((N, 4))
    problem = _rigid_body_problem(
        dyn, [X0, np.full(6, 1e-3)], Xref, xiref, uref, SE3_WEIGHTS, [1e-5] * 4, jit
    )
    return Scenario(
        "drone",
        problem,
        SE3,
        dt,
        200,
        SE3_INERTIA,
        "euler",
        "drone",
        {"alpha_q": 25.0, "alpha_X": 25.0, "Q_P": 1000.0, "Q_w": 1.0, "R": 1e-5},
    )


def drone_lgvi(*, jit: bool = True) -> Scenario:
    """The drone task in maximal coordinates: state ``(R, p, ω, v)`` on SO(3) × R³ × R³ × R³
    (world velocity), LGVI dynamics; same reference, weights, initial offsets and horizon."""
    dt, N = 0.004, 150
    Xref, _ = figure_eight_reference(dt, N)
    Rref, pref = Xref[:, :3, :3], Xref[:, :3, 3]
    wref = _twists_between(SO3, Rref, dt)
    vref = np.vstack([np.diff(pref, axis=0) / dt, (pref[-1] - pref[-2]) / dt])
    dyn = quadrotor_lgvi("drone_lgvi", INERTIA, 1.0, GRAVITY * DOWN, dt, jit=jit)
    space = dyn.space
    wq = [25.0] * 3 + [10.0] * 3 + [1.0] * 6
    x0 = space.pack([np.eye(3), pref[0] - 0.1, np.full(3, 1e-3), np.full(3, 1e-3)])
    problem = ShootingProblem(
        dynamics=dyn,
        cost=TrackingCost(space, 4, hessian=HESSIAN, jit=jit),
        x0=x0,
        x_ref=space.pack([Rref, pref, wref, vref]),
        u_ref=np.zeros((N, 4)),
        state_weights=wq,
        input_weights=[1e-5] * 4,
        terminal_weights=1.5 * np.asarray(wq),
    )
    return Scenario(
        "drone",
        problem,
        SO3,
        dt,
        200,
        INERTIA,
        "lgvi",
        "drone",
        {"alpha_q": 25.0, "alpha_X": 25.0, "Q_P": 1000.0, "Q_w": 1.0, "R": 1e-5},
    )


def build(name: str, integrator: str = "euler", *, jit: bool = True) -> Scenario:
    if name == "so3-tracking":
        return so3_tracking(integrator, jit=jit)
    if name == "pendulum":
        return pendulum(integrator, jit=jit)
    if name == "drone" and integrator == "lgvi":
        return drone_lgvi(jit=jit)
    if integrator != "euler":
        raise ValueError(f"{name}: only the thesis' forward Euler is implemented")
    if name == "se3-tracking":
        return se3_tracking(jit=jit)
    if name == "drone":
        return drone(jit=jit)
    raise ValueError(f"unknown scenario {name!r}; choose from {', '.join(SCENARIOS)}")
