"""Seeded task families chosen for what makes trajectory optimization hard, not for where a
method wins (``mbplan bench robustness``). Case ``i`` of a family draws from
``numpy.random.default_rng((seed, i, FAMILY_TAG))``, so a case does not depend on how many are
drawn. The arm families run over ``ARM_N`` steps of ``ARM_DT`` (3 s), more steps for an arm
slower than :data:`ARM_SPEED` (kinova 83, 6.2 s; so100 52, 3.9 s) so that its goals lie within
its velocity limits' reach:

* ``graded_chain``: a hanging chain of 8, 16, 32 or 64 links (cycling with ``i``; 4.8 m and
  16 kg in all) whose torque limits fall linearly from :data:`CHAIN_EFFORT` along the chain,
  joint speeds within :data:`CHAIN_VELOCITY`, reaching in 2 s a random wave (the paper's
  tracking costs and a hard terminal goal; the goal's holding torques within
  :data:`CHAIN_HOLD_FRACTION` of every limit);
* ``arm_boxes``: an arm with mesh collision geometry (:data:`MESH_ARMS`) moves its tool to a
  random reachable pose among one to three random boxes, coal distances of every link to every
  box above :data:`MARGIN` (the boxes clear of the start and the goal configurations);
* ``near_limits``: an arm (:data:`ARMS`) reaches a joint goal with half its joints within
  :data:`LIMIT_GAP` of a position limit;
* ``rest_goal``: an arm reaches a random tool pose and stops there (terminal joint velocity
  zero, a hard constraint);
* ``near_singular``: an arm moves its tool to the pose of the most singular of
  :data:`SINGULAR_SAMPLES` sampled configurations (the smallest singular value of the tool's
  Jacobian);
* ``paper_linear``: the paper's iiwa-obstacle and drone-docking tasks (even and odd ``i``) from
  the linear warm start instead of the via-point one.
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin

from mbplan.errors import InfeasibleRequestError
from mbplan.formulations.joint_space import evaluate
from mbplan.ocp.problem import OCP
from mbplan.ocp.scene import Scene
from mbplan.residuals import (
    Distance,
    FramePlacement,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    JointVelocityLimits,
)
from mbplan.robots.robot import Robot, load_robot
from mbplan.tasks.arm_sweep import joint_ranges, sweep_robot, tool_frame
from mbplan.tasks.paper import (
    add_obstacle_constraint,
    drone_docking_cases,
    iiwa_obstacle_cases,
    tracking_ocp,
)
from mbplan.tasks.speed import chain_urdf

ATTEMPTS = 2000  # draws of a case before giving up

CHAIN_LINKS = (8, 16, 32, 64)
CHAIN_LENGTH = 4.8  # m, whole chain
CHAIN_MASS = 16.0  # kg, whole chain
CHAIN_EFFORT = (65.0, 6.0)  # N m, torque limit of the first and the last joint
CHAIN_VELOCITY = 4.0  # rad/s
CHAIN_RANGE = 2.5  # rad, position limits ±
CHAIN_HOLD_FRACTION = 0.9  # largest holding torque at the goal / the joint's limit
CHAIN_N, CHAIN_DT = 40, 0.05

ARMS = ("iiwa", "panda", "ur5", "ur10", "kinova", "xarm7", "z1", "so100")
MESH_ARMS = ("panda", "ur5", "ur10", "kinova", "xarm7", "so100")
ARM_N, ARM_DT = 40, 0.075
ARM_SPEED = 1.3  # rad/s: an arm whose slowest joint's velocity limit is below gets more steps
MARGIN = 0.02  # m, least distance of every link to every box
BOX_CLEARANCE = 0.05  # m, least distance of the start and the goal configurations to a box
LIMIT_GAP = 0.02  # fraction of a joint's range between the goal and the limit
SINGULAR_SAMPLES = 200
GOAL_TOLERANCE = 1e-3


def _rng(seed: int, index: int, family: str) -> np.random.Generator:
    return np.random.default_rng((seed, index, sum(map(ord, family))))


# --------------------------------------------------------------------------- graded chain


def graded_chain_urdf(n: int) -> str:
    """URDF of a hanging chain of ``n`` equal links (revolute x, y, x, ...; 4.8 m, 16 kg) with
    torque limits falling linearly along it (:data:`CHAIN_EFFORT`)."""
    return chain_urdf(
        n, CHAIN_LENGTH, CHAIN_MASS, CHAIN_EFFORT, CHAIN_VELOCITY, CHAIN_RANGE, "graded_chain"
    )


# process-wide cache, result-neutral: the robot is a function of n alone
@functools.cache
def graded_chain(n: int) -> Robot:
    """The :func:`graded_chain_urdf` robot of ``n`` links."""
    return load_robot(pin.buildModelFromXML(graded_chain_urdf(n)))


def graded_chain_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``graded_chain`` (module docstring): joint ``j`` of the goal is
    ``a sin(2π j / λ + φ)`` (x joints) or ``a cos(...)`` (y joints), ``a`` in [0.15, 0.3] rad,
    ``λ`` in {6, 8, 10} joints, ``φ`` uniform."""
    n = CHAIN_LINKS[index % len(CHAIN_LINKS)]
    robot = graded_chain(n)
    model, data = robot.model, robot.model.createData()
    rng = _rng(seed, index, "graded_chain")
    j = np.arange(n)
    for _ in range(ATTEMPTS):
        a, wave, phase = rng.uniform(0.15, 0.3), rng.choice((6, 8, 10)), rng.uniform(0, 2 * np.pi)
        angle = 2 * np.pi * j / wave + phase
        goal = a * np.where(j % 2 == 0, np.sin(angle), np.cos(angle))
        hold = pin.computeGeneralizedGravity(model, data, goal)
        if np.all(np.abs(hold) <= CHAIN_HOLD_FRACTION * model.effortLimit):
            break
    else:
        raise InfeasibleRequestError(f"graded_chain case {index}: no goal within the limits")
    ocp = tracking_ocp(robot, np.zeros(n), goal, N=CHAIN_N, dt=CHAIN_DT)
    ocp.add_constraint("goal", JointPosition(goal), knots="terminal", tolerance=GOAL_TOLERANCE)
    return ocp


# --------------------------------------------------------------------------------- arms


def _pose(robot: Robot, frame: str, q: np.ndarray) -> pin.SE3:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(frame)].copy()


def _arm_ocp(robot: Robot, q0: np.ndarray, scene: Scene | None = None) -> OCP:
    """An arm's task from rest at ``q0`` over ``ARM_N`` steps of ``ARM_DT`` (more for a slow
    arm, module docstring) with the task files' default costs and every joint limit."""
    slowest = float(np.min(robot.model.velocityLimit))
    steps = int(np.ceil(ARM_N * max(1.0, ARM_SPEED / slowest)))
    ocp = OCP(robot, scene, N=steps, dt=ARM_DT, q0=q0)
    ocp.add_cost("velocity", JointVelocity(), 1e-2, knots="running")
    ocp.add_cost("torque", JointTorque(), 1e-4)
    ocp.add_constraint("position_limits", JointPositionLimits())
    ocp.add_constraint("velocity_limits", JointVelocityLimits())
    ocp.add_constraint("torque_limits", JointTorqueLimits())
    return ocp


def _start_and_goal(robot: Robot, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A start in the central half of every joint range, a goal up to 1 rad from it."""
    lo, hi = joint_ranges(robot)
    q0 = 0.5 * (lo + hi) + 0.25 * (hi - lo) * rng.uniform(-1, 1, robot.nq)
    return q0, np.clip(q0 + rng.uniform(-1, 1, robot.nq), lo, hi)


def _pose_goal(ocp: OCP, frame: str, q_goal: np.ndarray) -> OCP:
    placement = _pose(ocp.robot, frame, q_goal)
    goal = FramePlacement(frame, placement)
    ocp.add_constraint("goal", goal, knots="terminal", tolerance=GOAL_TOLERANCE)
    return ocp


def _clear(robot: Robot, scene: Scene, qs: list[np.ndarray]) -> bool:
    """Every configuration of ``qs`` at least :data:`BOX_CLEARANCE` from every object."""
    rows = Distance(BOX_CLEARANCE).resolve(robot, scene)
    return bool(np.max(evaluate(robot, scene, rows, np.array(qs), None, None)) <= 0)


def arm_boxes_case(index: int, seed: int = 0, between_knots: bool = False) -> OCP:
    """Case ``index`` of ``arm_boxes`` (module docstring): the arm ``MESH_ARMS[index % 6]``;
    boxes of sides 5–20 cm centred near the tool's straight path, kept when clear of the start
    and the goal configurations; the margin at the knots, and between them with
    ``between_knots``."""
    robot = sweep_robot(MESH_ARMS[index % len(MESH_ARMS)])
    rng = _rng(seed, index, "arm_boxes")
    tool = tool_frame(robot)
    for _ in range(ATTEMPTS):
        q0, q_goal = _start_and_goal(robot, rng)
        a, b = _pose(robot, tool, q0).translation, _pose(robot, tool, q_goal).translation
        if np.linalg.norm(a - b) < 0.1:
            continue
        scene = Scene()
        for k in range(rng.integers(1, 4)):
            centre = a + rng.uniform(0.3, 0.7) * (b - a) + rng.uniform(-0.1, 0.1, 3)
            scene.add_box(f"box{k + 1}", rng.uniform(0.05, 0.2, 3), centre)
        if _clear(robot, scene, [q0, q_goal]):
            break
    else:
        raise InfeasibleRequestError(f"arm_boxes case {index}: no clear scene")
    ocp = _pose_goal(_arm_ocp(robot, q0, scene), tool, q_goal)
    return add_obstacle_constraint(ocp, "distance", MARGIN, between_knots)


def near_limits_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``near_limits`` (module docstring): ``ARMS[index % 8]``; the goal's
    joints drawn as in the other arm families, half of them (at random) moved to within
    ``LIMIT_GAP`` of the range end they are nearer."""
    robot = sweep_robot(ARMS[index % len(ARMS)])
    rng = _rng(seed, index, "near_limits")
    lo, hi = joint_ranges(robot)
    q0, q_goal = _start_and_goal(robot, rng)
    edge = rng.permutation(robot.nq)[: robot.nq // 2]
    gap = LIMIT_GAP * (hi - lo)
    near = np.where(q_goal > 0.5 * (lo + hi), hi - gap, lo + gap)
    q_goal[edge] = near[edge]
    ocp = _arm_ocp(robot, q0)
    ocp.add_constraint("goal", JointPosition(q_goal), knots="terminal", tolerance=GOAL_TOLERANCE)
    return ocp


def rest_goal_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``rest_goal`` (module docstring): ``ARMS[index % 8]``, the tool's pose
    at a drawn goal configuration, reached at rest."""
    robot = sweep_robot(ARMS[index % len(ARMS)])
    q0, q_goal = _start_and_goal(robot, _rng(seed, index, "rest_goal"))
    ocp = _pose_goal(_arm_ocp(robot, q0), tool_frame(robot), q_goal)
    ocp.add_constraint("rest", JointVelocity(), knots="terminal")
    return ocp


def near_singular_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``near_singular`` (module docstring): ``ARMS[index % 8]``; of
    ``SINGULAR_SAMPLES`` goal configurations drawn as in the other arm families, the one whose
    tool Jacobian has the smallest singular value (over its first ``min(6, nv)``)."""
    robot = sweep_robot(ARMS[index % len(ARMS)])
    model, data = robot.model, robot.model.createData()
    rng = _rng(seed, index, "near_singular")
    tool = tool_frame(robot)
    fid = model.getFrameId(tool)
    q0, _ = _start_and_goal(robot, rng)
    lo, hi = joint_ranges(robot)
    best, sigma = None, np.inf
    for _ in range(SINGULAR_SAMPLES):
        q = np.clip(q0 + rng.uniform(-1, 1, robot.nq), lo, hi)
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        s = np.linalg.svd(J, compute_uv=False)[min(6, robot.nv) - 1]
        if s < sigma:
            best, sigma = q, s
    return _pose_goal(_arm_ocp(robot, q0), tool, best)


def paper_linear_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``paper_linear`` (module docstring): case ``index // 2`` of the
    iiwa-obstacle (even) or the drone-docking (odd) cases of ``seed``."""
    k = index // 2
    if index % 2 == 0:
        return iiwa_obstacle_cases(k + 1, seed)[k]
    return drone_docking_cases(k + 1, seed)[k]
