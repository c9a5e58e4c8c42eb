"""Drone docking task (RIPM paper §VIII.B): sampling, the geodesic warm start of its OCP, LGVI
simulator (30–35, 60)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.formulations.free_body import FreeBodyNLP
from mbplan.planning.initial_guess import initial_path
from mbplan.solvers import RIPMStatus, solve_ripm
from mbplan.tasks import paper
from mbplan.tasks.drone import (
    CostWeights,
    DockingTask,
    QuadrotorParams,
    cluttered_task,
    rotation_angles,
    sample_docking_cases,
    simulate,
    trajectory_cost,
)


def _vee(A: np.ndarray) -> np.ndarray:
    return 0.5 * np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])


def test_sampling_is_reproducible_and_within_bounds() -> None:
    box = ((-1.0, -2.0, 0.0), (1.0, 2.0, 0.5))
    a = sample_docking_cases(50, seed=7, box=box, with_input_limits=True)
    b = sample_docking_cases(50, seed=7, box=box, with_input_limits=True)
    c = sample_docking_cases(50, seed=8, box=box)
    assert all(
        np.array_equal(x.R0, y.R0) and np.array_equal(x.p0, y.p0) for x, y in zip(a, b, strict=True)
    )
    assert not np.allclose([t.p0 for t in a], [t.p0 for t in c])
    R0 = np.array([t.R0 for t in a])
    p0 = np.array([t.p0 for t in a])
    np.testing.assert_allclose(
        np.swapaxes(R0, 1, 2) @ R0, np.broadcast_to(np.eye(3), R0.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(R0), 1.0, atol=1e-12)
    angles = rotation_angles(R0)
    assert np.all((angles >= 0.0) & (angles <= np.pi)) and angles.max() > 2.0
    assert np.all((p0 >= box[0]) & (p0 <= box[1]))
    assert all(t.with_input_limits and t.N == 40 for t in a)
    assert all(np.array_equal(t.R_goal, np.eye(3)) and not t.p_goal.any() for t in a)
    small = sample_docking_cases(20, seed=1, max_angle=0.3)
    assert rotation_angles([t.R0 for t in small]).max() <= 0.3


def test_a_start_outside_the_kinematics_residuals_domain_is_reported_as_a_failure() -> None:
    """One knot's ``F`` turned by π puts ``R₁ᵀR₀F₀`` at the edge of the Cayley residual's
    domain (``1 + tr = 0``): the RIPM must not report that start's outcome as converged; the
    same start without the turn converges."""
    task = sample_docking_cases(1, seed=3)[0]
    ocp = paper.drone_docking(task)
    nlp = FreeBodyNLP(ocp, jit=False)
    statuses = []
    for flip in (None, np.diag([1.0, -1.0, -1.0])):
        x = nlp.initial_point(initial_path(ocp, "linear"))
        if flip is not None:
            x["F"][5] = x["F"][5] @ flip
            M = x["R"][6].T @ x["R"][5] @ x["F"][5]
            assert abs(1.0 + np.trace(M)) < 1e-12
        statuses.append(solve_ripm(nlp.problem, x, max_iter=100).status)
    assert statuses[0] is RIPMStatus.CONVERGED
    assert statuses[1] is not RIPMStatus.CONVERGED


def test_geodesic_guess_connects_start_and_goal() -> None:
    task = sample_docking_cases(1, seed=3)[0]
    ocp = paper.drone_docking(task)
    x = FreeBodyNLP(ocp, jit=False).initial_point(initial_path(ocp, "linear"))
    g = {key: x[key] for key in ("R", "p", "F", "v", "u")}
    N = task.N
    assert g["R"].shape == (N + 1, 3, 3) and g["F"].shape == (N + 1, 3, 3)
    assert g["p"].shape == g["v"].shape == (N + 1, 3) and g["u"].shape == (N, 4)
    np.testing.assert_allclose(g["R"][0], task.R0, atol=1e-12)
    np.testing.assert_allclose(g["p"][0], task.p0, atol=1e-12)
    np.testing.assert_allclose(g["R"][-1], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(g["p"][-1], 0.0, atol=1e-12)
    # kinematics (30) hold on knots 1..N-1; knot 0 keeps the zero initial twist
    np.testing.assert_allclose(g["R"][1:-1] @ g["F"][1:-1], g["R"][2:], atol=1e-12)
    np.testing.assert_allclose(g["p"][1:-1] + task.dt * g["v"][1:-1], g["p"][2:], atol=1e-12)
    np.testing.assert_array_equal(g["F"][[0, -1]], np.stack([np.eye(3)] * 2))
    assert not g["v"][[0, -1]].any()
    # inputs of the LGVI's inverse dynamics: along the uniform geodesic (steps 1..N-2; the first
    # and last start and stop it) the constant gyroscopic torque of a steady rotation and the
    # thrust m g cos(tilt) that holds the altitude
    inner = slice(1, N - 1)
    torque = g["u"][inner, 1:]
    np.testing.assert_allclose(torque, np.broadcast_to(torque[0], torque.shape), atol=1e-12)
    assert 0.0 < np.max(np.abs(torque)) < 1e-3
    cos_tilt = g["R"][2:N, 2, 2]
    np.testing.assert_allclose(g["u"][inner, 0], task.params.mass * 9.81 * cos_tilt, rtol=1e-9)
    # geodesic: equal rotation angle per step
    steps = rotation_angles(g["F"][1:-1])
    np.testing.assert_allclose(steps, rotation_angles(task.R0[None])[0] / N, atol=1e-12)
    assert trajectory_cost(task, g) > 0.0


def test_lgvi_conserves_energy_and_momentum_without_forces() -> None:
    params = QuadrotorParams(inertia=np.diag([1.0e-3, 2.0e-3, 2.5e-3]), gravity=np.zeros(3))
    dt = 0.05
    F0 = Rotation.from_rotvec(np.array([1.0, -2.0, 3.0]) * dt).as_matrix()
    R0 = Rotation.from_rotvec([0.3, 0.2, -0.1]).as_matrix()
    task = DockingTask(params=params, R0=R0, dt=dt, F0=F0, v0=[0.2, -0.1, 0.3])
    K = 400
    s = simulate(task, np.zeros((K, 4)))
    J = params.nonstandard_inertia
    # discrete kinetic energy tr((I - F)J)/Δt² and world angular momentum R (FJ - JFᵀ)^∨/Δt
    energy = np.array([np.trace((np.eye(3) - F) @ J) for F in s["F"]]) / dt**2
    momentum = (
        np.array([R @ _vee(F @ J - J @ F.T) for R, F in zip(s["R"], s["F"], strict=True)]) / dt
    )
    assert np.abs(energy - energy[0]).max() <= 1e-10 * energy[0]
    assert np.abs(momentum - momentum[0]).max() <= 1e-10 * np.linalg.norm(momentum[0])
    np.testing.assert_allclose(s["v"], np.broadcast_to(task.v0, s["v"].shape), atol=1e-15)
    np.testing.assert_allclose(s["p"][-1], task.p0 + K * dt * task.v0, atol=1e-12)
    RtR = np.swapaxes(s["R"], 1, 2) @ s["R"]
    np.testing.assert_allclose(RtR, np.broadcast_to(np.eye(3), RtR.shape), atol=1e-12)


def test_hover_input_keeps_the_drone_still() -> None:
    yaw = Rotation.from_rotvec([0.0, 0.0, 0.7]).as_matrix()
    task = DockingTask(R0=yaw, p0=[0.3, -0.2, 1.0])
    s = simulate(task, np.tile(task.params.hover_input, (task.N, 1)))
    np.testing.assert_allclose(s["p"], np.broadcast_to(task.p0, s["p"].shape), atol=1e-12)
    np.testing.assert_allclose(s["v"], 0.0, atol=1e-12)
    np.testing.assert_allclose(s["R"], np.broadcast_to(yaw, s["R"].shape), atol=1e-12)


def test_body_torque_spins_up_at_tau_over_inertia() -> None:
    task = DockingTask(params=QuadrotorParams(gravity=np.zeros(3)))
    tau, K = 0.01, 10
    u = np.tile([0.0, 0.0, 0.0, tau], (K, 1))
    s = simulate(task, u)
    omega = Rotation.from_matrix(s["F"][-1]).as_rotvec() / task.dt
    np.testing.assert_allclose(omega, [0.0, 0.0, tau * K * task.dt / 4.0e-3], rtol=1e-3, atol=1e-12)


def test_cluttered_task_has_obstacles_on_the_straight_line() -> None:
    task = cluttered_task(with_input_limits=True)
    assert len(task.obstacles) >= 2 and task.with_input_limits
    line = np.linspace(task.p0, task.p_goal, 200)
    blocked = [np.hypot(line[:, 0] - x, line[:, 1] - y).min() < r for x, y, r in task.obstacles]
    assert any(blocked)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: DockingTask(R0=np.diag([1.0, 1.0, 1.1])), "R0: not a rotation"),
        (lambda: DockingTask(R0=np.diag([1.0, 1.0, -1.0])), "R0: determinant"),
        (lambda: DockingTask(p0=[0.0, np.nan, 0.0]), "p0: contains NaN"),
        (lambda: DockingTask(N=0), "N: horizon"),
        (lambda: DockingTask(dt=-0.1), "dt: must be"),
        (lambda: QuadrotorParams(mass=-1.0), "mass: must be"),
        (lambda: QuadrotorParams(inertia=np.diag([1.0, 1.0, 3.0])), "triangle inequality"),
        (lambda: QuadrotorParams(gravity=[0.0, 0.0]), "gravity: expected shape"),
        (lambda: CostWeights(w_R=-1.0), "weights.w_R"),
        (lambda: sample_docking_cases(0, seed=0), "n: number of cases"),
        (lambda: sample_docking_cases(1, seed=0, box=((1, 0, 0), (0, 1, 1))), "box"),
        (lambda: simulate(DockingTask(), np.full((3, 4), np.nan)), "u: contains NaN"),
        (lambda: simulate(DockingTask(), np.zeros((3, 3))), "u: expected shape"),
        (lambda: simulate(DockingTask(), [[0.0, 0.0, 0.0, 100.0]]), r"equation \(34\)"),
    ],
)
def test_bad_input_is_rejected(build, message: str) -> None:
    with pytest.raises(InputError, match=message):
        build()


def test_start_inside_an_obstacle_is_infeasible() -> None:
    with pytest.raises(InfeasibleRequestError, match="p0"):
        DockingTask(p0=[1.0, 0.0, 0.0], obstacles=((1.0, 0.1, 0.3),))


def test_task_is_immutable() -> None:
    task = DockingTask()
    with pytest.raises(dataclasses.FrozenInstanceError):
        task.N = 3  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        task.p0[0] = 1.0
