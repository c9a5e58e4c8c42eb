"""The arm sweep's tasks (``tests/test_sweep.py``): every serial arm
of ``mbplan robots`` (prismatic joints locked) with a sampled joint goal and a frame goal, N = 6,
planned from rest."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

import mbplan as mb
from mbplan.robots import available_arms, load

KINDS = ("joint", "frame")


def sweep_robot(name: str) -> mb.Robot:
    """Robot ``name`` with its prismatic joints locked."""
    model = load(name, geometry=False).model
    prismatic = [
        model.names[j]
        for j in range(1, model.njoints)
        if model.joints[j].shortname().startswith("JointModelP")
    ]
    return mb.load_robot(name, lock=prismatic)


def joint_ranges(robot: mb.Robot) -> tuple[np.ndarray, np.ndarray]:
    """The joints' position limits clipped to ``[-π, π]``, where goals are drawn."""
    model = robot.model
    return np.maximum(model.lowerPositionLimit, -np.pi), np.minimum(model.upperPositionLimit, np.pi)


def tool_frame(robot: mb.Robot) -> str:
    """The BODY frame of the last joint (the tool's link)."""
    frames = [f for f in robot.model.frames if f.type == pin.FrameType.BODY and f.parentJoint > 0]
    return max(frames, key=lambda f: f.parentJoint).name


def sweep_tasks(robot: mb.Robot, seed: int) -> dict[str, mb.OCP]:
    """A joint-goal and a frame-goal task (``KINDS``) from a sampled start ``q0`` to a sampled
    goal; the frame is the BODY frame of the last joint (its origin: the frame goal of the
    3-dof ``finger_edu`` has rank 2, ``tests/test_sweep.py``)."""
    model = robot.model
    lo, hi = joint_ranges(robot)
    rng = np.random.default_rng(seed)
    q0 = 0.5 * (lo + hi) + 0.2 * (hi - lo) * rng.uniform(-0.5, 0.5, robot.nq)
    q_goal = np.clip(q0 + 0.3 * rng.uniform(-1, 1, robot.nq), lo, hi)
    tip = tool_frame(robot)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q_goal)
    point = data.oMf[model.getFrameId(tip)].translation.copy()
    tasks = {}
    for kind in KINDS:
        ocp = mb.OCP(robot, N=6, dt=0.1, q0=q0)
        ocp.add_cost("velocity", mb.residuals.JointVelocity(), 1e-2)
        ocp.add_cost("effort", mb.residuals.JointTorque(), 1e-4)
        if kind == "joint":
            ocp.add_terminal_constraint("goal", mb.residuals.JointPosition(q_goal))
        else:
            ocp.add_terminal_constraint("goal", mb.residuals.FrameTranslation(tip, point))
        tasks[kind] = ocp
    return tasks


def sweep_case(index: int) -> tuple[str, str, mb.OCP, np.ndarray]:
    """Case ``index`` of ``2 · len(available_arms())``: robot name, kind, task and the rest
    path it starts from (the seed is the length of the robot's name, as in the test)."""
    name = available_arms()[index // len(KINDS)]
    kind = KINDS[index % len(KINDS)]
    ocp = sweep_tasks(sweep_robot(name), seed=len(name))[kind]
    return name, kind, ocp, np.repeat(ocp.q0[None], ocp.N + 1, axis=0)
