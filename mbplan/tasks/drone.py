"""Quadrotor docking task of the RIPM paper §VIII.B as data, its sampler and a simulator.

State at knot ``k = 0..N`` is ``x_k = (R_k, p_k, F_k, v_k)`` ∈ SO(3)×R³×SO(3)×R³: orientation,
position, discrete pose change ``F_k = R_kᵀ R_{k+1}`` and linear velocity over ``[t_k, t_{k+1}]``
(so ``(F_N, v_N)`` is the terminal twist). Inputs ``u_k = (u_z, τ) ∈ R⁴``, ``k = 0..N-1``: total
thrust along the body z axis and body torque. With the non-standard inertia
``J = tr(I_b)/2·I₃ - I_b`` (the paper's ``I^b``, eq. 33), ``e_z = (0, 0, 1)`` and gravity ``g``,
step ``k`` of the discrete dynamics ``f_d(x_{k+1}, x_k, u_k) = 0`` (eq. 17) is the LGVI of
eq. (30)–(35) with the quadrotor forcing of eq. (60)::

    R_{k+1} = R_k F_k                                             (30, 31)
    p_{k+1} = p_k + v_k Δt                                        (30, 32)
    F_{k+1} J - J F_{k+1}ᵀ = J F_k - F_kᵀ J + τ_k^ Δt²            (34, 60)
    m v_{k+1} = m v_k + m g Δt + R_{k+1} e_z u_{z,k} Δt           (35, 60)

This is the index convention of :func:`mbplan.dynamics.quadrotor_step`. Given ``x_0`` and ``u``
the step is explicit except for ``F_{k+1}``, which :func:`simulate` finds by Newton's method.

Cost (Problem 1, eq. 18): the chordal terms (57) on ``R_k`` (target ``R_goal``) and ``F_k``
(target ``I``, zero angular velocity) and the quadratic terms (59) on ``p_k`` (target ``p_goal``)
and ``v_k`` (target 0) at knots ``1..N`` (knot ``N`` weighted by ``terminal_factor``; knot 0 is
fixed), plus ``½ w_u ‖u_k - u_hover‖²`` for ``k = 0..N-1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.lie import SO3
from mbplan.simulation.free_body import lgvi_step
from mbplan.validation import as_array, as_int, as_real, as_rotation

__all__ = [
    "CostWeights",
    "DockingTask",
    "QuadrotorParams",
    "cluttered_task",
    "rotation_angles",
    "sample_docking_cases",
    "simulate",
    "trajectory_cost",
]

E_Z = np.array([0.0, 0.0, 1.0])  # thrust axis in the body frame (eq. 60)


@dataclass(frozen=True, eq=False)
class QuadrotorParams:
    """Rigid-body quadrotor with thrust along body z and body torques (eq. 60).

    The paper gives no numbers. Mass, inertia and arm length are the defaults of Drake's
    ``examples/quadrotor/QuadrotorPlant`` (a Hummingbird-class vehicle: m = 0.5 kg, L = 0.175 m,
    I_b = diag(2.3, 2.3, 4.0)·10⁻³ kg m²). ``thrust_limit = 2 m |g|`` (thrust-to-weight ratio 2);
    ``torque_limit = 0.1 N m`` is below both the roll/pitch authority ``L · thrust_limit / 4 ≈
    0.43 N m`` of one rotor at full thrust and the yaw authority ``(k_M/k_F) · thrust_limit / 2 ≈
    0.12 N m`` of Drake's rotor model (``k_M/k_F = 0.0245 m``).
    """

    mass: float = 0.5
    inertia: np.ndarray = field(default_factory=lambda: np.diag([2.3e-3, 2.3e-3, 4.0e-3]))
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    torque_limit: float = 0.1
    thrust_limit: float = 9.81

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", as_real(self.mass, "mass", positive=True))
        inertia = as_array(self.inertia, (3, 3), "inertia")
        if not np.allclose(inertia, inertia.T, rtol=0.0, atol=1e-12 * np.abs(inertia).max()):
            raise InputError("inertia: not symmetric")
        moments = np.linalg.eigvalsh(inertia)
        if moments[0] <= 0.0:
            raise InputError(f"inertia: not positive definite (principal moments {moments})")
        if moments[0] + moments[1] < moments[2] * (1.0 - 1e-12):
            raise InputError(
                f"inertia: principal moments {moments} violate the triangle inequality "
                "(not a physical rigid body)"
            )
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "gravity", as_array(self.gravity, (3,), "gravity"))
        for name in ("torque_limit", "thrust_limit"):
            object.__setattr__(self, name, as_real(getattr(self, name), name, positive=True))

    @property
    def nonstandard_inertia(self) -> np.ndarray:
        """``J = tr(I_b)/2 · I₃ - I_b`` so that ``I_b = tr(J) I₃ - J`` (eq. 33)."""
        return 0.5 * np.trace(self.inertia) * np.eye(3) - self.inertia

    @property
    def hover_input(self) -> np.ndarray:
        """``u = (m |g|, 0, 0, 0)``: holds the vehicle still when its z axis points up."""
        return np.array([self.mass * np.linalg.norm(self.gravity), 0.0, 0.0, 0.0])


@dataclass(frozen=True)
class CostWeights:
    """Isotropic weights ``W = w I`` of the chordal cost (57) on R and F and the quadratic cost
    (59) on p, v and u; the terminal state weights are ``terminal_factor`` times the stage ones.

    The paper gives no numbers. Defaults balance a 1 m position error, a chordal orientation error
    of order 1 and an angular rate of ~3 rad/s (``‖F - I‖_F² ≈ 2 Δt² ‖ω‖²``), with cheap inputs.
    """

    w_R: float = 1.0
    w_F: float = 10.0
    w_p: float = 1.0
    w_v: float = 0.5
    w_u: float = 0.01
    terminal_factor: float = 10.0

    def __post_init__(self) -> None:
        for name in ("w_R", "w_F", "w_p", "w_v", "w_u", "terminal_factor"):
            object.__setattr__(self, name, as_real(getattr(self, name), f"weights.{name}"))


@dataclass(frozen=True, eq=False)
class DockingTask:
    """Dock a quadrotor from ``(R0, p0)`` at rest to ``(R_goal, p_goal)`` at rest (§VIII.B).

    ``dt = 0.05 s`` gives a 2 s horizon for the paper's N = 40: enough for the torque-limited
    vehicle of :class:`QuadrotorParams` to flip by π (≈ 0.55 s bang-bang) and cross the sampling
    box. ``F0``/``v0`` are the initial twist (zero for docking). ``obstacles`` are vertical
    cylinders ``(x_c, y_c, r)`` to avoid, ``(x - x_c)² + (y - y_c)² ≥ r²`` at knots 1..N (Fig. 5);
    ``r`` includes the vehicle's radius. ``with_input_limits`` adds ``u_z ∈ [0, u_lim]`` and
    ``τ ∈ [-τ_lim, τ_lim]³``.
    """

    params: QuadrotorParams = field(default_factory=QuadrotorParams)
    R0: np.ndarray = field(default_factory=lambda: np.eye(3))
    p0: np.ndarray = field(default_factory=lambda: np.zeros(3))
    N: int = 40
    dt: float = 0.05
    F0: np.ndarray = field(default_factory=lambda: np.eye(3))
    v0: np.ndarray = field(default_factory=lambda: np.zeros(3))
    R_goal: np.ndarray = field(default_factory=lambda: np.eye(3))
    p_goal: np.ndarray = field(default_factory=lambda: np.zeros(3))
    weights: CostWeights = field(default_factory=CostWeights)
    with_input_limits: bool = False
    obstacles: tuple[tuple[float, float, float], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.params, QuadrotorParams):
            raise InputError(f"params: expected QuadrotorParams, got {type(self.params).__name__}")
        if not isinstance(self.weights, CostWeights):
            raise InputError(f"weights: expected CostWeights, got {type(self.weights).__name__}")
        object.__setattr__(self, "N", as_int(self.N, "N", minimum=1, what="horizon"))
        object.__setattr__(self, "dt", as_real(self.dt, "dt", positive=True))
        for name in ("R0", "F0", "R_goal"):
            object.__setattr__(self, name, as_rotation(getattr(self, name), name))
        for name in ("p0", "v0", "p_goal"):
            object.__setattr__(self, name, as_array(getattr(self, name), (3,), name))
        object.__setattr__(self, "with_input_limits", bool(self.with_input_limits))
        obstacles = []
        for i, obstacle in enumerate(self.obstacles):
            xc, yc, r = as_array(obstacle, (3,), f"obstacles[{i}]")
            as_real(r, f"obstacles[{i}] radius", positive=True)
            for name, p in (("p0", self.p0), ("p_goal", self.p_goal)):
                if (p[0] - xc) ** 2 + (p[1] - yc) ** 2 < r**2:
                    raise InfeasibleRequestError(f"{name} = {p} lies inside obstacles[{i}]")
            obstacles.append((float(xc), float(yc), float(r)))
        object.__setattr__(self, "obstacles", tuple(obstacles))


def sample_docking_cases(
    n: int,
    seed: int,
    box: tuple[ArrayLike, ArrayLike] = ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)),
    with_input_limits: bool = False,
    max_angle: float = math.pi,
    params: QuadrotorParams | None = None,
) -> list[DockingTask]:
    """``n`` docking tasks as in §VIII.B / Fig. 3: ``p0`` uniform in ``box = (low, high)`` and
    ``R0 = exp(θ a^)`` with ``θ`` uniform in ``[0, max_angle]`` and ``a`` uniform on the sphere."""
    as_int(n, "n", minimum=1, what="number of cases")
    low = as_array(box[0], (3,), "box low corner")
    high = as_array(box[1], (3,), "box high corner")
    if np.any(low > high):
        raise InputError(f"box: low corner {low} exceeds high corner {high}")
    max_angle = as_real(max_angle, "max_angle", positive=True)
    if max_angle > math.pi:
        raise InputError(f"max_angle: must be <= π, got {max_angle}")
    params = QuadrotorParams() if params is None else params
    rng = np.random.default_rng(seed)
    tasks = []
    for _ in range(n):
        p0 = rng.uniform(low, high)
        axis = rng.standard_normal(3)
        angle = rng.uniform(0.0, max_angle)
        R0 = SO3.exp(angle * axis / np.linalg.norm(axis))
        tasks.append(DockingTask(params=params, R0=R0, p0=p0, with_input_limits=with_input_limits))
    return tasks


def cluttered_task(
    with_input_limits: bool = False, params: QuadrotorParams | None = None
) -> DockingTask:
    """Docking through three cylinders (Fig. 5): the straight line from ``p0`` to the origin
    crosses the first one and the way on passes a 0.4 m gap between the other two."""
    return DockingTask(
        params=QuadrotorParams() if params is None else params,
        R0=SO3.exp(np.array([0.0, 0.0, 0.5 * math.pi])),
        p0=np.array([-2.0, -0.4, 0.5]),
        with_input_limits=with_input_limits,
        obstacles=((-1.4, -0.25, 0.25), (-0.8, 0.25, 0.2), (-0.7, -0.55, 0.2)),
    )


def simulate(task: DockingTask, u: ArrayLike) -> dict[str, np.ndarray]:
    """Roll the discrete dynamics (30)–(35), (60) forward from ``(R0, p0, F0, v0)``.

    ``u`` has shape ``(K, 4)`` (any ``K >= 1``, usually ``task.N``). Returns ``R (K+1,3,3)``,
    ``p (K+1,3)``, ``F (K+1,3,3)`` and ``v (K+1,3)``.
    """
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] != 4 or u.shape[0] < 1:
        raise InputError(f"u: expected shape (K, 4) with K >= 1, got {u.shape}")
    if not np.all(np.isfinite(u)):
        raise InputError("u: contains NaN or inf")
    prm, dt = task.params, task.dt
    J = prm.nonstandard_inertia
    K = u.shape[0]
    R = np.empty((K + 1, 3, 3))
    F = np.empty((K + 1, 3, 3))
    p = np.empty((K + 1, 3))
    v = np.empty((K + 1, 3))
    R[0], F[0], p[0], v[0] = task.R0, task.F0, task.p0, task.v0
    for k in range(K):
        state = (R[k], p[k], F[k], v[k])
        thrust = E_Z * u[k, 0]
        R[k + 1], p[k + 1], F[k + 1], v[k + 1] = lgvi_step(
            state, u[k, 1:], thrust, J, prm.mass, prm.gravity, dt, k
        )
    return {"R": R, "p": p, "F": F, "v": v}


def _chordal(R: np.ndarray, R_ref: np.ndarray) -> np.ndarray:
    """Eq. (57) with ``W = I``: ``½ ‖R R_refᵀ - I‖_F²`` for a stack of ``R``."""
    return 0.5 * np.sum((R @ R_ref.T - np.eye(3)) ** 2, axis=(-2, -1))


def trajectory_cost(task: DockingTask, traj: dict[str, np.ndarray]) -> float:
    """Objective of Problem 1 (eq. 18) for ``traj`` with keys R, p, F, v (N+1 knots) and u (N).

    The state terms of the fixed knot 0 are a constant and left out, so the value equals the
    objective of both formulations of :func:`mbplan.tasks.paper.drone_docking` (an independent NumPy
    evaluation, for tests).
    """
    N, w = task.N, task.weights
    shapes = {"R": (N + 1, 3, 3), "p": (N + 1, 3), "F": (N + 1, 3, 3), "v": (N + 1, 3), "u": (N, 4)}
    x = {key: as_array(traj[key], shape, f"traj[{key!r}]") for key, shape in shapes.items()}
    scale = np.ones(N)
    scale[-1] = w.terminal_factor
    state = (
        w.w_R * _chordal(x["R"][1:], task.R_goal)
        + w.w_F * _chordal(x["F"][1:], np.eye(3))
        + 0.5 * w.w_p * np.sum((x["p"][1:] - task.p_goal) ** 2, axis=1)
        + 0.5 * w.w_v * np.sum(x["v"][1:] ** 2, axis=1)
    )
    inputs = 0.5 * w.w_u * np.sum((x["u"] - task.params.hover_input) ** 2)
    return float(scale @ state + inputs)


def rotation_angles(R: ArrayLike) -> np.ndarray:
    """Angles ``‖log R‖ ∈ [0, π]`` of a stack of rotations."""
    return np.linalg.norm(SO3.log(R).reshape(-1, 3), axis=1)
