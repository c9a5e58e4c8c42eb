"""The closed-loop mechanisms' tasks (``mbplan robots``: ``fourbar``, ``delta``,
``two_arm_carry``) as OCPs, and their seeded randomizations.

Case 0 of each is the example task (``examples/tasks/*.toml``, ``examples/*.py``), with the
item names a task file gives them; case ``i > 0`` draws its goal (and for the delta its start)
from ``numpy.random.default_rng((seed, i))``, so a case does not depend on how many are drawn:

* ``fourbar``: the rocker goal uniform in the rocker's reachable swing
  (:func:`rocker_range`) less :data:`ROCKER_MARGIN` at each end, at least
  :data:`ROCKER_MIN_MOVE` from its start;
* ``delta``: the platform from a point on the box's -x side to one on its +x side (|x| in
  :data:`DELTA_X`, y in :data:`DELTA_Y`, z in :data:`DELTA_Z`), both closing the legs within
  the joint limits and keeping the margin to the box;
* ``two_arm_carry``: the bar's goal offset from the example's by up to :data:`BAR_OFFSET` per
  axis and turned by a yaw in :data:`BAR_YAW`, a pose both arms reach with the weld closed.

Every task runs ``N = 40`` steps of 0.05 s from rest to its goal at rest (a hard terminal
constraint accepted within the goal's tolerance), with the task file's running costs and the
joint position and torque limits (the MJCF files carry no velocity limits).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.ocp.problem import OCP
from mbplan.ocp.scene import Scene
from mbplan.residuals import (
    FramePlacement,
    FrameTranslation,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    Residual,
)
from mbplan.robots.loops import CLOSE_TOLERANCE, close_loops
from mbplan.robots.robot import Robot, load_robot
from mbplan.tasks.paper import add_obstacle_constraint

MECHANISMS = ("fourbar", "delta", "two_arm_carry")
WARM_START = "via"  # linear for the four-bar and the two arms (no obstacle in their way)
TOL = 1e-8  # convergence tolerance: the closures hold to ~1e-12 at the knots (~1e-8 at 1e-6)
N, DT = 40, 0.05
ATTEMPTS = 1000  # draws of a randomized case before giving up

ROCKER_GOAL = 0.5  # rad (the closure puts the crank at 1.347 rad, or at -2.70 rad)
ROCKER_TOLERANCE = 1e-4  # rad
ROCKER_MARGIN = 0.05  # rad kept from either end of the rocker's swing
ROCKER_MIN_MOVE = 0.1  # rad, least rocker motion of a randomized case

DELTA_START = (-0.15, 0.0, 0.40)  # platform centre (m)
DELTA_GOAL = (0.15, 0.0, 0.40)
DELTA_BOX = ((0.08, 0.3, 0.12), (0.0, 0.0, 0.30))  # full sides, centre (m): top at 0.36 m
DELTA_MARGIN = 0.01  # m, coal distance of the legs and the platform to the box
DELTA_TOLERANCE = 1e-3  # m
DELTA_X = (0.10, 0.18)  # m, |x| of a randomized start (x < 0) and goal (x > 0)
DELTA_Y = (-0.08, 0.08)  # m
DELTA_Z = (0.38, 0.44)  # m
PLATFORM_SLIDES = ("platform_x", "platform_y", "platform_z")

# the bar's centre (at (0, 0, 0.52), level, along x at the neutral pose) 0.15 m to the side,
# 0.18 m up and turned 0.35 rad about z
BAR_GOAL = (0.0, 0.15, 0.70)
BAR_GOAL_YAW = 0.35  # rad
BAR_TOLERANCE = 1e-3  # m and rad
BAR_OFFSET = (0.08, 0.08, 0.06)  # m, largest offset per axis of a randomized goal
BAR_YAW = (-0.2, 0.6)  # rad, yaw of a randomized goal
ARM_A = tuple(f"a_joint{i}" for i in range(1, 7))  # the arm holding the bar


@functools.cache  # process-wide cache, result-neutral: the bundled model of a name
def _robot(name: str) -> Robot:
    return load_robot(name)


def _common(ocp: OCP, goal: Residual, tolerance: float, torque: float) -> OCP:
    """The items every mechanism task shares, named as a task file names them."""
    ocp.add_constraint("goal", goal, knots="terminal", tolerance=tolerance)
    ocp.add_cost("velocity", JointVelocity(), 1e-2, knots="running")
    ocp.add_cost("torque", JointTorque(), torque)
    # J v = 0 through the closures: rest on the independent joints rests every joint, without
    # repeating the closures' rows (a rank-deficient equality Jacobian at the last knots)
    rest = JointVelocity(joints=ocp.robot.independent_joints(ocp.q0))
    ocp.add_constraint("rest", rest, knots="terminal")
    ocp.add_constraint("position_limits", JointPositionLimits())
    ocp.add_constraint("torque_limits", JointTorqueLimits())
    return ocp


# ------------------------------------------------------------------------------- four-bar


def fourbar_crank(rocker_goal: float = ROCKER_GOAL, N: int = N, dt: float = DT) -> OCP:
    """The four-bar from rest at its neutral pose (crank up, the loop closed) to the rocker at
    ``rocker_goal`` (rad), at rest; the crank's torque is the only one (the others are
    passive)."""
    ocp = OCP(_robot("fourbar"), N=N, dt=dt)
    goal = JointPosition([rocker_goal], joints=["rocker_joint"])
    return _common(ocp, goal, ROCKER_TOLERANCE, 1e-2)


@functools.cache  # process-wide cache, result-neutral: a property of the bundled model
def rocker_range(turns: int = 720) -> tuple[float, float]:
    """The rocker's swing (rad) over a full turn of the crank (``turns`` steps, the loop closed
    at each, the other joints continued from the previous step)."""
    robot = _robot("fourbar")
    crank = robot.joint_indices(["crank_joint"])
    rocker = robot.joint_indices(["rocker_joint"])[0]
    q, angles = robot.configuration("neutral"), []
    for theta in np.linspace(-np.pi, np.pi, turns + 1):
        q[crank] = theta
        q, gap = close_loops(robot.model, robot.loops, q, fixed=crank)
        if gap <= CLOSE_TOLERANCE:
            angles.append(float(q[rocker]))
    return min(angles), max(angles)


def _fourbar_goal(rng: np.random.Generator) -> float:
    lo, hi = rocker_range()
    robot = _robot("fourbar")
    start = float(robot.configuration("neutral")[robot.joint_indices(["rocker_joint"])[0]])
    for _ in range(ATTEMPTS):
        goal = float(rng.uniform(lo + ROCKER_MARGIN, hi - ROCKER_MARGIN))
        if abs(goal - start) >= ROCKER_MIN_MOVE:
            return goal
    raise InfeasibleRequestError("four-bar: no rocker goal drawn")  # pragma: no cover


# ------------------------------------------------------------------------------- delta


def delta_configuration(platform: np.ndarray) -> np.ndarray:
    """The closed configuration of the delta with the platform centre at ``platform`` (m),
    the legs following; :class:`InfeasibleRequestError` if the legs cannot reach it within
    their limits."""
    robot = _robot("delta")
    slides = robot.joint_indices(list(PLATFORM_SLIDES))
    data = robot.model.createData()
    neutral = robot.configuration("neutral")
    pin.framesForwardKinematics(robot.model, data, neutral)
    at_neutral = data.oMf[robot.frame_id("platform")].translation
    q = neutral.copy()
    q[slides] += np.asarray(platform, dtype=float) - at_neutral
    q, gap = close_loops(robot.model, robot.loops, q, fixed=slides)
    if gap > 1e-9:
        where = np.round(np.asarray(platform, float), 4).tolist()
        raise InfeasibleRequestError(f"the delta's legs cannot reach the platform at {where}")
    return q


def delta_obstacle(
    start: tuple[float, float, float] = DELTA_START,
    goal: tuple[float, float, float] = DELTA_GOAL,
    N: int = N,
    dt: float = DT,
) -> OCP:
    """The delta from rest with its platform at ``start`` to ``goal`` at rest, over the box
    (coal distances of the legs and the platform to it at least :data:`DELTA_MARGIN`, at the
    knots and between them)."""
    size, centre = DELTA_BOX
    scene = Scene().add_box("box", size, centre)
    ocp = OCP(_robot("delta"), scene, N=N, dt=dt, q0=delta_configuration(np.array(start)))
    _common(ocp, FrameTranslation("platform", np.array(goal)), DELTA_TOLERANCE, 1e-3)
    return add_obstacle_constraint(ocp, "distance", DELTA_MARGIN, between_knots=True)


def _delta_points(rng: np.random.Generator) -> tuple[tuple, tuple]:
    from mbplan.planning.initial_guess import path_clearance

    reference = delta_obstacle(N=2)
    points = []
    for side in (-1.0, 1.0):
        for _ in range(ATTEMPTS):
            point = (side * rng.uniform(*DELTA_X), rng.uniform(*DELTA_Y), rng.uniform(*DELTA_Z))
            try:
                q = delta_configuration(np.array(point))
            except InfeasibleRequestError:
                continue
            if path_clearance(reference, q[None]) <= 0.0:
                points.append(tuple(float(x) for x in point))
                break
        else:  # pragma: no cover
            raise InfeasibleRequestError("delta: no platform point drawn clear of the box")
    return points[0], points[1]


# ------------------------------------------------------------------------------- two arms


def bar_goal(xyz: tuple[float, float, float] = BAR_GOAL, yaw: float = BAR_GOAL_YAW) -> pin.SE3:
    """The bar centre's pose: at ``xyz``, level, turned ``yaw`` about z."""
    return pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array(xyz, dtype=float))


def two_arm_carry(
    xyz: tuple[float, float, float] = BAR_GOAL,
    yaw: float = BAR_GOAL_YAW,
    N: int = N,
    dt: float = DT,
) -> OCP:
    """The two arms from rest at the neutral pose (the weld closed) carrying the bar to
    :func:`bar_goal` of ``xyz`` and ``yaw``, at rest."""
    ocp = OCP(_robot("two_arm_carry"), N=N, dt=dt)
    goal = FramePlacement("bar_center", bar_goal(xyz, yaw).homogeneous)
    return _common(ocp, goal, BAR_TOLERANCE, 1e-4)


def bar_pose_reachable(goal: pin.SE3) -> bool:
    """Whether arm a can hold the bar at ``goal`` (inverse kinematics) with arm b closing the
    weld, both within their joint limits."""
    from mbplan.planning.initial_guess import inverse_kinematics

    robot = _robot("two_arm_carry")
    neutral = robot.configuration("neutral")
    try:
        q = inverse_kinematics(robot, FramePlacement("bar_center", goal.homogeneous), neutral)
    except InfeasibleRequestError:
        return False
    _, gap = close_loops(robot.model, robot.loops, q, fixed=robot.joint_indices(list(ARM_A)))
    return gap <= CLOSE_TOLERANCE


def _bar_goal(rng: np.random.Generator) -> tuple[tuple[float, float, float], float]:
    for _ in range(ATTEMPTS):
        xyz = tuple(
            float(c + rng.uniform(-d, d)) for c, d in zip(BAR_GOAL, BAR_OFFSET, strict=True)
        )
        yaw = float(rng.uniform(*BAR_YAW))
        if bar_pose_reachable(bar_goal(xyz, yaw)):  # type: ignore[arg-type]
            return xyz, yaw  # type: ignore[return-value]
    raise InfeasibleRequestError("two_arm_carry: no reachable bar goal drawn")  # pragma: no cover


# ------------------------------------------------------------------------------- cases


def _fourbar_case(rng: np.random.Generator) -> OCP:
    return fourbar_crank(_fourbar_goal(rng))


def _delta_case(rng: np.random.Generator) -> OCP:
    return delta_obstacle(*_delta_points(rng))


def _two_arm_case(rng: np.random.Generator) -> OCP:
    return two_arm_carry(*_bar_goal(rng))


EXAMPLES: dict[str, Callable[[], OCP]] = {
    "fourbar": fourbar_crank,
    "delta": delta_obstacle,
    "two_arm_carry": two_arm_carry,
}
_RANDOMIZED: dict[str, Callable[[np.random.Generator], OCP]] = {
    "fourbar": _fourbar_case,
    "delta": _delta_case,
    "two_arm_carry": _two_arm_case,
}


def mechanism_case(mechanism: str, index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``mechanism`` (module docstring): 0 the example task, else a draw of
    ``default_rng((seed, index))``."""
    if mechanism not in MECHANISMS:
        raise InputError(f"unknown mechanism {mechanism!r}; choose from {', '.join(MECHANISMS)}")
    if index == 0:
        return EXAMPLES[mechanism]()
    return _RANDOMIZED[mechanism](np.random.default_rng((seed, index)))
