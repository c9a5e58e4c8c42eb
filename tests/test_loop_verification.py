"""The verifier of plans with closed loops and passive joints: its closure kinematics and
constraint dynamics against finite differences and Pinocchio, and the plans it passes and
fails, with their reasons."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from loop_problems import fourbar, fourbar_ocp, fourbar_plan

import mbplan as mb
from mbplan.planning.solve import finish
from mbplan.residuals import JointTorque
from mbplan.robots.loops import LOOP_KINDS, Loop, closure_jacobian, closure_residual
from mbplan.verification.loops import (
    CLOSURE_TOLERANCE,
    closure_kinematics,
    constrained_acceleration,
    rk4_step,
)


@pytest.mark.parametrize("kind", list(LOOP_KINDS))
def test_closure_kinematics_match_finite_differences(kind: str) -> None:
    """``r``, ``J_c`` and the drift ``J̇_c v = d²r(q + s v)/ds²`` of every loop kind between two
    bodies of a chain, at random frames and states."""
    model = pin.buildSampleModelManipulator()
    rng = np.random.default_rng(2)
    pin.seed(3)
    for _ in range(3):
        loop = Loop(
            "l",
            kind,
            "shoulder2_joint",
            pin.SE3.Random().homogeneous,
            "wrist1_joint",
            pin.SE3.Random().homogeneous,
            LOOP_KINDS[kind],
        )
        q, v = rng.uniform(-1.5, 1.5, model.nq), rng.standard_normal(model.nv)
        r, J, drift = closure_kinematics(model, (loop,), q, v)
        np.testing.assert_allclose(r, closure_residual(model, (loop,), q), atol=1e-14)
        np.testing.assert_allclose(J, closure_jacobian(model, (loop,), q), atol=1e-7)
        h = 1e-4
        second = (
            closure_residual(model, (loop,), q + h * v)
            - 2.0 * r
            + closure_residual(model, (loop,), q - h * v)
        ) / h**2
        np.testing.assert_allclose(drift, second, atol=1e-5 * max(1.0, np.abs(drift).max()))


def test_constrained_acceleration_equals_pinocchio_constraint_dynamics() -> None:
    """The KKT solve of the imposed rows (the four-bar's y row dropped) gives the accelerations
    of Pinocchio's proximal constraint dynamics on the full 3-D connect."""
    robot = fourbar()
    model, (loop,) = robot.model, robot.loops
    q = robot.closed(robot.configuration("neutral") + np.array([0.4, 0.0, 0.0]))
    tangent = np.linalg.svd(closure_jacobian(model, robot.loops, q))[2][-1]
    v, tau = 2.0 * tangent, np.array([0.3, 0.0, 0.0])
    constraint = pin.RigidConstraintModel(
        pin.ContactType.CONTACT_3D,
        model,
        model.getJointId(loop.joint1),
        pin.SE3(loop.placement1),
        model.getJointId(loop.joint2),
        pin.SE3(loop.placement2),
        pin.ReferenceFrame.LOCAL,
    )
    models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    models.append(constraint)
    datas.append(constraint.createData())
    data = model.createData()
    pin.initConstraintDynamics(model, data, models, datas)
    prox = pin.ProximalSettings(1e-12, 1e-10, 100)
    expected = pin.constraintDynamics(model, data, q, v, tau, models, datas, prox)
    a = constrained_acceleration(robot, q, v, tau, alpha=0.0)
    np.testing.assert_allclose(a, expected, atol=1e-9 * np.abs(expected).max())


def test_the_replay_keeps_the_loops_closed() -> None:
    """0.1 s of free fall from a closed state at rest: the constraint dynamics hold the closure
    (RK4's error only)."""
    robot = fourbar()
    q, v = robot.configuration("neutral"), np.zeros(robot.nv)
    for _ in range(100):
        q, v = rk4_step(robot, q, v, np.zeros(robot.nv), 1e-3, alpha=10.0)
    assert np.abs(v).max() > 1.0  # it fell
    assert np.abs(closure_residual(robot.model, robot.loops, q)).max() < 1e-8


def test_an_exact_simulation_of_the_transcription_passes_at_ratio_one_half() -> None:
    """Every torque given: the plan is the transcription's own simulation, whose deviation from
    the replay equals the reference step's (ratio 0.5, like a tree's exact eq. (61) plan)."""
    ocp = mb.OCP(fourbar(), N=10, dt=0.01)
    ocp.add_constraint("drive", JointTorque(joints=["crank_joint"], target=[0.02]))
    result = mb.plan(ocp, "ipopt", warm_start="linear", tol=1e-10)
    assert result.success, result.message
    check = mb.verify(ocp, result)
    assert check.passed, check.reasons
    assert check.max_velocity_deviation > 1e-4  # a real discretisation error is measured
    assert check.velocity_deviation_ratio == pytest.approx(0.5, abs=0.01)
    assert check.joint_deviation_ratio == pytest.approx(0.5, abs=0.01)


def test_knots_that_do_not_close_fail_with_a_reason() -> None:
    ocp, result = fourbar_ocp(), fourbar_plan()
    q = result.q.copy()
    q[10, 2] += 1e-3  # the rocker off the coupler's tip
    bad = dataclasses.replace(result, q=q)
    check = mb.verify(ocp, bad)
    assert not check.passed
    assert check.closure_residual > CLOSURE_TOLERANCE
    assert any("do not close the loops (close)" in r for r in check.reasons), check.reasons
    finished = finish(ocp, bad)
    assert not finished.success and "do not close the loops" in finished.message


def test_torque_on_a_passive_joint_fails_with_a_reason() -> None:
    ocp, result = fourbar_ocp(), fourbar_plan()
    tau = result.tau.copy()
    tau[5, ocp.robot.joint_indices(["rocker_joint"])] = 1e-3
    check = mb.verify(ocp, dataclasses.replace(result, tau=tau))
    assert not check.passed
    assert check.passive_torque_nm == pytest.approx(1e-3)
    assert any("passive joints" in r and "no actuator" in r for r in check.reasons)


def test_wrong_torques_fail_the_replay() -> None:
    """30 % more crank torque than planned: the replay's velocities leave the plan's."""
    ocp, result = fourbar_ocp(), fourbar_plan()
    tau = result.tau * np.array([1.3, 1.0, 1.0])
    check = mb.verify(ocp, dataclasses.replace(result, tau=tau))
    assert not check.passed and check.velocity_deviation_ratio > 1.0
    assert any("velocity deviation" in r for r in check.reasons)
