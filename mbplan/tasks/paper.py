"""The paper's tasks as data: functions returning :class:`~mbplan.OCP` s, with their samplers.

iiwa obstacle task (RIPM paper §VIII.C, Table III): the KUKA iiwa 14 moves from ``q0`` at rest
towards :data:`IIWA_TARGET` in ``N = 40`` steps of ``Δt = 0.075 s`` around a vertical cylinder,
with the joint-space tracking cost (the paper gives no numbers)::

    Σ_{k=1..N} s_k (½ w_q ‖q_k - q_target‖² + ½ w_v ‖v_k‖²) + Σ_{k=0..N-1} ½ w_τ ‖τ_k‖²,

``s_k = 1``, ``s_N = terminal_factor``; URDF joint position, velocity and torque limits; and
either eq. (62) (every link COM outside the cylinder + margin, ``constraint="com"``) or coal
distances of every link geometry ≥ margin (``constraint="distance"``). The terminal joint
goal is soft, with a tolerance of :data:`IIWA_GOAL_TOLERANCE` checked by the verifier.

Constants: ``w_q = 1`` per rad², ``w_v = 0.1`` per (rad/s)², ``w_τ = 1e-4`` per (N m)² — the
gravity torques of a stretched iiwa (~100 N m) cost about as much as a 0.3 rad tracking error;
``terminal_factor = 50``. The iiwa URDF's joint damping (0.5 N m s/rad) is ignored
(``load_robot(..., damping=False)``): the paper's dynamics have none, and the committed
benchmarks stay comparable. ``N = 40`` as in the paper; 3 s let the velocity limits cover the joint
displacements of the sampled starts. The target reaches forward-left; :data:`IIWA_CYLINDER`
stands where the COMs pass when joint 1 sweeps from a start at smaller azimuth (the straight path
of 48 of 100 sampled starts, seed 0, runs through it); for coal distances the link geometry
reaches further, so :data:`IIWA_DISTANCE_CYLINDER` is moved 7 cm (57 of 100 blocked).

Drone docking (RIPM paper §VIII.B, Table II): :func:`drone_docking` turns a
:class:`~mbplan.tasks.drone.DockingTask` (its sampler: :func:`drone_docking_cases`) into an OCP of
a :class:`~mbplan.robots.free_body.FreeBody` quadrotor: the costs of Problem 1 (eq. 18, 57, 59) as
one item per state residual on the running knots and one on the terminal knot (weighted by
``terminal_factor``), the input cost about hover, optional input limits and its cylinders.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.formulations.joint_space import evaluate
from mbplan.ocp.problem import OCP
from mbplan.ocp.scene import Scene
from mbplan.residuals import (
    BodyInput,
    BodyInputLimits,
    BodyOrientation,
    BodyPosition,
    BodyRotationStep,
    BodyVelocity,
    ComOutsideCylinder,
    Distance,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    JointVelocityLimits,
)
from mbplan.robots.free_body import FreeBody, free_flyer_state
from mbplan.robots.robot import load_robot
from mbplan.tasks.drone import DockingTask, sample_docking_cases
from mbplan.validation import as_int

IIWA_TARGET = (1.0, 0.6, 0.0, -1.4, 0.0, 1.0, 0.0)
IIWA_START = (-0.8, 0.2, 0.5, -1.6, 0.0, 1.0, 0.0)
IIWA_CYLINDER = ((0.4, 0.2), 0.1)  # (centre xy, radius), from z = 0 to 1.5 m
IIWA_DISTANCE_CYLINDER = ((0.45, 0.15), 0.1)
IIWA_CYLINDER_HEIGHT = 1.5
IIWA_WEIGHTS = {"w_q": 1.0, "w_v": 0.1, "w_tau": 1e-4, "terminal_factor": 50.0}
IIWA_MARGIN = 0.03
IIWA_GOAL_TOLERANCE = 0.05  # rad: the soft tracking cost leaves ~0.02 rad
SAMPLING_RANGE = 0.8  # fraction of each joint range (about its centre) that start samples use
_MAX_REJECTIONS = 10_000


def tracking_ocp(
    robot: Any,
    q0: Any,
    q_target: Any,
    scene: Scene | None = None,
    *,
    N: int = 40,
    dt: float = 0.075,
    weights: dict[str, float] | None = None,
    goal_tolerance: float | None = IIWA_GOAL_TOLERANCE,
    torque_limit: Any = None,
    velocity_limit: Any = None,
) -> OCP:
    """The point-to-point joint tracking problem (module docstring) without obstacles."""
    w = {**IIWA_WEIGHTS, **(weights or {})}
    robot = (
        load_robot("iiwa", damping=False) if isinstance(robot, str) and robot == "iiwa" else robot
    )
    ocp = OCP(robot, scene, N=N, dt=dt, q0=q0)
    goal = JointPosition(q_target)
    ocp.add_cost("joint_position", goal, w["w_q"], knots="running")
    ocp.add_cost(
        "joint_position_terminal",
        goal,
        w["w_q"] * w["terminal_factor"],
        knots="terminal",
        tolerance=goal_tolerance,
    )
    ocp.add_cost("joint_velocity", JointVelocity(), w["w_v"], knots="running")
    ocp.add_cost(
        "joint_velocity_terminal", JointVelocity(), w["w_v"] * w["terminal_factor"], "terminal"
    )
    ocp.add_cost("torque", JointTorque(), w["w_tau"])
    ocp.add_constraint("position_limits", JointPositionLimits())
    vel = None if velocity_limit is None else np.asarray(velocity_limit, float)
    tau = None if torque_limit is None else np.asarray(torque_limit, float)
    ocp.add_constraint(
        "velocity_limits",
        JointVelocityLimits(None if vel is None else -vel, vel),
    )
    ocp.add_constraint("torque_limits", JointTorqueLimits(None if tau is None else -tau, tau))
    return ocp


def iiwa_scene(constraint: str = "com") -> Scene:
    (x, y), r = IIWA_DISTANCE_CYLINDER if constraint == "distance" else IIWA_CYLINDER
    h = IIWA_CYLINDER_HEIGHT
    return Scene().add_cylinder("cylinder", r, h, (x, y, 0.5 * h))


def add_obstacle_constraint(
    ocp: OCP, constraint: str, margin: float = IIWA_MARGIN, between_knots: bool = False
) -> OCP:
    """Eq. (62) against every scene cylinder (``"com"``) or coal distances to every scene object
    (``"distance"``), at knots ``1..N`` (and with ``between_knots`` along the intervals; the
    paper's tasks constrain the knots only)."""
    if constraint == "com":
        for o in ocp.scene:
            residual = ComOutsideCylinder(o.name, margin, between_knots)
            ocp.add_constraint(f"com_outside_{o.name}", residual)
    elif constraint == "distance":
        if len(ocp.scene):
            ocp.add_constraint("clearance", Distance(margin, between_knots=between_knots))
    else:
        raise InputError(f"constraint: expected 'com' (eq. 62) or 'distance', got {constraint!r}")
    return ocp


def iiwa_obstacle(
    q0: Any = IIWA_START, *, N: int = 40, dt: float = 0.075, constraint: str = "com"
) -> OCP:
    """The iiwa obstacle task from ``q0`` (module docstring)."""
    robot = load_robot("iiwa", damping=False)
    ocp = tracking_ocp(robot, q0, IIWA_TARGET, iiwa_scene(constraint), N=N, dt=dt)
    return add_obstacle_constraint(ocp, constraint)


def _start_problem(ocp: OCP, q: np.ndarray, constraint: str) -> str | None:
    """Why ``q`` cannot start the task (a violated constraint at knot 1; with eq. 62 also robot
    geometry penetrating a scene object), else None."""
    for item in ocp.constraints:
        r = item.residual
        if r.space == "state" and r.sense == "ineq":
            if np.max(evaluate(ocp.robot, ocp.scene, r, q[None], np.zeros((1, len(q))), None)) > 0:
                return item.name
    if constraint == "com" and ocp.robot.collision_model is not None and len(ocp.scene):
        touch = Distance(0.0).resolve(ocp.robot, ocp.scene)
        if np.max(evaluate(ocp.robot, ocp.scene, touch, q[None], None, None)) > 0:
            return "geometry penetration"
    return None


def iiwa_obstacle_cases(
    n: int = 100, seed: int = 0, *, N: int = 40, constraint: str = "com"
) -> list[OCP]:
    """``n`` iiwa tasks with the starts of :func:`iiwa_obstacle_starts`."""
    starts = iiwa_obstacle_starts(n, seed, constraint)
    return [iiwa_obstacle(q0, N=N, constraint=constraint) for q0 in starts]


# process-wide cache, result-neutral: a seeded sampler: a function of its arguments alone
@lru_cache(maxsize=8)
def iiwa_obstacle_starts(n: int = 100, seed: int = 0, constraint: str = "com") -> tuple:
    """``n`` random starts (Table III): ``q0`` uniform in the central :data:`SAMPLING_RANGE` of
    each joint range (a seeded ``numpy`` Generator), resampled while it violates a constraint at
    the start (or, with eq. 62, the robot geometry penetrates the cylinder)."""
    as_int(n, "n", minimum=1, what="number of cases")
    as_int(seed, "seed", minimum=0, what="random seed")
    robot = load_robot("iiwa", damping=False)
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    centre, half = 0.5 * (lo + hi), 0.5 * SAMPLING_RANGE * (hi - lo)
    rng = np.random.default_rng(seed)
    template = iiwa_obstacle(centre, N=4, constraint=constraint)
    why = _start_problem(template, np.asarray(IIWA_TARGET), constraint)
    if why is not None:
        raise InfeasibleRequestError(f"the target violates {why}")
    cases = []
    for case in range(n):
        for _ in range(_MAX_REJECTIONS):
            q0 = rng.uniform(centre - half, centre + half)
            if _start_problem(template, q0, constraint) is None:
                break
        else:
            raise InfeasibleRequestError(
                f"case {case}: no collision-free start in {_MAX_REJECTIONS} samples"
            )
        cases.append(q0)
    return tuple(cases)


def drone_docking(
    case: DockingTask | None = None, margin: float = 0.0, cylinder_height: float = 3.0
) -> OCP:
    """The docking task ``case`` (default :class:`~mbplan.tasks.drone.DockingTask`) as an OCP
    (module docstring). Its cylinders stand in the scene from ``z = -height/2`` to ``height/2``
    (eq. 62 treats them as infinite) and are kept at the knots only, as in the paper;
    ``margin`` (m) widens them so that the straight segments between knots clear them too
    (:func:`mbplan.verify` checks those)."""
    task = DockingTask() if case is None else case
    if not isinstance(task, DockingTask):
        raise InputError(f"drone_docking: expected a DockingTask, got {type(task).__name__}")
    prm, w = task.params, task.weights
    body = FreeBody.quadrotor(prm.mass, prm.inertia, prm.gravity)
    scene = Scene()
    for i, (xc, yc, r) in enumerate(task.obstacles):
        scene.add_cylinder(f"cylinder_{i}", r, cylinder_height, (xc, yc, 0.0))
    q0, v0 = free_flyer_state(task.R0[None], task.p0[None], task.F0[None], task.v0[None], task.dt)
    ocp = OCP(body, scene, N=task.N, dt=task.dt, q0=q0[0], v0=v0[0])
    for knots, scale in (("running", 1.0), ("terminal", w.terminal_factor)):
        tail = "" if knots == "running" else "_terminal"
        ocp.add_cost(f"orientation{tail}", BodyOrientation(task.R_goal), scale * w.w_R, knots)
        ocp.add_cost(f"position{tail}", BodyPosition(task.p_goal), scale * w.w_p, knots)
        ocp.add_cost(f"rotation_step{tail}", BodyRotationStep(), scale * w.w_F, knots)
        ocp.add_cost(f"velocity{tail}", BodyVelocity(), scale * w.w_v, knots)
    ocp.add_cost("input", BodyInput(prm.hover_input), w.w_u)
    if task.with_input_limits:  # u_z ∈ [0, u_lim], τ ∈ [-τ_lim, τ_lim]³
        tau = prm.torque_limit
        limits = BodyInputLimits([0.0, -tau, -tau, -tau], [prm.thrust_limit, tau, tau, tau])
        ocp.add_constraint("input_limits", limits)
    for name in scene.names:
        ocp.add_constraint(name, ComOutsideCylinder(name, margin, between_knots=False))
    return ocp


def drone_docking_cases(n: int = 100, seed: int = 0, with_input_limits: bool = False) -> list[OCP]:
    """:func:`drone_docking` of :func:`~mbplan.tasks.drone.sample_docking_cases` (§VIII.B)."""
    tasks = sample_docking_cases(n, seed, with_input_limits=with_input_limits)
    return [drone_docking(t) for t in tasks]
