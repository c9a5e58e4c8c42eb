"""A task file (TOML) as an :class:`~mbplan.OCP` plus solver settings: :func:`load_task`.

Every key is documented in docs/task-files.md. Tables: ``[robot]`` and ``[[loop]]``
(:mod:`.robot`, :mod:`.loops`), ``[horizon]``, ``[start]``, ``[[contact]]`` (:mod:`.contacts`),
``[goal]``, ``[[obstacle]]``, ``[cost]``, ``[constraints]``, ``[solver]``. Item names of the OCP: ``goal`` (terminal),
``rest`` (terminal, ``[goal].rest``), ``goal_tracking`` (running),
``velocity``, ``velocity_terminal``, ``torque``, ``position_limits``, ``velocity_limits``,
``torque_limits``, and the obstacle constraints of :func:`mbplan.tasks.paper.add_obstacle_constraint`
(``clearance``, or ``com_outside_<name>`` per cylinder).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.ocp.problem import OCP
from mbplan.ocp.scene import Scene
from mbplan.planning.solve import METHODS, plan
from mbplan.residuals import (
    FramePlacement,
    FrameTranslation,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    JointVelocityLimits,
    Residual,
)
from mbplan.results import PlanResult
from mbplan.robots.robot import Robot
from mbplan.taskfile.contacts import add_contacts
from mbplan.taskfile.robot import read_robot
from mbplan.taskfile.toml_table import Document, Table, read_toml
from mbplan.tasks.paper import add_obstacle_constraint

TABLES = (
    "robot", "loop", "horizon", "start", "contact", "goal", "obstacle", "cost", "constraints",
    "solver",
)  # fmt: skip
SHAPES = {"box": 3, "cylinder": 2, "sphere": 1, "capsule": 2, "mesh": 3}
COST_DEFAULTS = {"velocity": 1e-2, "terminal_velocity": 0.0, "torque": 1e-4, "tracking": 0.0}
MARGIN = 0.02  # m, default [constraints].margin


@dataclass(frozen=True)
class Task:
    """A loaded task file: its OCP and how to solve it (``[solver]`` after the overrides)."""

    path: Path
    ocp: OCP
    method: str
    warm_start: str
    tol: float
    max_iter: int
    text: str
    overrides: dict[str, Any] = field(default_factory=dict)

    def plan(self) -> PlanResult:
        """:func:`mbplan.plan` of the OCP with the task's settings; the result's ``extra``
        records the task file (``task_file``: path, text, overrides)."""
        result = plan(
            self.ocp, self.method, warm_start=self.warm_start, tol=self.tol, max_iter=self.max_iter
        )
        record = {"path": str(self.path), "toml": self.text, "overrides": self.overrides}
        return dataclasses.replace(result, extra={**result.extra, "task_file": record})


def load_task(
    path: str | Path, overrides: Mapping[str, Any] | Sequence[tuple[str, Any, str]] = ()
) -> Task:
    """Read and check the task file ``path``; ``overrides`` ``{"horizon.N": 10, ...}`` (or
    ``(key, value, origin)`` triples, as the command line passes them) replace keys of the file.
    :class:`~mbplan.errors.InputError` (or ``RobotModelError``, ``InfeasibleRequestError``)
    naming the key and its line for anything wrong; nothing is solved."""
    triples = (
        [(k, v, "override") for k, v in overrides.items()]
        if isinstance(overrides, Mapping)
        else list(overrides)
    )
    doc = read_toml(path, triples)
    doc.check_tables(TABLES)
    robot, full_names = read_robot(doc)
    limits = doc.table("constraints").boolean("position_limits", True)
    N, dt = _horizon(doc.table("horizon", required=True, what=" (with N and dt)"))
    q0 = _start(doc.table("start"), robot, full_names, limits)
    scene = _scene(doc)
    try:
        ocp = OCP(robot, scene, N=N, dt=dt, q0=q0)
    except InputError as err:  # the start off a mimic coupling
        raise InputError(f"{doc.where(('start', 'q'))}: {str(err).removeprefix('q0: ')}") from None
    add_contacts(doc.tables("contact"), ocp)
    goal = doc.table("goal", required=True, what=" (with q, or frame and xyz)")
    residual = _goal(goal, robot, full_names, limits)
    _costs(doc.table("cost"), ocp, residual, goal)
    if goal.boolean("rest", False):
        joints = robot.independent_joints(q0) if getattr(robot, "loops", ()) else None
        ocp.add_constraint("rest", JointVelocity(joints=joints), knots="terminal")
    _constraints(doc.table("constraints"), ocp, limits)
    method, warm_start, tol, max_iter = _solver(doc.table("solver"))
    return Task(
        doc.path,
        ocp,
        method,
        warm_start,
        tol,
        max_iter,
        doc.text,
        {k: v for k, v, _ in triples},
    )


def _horizon(t: Table) -> tuple[int, float]:
    t.check_keys(("N", "dt", "T"))
    N = int(t.integer("N", required=True, minimum=2))  # type: ignore[arg-type]
    if (*t.key, "dt") in t.doc.overridden:  # --dt replaces the file's step or duration
        t.data.pop("T", None)
    if ("dt" in t) == ("T" in t):
        raise t.error(None, "give one of dt (the step, s) or T (the duration, s)")
    if "dt" in t:
        return N, float(t.number("dt", positive=True))  # type: ignore[arg-type]
    return N, float(t.number("T", positive=True)) / N  # type: ignore[operator]


def _configuration(
    t: Table, name: str, robot: Robot, full_names: list[str] | None, limits: bool
) -> np.ndarray:
    """``q`` of ``t[name]``: the planned joints (or all joints of the unlocked robot, the
    locked ones' values dropped; a floating base's position and quaternion first), the joints
    inside their position limits if those are constrained."""
    names = list(robot.joint_names)
    sizes = [robot.nq] + ([len(full_names)] if full_names and len(full_names) != robot.nq else [])
    base = "base position and quaternion (x, y, z, w), then " if robot.floating else ""
    hint = f" (the joints of {robot.name!r}: {base}{', '.join(names)})"
    q = np.array(t.vector(name, sizes, required=True, hint=hint))
    if len(q) != robot.nq:
        q = q[[full_names.index(n) for n in robot.model.names[1:]]]  # type: ignore[union-attr]
    iq = robot.q_of_v[robot.joint_indices(None)]
    lo, hi = robot.model.lowerPositionLimit[iq], robot.model.upperPositionLimit[iq]
    outside = np.flatnonzero((q[iq] < lo - 1e-12) | (q[iq] > hi + 1e-12)) if limits else []
    if len(outside):
        j = int(outside[0])
        raise t.error(
            name,
            f"joint {names[j]!r} = {q[iq][j]:g} is outside its limits [{lo[j]:g}, {hi[j]:g}]",
        )
    return q


def _start(t: Table, robot: Robot, full_names: list[str] | None, limits: bool) -> np.ndarray:
    t.check_keys(("q",))
    value = t.data.get("q", "default")
    if isinstance(value, str):
        refs = robot.model.referenceConfigurations
        name = "neutral" if value == "default" and "default" not in refs else value
        try:
            return robot.configuration(name)
        except InputError as err:
            raise t.error("q", str(err)) from None
    return _configuration(t, "q", robot, full_names, limits)


def _scene(doc: Document) -> Scene:
    scene = Scene()
    for i, t in enumerate(doc.tables("obstacle")):
        t.check_keys(("name", "shape", "size", "xyz", "rpy", "mesh"))
        name = t.string("name") or f"obstacle_{i + 1}"
        if name in scene.names:
            raise t.error("name", f"a second obstacle named {name!r}")
        shape = str(t.string("shape", required=True, choices=tuple(SHAPES)))
        xyz = t.vector("xyz", 3, required=True)
        rpy = t.vector("rpy", 3) or [0.0, 0.0, 0.0]
        R = pin.rpy.rpyToMatrix(*rpy)
        if shape == "mesh":
            mesh = doc.path.parent / str(t.string("mesh", required=True, hint=" (a mesh file)"))
            if not mesh.is_file():
                raise t.error("mesh", f"file not found: {mesh}")
            scale = t.vector("size", 3, positive=True) or [1.0, 1.0, 1.0]
            try:
                scene.add_mesh(name, mesh, scale, xyz, R)
            except (InputError, ValueError, RuntimeError) as err:
                raise t.error("mesh", f"cannot load {mesh.name}: {err}") from None
            continue
        if "mesh" in t:
            raise t.error("mesh", f"only for shape = 'mesh', not a {shape}")
        size = t.vector("size", SHAPES[shape], required=True, positive=True, hint=_SIZE[shape])
        if shape == "box":
            scene.add_box(name, size, xyz, R)
        elif shape == "sphere":
            scene.add_sphere(name, size[0], xyz)
        else:
            getattr(scene, f"add_{shape}")(name, *size, xyz, R)
    return scene


_SIZE = {
    "box": " (box: full side lengths x, y, z)",
    "cylinder": " (cylinder: radius, height)",
    "capsule": " (capsule: radius, height without the caps)",
    "sphere": " (sphere: radius)",
    "mesh": "",
}


def _pose(xyz: list[float], R: np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, xyz
    return M


def _goal(t: Table, robot: Robot, full_names: list[str] | None, limits: bool) -> Residual:
    t.check_keys(("q", "joints", "frame", "xyz", "rpy", "tolerance", "weight", "rest"))
    if "q" in t:
        for key in ("frame", "xyz", "rpy"):
            if key in t:
                raise t.error(key, "a joint goal (q) takes no frame, xyz or rpy")
        if "joints" in t:
            return _joint_goal(t, robot, limits)
        if robot.floating:
            raise t.error(
                "q",
                "a goal for every joint of a floating-base robot lists them: joints = [...] "
                "and q = [...] (the base takes frame goals)",
            )
        return JointPosition(_configuration(t, "q", robot, full_names, limits))
    if "joints" in t:
        raise t.error("joints", "a goal on some joints needs their values: q = [...]")
    frame = t.string("frame", required=True, hint=" (give q = [...], or frame and xyz)")
    try:
        fid = robot.frame_id(str(frame))
    except InputError as err:
        raise t.error("frame", str(err)) from None
    if robot.model.frames[fid].parentJoint == 0:
        raise t.error("frame", f"frame {frame!r} is fixed to the base: its pose cannot change")
    xyz = np.array(t.vector("xyz", 3, required=True))
    _check_reach(t, robot, fid, xyz)
    if "rpy" not in t:
        return FrameTranslation(str(frame), xyz)
    M = _pose(list(xyz), pin.rpy.rpyToMatrix(*t.vector("rpy", 3)))  # type: ignore[misc]
    return FramePlacement(str(frame), M)


def _joint_goal(t: Table, robot: Robot, limits: bool) -> Residual:
    """``[goal]`` ``joints`` and ``q``: a goal on those joints only."""
    names = t.strings("joints") or []
    joints = list(robot.joint_names)
    for name in names:
        if name not in joints:
            raise t.error("joints", f"{name!r} is not a joint of the planned robot: {joints}")
    if not names or len(set(names)) != len(names):
        raise t.error("joints", "expected distinct joint names")
    q = np.array(t.vector("q", len(names), required=True, hint=f" (one per joint of {names})"))
    idx = robot.q_of_v[robot.joint_indices(names)]
    lo, hi = robot.model.lowerPositionLimit[idx], robot.model.upperPositionLimit[idx]
    outside = np.flatnonzero((q < lo - 1e-12) | (q > hi + 1e-12)) if limits else []
    if len(outside):
        j = int(outside[0])
        raise t.error(
            "q", f"joint {names[j]!r} = {q[j]:g} is outside its limits [{lo[j]:g}, {hi[j]:g}]"
        )
    return JointPosition(q, joints=tuple(names))


def _check_reach(t: Table, robot: Robot, fid: int, xyz: np.ndarray) -> None:
    """Refuse a frame goal farther from the first joint of its chain than the chain can reach
    (the sum of its link lengths and prismatic travel); finer cases are the inverse
    kinematics' (before any solve)."""
    if robot.floating:  # the base goes anywhere: no bound on a frame's reach
        return
    model = robot.model
    frame = model.frames[fid]
    chain = []
    j = frame.parentJoint
    while j > 0:
        chain.append(j)
        j = model.parents[j]
    first = chain[-1]
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    origin = data.oMi[first].translation
    reach = float(np.linalg.norm(frame.placement.translation))
    for j in chain[:-1]:
        reach += float(np.linalg.norm(model.jointPlacements[j].translation))
    for j in chain:
        if model.joints[j].shortname().startswith("JointModelP"):
            i = model.joints[j].idx_q
            reach += max(abs(model.lowerPositionLimit[i]), abs(model.upperPositionLimit[i]))
    distance = float(np.linalg.norm(xyz - origin))
    if distance > reach:
        raise InfeasibleRequestError(
            f"{t.doc.where((*t.key, 'xyz'))}: the goal is outside the workspace: "
            f"{xyz.round(4).tolist()} is {distance:.3f} m from joint {model.names[first]!r}, "
            f"beyond the {reach:.3f} m that frame {frame.name!r} can reach"
        )


def _costs(t: Table, ocp: OCP, goal: Residual, goal_table: Table) -> None:
    t.check_keys(tuple(COST_DEFAULTS))
    w = {k: t.number(k) if k in t else v for k, v in COST_DEFAULTS.items()}
    tolerance = goal_table.number("tolerance", positive=True)
    weight = goal_table.number("weight", positive=True)
    if weight is None and tolerance is not None:
        ocp.add_constraint("goal", goal, knots="terminal", tolerance=tolerance)
    else:
        ocp.add_cost("goal", goal, weight or 1e2, knots="terminal", tolerance=tolerance)
    if w["tracking"]:
        ocp.add_cost("goal_tracking", goal, w["tracking"], knots="running")
    if w["velocity"]:
        ocp.add_cost("velocity", JointVelocity(), w["velocity"], knots="running")
    if w["terminal_velocity"]:
        ocp.add_cost("velocity_terminal", JointVelocity(), w["terminal_velocity"], "terminal")
    if w["torque"]:
        ocp.add_cost("torque", JointTorque(), w["torque"])


def _constraints(t: Table, ocp: OCP, position_limits: bool) -> None:
    obstacles = ("obstacle", "margin", "between_knots")
    t.check_keys((*obstacles, "position_limits", "velocity_limits", "torque_limits"))
    kind = t.string("obstacle", choices=("distance", "com")) or "distance"
    margin = t.number("margin")
    margin = MARGIN if margin is None else margin
    between_knots = t.boolean("between_knots", True)
    for name, residual, on in (
        ("position_limits", JointPositionLimits(), position_limits),
        ("velocity_limits", JointVelocityLimits(), t.boolean("velocity_limits", True)),
        ("torque_limits", JointTorqueLimits(), t.boolean("torque_limits", True)),
    ):
        if on:
            try:
                ocp.add_constraint(name, residual)
            except InputError as err:
                raise t.error(name, f"{err} (set {name} = false)") from None
    if not len(ocp.scene):
        return
    if kind == "com":
        for i, o in enumerate(ocp.scene):
            if o.shape != "cylinder" or not np.allclose(o.pose[:3, 2], [0, 0, 1], atol=1e-9):
                raise t.doc.error(
                    ("obstacle", i, "shape"),
                    f'{o} is not a vertical cylinder, which obstacle = "com" (eq. 62) needs; '
                    'use obstacle = "distance"',
                )
    try:
        add_obstacle_constraint(ocp, kind, margin, between_knots)
    except InputError as err:
        raise t.error("obstacle", str(err)) from None


def _solver(t: Table) -> tuple[str, str, float, int]:
    t.check_keys(("method", "warm_start", "tol", "max_iter"))
    method = t.string("method", choices=tuple(METHODS)) or "ripm"
    warm_start = t.string("warm_start", choices=("linear", "via")) or "via"
    tol = t.number("tol", positive=True)
    max_iter = t.integer("max_iter", minimum=0)
    return method, warm_start, 1e-6 if tol is None else tol, 500 if max_iter is None else max_iter
