"""Continuous joints through the OCP API: one unbounded angle per joint
(:mod:`mbplan.robots.continuous`), planned in maximal (RIPM) and generalized (IPOPT) coordinates."""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
import pytest
from fd import check_generalized_derivatives

import mbplan as mb
from mbplan import residuals as res
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.joint_space import evaluate
from mbplan.formulations.maximal import MaximalNLP
from mbplan.robots import load
from mbplan.robots.continuous import from_angles, to_angles
from mbplan.tasks.paper import tracking_ocp

LIMITS = {"torque_limit": [20.0, 20.0], "velocity_limit": [10.0, 10.0]}  # the URDF's are 0


@cache
def pendulum() -> mb.Robot:
    """example-robot-data's double pendulum (two continuous joints about x), undamped (the
    generalized transcription and the verifier's replay do not model damping yet)."""
    desc = load("double_pendulum_continuous")
    model = desc.model.copy()
    model.damping[:] = 0.0
    return mb.load_robot(model, collision_model=desc.collision_model)


def frame_ocp(q_goal: np.ndarray) -> tuple[mb.OCP, pin.SE3]:
    robot = pendulum()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q_goal)
    goal = data.oMf[robot.frame_id("link2")].copy()
    ocp = mb.OCP(robot, N=24, dt=0.05, q0=np.zeros(2))
    ocp.add_cost("v", res.JointVelocity(), 0.1)
    ocp.add_cost("tau", res.JointTorque(), 1e-3)
    ocp.add_terminal_constraint("pose", res.FramePlacement("link2", goal))
    ocp.add_cost("rest", res.JointVelocity(), 10.0, knots="terminal")
    ocp.add_constraint("tau_limits", res.JointTorqueLimits(-np.full(2, 20.0), np.full(2, 20.0)))
    return ocp, goal


def test_continuous_joints_become_unbounded_angles_with_the_same_dynamics() -> None:
    original = load("double_pendulum_continuous").model
    robot = pendulum()
    assert robot.continuous == ("joint1", "joint2") and robot.nq == robot.nv == 2
    assert np.all(np.isinf(robot.model.lowerPositionLimit))
    rng = np.random.default_rng(0)
    theta, v, a = 3.0 * rng.standard_normal(2), rng.standard_normal(2), rng.standard_normal(2)
    q = from_angles(original, theta)
    np.testing.assert_allclose(np.exp(1j * to_angles(original, q)), np.exp(1j * theta))
    undamped = original.copy()
    np.testing.assert_allclose(
        pin.rnea(robot.model, robot.model.createData(), theta, v, a),
        pin.rnea(undamped, undamped.createData(), q, v, a),
        atol=1e-12,
    )
    d0, d1 = undamped.createData(), robot.model.createData()
    pin.framesForwardKinematics(undamped, d0, q)
    pin.framesForwardKinematics(robot.model, d1, theta)
    for f in range(undamped.nframes):
        np.testing.assert_allclose(d0.oMf[f].homogeneous, d1.oMf[f].homogeneous, atol=1e-12)
    # position limits have no rows for continuous joints; a goal compares angles modulo 2π
    scene = mb.Scene()
    assert res.JointPositionLimits().resolve(robot, scene).dim(robot, scene) == 0
    goal = res.JointPosition([0.5, -3.0]).resolve(robot, scene)
    turned = np.array([[0.5 + 2 * np.pi, -3.0 - 4 * np.pi]])
    np.testing.assert_allclose(
        evaluate(robot, scene, goal, turned, 0 * turned, None), 0, atol=1e-12
    )


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_joint_goal_past_pi_plans_and_verifies(method: str) -> None:
    goal = np.array([3.6, -1.0])  # joint 1 turns past π
    ocp = tracking_ocp(pendulum(), np.zeros(2), goal, N=30, dt=0.05, **LIMITS)
    result = mb.plan(ocp, method)
    assert result.success, result.message
    check = mb.verify(ocp, result)
    assert check.passed, check.reasons
    assert np.all(np.abs(result.q[-1] - goal) < 0.06)


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_frame_goal_plans_and_verifies(method: str) -> None:
    ocp, goal = frame_ocp(np.array([2.0, 1.5]))
    result = mb.plan(ocp, method)
    assert result.success, result.message
    check = mb.verify(ocp, result)
    assert check.passed, check.reasons
    data = ocp.robot.model.createData()
    pin.framesForwardKinematics(ocp.robot.model, data, result.q[-1])
    err = pin.log6(goal.inverse() * data.oMf[ocp.robot.frame_id("link2")]).vector
    assert np.linalg.norm(err) < 1e-5


def fd_ocp() -> mb.OCP:
    ocp = mb.OCP(pendulum(), N=3, dt=0.05, q0=np.array([0.3, -0.2]))
    ocp.add_cost("q", res.JointPosition([3.0, -2.5]), 1.3)
    ocp.add_cost("v", res.JointVelocity(), 0.1)
    ocp.add_constraint("q_eq", res.JointPosition([0.5], joints=("joint2",)), knots=[2])
    ocp.add_constraint("point", res.FrameTranslation("link2", [0.0, 0.1, 0.3]), knots=[3])
    ocp.add_constraint("q_limits", res.JointPositionLimits())
    ocp.add_constraint("tau_limits", res.JointTorqueLimits(-np.full(2, 5.0), np.full(2, 5.0)))
    return ocp


def test_generalized_continuous_residuals_match_finite_differences() -> None:
    ocp = fd_ocp()
    nlp = GeneralizedNLP(ocp)
    rng = np.random.default_rng(0)
    z = nlp.initial_guess(np.linspace(ocp.q0, [3.0, -2.5], ocp.N + 1))
    z = z + 0.05 * rng.standard_normal(nlp.n)
    check_generalized_derivatives(nlp, z, rng.standard_normal(nlp.m))


def test_maximal_continuous_residuals_match_finite_differences_along_the_retraction() -> None:
    ocp = fd_ocp()
    nlp = MaximalNLP(ocp, jit=False)
    prob = nlp.problem
    rng = np.random.default_rng(1)
    x = nlp.initial_point(np.linspace(ocp.q0, [3.0, -2.5], ocp.N + 1))
    x = prob.retract(x, 0.05 * rng.standard_normal(prob.n))
    y, zi = rng.standard_normal(prob.n_eq), rng.standard_normal(prob.n_ineq)
    ev = prob.evaluate(x, 1.0, y, zi)
    for _ in range(3):
        d = rng.standard_normal(prob.n)
        h = 1e-6
        (fp, hp, gp), (fm, hm, gm) = (
            prob.values(prob.retract(x, h * d)),
            prob.values(prob.retract(x, -h * d)),
        )
        np.testing.assert_allclose((fp - fm) / (2 * h), ev.gradient @ d, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose((hp - hm) / (2 * h), ev.eq_jacobian @ d, atol=1e-5)
        np.testing.assert_allclose((gp - gm) / (2 * h), ev.ineq_jacobian @ d, atol=1e-5)


def test_a_joint_target_of_the_wrong_length_names_the_expected_size() -> None:
    ocp = mb.OCP(pendulum(), N=4, q0=np.zeros(2))
    with pytest.raises(mb.InputError, match=r"JointPosition.target: expected shape \(2,\)"):
        ocp.add_cost("q", res.JointPosition([0.0, 1.0, 0.0]))
    with pytest.raises(mb.InputError, match=r"expected shape \(1,\)"):
        ocp.add_cost("q1", res.JointPosition([0.0, 1.0], joints=("joint1",)))


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_kinova_with_three_continuous_joints_plans_and_verifies(method: str) -> None:
    """Continuous joints 1, 4, 6 beside limited ones (their limits keep their rows); joint 4
    goes past π. The SRDF's ``arm_up`` has joint 3 outside its limits modulo 2π: shifted in."""
    robot = mb.load_robot("kinova")
    assert robot.continuous == ("j2s6s200_joint_1", "j2s6s200_joint_4", "j2s6s200_joint_6")
    scene = mb.Scene()
    assert res.JointPositionLimits().resolve(robot, scene).dim(robot, scene) == 6
    q0 = robot.configuration("arm_up") + np.array([0.0, 0.0, 2 * np.pi, 0.0, 0.0, 0.0])
    goal = q0 + np.array([1.0, -0.3, 0.3, 1.0, -0.3, 1.0])
    ocp = tracking_ocp(robot, q0, goal, N=20, dt=0.1)
    result = mb.plan(ocp, method)
    assert result.success, result.message
    check = mb.verify(ocp, result)
    assert check.passed, check.reasons
    assert np.all(np.abs(result.q[-1] - goal) < 0.01)


def test_a_continuous_joint_locks_at_an_angle() -> None:
    robot = mb.load_robot("double_pendulum_continuous", lock={"joint2": 0.5})
    assert robot.continuous == ("joint1",) and robot.nq == 1
    original = load("double_pendulum_continuous").model
    d0, d1 = original.createData(), robot.model.createData()
    pin.framesForwardKinematics(original, d0, from_angles(original, np.array([1.2, 0.5])))
    pin.framesForwardKinematics(robot.model, d1, np.array([1.2]))
    M0, M1 = d0.oMf[original.getFrameId("link2")], d1.oMf[robot.frame_id("link2")]
    np.testing.assert_allclose(M0.homogeneous, M1.homogeneous, atol=1e-12)


def test_both_formulations_cost_a_continuous_goal_alike_modulo_two_pi() -> None:
    """The maximal chordal cost ``w (1 - cos Δθ)`` equals joint space's ``½ w (2 sin(Δθ/2))²``
    knot by knot, on a path that turns a full turn past the target."""
    ocp = fd_ocp()
    nlp = MaximalNLP(ocp, jit=False)
    q = np.linspace(ocp.q0, [3.0 + 2 * np.pi, -2.5 - 0.4], ocp.N + 1)
    x = nlp.initial_point(q)
    np.testing.assert_allclose(nlp.joint_trajectory(x)["q"], q, atol=1e-9)
    item = ocp["q"]
    expected = evaluate(ocp.robot, ocp.scene, item.residual, q[item.knots], q[item.knots], None)
    flat = {n: nlp.problem.variables.blocks[n].flat(a) for n, a in x.items()}
    value = {  # joint 1 hangs from the world, joint 2 from link 1: one term each, per knot
        t.name: np.ravel(t.function.value(t.gather(flat), t.parameters))
        for t in nlp.problem.terms
        if t.name in ("q_world", "q")
    }
    cost = 0.5 * item.weight * expected**2
    np.testing.assert_allclose(value["q_world"], cost[:, 0], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(value["q"], cost[:, 1], rtol=1e-10, atol=1e-14)
    assert cost.sum() > 1.0
