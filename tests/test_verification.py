"""Replay verification of planned trajectories, and the PlanResult record with its npz I/O."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from mbplan.errors import InputError
from mbplan.ocp import OCP, Scene
from mbplan.results import PlanResult, load_npz, save_npz
from mbplan.robots import load_robot
from mbplan.simulation.reference import integrate_aba
from mbplan.tasks.paper import (
    IIWA_GOAL_TOLERANCE,
    IIWA_START,
    IIWA_TARGET,
    add_obstacle_constraint,
    iiwa_obstacle_starts,
    tracking_ocp,
)
from mbplan.verification import verify
from mbplan.verification.multibody import SUBSTEPS

MODEL = load_robot("iiwa", damping=False).model  # the paper task: no damping


def make_task(q0=IIWA_START, q_target=IIWA_TARGET, cylinder=None, **fields) -> OCP:
    """The iiwa tracking OCP, with an optional eq.-62 cylinder ``((x, y), r)``."""
    scene = Scene()
    if cylinder is not None:
        scene.add_cylinder("cylinder", cylinder[1], 1.5, (*cylinder[0], 0.75))
    ocp = tracking_ocp(load_robot("iiwa", damping=False), q0, q_target, scene, **fields)
    return add_obstacle_constraint(ocp, "com")


def link_coms(q: np.ndarray) -> np.ndarray:
    data = MODEL.createData()
    pin.forwardKinematics(MODEL, data, q)
    return np.array([data.oMi[j].act(MODEL.inertias[j].lever) for j in range(1, MODEL.njoints)])


def euler_rollout(task: OCP, gain: float = 4.0, q_target=IIWA_TARGET) -> PlanResult:
    """A known solution of eq. (61): explicit Euler under computed-torque PD control towards
    ``q_target`` (``q̈ = ω² e - 2ω q̇`` with ``ω = 2 rad/s``), torques by RNEA."""
    data = MODEL.createData()
    q, v = np.array(task.q0), np.zeros(7)
    qs, vs, taus = [q], [v], []
    for _ in range(task.N):
        tau = pin.rnea(MODEL, data, q, v, gain * (np.asarray(q_target) - q) - gain * v)
        q, v = q + task.dt * v, v + task.dt * pin.aba(MODEL, data, q, v, tau)
        qs.append(q)
        vs.append(v)
        taus.append(tau)
    return PlanResult(
        "euler_rollout", "simulated", False, "", 0, 0.0, 0.0, 0.0, qs, vs, taus, task.dt
    )


def verlet_rollout(task: OCP, acc: np.ndarray) -> PlanResult:
    """The LGVI's scheme in joint space (velocity Verlet: forces at the knots, trapezoidal
    weights): ``q_{k+1} = q_k + Δt v_k + ½Δt² a_k``, ``v_{k+1} = v_k + ½Δt (a_k + a_{k+1})`` for
    prescribed knot accelerations ``acc (N+1, nv)``, knot torques by RNEA."""
    data = MODEL.createData()
    q, v = np.array(task.q0), np.zeros(7)
    qs, vs, knots = [q], [v], [pin.rnea(MODEL, data, q, v, acc[0])]
    for k in range(task.N):
        q = q + task.dt * v + 0.5 * task.dt**2 * acc[k]
        v = v + 0.5 * task.dt * (acc[k] + acc[k + 1])
        qs.append(q)
        vs.append(v)
        knots.append(pin.rnea(MODEL, data, q, v, acc[k + 1]))
    tau_knots = np.array(knots)
    tau = 0.5 * (tau_knots[:-1] + tau_knots[1:])
    return PlanResult(
        "verlet",
        "simulated",
        False,
        "",
        0,
        0.0,
        0.0,
        0.0,
        qs,
        vs,
        tau,
        task.dt,
        tau_knots=tau_knots,
    )


@pytest.fixture(scope="module")
def free_task() -> OCP:
    return make_task()


@pytest.fixture(scope="module")
def rollout(free_task: OCP) -> PlanResult:
    return euler_rollout(free_task)


def test_a_known_solution_of_eq61_passes(free_task: OCP, rollout: PlanResult) -> None:
    check = verify(free_task, rollout)
    assert check.passed, check.reasons
    # exact eq.-(61) plans deviate from the replay by exactly the Euler error: ratio 1/2
    assert check.joint_deviation_ratio == pytest.approx(0.5, abs=1e-3)
    assert check.velocity_deviation_ratio == pytest.approx(0.5, abs=1e-3)
    assert 1e-3 < check.max_joint_deviation_rad < 0.1  # first order: visible at Δt = 0.075 s
    assert check.final_goal_error_rad < IIWA_GOAL_TOLERANCE
    assert check.torque_limit_violation == 0.0 and check.min_obstacle_distance_m == np.inf


def test_torques_inconsistent_with_the_dynamics_fail(free_task: OCP, rollout: PlanResult) -> None:
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


def test_knot_torques_are_replayed_with_a_first_order_hold(free_task: OCP) -> None:
    """Where the knot accelerations turn (``a_{k+1} = -0.6 a_k``), the interval mean held adds
    ``¼Δt²|a_k - a_{k+1}|`` to the LGVI's ``q`` step (ratio ``|1-r|/(2|1+r|) = 2``), linear
    interpolation leaves its own ``⅙Δt²|a_k - a_{k+1}|`` (ratio ``|1-r|/(2|2+r|) ≈ 0.57``)."""
    acc = np.zeros((free_task.N + 1, 7))
    acc[:, 0] = np.where(np.arange(free_task.N + 1) <= 10, 1.0, -0.6)  # base joint, rad/s²
    plan = verlet_rollout(free_task, acc)
    check = verify(free_task, plan)
    assert check.joint_deviation_ratio == pytest.approx(0.57, abs=0.03)
    assert check.velocity_deviation_ratio < 0.5
    assert not any("deviation" in r for r in check.reasons)
    held = verify(free_task, dataclasses.replace(plan, tau_knots=None))
    assert held.joint_deviation_ratio == pytest.approx(2.0, abs=0.03)
    assert any("joint deviation" in r for r in held.reasons)
    # the torque limits apply to the knot torques, the extremes of the ramp
    knots = plan.tau_knots.copy()
    knots[5, 0] += 50.0
    spiked = dataclasses.replace(plan, tau=0.5 * (knots[:-1] + knots[1:]), tau_knots=knots)
    limit = np.max(np.abs(spiked.tau), axis=0) + 1.0
    check = verify(make_task(torque_limit=limit), spiked)
    assert check.torque_limit_violation == pytest.approx(np.abs(knots[5, 0]) - limit[0])
    assert any("exceed the limits" in r for r in check.reasons)


def test_an_lgvi_solution_verifies(free_task: OCP) -> None:
    """A RIPM (maximal-coordinate LGVI) plan passes with its knot torques; held at their interval
    means, its launch at knot 1 fails the joint row (the benchmark's former failure mode)."""
    from mbplan.planning.solve import plan as plan_ocp

    plan = plan_ocp(free_task, "ripm", warm_start="linear")
    assert plan.success and plan.tau_knots is not None
    np.testing.assert_allclose(plan.tau, 0.5 * (plan.tau_knots[:-1] + plan.tau_knots[1:]))
    check = verify(free_task, plan)
    assert check.passed, check.reasons
    assert max(check.joint_deviation_ratio, check.velocity_deviation_ratio) < 0.75
    held = verify(free_task, dataclasses.replace(plan, tau_knots=None))
    assert held.joint_deviation_ratio > 1.0


def test_linear_torque_ramp_integration() -> None:
    q0, v0 = np.array(iiwa_obstacle_starts(1, 0)[0]), np.full(7, 0.3)
    data = MODEL.createData()
    tau0 = pin.computeGeneralizedGravity(MODEL, data, q0)
    tau1 = tau0 + np.linspace(-0.2, 0.2, 7)  # N m: the wrist has 1e-3 kg m²
    T = 0.075
    const = integrate_aba(MODEL, q0, v0, tau0, T, SUBSTEPS)
    same = integrate_aba(MODEL, q0, v0, tau0, T, SUBSTEPS, tau_end=tau0)
    np.testing.assert_array_equal(const[0], same[0])
    np.testing.assert_array_equal(const[1], same[1])
    ramp = integrate_aba(MODEL, q0, v0, tau0, T, SUBSTEPS, tau_end=tau1)
    fine = integrate_aba(MODEL, q0, v0, tau0, T, 4 * SUBSTEPS, tau_end=tau1)
    assert np.max(np.abs(ramp[0] - fine[0])) < 1e-8 and np.max(np.abs(ramp[1] - fine[1])) < 1e-7
    q, v, n = q0, v0, 400  # a fine zero-order hold of the ramp converges to it (second order)
    for i in range(n):
        q, v = integrate_aba(MODEL, q, v, tau0 + (i + 0.5) / n * (tau1 - tau0), T / n, 1)
    assert np.max(np.abs(fine[0] - q)) < 1e-6 and np.max(np.abs(fine[1] - v)) < 1e-7
    assert np.max(np.abs(ramp[1] - const[1])) > 1.0


def test_obstacle_goal_torque_and_nan_failures(free_task: OCP, rollout: PlanResult) -> None:
    wrist = link_coms(rollout.q[20])[-1]
    blocked = make_task(cylinder=(tuple(wrist[:2]), 0.05))
    check = verify(blocked, rollout)
    assert check.min_obstacle_distance_m <= -0.05 + 1e-9
    assert any("enters an obstacle" in r for r in check.reasons)
    far = make_task(q_target=np.array(IIWA_TARGET) + 0.2)
    assert any("goal 'joint_position_terminal'" in r for r in verify(far, rollout).reasons)
    tight = make_task(torque_limit=0.5 * np.max(np.abs(rollout.tau), axis=0))
    check = verify(tight, rollout)
    assert check.torque_limit_violation == pytest.approx(np.max(np.abs(rollout.tau)) / 2)
    assert any("exceed the limits" in r for r in check.reasons)
    tau = rollout.tau.copy()
    tau[3, 1] = np.nan
    check = verify(free_task, dataclasses.replace(rollout, tau=tau))
    assert not check.passed and check.reasons == ["the trajectory contains NaN or inf"]
    assert np.isnan(check.max_joint_deviation_rad)


def test_a_diverging_replay_fails(free_task: OCP, rollout: PlanResult) -> None:
    tau = rollout.tau.copy()
    tau[3] = 1e200  # finite, but the replay of interval 3 overflows to NaN
    check = verify(free_task, dataclasses.replace(rollout, tau=tau))
    assert not check.passed
    assert "the replay diverges (non-finite state) in 1 of 40 intervals, the first from knot 3" in (
        check.reasons
    )


def test_mismatched_result_is_an_input_error(free_task: OCP, rollout: PlanResult) -> None:
    with pytest.raises(InputError, match="does not match the OCP"):
        verify(make_task(N=20), rollout)
    with pytest.raises(InputError, match="dt"):
        verify(make_task(dt=0.05), rollout)
    q = rollout.q.copy()
    q[0] += 0.1
    with pytest.raises(InputError, match="knot 0"):
        verify(free_task, dataclasses.replace(rollout, q=q))


def test_documented_replay_numbers() -> None:
    """SUBSTEPS is fine enough per interval, and an open-loop replay is hopeless (docstring)."""
    task = make_task(q0=iiwa_obstacle_starts(1, 0)[0])
    plan = euler_rollout(task)
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
    assert verify(task, plan).open_loop_deviation_rad > 10.0


def _result(**changes: object) -> PlanResult:
    rng = np.random.default_rng(0)
    tau_knots = rng.standard_normal((5, 7))
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
        "tau": 0.5 * (tau_knots[:-1] + tau_knots[1:]),
        "dt": 0.075,
        "kkt_history": rng.random((13, 2)),
        "entered_restoration": False,
        "extra": {"objective": np.float64(1.5), "counts": np.arange(3), "note": "x"},
        "R": np.broadcast_to(np.eye(3), (5, 7, 3, 3)).copy(),
        "p": rng.standard_normal((5, 7, 3)),
        "body_names": [f"link_{i}" for i in range(7)],
        "tau_knots": tau_knots,
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
    failed = _result(
        success=False, R=None, p=None, body_names=None, entered_restoration=None, tau_knots=None
    )
    failed.q[2, 3] = np.nan
    loaded = load_npz(save_npz(failed, path))
    assert loaded.R is None and loaded.body_names is None and loaded.entered_restoration is None
    assert loaded.tau_knots is None
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
    with pytest.raises(InputError, match="tau_knots: expected"):
        _result(tau_knots=np.zeros((4, 7)))
    with pytest.raises(InputError, match="interval mean of tau_knots"):
        _result(tau_knots=np.zeros((5, 7)))
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


def test_npz_carries_the_ocp_and_old_files_still_load(tmp_path: Path, rollout: PlanResult) -> None:
    task = make_task(cylinder=((2.0, 2.0), 0.1))
    with_ocp = dataclasses.replace(rollout, ocp=task, formulation="generalized")
    loaded = load_npz(save_npz(with_ocp, tmp_path / "plan.npz"))
    assert loaded.ocp is not None and loaded.ocp.names == task.names
    assert loaded.ocp.scene.names == ["cylinder"] and loaded.formulation == "generalized"
    assert verify(loaded).passed == verify(task, rollout).passed
    old = load_npz(save_npz(rollout, tmp_path / "old.npz"))  # written as before the OCP API
    assert old.ocp is None
    with pytest.raises(InputError, match=r"carries no OCP.*verify\(ocp, result\)"):
        verify(old)
    assert verify(task, old).passed == verify(task, rollout).passed
    model_ocp = dataclasses.replace(rollout, ocp=OCP(MODEL, N=task.N))  # an in-memory model
    unavailable = load_npz(save_npz(model_ocp, tmp_path / "model.npz"))
    assert unavailable.ocp is None and "in-memory" in unavailable.extra["ocp_unavailable"]
    with pytest.raises(InputError, match=r"in-memory pinocchio\.Model"):
        verify(unavailable)
    assert load_npz(tmp_path / "model.npz", robot=MODEL).ocp is not None
