"""Loop closures and passive joints as robot data: reading, redundant rows, start checks, errors."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pinocchio as pin
import pytest

import mbplan
from mbplan.errors import InputError, RobotModelError
from mbplan.residuals import JointTorque
from mbplan.robots.loops import (
    LOOP_KINDS,
    close_loops,
    closure_jacobian,
    closure_residual,
    independent_joints,
    loop_jacobian,
    loop_residual,
)
from mbplan.robots.mjcf import mjcf_actuated
from mbplan.robots.robot import robot_from_source

FOURBAR = """<mujoco model="fourbar">
  <compiler angle="radian"/>
  <worldbody>
    <body name="base">
      <body name="crank">
        <joint name="crank_joint" type="hinge" axis="0 1 0" range="-3 3"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01" mass="0.1"/>
        <body name="coupler" pos="0.1 0 0">
          <joint name="coupler_joint" type="hinge" axis="0 1 0" range="-3 3"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.01" mass="0.2"/>
          <site name="coupler_tip" pos="0 0 0.3"/>
        </body>
      </body>
      <body name="rocker" pos="0.3 0 0">
        <joint name="rocker_joint" type="hinge" axis="0 1 0" range="-3 3"/>
        <geom type="capsule" fromto="0 0 0 -0.2 0 0.3" size="0.01" mass="0.2"/>
      </body>
    </body>
  </worldbody>
  {equality}
  {actuator}
</mujoco>
"""
CONNECT = (
    '<equality><connect name="close" body1="coupler" body2="rocker" anchor="0 0 0.3"/></equality>'
)
MOTOR = '<actuator><motor joint="crank_joint"/></actuator>'


def _mjcf(tmp_path, equality=CONNECT, actuator=MOTOR, name="fourbar.xml"):
    path = tmp_path / name
    path.write_text(FOURBAR.replace("{equality}", equality).replace("{actuator}", actuator))
    return path


@pytest.fixture
def fourbar(tmp_path):
    return mbplan.load_robot(_mjcf(tmp_path))


def _random_rotation(rng):
    return pin.exp3(rng.normal(size=3))


@pytest.mark.parametrize("kind", list(LOOP_KINDS))
def test_residual_numpy_matches_casadi_and_vanishes_on_coincident_frames(kind):
    rng = np.random.default_rng(0)
    R1, R2 = _random_rotation(rng), _random_rotation(rng)
    p1, p2 = rng.normal(size=3), rng.normal(size=3)
    numeric = loop_residual(kind, R1, p1, R2, p2)
    symbolic = loop_residual(kind, cs.DM(R1), cs.DM(p1), cs.DM(R2), cs.DM(p2), xp=cs)
    assert numeric.shape == (len(LOOP_KINDS[kind]),)
    np.testing.assert_allclose(np.asarray(symbolic).ravel(), numeric, atol=1e-14)
    assert np.linalg.norm(numeric) > 1e-3
    np.testing.assert_allclose(loop_residual(kind, R1, p1, R1, p1), 0.0, atol=1e-14)


def test_revolute_residual_allows_rotation_about_z_only():
    rng = np.random.default_rng(1)
    R1, p = _random_rotation(rng), rng.normal(size=3)
    about_z = R1 @ pin.exp3(np.array([0.0, 0.0, 0.7]))
    np.testing.assert_allclose(loop_residual("revolute", R1, p, about_z, p), 0.0, atol=1e-14)
    about_x = R1 @ pin.exp3(np.array([0.7, 0.0, 0.0]))
    assert np.abs(loop_residual("revolute", R1, p, about_x, p)).max() > 0.1
    assert np.abs(loop_residual("weld", R1, p, about_z, p)).max() > 0.1


def test_mjcf_connect_and_actuators_are_read(fourbar):
    (loop,) = fourbar.loops
    assert (loop.name, loop.kind, loop.joint1, loop.joint2) == (
        "close",
        "point",
        "coupler_joint",
        "rocker_joint",
    )
    # a planar mechanism: the out-of-plane row vanishes identically and is not imposed
    assert loop.components == ("x", "z") and loop.dropped == ("y",)
    assert fourbar.passive == ("coupler_joint", "rocker_joint")
    q = fourbar.configuration("neutral")
    np.testing.assert_allclose(closure_residual(fourbar.model, fourbar.loops, q), 0.0, atol=1e-12)
    J = closure_jacobian(fourbar.model, fourbar.loops, q)
    assert J.shape == (2, 3) and np.linalg.matrix_rank(J) == 2


def test_independent_joints_keep_the_actuated_ones_and_fix_every_velocity(tmp_path, fourbar):
    q = fourbar.configuration("neutral")
    assert fourbar.independent_joints(q) == ("crank_joint",)
    J = loop_jacobian(fourbar.model, fourbar.loops, q)
    for passive in ([], [1, 2], [0]):  # any preference: rank(J) dependent joints, the rest fixed
        keep = independent_joints(fourbar.model, fourbar.loops, q, passive)
        assert len(keep) == 3 - np.linalg.matrix_rank(J)
        assert np.linalg.matrix_rank(np.vstack([J, np.eye(3)[keep]])) == 3  # J v = 0, v[keep] = 0
    assert independent_joints(fourbar.model, fourbar.loops, q, [0]).tolist() in ([1], [2])
    open_chain = mbplan.load_robot(_mjcf(tmp_path, equality="", name="open.xml"))
    assert open_chain.independent_joints(q) == ("crank_joint", "coupler_joint", "rocker_joint")


def test_close_loops_keeps_fixed_coordinates(fourbar):
    q, gap = close_loops(fourbar.model, fourbar.loops, np.array([0.4, 0.0, 0.0]), fixed=[0])
    assert gap < 1e-9 and q[0] == 0.4
    np.testing.assert_allclose(closure_residual(fourbar.model, fourbar.loops, q), 0.0, atol=1e-9)


def test_over_constrained_closure_is_refused(tmp_path):
    weld = CONNECT.replace("</equality>", '<weld body1="coupler" body2="rocker"/></equality>')
    with pytest.raises(RobotModelError, match="every row is redundant"):
        mbplan.load_robot(_mjcf(tmp_path, equality=weld))


def test_loops_given_by_frames_match_the_mjcf_closure(tmp_path, fourbar):
    plain = _mjcf(tmp_path, equality="", name="open.xml")
    spec = {"name": "close", "frame1": "coupler_tip", "frame2": "rocker", "kind": "point"}
    spec["placement2"] = [-0.2, 0.0, 0.3]
    robot = mbplan.load_robot(plain, loops=[spec])
    assert robot.loops[0].components == ("x", "z")
    rng = np.random.default_rng(2)
    for _ in range(3):
        q = rng.uniform(-1, 1, size=3)
        np.testing.assert_allclose(
            closure_residual(robot.model, robot.loops, q),
            closure_residual(fourbar.model, fourbar.loops, q),
            atol=1e-12,
        )
    again = robot_from_source(robot.source)
    assert [loop.to_dict() for loop in again.loops] == [loop.to_dict() for loop in robot.loops]
    assert again.passive == robot.passive


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ({"frame1": "nowhere", "frame2": "rocker"}, "frame1 'nowhere' is not a frame"),
        ({"frame1": "coupler", "frame2": "coupler_tip"}, "both frames are on the body"),
        ({"frame1": "coupler_tip", "frame2": "rocker", "kind": "ball"}, "kind 'ball'"),
        ({"frame1": "coupler_tip", "frame2": "rocker", "axis": [0, 1, 0]}, "an axis is given"),
        ({"frame1": "coupler_tip", "frame2": "rocker", "placement1": [1, 2]}, "placement1"),
        ({"frame1": "coupler_tip", "frame2": "rocker", "bogus": 1}, "unknown keys"),
        (
            {"frame1": "coupler_tip", "frame2": "rocker", "kind": "revolute", "axis": [0, 0, 0]},
            "nonzero 3-vector",
        ),
    ],
)
def test_bad_loop_specs_are_named(tmp_path, spec, match):
    plain = _mjcf(tmp_path, equality="", name="open.xml")
    with pytest.raises(InputError, match=match):
        mbplan.load_robot(plain, loops=[spec])


def test_loops_that_cannot_close_are_refused(tmp_path):
    plain = _mjcf(tmp_path, equality="", name="open.xml")
    spec = {"frame1": "coupler_tip", "frame2": "rocker", "placement2": [5.0, 0.0, 0.0]}
    with pytest.raises(RobotModelError, match="cannot all close"):
        mbplan.load_robot(plain, loops=[spec])


def test_actuated_joints_are_checked(tmp_path):
    plain = _mjcf(tmp_path, actuator="", name="all.xml")
    assert mbplan.load_robot(plain).passive == ()
    robot = mbplan.load_robot(plain, actuated=["crank_joint", "rocker_joint"])
    assert robot.passive == ("coupler_joint",)
    with pytest.raises(InputError, match="'elbow' is not a joint"):
        mbplan.load_robot(plain, actuated=["elbow"])


def test_actuators_that_drive_no_joint_are_refused(tmp_path):
    path = _mjcf(tmp_path, actuator='<actuator><motor tendon="t"/></actuator>')
    with pytest.raises(RobotModelError, match="drives no joint"):
        mjcf_actuated(path)


def test_locking_a_joint_of_a_loop_is_refused(tmp_path):
    with pytest.raises(InputError, match="carries the loop 'close'"):
        mbplan.load_robot(_mjcf(tmp_path), lock={"rocker_joint": 0.0})


def test_ocp_imposes_zero_passive_torque_and_refuses_a_torque_goal(fourbar):
    ocp = mbplan.OCP(fourbar, N=5, dt=0.05)
    assert ocp["passive"].residual.joints == fourbar.passive
    assert np.all(ocp["passive"].residual.target == 0.0)
    with pytest.raises(InputError, match="passive"):
        ocp.add_cost("effort", JointTorque(joints=["rocker_joint"]))
    ocp.add_cost("crank_effort", JointTorque(joints=["crank_joint"]))


def test_ocp_start_must_close_the_loops(fourbar):
    with pytest.raises(InputError, match=r"would close at q0 = \[ 0.4"):
        mbplan.OCP(fourbar, q0=[0.4, 0.0, 0.0])
    q0, _ = close_loops(fourbar.model, fourbar.loops, np.array([0.4, 0.0, 0.0]), fixed=[0])
    assert mbplan.OCP(fourbar, q0=q0).q0[0] == 0.4
