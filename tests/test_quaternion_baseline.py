"""Quaternion + IPOPT baseline (RIPM paper §VIII.B, Table II) on the drone docking task."""

from __future__ import annotations

import numpy as np
import pytest

from mbplan.baselines import QuaternionIpoptResult, solve_quaternion_ipopt
from mbplan.errors import InputError
from mbplan.tasks import cluttered_task, sample_docking_cases, simulate, trajectory_cost


def _assert_consistent(result: QuaternionIpoptResult) -> None:
    arrays = (result.q, result.f, result.R, result.F, result.p, result.v, result.u)
    if result.success:
        assert result.status == "Solve_Succeeded"
        assert all(np.all(np.isfinite(a)) for a in arrays) and np.isfinite(result.objective)
    assert result.iterations >= 0 and result.solve_time >= 0.0
    assert len(result.kkt_history) == result.iterations + 1
    np.testing.assert_array_equal(result.kkt_history, np.maximum(result.inf_pr, result.inf_du))


@pytest.mark.parametrize("task", sample_docking_cases(3, seed=11, max_angle=0.5))
def test_easy_cases_converge_to_dynamically_feasible_trajectories(task) -> None:
    result = solve_quaternion_ipopt(task, tol=1e-8)
    _assert_consistent(result)
    assert result.success, result.status
    assert 0 < result.iterations < 200 and result.time_per_iteration > 0.0
    np.testing.assert_allclose(np.linalg.norm(result.q, axis=1), 1.0, atol=1e-9)
    assert np.all(result.q[:, 0] >= -1e-9)
    # independent check: replay the inputs through the rotation-matrix LGVI simulator
    replay = simulate(task, result.u)
    assert np.abs(replay["p"] - result.p).max() < 1e-6
    assert np.abs(replay["R"] - result.R).max() < 1e-6
    traj = {"R": result.R, "p": result.p, "F": result.F, "v": result.v, "u": result.u}
    assert trajectory_cost(task, traj) == pytest.approx(result.objective, rel=1e-9)
    # the drone actually docks
    assert np.linalg.norm(result.p[-1]) < 0.3 * np.linalg.norm(task.p0) + 0.05


def test_input_limits_and_obstacles_are_respected() -> None:
    task = cluttered_task(with_input_limits=True)
    result = solve_quaternion_ipopt(task)
    _assert_consistent(result)
    assert result.success, result.status
    prm = task.params
    assert result.u[:, 0].min() >= -1e-6 and result.u[:, 0].max() <= prm.thrust_limit + 1e-6
    assert np.abs(result.u[:, 1:]).max() <= prm.torque_limit + 1e-6
    for xc, yc, r in task.obstacles:
        assert np.hypot(result.p[1:, 0] - xc, result.p[1:, 1] - yc).min() >= r - 1e-6


def test_unconverged_solve_reports_failure() -> None:
    task = sample_docking_cases(1, seed=2)[0]
    result = solve_quaternion_ipopt(task, max_iter=2)
    _assert_consistent(result)
    assert not result.success and result.status == "Maximum_Iterations_Exceeded"
    assert result.iterations == 2


def test_bad_arguments_are_rejected() -> None:
    task = sample_docking_cases(1, seed=0)[0]
    with pytest.raises(InputError, match="tol"):
        solve_quaternion_ipopt(task, tol=float("nan"))
    with pytest.raises(InputError, match="max_iter"):
        solve_quaternion_ipopt(task, max_iter=-1)
    with pytest.raises(InputError, match="initial_guess\\['p'\\]"):
        solve_quaternion_ipopt(task, initial_guess={"R": np.zeros((41, 3, 3))})
