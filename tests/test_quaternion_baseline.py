"""Quaternion + IPOPT baseline (RIPM paper §VIII.B, Table II) on the drone docking task, through
``mbplan.plan(ocp, "ipopt")`` (:mod:`mbplan.formulations.quaternion`)."""

from __future__ import annotations

import numpy as np
import pytest

import mbplan as mb
from mbplan.errors import InputError
from mbplan.robots.free_body import body_state
from mbplan.tasks import paper
from mbplan.tasks.drone import sample_docking_cases, simulate, trajectory_cost


def _assert_consistent(result: mb.PlanResult) -> None:
    if result.success:
        assert result.status == "Solve_Succeeded"
        assert all(np.all(np.isfinite(a)) for a in (result.q, result.v, result.tau))
        assert np.isfinite(result.extra["objective"])
    assert result.iterations >= 0 and result.solve_time_s >= 0.0
    assert result.kkt_history.shape == (result.iterations + 1, 2)


@pytest.mark.parametrize("task", sample_docking_cases(3, seed=11, max_angle=0.5))
def test_easy_cases_converge_to_dynamically_feasible_trajectories(task) -> None:
    result = mb.plan(paper.drone_docking(task), "ipopt", tol=1e-8)
    _assert_consistent(result)
    assert result.success, result.message
    assert 0 < result.iterations < 200 and result.time_per_iter_s > 0.0
    np.testing.assert_allclose(np.linalg.norm(result.q[:, 3:], axis=1), 1.0, atol=1e-9)
    # independent check: replay the inputs through the rotation-matrix LGVI simulator
    traj = body_state(result.q, result.v, task.dt)
    replay = simulate(task, result.tau)
    assert np.abs(replay["p"] - traj["p"]).max() < 1e-6
    assert np.abs(replay["R"] - traj["R"]).max() < 1e-6
    traj["u"] = result.tau
    assert trajectory_cost(task, traj) == pytest.approx(result.extra["objective"], rel=1e-9)
    # the drone actually docks
    assert np.linalg.norm(traj["p"][-1]) < 0.3 * np.linalg.norm(task.p0) + 0.05


def test_unconverged_solve_reports_failure() -> None:
    ocp = paper.drone_docking(sample_docking_cases(1, seed=2)[0])
    result = mb.plan(ocp, "ipopt", max_iter=2)
    _assert_consistent(result)
    assert not result.success and result.status == "Maximum_Iterations_Exceeded"
    assert result.iterations == 2


def test_bad_arguments_are_rejected() -> None:
    ocp = paper.drone_docking(sample_docking_cases(1, seed=0)[0])
    with pytest.raises(InputError, match="tol"):
        mb.plan(ocp, "ipopt", tol=float("nan"))
    with pytest.raises(InputError, match="max_iter"):
        mb.plan(ocp, "ipopt", max_iter=-1)
    with pytest.raises(InputError, match="warm_start"):
        mb.plan(ocp, "ipopt", warm_start=np.zeros((40, 7)))
