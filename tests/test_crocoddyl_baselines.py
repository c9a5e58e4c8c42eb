"""Crocoddyl FDDP and mim-solvers CSQP baselines of the obstacle task (the ``baselines`` extra)."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest

pytest.importorskip("crocoddyl", reason="the baselines extra (crocoddyl) is not installed")
pytest.importorskip("mim_solvers", reason="the baselines extra (mim-solvers) is not installed")

import crocoddyl

from mbplan.baselines import crocoddyl_solvers as cs
from mbplan.errors import InputError, MbplanError
from mbplan.tasks.obstacle import (
    IIWA_TARGET,
    Cylinder,
    Obstacle,
    ObstacleTask,
    com_clearances,
    link_coms,
    pair_distances,
    robot_description,
    task_collision_pairs,
)
from mbplan.verification import verify

MODEL = robot_description("iiwa").model
SOLVERS = {"fddp": cs.solve_fddp, "csqp": cs.solve_csqp}


def small_cases(n: int = 3) -> list[ObstacleTask]:
    """N = 10 tasks whose straight path brushes a cylinder in the way of the wrist, with joint 1
    limited to 10 N m so that the torque bound is active."""
    rng = np.random.default_rng(0)
    cylinder = Cylinder((0.68 * np.cos(0.6), 0.68 * np.sin(0.6)), 0.08)
    target = np.array(IIWA_TARGET)
    limit = MODEL.effortLimit.copy()
    limit[0] = 10.0
    return [
        ObstacleTask(
            N=10,
            dt=0.1,
            q0=target + np.concatenate([[-0.8], 0.1 * rng.uniform(-1.0, 1.0, 6)]),
            obstacles=(cylinder,),
            torque_limit=limit,
        )
        for _ in range(n)
    ]


def test_forward_dynamics_guard_passes_on_the_installed_versions() -> None:
    cs.check_forward_dynamics(seed=3)


def test_forward_dynamics_comparison_raises_on_a_mismatch() -> None:
    reference = np.array([1.0, -200.0, 3.0])
    cs.compare_forward_dynamics(reference * (1.0 + 1e-12), reference)
    with pytest.raises(MbplanError, match=r"forward dynamics different.*pin==4\.0\.0"):
        cs.compare_forward_dynamics(reference + np.array([0.0, 1e-4, 0.0]), reference)
    with pytest.raises(MbplanError, match="forward dynamics different"):
        cs.compare_forward_dynamics(np.array([np.nan, -200.0, 3.0]), reference)


def test_missing_crocoddyl_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "crocoddyl", None)
    monkeypatch.delitem(sys.modules, cs.__name__)
    with pytest.raises(MbplanError, match=r"pip install 'mbplan\[baselines\]'"):
        importlib.import_module(cs.__name__)


def test_clearance_residual_values_and_jacobian() -> None:
    task = ObstacleTask(obstacles=(Cylinder((0.4, 0.2), 0.1), Cylinder((-0.3, 0.4), 0.15)))
    state = crocoddyl.StateMultibody(MODEL)
    centers = np.array([c.center_xy for c in task.cylinders])
    radii = np.array([c.radius for c in task.cylinders])
    residual = cs.ResidualModelCylinderClearance(state, MODEL.nv, centers, radii)
    data = residual.createData(crocoddyl.DataCollectorMultibody(MODEL.createData()))
    rng = np.random.default_rng(0)
    x = np.concatenate([np.array(IIWA_TARGET) + 0.3 * rng.standard_normal(7), np.ones(7)])

    def r(x: np.ndarray) -> np.ndarray:
        residual.calc(data, x)
        return data.r.copy()

    expected = com_clearances(task, link_coms(MODEL, MODEL.createData(), x[:7])).ravel()
    np.testing.assert_allclose(r(x), expected, rtol=0.0, atol=1e-12)
    residual.calcDiff(data, x)
    h = 1e-6
    fd = np.column_stack([(r(x + h * e) - r(x - h * e)) / (2.0 * h) for e in np.eye(14)])
    assert np.max(np.abs(data.Rx - fd)) <= 1e-7 * np.max(np.abs(fd))
    assert not np.any(data.Rx[:, 7:])  # no velocity dependence


@pytest.mark.parametrize("method", sorted(SOLVERS))
def test_small_cases_converge_within_the_torque_limits(method: str) -> None:
    verified = 0
    for task in small_cases():
        result = SOLVERS[method](task, max_iter=200)
        assert result.success and result.status == "converged", result.message
        assert result.method == method
        assert result.q.shape == (11, 7) and result.tau.shape == (10, 7)
        assert result.kkt_history.shape == (result.iterations + 1, 2)
        assert result.time_per_iter_s == pytest.approx(
            result.solve_time_s / max(result.iterations, 1)
        )
        check = verify(task, result)  # also checks knot 0 = (q0, 0)
        assert check.torque_limit_violation <= 1e-6 * 10.0
        assert np.max(np.abs(result.tau[:, 0])) > 0.99 * 10.0  # the bound is active
        verified += check.passed
    print(f"{method}: {verified}/3 small cases pass verify")


@pytest.mark.parametrize("method", sorted(SOLVERS))
def test_default_task_short_run_respects_the_torque_limits(method: str) -> None:
    task = ObstacleTask()
    result = SOLVERS[method](task, max_iter=30)
    assert result.status in ("converged", "max_iter")
    assert result.success == (result.status == "converged")
    assert all(np.all(np.isfinite(a)) for a in (result.q, result.v, result.tau))
    check = verify(task, result)
    assert check.torque_limit_violation <= 1e-6 * np.max(task.torque_limit)
    print(f"{method} on the default task after {result.iterations} iterations: {check.reasons}")


def test_general_obstacles_are_rejected() -> None:
    pose = np.eye(4)
    pose[:3, 3] = (0.5, -0.5, 0.5)
    task = ObstacleTask(N=4, obstacles=(Obstacle("box", pose, (0.1, 0.1, 0.1)),))
    for solve in SOLVERS.values():
        with pytest.raises(InputError, match="Cylinder obstacles"):
            solve(task)


def test_coal_distance_residual_values_and_jacobian() -> None:
    task = ObstacleTask(obstacle_constraint="distance")
    state = crocoddyl.StateMultibody(MODEL)
    residual = cs.ResidualModelCoalDistance(state, MODEL.nv, task_collision_pairs(task))
    data = residual.createData(crocoddyl.DataCollectorMultibody(MODEL.createData()))
    x = np.concatenate([np.array(IIWA_TARGET), np.ones(7)])

    def r(x: np.ndarray) -> np.ndarray:
        residual.calc(data, x)
        return data.r.copy()

    np.testing.assert_allclose(r(x), pair_distances(task, x[None, :7])[0], atol=1e-12)
    residual.calcDiff(data, x)
    h = 1e-5
    fd = np.column_stack([(r(x + h * e) - r(x - h * e)) / (2.0 * h) for e in np.eye(14)])
    np.testing.assert_allclose(data.Rx, fd, atol=1e-6)
    assert not np.any(data.Rx[:, 7:])  # no velocity dependence
