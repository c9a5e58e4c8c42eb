"""Floating-base robots: a free-flyer root joint is a free rigid body in maximal coordinates (no
constraint rows, no multipliers, no actuation). Loading by name, the maximal model and its
state maps, the LGVI in free flight against Pinocchio (order 2, momentum), a RIPM plan verified
by the replay, and the methods that refuse such robots before any solve."""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
import pytest
from fd import check_generalized_derivatives

import mbplan as mb
from mbplan.benchmarks.validate_dynamics import validate_case
from mbplan.errors import InputError, RobotModelError
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.joint_space import evaluate
from mbplan.formulations.maximal import free_first_step
from mbplan.lie import SO3
from mbplan.multibody import (
    MaximalModel,
    body_poses,
    body_velocities,
    joint_constraint_residuals,
    joint_positions,
    joint_velocities,
    maximal_model,
)
from mbplan.residuals import (
    FrameTranslation,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
)
from mbplan.robots import available_floating, available_robots, load, load_robot
from mbplan.robots.configuration import difference, integrate
from mbplan.simulation import discrete_momentum, simulate_maximal

QUADRUPEDS = ("solo12", "anymal")


@cache
def _robot(name: str) -> mb.Robot:
    return load_robot(name)


@cache
def _mm(name: str) -> MaximalModel:
    return maximal_model(_robot(name))


def _random_state(robot: mb.Robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A configuration within the joint limits (the base anywhere in a 1 m cube, any
    orientation) and a random velocity."""
    rng = np.random.default_rng(seed)
    model = robot.model
    lo, hi = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    lo[:7], hi[:7] = -1.0, 1.0
    q = pin.randomConfiguration(model, lo, hi)
    return q, rng.standard_normal(model.nv)


# ---------------------------------------------------------------------------- loading


def test_floating_robots_are_listed_and_load_by_name() -> None:
    names = available_floating()
    assert {"solo12", "anymal", "talos_legs", "talos"} <= set(names)
    assert set(names) <= set(available_robots())
    for name in ("solo12", "anymal", "talos_legs", "talos", "bolt"):
        robot = _robot(name)
        assert robot.floating
        assert robot.model.joints[1].shortname() == "JointModelFreeFlyer"
        assert robot.nq == robot.nv + 1
        assert "root_joint" not in robot.joint_names
        assert len(robot.joint_names) == robot.nv - 6
        np.testing.assert_array_equal(robot.joint_indices(None), np.arange(6, robot.nv))
        np.testing.assert_array_equal(robot.q_of_v[6:], np.arange(7, robot.nq))
        assert np.all(robot.q_of_v[:6] == -1)


def test_talos_legs_keeps_the_upper_body_as_one_rigid_body() -> None:
    legs, full = _robot("talos_legs").model, _robot("talos").model
    assert legs.nv == 18 and full.nv == 38
    assert pin.computeTotalMass(legs) == pytest.approx(pin.computeTotalMass(full), rel=1e-12)


def test_the_base_is_no_joint_of_a_joint_residual() -> None:
    robot = _robot("solo12")
    with pytest.raises(InputError, match="'root_joint' is its floating base"):
        robot.joint_indices(["root_joint"])
    assert not load_robot("iiwa").floating


def test_a_free_flyer_below_the_root_is_refused() -> None:
    model = pin.Model()
    inertia = pin.Inertia(1.0, np.zeros(3), np.diag([0.1, 0.2, 0.25]))
    j = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "hinge")
    model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
    j = model.addJoint(j, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "loose")
    model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
    with pytest.raises(RobotModelError, match="'loose' is a JointModelFreeFlyer"):
        maximal_model(model)
    with pytest.raises(RobotModelError, match="'loose'"):
        load_robot(model)


# ---------------------------------------------------------------------------- maximal model


@pytest.mark.parametrize("name", QUADRUPEDS)
def test_the_base_is_a_free_body_without_joint_rows(name: str) -> None:
    mm = _mm(name)
    assert mm.joint_types[0] == "free" and mm.free[0] and not mm.free[1:].any()
    assert mm.nb == mm.model.njoints - 1 and mm.nj == mm.nb - 1
    np.testing.assert_array_equal(mm.jointed, np.arange(1, mm.nb))
    np.testing.assert_array_equal(mm.joint_slot, np.arange(-1, mm.nb - 1))
    assert mm.effort_limit[0] == 0.0 and not np.isfinite(mm.upper_position_limit[0])
    assert mm.mass.sum() == pytest.approx(pin.computeTotalMass(mm.model), rel=1e-12)
    for seed in range(3):
        q, _ = _random_state(_robot(name), seed)
        R, p = body_poses(mm, q)
        assert joint_constraint_residuals(mm, R[None], p[None])[0] < 1e-12


@pytest.mark.parametrize("name", QUADRUPEDS)
def test_state_maps_round_trip_with_a_floating_base(name: str) -> None:
    """Free-flyer coordinates are the base joint frame's placement (quaternion ``w ≥ 0``) and
    Pinocchio's local velocity; COM and kinetic energy as Pinocchio's."""
    robot, mm = _robot(name), _mm(name)
    data = robot.model.createData()
    for seed in range(4):
        q, v = _random_state(robot, seed)
        q[3:7] *= np.sign(q[6])  # the canonical sign
        R, p = body_poses(mm, q)
        omega, v_com = body_velocities(mm, q, v)
        np.testing.assert_allclose(joint_positions(mm, R, p, q_ref=q), q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(joint_velocities(mm, R, omega, p, v_com), v, atol=1e-12)
        com = mm.mass @ p / mm.mass.sum()
        np.testing.assert_allclose(com, pin.centerOfMass(robot.model, data, q), atol=1e-12)
        kinetic = 0.5 * mm.mass @ np.sum(v_com**2, axis=1) + 0.5 * np.einsum(
            "bi,bij,bj->", omega, mm.inertia, omega
        )
        assert kinetic == pytest.approx(pin.computeKineticEnergy(robot.model, data, q, v))


def test_a_path_of_base_orientations_keeps_its_quaternions_continuous() -> None:
    robot, mm = _robot("solo12"), _mm("solo12")
    q0 = robot.configuration("default")
    turn = np.zeros(robot.nv)
    turn[3:6] = [0.3, -0.2, 2.9]  # past π/2 the canonical sign would flip
    path = np.array([integrate(robot.model, q0, s * turn) for s in np.linspace(0, 1.6, 17)])
    R, p = body_poses(mm, path)
    quats = joint_positions(mm, R, p, q_ref=q0)[:, 3:7]
    assert np.all(np.einsum("ki,ki->k", quats[1:], quats[:-1]) > 0.9)
    np.testing.assert_allclose(np.abs(np.einsum("ki,ki->k", quats, path[:, 3:7])), 1.0)


def test_joint_space_kinematics_of_a_floating_base_are_pinocchio_s() -> None:
    """The symbolic kinematics (frame residuals of the verifier and the start check) place the
    base by its quaternion."""
    robot = _robot("solo12")
    data = robot.model.createData()
    foot = robot.model.getFrameId("FL_FOOT")
    residual = FrameTranslation("FL_FOOT", np.zeros(3))
    for seed in range(3):
        q, v = _random_state(robot, seed)
        pin.framesForwardKinematics(robot.model, data, q)
        value = evaluate(
            robot, mb.Scene(), residual.resolve(robot, mb.Scene()), q[None], v[None], None
        )
        np.testing.assert_allclose(value[0], data.oMf[foot].translation, atol=1e-12)


# ---------------------------------------------------------------------------- free flight


def test_a_released_robot_falls_as_one_body() -> None:
    """From rest with zero joint torques every body falls by ½gt², the joints stay (uniform
    gravity exerts no internal force): the LGVI and Pinocchio's first step agree exactly."""
    robot, mm = _robot("solo12"), _mm("solo12")
    q0, dt, N = robot.configuration("default"), 0.01, 30
    q1 = free_first_step(robot.model, q0, np.zeros(robot.nv), dt)
    np.testing.assert_allclose(q1 - q0, np.r_[0, 0, -0.5 * 9.81 * dt**2, np.zeros(16)], atol=1e-15)
    traj = simulate_maximal(mm, q0, q1, np.zeros(mm.nj), dt, N)
    q = joint_positions(mm, traj.R, traj.p, q_ref=q0)
    t = dt * np.arange(N + 1)
    np.testing.assert_allclose(q[:, 2] - q0[2], -0.5 * 9.81 * t**2, atol=1e-12)
    np.testing.assert_allclose(q[:, 7:], np.tile(q0[7:], (N + 1, 1)), atol=1e-12)


@pytest.mark.parametrize("gravity", [0.0, -9.81])
def test_free_flight_keeps_the_discrete_momentum(gravity: float) -> None:
    """Joint forces and torques are internal: the LGVI keeps the discrete linear and angular
    momentum (less gravity's impulses, :func:`discrete_momentum`) to round-off."""
    model = _robot("solo12").model.copy()
    model.gravity.linear = np.array([0.0, 0.0, gravity])
    mm = maximal_model(model)
    q0, v0 = _random_state(_robot("solo12"), 7)
    dt, N = 0.005, 80
    q1 = integrate(model, q0, dt * 0.3 * v0)
    # torques that keep the light lower legs below ~0.3 rad per step (0.2 N m spun them at up
    # to 0.85 rad per step, where the simulation's Newton depends on round-off)
    tau = np.sin(np.arange(N + 1)[:, None] * dt * np.linspace(3, 9, mm.nj)) * 0.05
    traj = simulate_maximal(mm, q0, q1, tau, dt, N)
    assert np.linalg.norm(SO3.log(traj.F), axis=-1).max() < 0.4
    for momentum in discrete_momentum(mm, traj, dt):
        assert np.abs(momentum[0]).max() > 1e-3  # a motion that has some
        scale = np.abs(momentum).max()
        np.testing.assert_allclose(momentum, np.tile(momentum[0], (N + 1, 1)), atol=1e-11 * scale)
    if gravity:  # the raw momentum is not constant: gravity's impulses are what was taken out
        raw = np.einsum("b,kbi->ki", mm.mass, traj.v)
        assert np.abs(raw[-1] - raw[0]).max() > 1.0


def test_the_lgvi_of_a_floating_robot_is_second_order_against_pinocchio() -> None:
    case = validate_case(_robot("solo12").model, 0, (0.008, 0.004, 0.002), 0.2)
    assert 1.8 <= case["observed_order"] <= 2.2
    assert case["joints"] == {"revolute": 12, "free": 1}
    assert max(r["max_constraint_residual"] for r in case["runs"]) < 1e-10


# ---------------------------------------------------------------------------- planning


def _tuck_ocp() -> mb.OCP:
    """solo12 released 1 m above the ground (no contact) tucks its legs in 0.4 s."""
    robot = _robot("solo12")
    q0 = robot.configuration("default")
    q0[2] = 1.0
    ocp = mb.OCP(robot, N=20, dt=0.02, q0=q0)
    target = q0[robot.q_of_v[robot.joint_indices(None)]].copy()
    target[[1, 4, 7, 10]] += 0.5
    ocp.add_constraint("goal", JointPosition(target=target), knots="terminal")
    ocp.add_cost("effort", JointTorque(), weight=1e-3)
    ocp.add_constraint("position_limits", JointPositionLimits())
    ocp.add_constraint("torque_limits", JointTorqueLimits())
    return ocp


@cache
def _tuck_plan() -> mb.PlanResult:
    return mb.plan(_tuck_ocp(), "ripm", warm_start="linear")


def test_a_floating_robot_plans_in_free_flight_and_the_replay_verifies_it() -> None:
    result = _tuck_plan()
    assert result.success, result.message
    assert result.q.shape == (21, 19) and result.tau.shape == (20, 18)
    assert np.all(result.tau[:, :6] == 0.0) and np.all(result.tau_knots[:, :6] == 0.0)
    np.testing.assert_allclose(np.linalg.norm(result.q[:, 3:7], axis=1), 1.0, atol=1e-12)
    fall = result.q[0, 2] - result.q[-1, 2]
    assert 0.7 < fall < 0.5 * 9.81 * 0.4**2 + 0.05  # the base falls freely, the legs swing
    check = mb.verify(result)
    assert check.passed, check.reasons


@pytest.mark.parametrize("method", ["fddp", "csqp"])
def test_shooting_methods_refuse_a_floating_base_before_any_solve(method: str) -> None:
    with pytest.raises(InputError, match="does not plan floating-base robots"):
        mb.plan(_tuck_ocp(), method)


def test_a_floating_robot_loads_from_a_pinocchio_model() -> None:
    model = load("solo12", geometry=False).model
    robot = load_robot(model)
    assert robot.floating and robot.nv == 18


def test_configuration_arithmetic_inverts_itself() -> None:
    """``(q ⊕ δ) ⊖ q = δ`` on batches, with Pinocchio's free flyer; plain arithmetic when
    ``nq = nv``."""
    robot = _robot("solo12")
    q = np.array([_random_state(robot, s)[0] for s in range(4)])
    delta = 0.3 * np.random.default_rng(0).standard_normal((4, robot.nv))
    np.testing.assert_allclose(difference(robot.model, q, integrate(robot.model, q, delta)), delta)
    arm = load_robot("iiwa").model
    a, d = np.ones((2, 7)), np.arange(14.0).reshape(2, 7)
    np.testing.assert_array_equal(integrate(arm, a, d), a + d)
    np.testing.assert_array_equal(difference(arm, a, a + d), d)


def test_loops_on_a_floating_base_are_refused() -> None:
    foot = {"name": "stance", "frame1": "FL_FOOT", "frame2": "universe"}
    with pytest.raises(RobotModelError, match="loop closures on a floating-base robot"):
        load_robot("solo12", loops=[foot])


def test_the_generalized_nlp_of_a_floating_base_has_exact_derivatives() -> None:
    """IPOPT's NLP with the base's position and quaternion as coordinates (normalized where
    read): constraint Jacobian, objective gradient and Lagrangian Hessian against central
    differences in those coordinates, off the unit sphere too."""
    robot = _robot("solo12")
    q0 = robot.configuration("default")
    ocp = mb.OCP(robot, N=4, dt=0.05, q0=q0)
    ocp.add_cost("effort", JointTorque(), weight=1e-2)
    ocp.add_cost("foot", FrameTranslation("FL_FOOT", np.array([0.2, 0.1, -0.1])), weight=3.0)
    target = q0[robot.q_of_v[robot.joint_indices(None)]] + 0.2
    ocp.add_constraint("goal", JointPosition(target=target), knots="terminal")
    nlp = GeneralizedNLP(ocp)
    assert nlp.n == 4 * (19 + 2 * 18) and nlp.m == 2 * 4 * 18 + 4 + 12
    rng = np.random.default_rng(3)
    path = np.array([integrate(robot.model, q0, 0.1 * rng.standard_normal(18)) for _ in range(5)])
    z = nlp.initial_guess(path) + 0.05 * rng.standard_normal(nlp.n)
    lam = rng.standard_normal(nlp.m)
    check_generalized_derivatives(nlp, z, lam)


def test_ipopt_plans_a_floating_base_in_free_flight_as_the_ripm() -> None:
    result = mb.plan(_tuck_ocp(), "ipopt", warm_start="linear")
    assert result.success, result.message
    np.testing.assert_allclose(np.linalg.norm(result.q[:, 3:7], axis=1), 1.0, atol=1e-9)
    assert np.all(result.tau[:, :6] == 0.0)
    check = mb.verify(result)
    assert check.passed, check.reasons
    ripm = _tuck_plan()  # both fall freely the same way
    assert abs(result.q[-1, 2] - ripm.q[-1, 2]) < 0.05


def test_the_free_flight_family_draws_reproducible_reachable_targets() -> None:
    from mbplan.tasks.floating import SWING, free_flight_case

    a, b = free_flight_case("anymal", 3, seed=1), free_flight_case("anymal", 3, seed=1)
    target = a["goal"].residual.target
    np.testing.assert_array_equal(target, b["goal"].residual.target)
    assert not np.array_equal(target, free_flight_case("anymal", 4, seed=1)["goal"].residual.target)
    robot = a.robot
    start = a.q0[robot.q_of_v[robot.joint_indices(None)]]
    assert np.all(np.abs(target - start) <= SWING + 1e-12)
    with pytest.raises(InputError, match="unknown robot 'iiwa'"):
        free_flight_case("iiwa", 0)


def test_a_locked_robot_keeps_its_floating_base_in_its_reference_configurations() -> None:
    robot = _robot("talos_legs")
    q = robot.configuration("default")
    assert q.shape == (robot.nq,)
    np.testing.assert_allclose(np.linalg.norm(q[3:7]), 1.0)
    full = _robot("talos").configuration("default")
    np.testing.assert_array_equal(q[:7], full[:7])


def test_the_base_error_of_validate_dynamics_resolves_tiny_rotations() -> None:
    """The base's rotation error is the angle of ``q_ref⁻¹q`` to round-off (an arccos of the
    quaternions' dot product would floor at ~1e-8 rad)."""
    from scipy.spatial.transform import Rotation

    from mbplan.benchmarks.dynamics_scenario import joint_errors

    mm, q = _mm("solo12"), np.tile(_robot("solo12").configuration("default"), (2, 1))
    turn = Rotation.from_rotvec([0.3, -0.2, 0.5])
    q[:, 3:7] = turn.as_quat()
    moved = q.copy()
    moved[0, 3:7] = (turn * Rotation.from_rotvec([1e-9, 0.0, 0.0])).as_quat()
    moved[1, 0] += 2e-3  # and a base position error
    err = joint_errors(mm, moved, q)[:, 0]
    np.testing.assert_allclose(err, [1e-9, 2e-3], rtol=1e-6)


def test_floating_inputs_are_checked_and_named() -> None:
    """A start quaternion off the unit sphere, a zero quaternion in a warm start, a goal for
    every coordinate in a task file: mbplan errors; limit rows are labelled by their joints."""
    robot = _robot("solo12")
    q0 = robot.configuration("default")
    bad = q0.copy()
    bad[3:7] = [0.0, 0.0, 0.3, 1.0]
    with pytest.raises(InputError, match="not of unit norm"):
        mb.OCP(robot, N=4, dt=0.05, q0=bad)
    flipped = q0.copy()
    flipped[3:7] = [0.0, 0.0, -0.6, -0.8]
    assert mb.OCP(robot, N=4, dt=0.05, q0=flipped).q0[6] == pytest.approx(0.8)
    ocp = _tuck_ocp()
    guess = np.tile(ocp.q0, (ocp.N + 1, 1))
    guess[3, 3:7] = 0.0
    with pytest.raises(InputError, match="knot 3 has a zero quaternion"):
        mb.plan(ocp, "ripm", warm_start=guess)
    limits = ocp["position_limits"].residual
    assert limits.row_label(robot, ocp.scene, 0) == "the lower limit of joint 'FL_HAA'"
    assert limits.row_label(robot, ocp.scene, 23) == "the upper limit of joint 'HR_KFE'"


def test_a_floating_task_file_refuses_a_goal_on_every_coordinate(tmp_path) -> None:
    from mbplan.taskfile import load_task

    task = tmp_path / "solo.toml"
    q = ", ".join(str(x) for x in _robot("solo12").configuration("default"))
    task.write_text(f'[robot]\nname = "solo12"\n[horizon]\nN = 5\ndt = 0.02\n[goal]\nq = [{q}]\n')
    with pytest.raises(InputError, match=r"lists them: joints = \[\.\.\.\] and q"):
        load_task(str(task))


def test_mbplan_robots_lists_the_floating_bases(capsys) -> None:
    from mbplan.cli.main import main

    assert main(["robots"]) == 0
    listed = capsys.readouterr().out
    assert "solo12  (floating base: a free body and 12 joints)" in listed
    assert "talos  (floating base: a free body and 32 joints)" in listed
    assert "talos_legs  (floating base: a free body and 12 joints)" in listed


def test_paths_a_floating_base_does_not_take_are_refused_by_name() -> None:
    """IPOPT with coal distances on a floating base, wrench blocks of the joint elimination for
    a free body, a torque per body instead of per joint slot: mbplan errors before any solve."""
    from mbplan.formulations.maximal import MaximalNLP
    from mbplan.formulations.maximal_layout import joint_elimination_plan
    from mbplan.residuals import Distance

    robot = _robot("solo12")
    scene = mb.Scene().add_box("wall", (0.05, 1.0, 1.0), (0.6, 0.0, 1.0))
    ocp = mb.OCP(robot, scene, N=4, dt=0.02, q0=_tuck_ocp().q0)
    ocp.add_constraint("clearance", Distance(margin=0.02))
    with pytest.raises(InputError, match=r"constraint 'clearance'.*floating base; plan it with"):
        GeneralizedNLP(ocp)
    nlp = MaximalNLP(_tuck_ocp(), jit=False)
    point = nlp.initial_point(np.tile(nlp.ocp.q0, (nlp.ocp.N + 1, 1)))
    jac = nlp.problem.evaluate(point, hessian=False).eq_jacobian
    with pytest.raises(InputError, match="no wrench blocks for a free body"):
        joint_elimination_plan(nlp.problem, jac, forces=True)
    mm = _mm("solo12")
    q0 = robot.configuration("default")
    with pytest.raises(InputError, match=r"tau: expected shape \(12,\) or \(4, 12\)"):
        simulate_maximal(mm, q0, q0, np.zeros(mm.nb), 0.01, 3)
