"""Mechanisms with closed loops for the tests: a planar four-bar (MJCF ``tests/data/fourbar.xml``:
crank actuated, coupler and rocker passive, a ``<connect>`` closure) and Pinocchio's sample
manipulator welded, hinged or pinned to the world."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin

import mbplan as mb
from mbplan.residuals import JointPosition, JointTorque, JointVelocity
from mbplan.robots import load_robot
from mbplan.robots.loops import LOOP_KINDS, Loop, close_loops
from mbplan.robots.robot import Robot

FOURBAR = Path(__file__).parent / "data" / "fourbar.xml"
CRANK_GOAL = 1.0  # rad: the crank angle whose closed configuration sets the rocker goal


def fourbar() -> Robot:
    return load_robot(FOURBAR)


def rocker_goal(robot: Robot) -> float:
    """The rocker angle of the closed configuration with the crank at :data:`CRANK_GOAL`."""
    q = robot.configuration("neutral")
    q[0] = CRANK_GOAL
    closed, gap = close_loops(robot.model, robot.loops, q, fixed=[0])
    assert gap < 1e-12
    return float(closed[2])


def fourbar_ocp(N: int = 20, dt: float = 0.05) -> mb.OCP:
    """From rest at the neutral configuration to the rocker goal at rest at knot ``N``, with
    the least crank effort."""
    robot = fourbar()
    ocp = mb.OCP(robot, N=N, dt=dt)
    goal = JointPosition(joints=["rocker_joint"], target=[rocker_goal(robot)])
    ocp.add_terminal_constraint("rocker_goal", goal)
    ocp.add_terminal_constraint("rest", JointVelocity())
    ocp.add_cost("effort", JointTorque(joints=["crank_joint"]), 1e-2)
    return ocp


@cache
def fourbar_plan() -> mb.PlanResult:
    """IPOPT's plan of :func:`fourbar_ocp` to ``tol`` 1e-8 (the closures then hold to ~1e-12;
    at the default 1e-6 IPOPT may stop with them at ~1e-7, within its constraint tolerance),
    shared by the tests of one process."""
    return mb.plan(fourbar_ocp(), "ipopt", warm_start="linear", tol=1e-8)


def welded_arm(kind: str, rows: tuple[str, ...] | None = None) -> Robot:
    """The sample manipulator with its wrist frame tied to the world by a ``kind`` closure,
    closed at the neutral configuration (all rows of the kind imposed unless ``rows``)."""
    model = pin.buildSampleModelManipulator()
    data = model.createData()
    q = pin.neutral(model)
    pin.forwardKinematics(model, data, q)
    wrist = model.getJointId("wrist2_joint")
    M = pin.SE3(pin.rpy.rpyToMatrix(0.2, -0.4, 0.7), np.array([0.05, -0.02, 0.1]))
    world = (data.oMi[wrist] * M).homogeneous
    components = LOOP_KINDS[kind] if rows is None else rows
    loop = Loop("tie", kind, "wrist2_joint", M.homogeneous, "universe", world, components)
    return replace(load_robot(model), loops=(loop,))
