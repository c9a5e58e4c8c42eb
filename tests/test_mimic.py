"""Mimic joints: a URDF's ``<mimic>`` tags become couplings ``q_f = m q_l + o`` of the robot, which
every OCP imposes at its state knots (``mimic="couple"``, the default) and every formulation
plans; ``mimic="independent"`` plans the follower as a joint of its own."""

import numpy as np
import pytest
from test_inputs import two_joint_urdf
from test_ocp import FINGERS, PANDA_START

import mbplan as mb
from mbplan import residuals as res
from mbplan.errors import RobotModelError
from mbplan.robots.robot import Mimic


def _urdf(tmp_path, mimic: str, kind: str = "revolute") -> str:
    path = tmp_path / "robot.urdf"
    path.write_text(two_joint_urdf(mimic, kind))
    return str(path)


def test_the_robot_records_its_couplings(tmp_path) -> None:
    assert mb.load_robot("panda").mimic == (Mimic(FINGERS[1], FINGERS[0], 1.0, 0.0),)
    assert mb.load_robot("panda", mimic="independent").mimic == ()
    path = _urdf(tmp_path, '<mimic joint="j1" multiplier="-0.5" offset="0.2"/>')
    robot = mb.load_robot(path)
    assert robot.mimic == (Mimic("j2", "j1", -0.5, 0.2),)
    assert robot.configuration("neutral").tolist() == [0.0, 0.2]  # the follower coupled
    assert mb.load_robot(path, lock=["j2"]).mimic == ()  # a locked follower needs no coupling
    talos = mb.load_robot("talos_arm")  # <mimic> on its fixed gripper joints: no coordinate
    assert talos.mimic == () and "gripper_left_inner_double_joint" not in talos.model.names


def test_the_ocp_imposes_each_coupling_at_every_state_knot() -> None:
    ocp = mb.OCP("panda", N=4)
    item = ocp["mimic_panda_finger_joint2"]
    assert item.role == "constraint" and item.knots.tolist() == [1, 2, 3, 4]
    assert ocp.q0[7] == ocp.q0[8]  # the SRDF default (0.001, 0) with the follower coupled
    again = mb.OCP.from_dict(ocp.to_dict())
    assert again.names == ocp.names
    old = mb.OCP.from_dict({**ocp.to_dict(), "robot": {"kind": "name", "name": "panda"}})
    assert old.robot.mimic == ()  # a source from before the couplings: independent joints
    assert old.names == ocp.names  # the saved coupling, a constraint of the OCP


BAD = [
    ('<mimic joint="j9"/>', {}, RobotModelError, r"joint 'j2' <mimic> follows joint 'j9', which is not defined"),
    ('<mimic joint="j1"/>', {"mimic": "follow"}, mb.InputError, r"mimic: expected one of couple, independent, got 'follow'"),
    ('<mimic joint="j1"/>', {"lock": {"j1": 0.3}}, mb.InputError, r"joint 'j2' mimics 'j1', which is locked: lock 'j2' too \(at 0.3\)"),
]  # fmt: skip


@pytest.mark.parametrize(("tag", "options", "error", "message"), BAD)
def test_bad_mimic_input_is_named_before_any_solve(tmp_path, tag, options, error, message) -> None:
    with pytest.raises(error, match=message):
        mb.load_robot(_urdf(tmp_path, tag), **options)


def test_bad_couplings_are_named_before_any_solve(tmp_path) -> None:
    with pytest.raises(RobotModelError, match=r"a prismatic joint cannot follow a revolute one"):
        mb.load_robot(_urdf(tmp_path, '<mimic joint="j1"/>', "prismatic"))
    with pytest.raises(mb.InputError, match=r"q0: joint 'j2' is at 0.1, but it mimics 'j1'"):
        mb.OCP(_urdf(tmp_path, '<mimic joint="j1"/>'), q0=[0.0, 0.1])
    ocp = mb.OCP("panda", N=4, q0=PANDA_START)
    with pytest.raises(
        mb.InputError, match=r"'q_to_f': JointCoupling: joint 'panda_finger_joint1'"
    ):
        ocp.add_constraint("q_to_f", res.JointCoupling(FINGERS[0], "panda_joint7"))
    with pytest.raises(mb.InputError, match=r"JointCoupling can only be a constraint"):
        ocp.add_cost("soft", res.JointCoupling(FINGERS[1], FINGERS[0]))


def hand_ocp(mimic: str) -> mb.OCP:
    """A hand position for the panda, its fingers pulled apart: 3 cm for the first, 1 cm for
    the second (the coupled fingers meet halfway)."""
    robot = mb.load_robot("panda", mimic=mimic)
    ocp = mb.OCP(robot, N=8, dt=0.06, q0=PANDA_START)
    ocp.add_cost("v", res.JointVelocity(), 1e-2)
    ocp.add_cost("tau", res.JointTorque(), 1e-4)
    ocp.add_cost("fingers", res.JointPosition([0.03, 0.01], joints=FINGERS), 100.0)
    ocp.add_terminal_constraint("hand", res.FrameTranslation("panda_hand", [0.35, 0.1, 0.45]))
    for limits in (res.JointPositionLimits(), res.JointVelocityLimits(), res.JointTorqueLimits()):
        ocp.add_constraint(type(limits).__name__, limits)
    return ocp


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_mimic_fingers_plan_coupled_and_the_uncoupled_plan_differs_only_by_it(method) -> None:
    coupled, free = hand_ocp("couple"), hand_ocp("independent")
    assert coupled.names == ["mimic_panda_finger_joint2", *free.names]
    plans = {}
    for name, ocp in (("coupled", coupled), ("free", free)):
        plan = mb.plan(ocp, method)
        assert plan.success, (name, plan.message)
        check = mb.verify(ocp, plan)
        assert check.passed, (name, check.reasons)
        plans[name] = plan
    gap = {n: np.abs(p.q[:, 7] - p.q[:, 8]) for n, p in plans.items()}
    assert np.max(gap["coupled"]) <= 1e-8
    assert gap["free"][-1] > 5e-3  # each finger toward its own target
    assert abs(np.mean(plans["coupled"].q[-1, 7:]) - 0.02) < 2e-3


def test_crocoddyl_plans_the_coupling_with_csqp_and_fddp_refuses_it() -> None:
    """CSQP: the coupling an equality of every node (the panda undamped: Crocoddyl's explicit
    Euler step); FDDP has no constraints: refused, naming the constraint and its residual."""
    ocp = mb.OCP(mb.load_robot("panda", damping=False), N=8, dt=0.06, q0=PANDA_START)
    ocp.add_cost("v", res.JointVelocity(), 1e-2)
    ocp.add_cost("tau", res.JointTorque(), 1e-4)
    ocp.add_cost("fingers", res.JointPosition([0.03, 0.01], joints=FINGERS), 100.0)
    ocp.add_terminal_cost("hand", res.FrameTranslation("panda_hand", [0.35, 0.1, 0.45]), 100.0)
    plan = mb.plan(ocp, "csqp")
    assert plan.success, plan.message
    assert mb.verify(ocp, plan).passed
    assert np.max(np.abs(plan.q[:, 7] - plan.q[:, 8])) <= 1e-8
    message = r"fddp cannot express .* 'mimic_panda_finger_joint2' \(JointCoupling; .*\): use csqp"
    with pytest.raises(mb.InputError, match=message):
        mb.plan(ocp, "fddp")
