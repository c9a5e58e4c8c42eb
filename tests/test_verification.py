"""Replay verification of planned trajectories, and the PlanResult record with its npz I/O."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from mbplan.errors import InputError
from mbplan.results import PlanResult, load_npz, save_npz
from mbplan.simulation.reference import integrate_aba
from mbplan.tasks.obstacle import (
    Cylinder,
    ObstacleTask,
    link_coms,
    robot_description,
    sample_obstacle_cases,
)
from mbplan.verification import SUBSTEPS, verify

MODEL = robot_description("iiwa").model


def euler_rollout(task: ObstacleTask, gain: float = 4.0) -> PlanResult:
    """A known solution of eq. (61): explicit Euler under computed-torque PD control towards
    ``q_target`` (``q̈ = ω² e - 2ω q̇`` with ``ω = 2 rad/s``), torques by RNEA."""
    data = MODEL.createData()
    q, v = np.array(task.q0), np.zeros(7)
    qs, vs, taus = [q], [v], []
    for _ in range(task.N):
        tau = pin.rnea(MODEL, data, q, v, gain * (task.q_target - q) - gain * v)
        q, v = q + task.dt * v, v + task.dt * pin.aba(MODEL, data, q, v, tau)
        qs.append(q)
        vs.append(v)
        taus.append(tau)
    return PlanResult(
        "euler_rollout", "simulated", False, "", 0, 0.0, 0.0, 0.0, qs, vs, taus, task.dt
    )


@pytest.fixture(scope="module")
def free_task() -> ObstacleTask:
    return ObstacleTask(obstacles=())


@pytest.fixture(scope="module")
def rollout(free_task: ObstacleTask) -> PlanResult:
    return euler_rollout(free_task)


def test_a_known_solution_of_eq61_passes(free_task: ObstacleTask, rollout: PlanResult) -> None:
    check = verify(free_task, rollout)
    assert check.passed, check.reasons
    # exact eq.-(61) plans deviate from the replay by exactly the Euler error: ratio 1/2
    assert check.joint_deviation_ratio == pytest.approx(0.5, abs=1e-3)
    assert check.velocity_deviation_ratio == pytest.approx(0.5, abs=1e-3)
    assert 1e-3 < check.max_joint_deviation_rad < 0.1  # first order: visible at Δt = 0.075 s
    assert check.final_goal_error_rad < free_task.goal_tolerance
    assert check.torque_limit_violation == 0.0 and check.min_obstacle_distance_m == np.inf


def test_torques_inconsistent_with_the_dynamics_fail(
    free_task: ObstacleTask, rollout: PlanResult
) -> None:
    data = MODEL.createData()
    gravity = np.array([pin.computeGeneralizedGravity(MODEL, data, q) for q in rollout.q[:-1]])
    for error in (0.02, 0.1):  # gravity compensation 2 % / 10 % off
        check = verify(free_task, dataclasses.replace(rollout, tau=rollout.tau + error * gravity))
        assert not check.passed and check.velocity_deviation_ratio > 4.0
        assert any("velocity deviation" in r for r in check.reasons)
        assert check.joint_deviation_ratio < 1.0  # q_{k+1} = q_k + Δt v_k cannot see τ
    # one global threshold (max deviation vs 2 max Euler error) would miss the 2 % error
    tau = rollout.tau + 0.02 * gravity
    data = MODEL.createData()
    deviation = euler_error = 0.0
    for k in range(free_task.N):
        q, v = rollout.q[k], rollout.v[k]
        _, v_replay = integrate_aba(MODEL, q, v, tau[k], free_task.dt, SUBSTEPS)
        v_euler = v + free_task.dt * pin.aba(MODEL, data, q, v, tau[k])
        deviation = max(deviation, np.max(np.abs(v_replay - rollout.v[k + 1])))
        euler_error = max(euler_error, np.max(np.abs(v_replay - v_euler)))
    assert deviation / (2.0 * euler_error) == pytest.approx(0.78, abs=0.01)


def test_obstacle_goal_torque_and_nan_failures(
    free_task: ObstacleTask, rollout: PlanResult
) -> None:
    wrist = link_coms(MODEL, MODEL.createData(), rollout.q[20])[-1]
    blocked = dataclasses.replace(free_task, obstacles=(Cylinder(tuple(wrist[:2]), 0.05),))
    check = verify(blocked, rollout)
    assert check.min_obstacle_distance_m <= -0.05 + 1e-9
    assert any("enters an obstacle" in r for r in check.reasons)
    far = dataclasses.replace(free_task, q_target=free_task.q_target + 0.2)
    assert any("goal error" in r for r in verify(far, rollout).reasons)
    tight = dataclasses.replace(free_task, torque_limit=0.5 * np.max(np.abs(rollout.tau), axis=0))
    check = verify(tight, rollout)
    assert check.torque_limit_violation == pytest.approx(np.max(np.abs(rollout.tau)) / 2)
    assert any("exceed the limits" in r for r in check.reasons)
    tau = rollout.tau.copy()
    tau[3, 1] = np.nan
    check = verify(free_task, dataclasses.replace(rollout, tau=tau))
    assert not check.passed and check.reasons == ["the trajectory contains NaN or inf"]
    assert np.isnan(check.max_joint_deviation_rad)


def test_mismatched_result_is_an_input_error(free_task: ObstacleTask, rollout: PlanResult) -> None:
    with pytest.raises(InputError, match="does not match the task"):
        verify(dataclasses.replace(free_task, N=20), rollout)
    with pytest.raises(InputError, match="dt"):
        verify(dataclasses.replace(free_task, dt=0.05), rollout)
    q = rollout.q.copy()
    q[0] += 0.1
    with pytest.raises(InputError, match="knot 0"):
        verify(free_task, dataclasses.replace(rollout, q=q))


def test_documented_replay_numbers() -> None:
    """SUBSTEPS is fine enough per interval, and an open-loop replay is hopeless (docstring)."""
    task = sample_obstacle_cases(n=1, seed=0)[0]
    plan = euler_rollout(dataclasses.replace(task, obstacles=()))
    k = 20
    q20, _ = integrate_aba(MODEL, plan.q[k], plan.v[k], plan.tau[k], task.dt, SUBSTEPS)
    q40, _ = integrate_aba(MODEL, plan.q[k], plan.v[k], plan.tau[k], task.dt, 2 * SUBSTEPS)
    assert np.max(np.abs(q20 - q40)) < 1e-8

    def open_loop(substeps: int) -> np.ndarray:
        q, v = plan.q[0], plan.v[0]
        for j in range(20):  # 1.5 s
            q, v = integrate_aba(MODEL, q, v, plan.tau[j], task.dt, substeps)
        return q

    assert np.max(np.abs(open_loop(10) - open_loop(40))) > 1.0
    assert verify(dataclasses.replace(task, obstacles=()), plan).open_loop_deviation_rad > 10.0


def _result(**changes: object) -> PlanResult:
    rng = np.random.default_rng(0)
    fields = {
        "method": "maximal_ripm",
        "status": "Solve_Succeeded",
        "success": True,
        "message": "converged",
        "iterations": 12,
        "solve_time_s": 0.5,
        "total_time_s": 0.75,
        "time_per_iter_s": 0.5 / 12,
        "q": rng.standard_normal((5, 7)),
        "v": rng.standard_normal((5, 7)),
        "tau": rng.standard_normal((4, 7)),
        "dt": 0.075,
        "kkt_history": rng.random((13, 2)),
        "entered_restoration": False,
        "extra": {"objective": np.float64(1.5), "counts": np.arange(3), "note": "x"},
        "R": np.broadcast_to(np.eye(3), (5, 7, 3, 3)).copy(),
        "p": rng.standard_normal((5, 7, 3)),
        "body_names": [f"link_{i}" for i in range(7)],
    }
    fields.update(changes)
    return PlanResult(**fields)  # type: ignore[arg-type]


def test_npz_round_trip(tmp_path: Path) -> None:
    result = _result()
    path = save_npz(result, tmp_path / "sub" / "case_0.npz")
    assert [p.name for p in path.parent.iterdir()] == ["case_0.npz"]  # no temporary left
    loaded = load_npz(path)
    for f in dataclasses.fields(PlanResult):
        a, b = getattr(result, f.name), getattr(loaded, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        elif f.name == "extra":
            assert b == {"objective": 1.5, "counts": [0, 1, 2], "note": "x"}
        else:
            assert a == b and type(a) is type(b), f.name
    # generalized results have no R, p, body_names; a failed run may hold NaN; overwrite works
    failed = _result(success=False, R=None, p=None, body_names=None, entered_restoration=None)
    failed.q[2, 3] = np.nan
    loaded = load_npz(save_npz(failed, path))
    assert loaded.R is None and loaded.body_names is None and loaded.entered_restoration is None
    assert np.isnan(loaded.q[2, 3]) and not loaded.success
    with np.load(path) as data:
        assert {"q", "v", "tau", "dt", "method", "status", "iterations", "solve_time_s"} <= set(
            data.files
        )


def test_plan_result_checks(tmp_path: Path) -> None:
    q = np.zeros((5, 7))
    q[1, 1] = np.nan
    with pytest.raises(InputError, match="success=True with non-finite"):
        _result(q=q)
    with pytest.raises(InputError, match="expected q"):
        _result(tau=np.zeros((5, 7)))
    with pytest.raises(InputError, match="kkt_history"):
        _result(kkt_history=np.zeros(3))
    with pytest.raises(InputError, match=r"\.npz"):
        save_npz(_result(), tmp_path / "x.json")
    with pytest.raises(InputError, match="JSON"):
        save_npz(_result(extra={"f": object()}), tmp_path / "x.npz")
    assert not list(tmp_path.iterdir())
    np.savez(tmp_path / "partial.npz", q=np.zeros((2, 7)))
    with pytest.raises(InputError, match="lacks the fields"):
        load_npz(tmp_path / "partial.npz")
