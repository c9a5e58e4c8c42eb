"""Manipulator point-to-point task with obstacles of the RIPM paper §VIII.C / Table III, as data.

A fixed-base arm (default: the bundled KUKA iiwa 14) moves from ``q0`` at rest towards the fixed
``q_target`` in ``N`` steps of ``dt`` while staying clear of the obstacles at knots
``k = 1..N``, with one of two kinds of constraint (``ObstacleTask.obstacle_constraint``):

* ``"com"`` — the paper's eq. (62): every link's centre of mass (COM) outside each vertical
  cylinder, ``(x_i - x_c)² + (y_i - y_c)² ≥ (r_c + margin)²``. Eq. (62) treats a
  :class:`Cylinder` as infinite in z; general :class:`Obstacle` s are not constrained (planners
  refuse them, :func:`require_eq62`), only its finite solid is checked geometrically.
* ``"distance"`` — coal signed distances ``d ≥ margin`` between every collision geometry of a
  moving link and every obstacle (box, cylinder, sphere, capsule at any pose; a
  :class:`Cylinder` is its finite solid ``z_min..z_max``), see
  :mod:`mbplan.multibody.collision` for the derivatives.

The cost of the generalized-coordinate transcription (eq. 61) tracks ``q_target``::

    Σ_{k=1..N} s_k (½ w_q ‖q_k - q_target‖² + ½ w_v ‖v_k‖²) + Σ_{k=0..N-1} ½ w_tau ‖τ_k‖²,

with ``s_k = 1`` and ``s_N = terminal_factor``; knot 0 is fixed at ``(q0, v0 = 0)``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from functools import cache, lru_cache
from typing import Literal

import coal
import numpy as np
import pinocchio as pin

from mbplan.errors import InfeasibleRequestError, InputError, RobotModelError, WarmStartWarning
from mbplan.multibody.collision import (
    CollisionPairs,
    chain_kinematics,
    collision_pairs,
    joint_space_contacts,
)
from mbplan.robots import RobotDescription, load
from mbplan.validation import as_array, as_int, as_real, as_rotation

ShapeName = Literal["box", "cylinder", "sphere", "capsule"]
_SHAPE_SIZES: dict[str, tuple[str, ...]] = {
    "box": ("length x", "length y", "length z"),
    "cylinder": ("radius", "height"),
    "sphere": ("radius",),
    "capsule": ("radius", "height"),
}
SAMPLING_RANGE = 0.8  # fraction of each joint range (about its centre) that start samples use
_MAX_REJECTIONS = 10_000  # per case, before the sampler gives up

# iiwa defaults. The target reaches forward-left (joint 1 at 1 rad, elbow bent: the link COMs lie
# 0.03-0.62 m from the base axis at azimuth ≈ 57°). IIWA_CYLINDER (below) stands at azimuth 27°,
# 0.45 m from the base axis, where the COMs pass when joint 1 sweeps from a start at smaller
# azimuth: the straight joint-space path from IIWA_START and from about half of the sampled
# starts (48 of 100 for seed 0) runs through it.
IIWA_TARGET = (1.0, 0.6, 0.0, -1.4, 0.0, 1.0, 0.0)
IIWA_START = (-0.8, 0.2, 0.5, -1.6, 0.0, 1.0, 0.0)


@dataclass(frozen=True)
class Cylinder:
    """Vertical cylinder of ``radius`` around the axis through ``center_xy``, from ``z_min`` to
    ``z_max`` (m, world frame). Eq. (62) uses the infinite cylinder; see the module docstring."""

    center_xy: tuple[float, float]
    radius: float
    z_min: float = 0.0
    z_max: float = 1.5

    def __post_init__(self) -> None:
        c = as_array(self.center_xy, (2,), "Cylinder.center_xy")
        object.__setattr__(self, "center_xy", (float(c[0]), float(c[1])))
        object.__setattr__(self, "radius", as_real(self.radius, "Cylinder.radius", positive=True))
        z = as_array([self.z_min, self.z_max], (2,), "Cylinder z_min, z_max")
        if z[1] <= z[0]:
            raise InputError(f"Cylinder: z_max = {z[1]} must exceed z_min = {z[0]}")
        object.__setattr__(self, "z_min", float(z[0]))
        object.__setattr__(self, "z_max", float(z[1]))

    def __str__(self) -> str:
        x, y = self.center_xy
        return f"cylinder at ({x:g}, {y:g}) m, radius {self.radius:g} m"

    def as_obstacle(self) -> Obstacle:
        """The same solid as a general :class:`Obstacle` (for coal)."""
        pose = np.eye(4)
        pose[:3, 3] = (*self.center_xy, 0.5 * (self.z_min + self.z_max))
        return Obstacle("cylinder", pose, (self.radius, self.z_max - self.z_min))


@dataclass(frozen=True, eq=False)
class Obstacle:
    """A solid for coal distance checks: ``shape`` with ``size`` at ``pose`` (4x4, world frame).

    ``size``: box ``(lx, ly, lz)`` full side lengths; cylinder and capsule ``(radius, height)``
    along the local z axis (capsule height without the caps); sphere ``(radius,)``. The shape is
    centred at the pose origin, as in coal.
    """

    shape: ShapeName
    pose: np.ndarray
    size: tuple[float, ...]

    def __post_init__(self) -> None:
        if self.shape not in _SHAPE_SIZES:
            raise InputError(f"Obstacle.shape: {self.shape!r} is not one of {list(_SHAPE_SIZES)}")
        pose = as_array(self.pose, (4, 4), "Obstacle.pose")
        as_rotation(pose[:3, :3], "Obstacle.pose rotation (top-left 3x3 block)")
        if not np.array_equal(pose[3], [0.0, 0.0, 0.0, 1.0]):
            raise InputError("Obstacle.pose: last row must be (0, 0, 0, 1)")
        names = _SHAPE_SIZES[self.shape]
        try:
            size = tuple(self.size)
        except TypeError:
            raise InputError(f"Obstacle.size: expected {len(names)} numbers {names}") from None
        if len(size) != len(names):
            raise InputError(f"Obstacle.size of a {self.shape}: expected {names}, got {size}")
        size = tuple(
            as_real(s, f"Obstacle.size {n}", positive=True)
            for s, n in zip(size, names, strict=True)
        )
        object.__setattr__(self, "pose", pose)
        object.__setattr__(self, "size", size)

    def __str__(self) -> str:
        x, y, z = self.pose[:3, 3]
        return f"{self.shape} {self.size} at ({x:g}, {y:g}, {z:g}) m"

    def geometry(self) -> coal.ShapeBase:
        """The coal collision geometry (in the obstacle's own frame)."""
        s = self.size
        if self.shape == "box":
            return coal.Box(*s)
        if self.shape == "cylinder":
            return coal.Cylinder(*s)
        if self.shape == "capsule":
            return coal.Capsule(*s)
        return coal.Sphere(*s)

    def transform(self) -> coal.Transform3s:
        return coal.Transform3s(self.pose[:3, :3], self.pose[:3, 3])


IIWA_CYLINDER = Cylinder((0.4, 0.2), 0.1)  # see IIWA_TARGET
# The default for coal-distance tasks: the link geometry (radius ~0.1 m) reaches further than the
# COMs, so at IIWA_CYLINDER the target pose would leave link 4 only 0.012 m from the cylinder;
# here the target clears it by 0.081 m and the straight path of 57 of 100 sampled starts (seed 0)
# runs through it.
IIWA_DISTANCE_CYLINDER = Cylinder((0.45, 0.15), 0.1)


@dataclass(frozen=True)
class CostWeights:
    """Weights of the joint-space tracking cost (module docstring).

    The paper gives no numbers. ``w_q = 1`` per rad², ``w_v = 0.1`` per (rad/s)² and
    ``w_tau = 1e-4`` per (N m)²: the gravity torques of a stretched iiwa (~100 N m at joints 2/4)
    cost about as much as a 0.3 rad tracking error, so torques are regularised without holding
    the arm away from the target; ``terminal_factor = 50`` pulls the last knot onto it.
    """

    w_q: float = 1.0
    w_v: float = 0.1
    w_tau: float = 1e-4
    terminal_factor: float = 50.0

    def __post_init__(self) -> None:
        for name in ("w_q", "w_v", "w_tau", "terminal_factor"):
            object.__setattr__(self, name, as_real(getattr(self, name), f"weights.{name}"))


@dataclass(frozen=True, eq=False)
class ObstacleTask:
    """Move ``robot`` from ``(q0, 0)`` towards ``q_target`` avoiding ``obstacles`` (§VIII.C).

    ``N = 40`` as in the paper, ``dt = 0.075 s``: a 3 s horizon. The paper gives no Δt; 2 s
    (Δt = 0.05) is too short for the iiwa's velocity limits (1.31-2.36 rad/s) to cover the joint
    displacements of starts sampled in 80 % of the joint ranges (up to 3.4 rad: ≥ 2.3 s), and a
    larger Δt makes the first-order eq. (61) coarser still (its one-step error is already
    ~0.1 rad at 0.075 s, see :mod:`mbplan.verification`). For ``robot = "iiwa"``,
    ``q0``/``q_target``/``obstacles`` default to :data:`IIWA_START`/:data:`IIWA_TARGET`/
    ``(IIWA_CYLINDER,)`` (``(IIWA_DISTANCE_CYLINDER,)`` for coal distances); other robots must give ``q0`` and ``q_target``. ``torque_limit``/``velocity_limit`` default to the
    URDF effort/velocity limits (symmetric bounds). ``margin`` (m) is added to every cylinder
    radius in eq. (62): it keeps the COMs of the continuous, replayed motion (not only the knots)
    outside the cylinder; with ``obstacle_constraint = "distance"`` it is the required coal
    distance (m) between robot and obstacle geometry. ``goal_tolerance`` (rad) is the final joint error that
    :func:`mbplan.verification.verify` accepts: the soft tracking cost leaves ~0.02 rad. Arrays
    are stored read-only; :func:`validate` checks feasibility.
    """

    robot: str = "iiwa"
    N: int = 40
    dt: float = 0.075
    q0: np.ndarray | None = None
    q_target: np.ndarray | None = None
    obstacles: tuple[Cylinder | Obstacle, ...] | None = None
    torque_limit: np.ndarray | None = None
    velocity_limit: np.ndarray | None = None
    weights: CostWeights = field(default_factory=CostWeights)
    margin: float = 0.03
    goal_tolerance: float = 0.05
    warm_start: Literal["linear", "via"] = "linear"
    obstacle_constraint: Literal["com", "distance"] = "com"

    def __post_init__(self) -> None:
        if not isinstance(self.robot, str):
            raise InputError(f"robot: expected a robot name, got {type(self.robot).__name__}")
        model = robot_description(self.robot).model
        nq, nv, is_iiwa = model.nq, model.nv, self.robot == "iiwa"
        object.__setattr__(self, "N", as_int(self.N, "N", minimum=2, what="horizon"))
        object.__setattr__(self, "dt", as_real(self.dt, "dt", positive=True))
        for name, default in (("q0", IIWA_START), ("q_target", IIWA_TARGET)):
            value = getattr(self, name)
            if value is None and not is_iiwa:
                raise InputError(f"{name}: required for robot {self.robot!r}")
            object.__setattr__(
                self, name, as_array(default if value is None else value, (nq,), name)
            )
        default = (
            IIWA_DISTANCE_CYLINDER if self.obstacle_constraint == "distance" else IIWA_CYLINDER
        )
        obstacles = (default,) if self.obstacles is None and is_iiwa else self.obstacles
        obstacles = tuple(obstacles or ())
        for i, obstacle in enumerate(obstacles):
            if not isinstance(obstacle, Cylinder | Obstacle):
                raise InputError(f"obstacles[{i}]: expected Cylinder or Obstacle, got {obstacle!r}")
        object.__setattr__(self, "obstacles", obstacles)
        for name, urdf in (
            ("torque_limit", model.effortLimit),
            ("velocity_limit", model.velocityLimit),
        ):
            value = as_array(
                urdf if getattr(self, name) is None else getattr(self, name), (nv,), name
            )
            if np.any(value <= 0.0):
                raise InputError(f"{name}: limits must be > 0 (URDF without limits?), got {value}")
            object.__setattr__(self, name, value)
        if not isinstance(self.weights, CostWeights):
            raise InputError(f"weights: expected CostWeights, got {type(self.weights).__name__}")
        object.__setattr__(self, "margin", as_real(self.margin, "margin"))
        object.__setattr__(self, "goal_tolerance", as_real(self.goal_tolerance, "goal_tolerance"))
        if self.warm_start not in ("linear", "via"):
            raise InputError(f"warm_start: expected 'linear' or 'via', got {self.warm_start!r}")
        if self.obstacle_constraint not in ("com", "distance"):
            raise InputError(
                "obstacle_constraint: expected 'com' (eq. 62) or 'distance' (coal), got "
                f"{self.obstacle_constraint!r}"
            )
        if self.obstacle_constraint == "distance" and self.obstacles:
            if robot_description(self.robot).collision_model is None:
                raise InputError(
                    f"obstacle_constraint='distance': robot {self.robot!r} has no collision "
                    "geometry"
                )

    @property
    def cylinders(self) -> tuple[Cylinder, ...]:
        """The obstacles of eq. (62) (none when ``obstacle_constraint = "distance"``)."""
        if self.obstacle_constraint == "distance":
            return ()
        return tuple(o for o in self.obstacles if isinstance(o, Cylinder))

    @property
    def solids(self) -> tuple[Obstacle, ...]:
        """Every obstacle as a finite solid for coal (a :class:`Cylinder` from z_min to z_max)."""
        return tuple(o.as_obstacle() if isinstance(o, Cylinder) else o for o in self.obstacles)


def require_eq62(task: ObstacleTask, planner: str) -> None:
    """Raise :class:`InputError` if a planner that implements eq. (62) only gets a task with
    general :class:`Obstacle` shapes under ``obstacle_constraint = "com"``."""
    if task.obstacle_constraint == "com" and any(isinstance(o, Obstacle) for o in task.obstacles):
        raise InputError(
            f"{planner}: obstacle_constraint='com' (eq. 62) handles vertical Cylinder obstacles "
            "only; use obstacle_constraint='distance' for general Obstacle shapes"
        )


@lru_cache(maxsize=8)
def task_collision_pairs(task: ObstacleTask) -> CollisionPairs:
    """The (link geometry, obstacle) pairs of a ``"distance"`` task."""
    desc = robot_description(task.robot)
    return collision_pairs(desc.collision_model, [(o.geometry(), o.pose) for o in task.solids])


def pair_distances(task: ObstacleTask, q: np.ndarray) -> np.ndarray:
    """Coal distances ``(K, P)`` of the pairs of :func:`task_collision_pairs` at ``q (K, nq)``."""
    model = robot_description(task.robot).model
    kin = chain_kinematics(model, model.createData(), np.atleast_2d(q))
    return joint_space_contacts(task_collision_pairs(task), kin)[0].distance


@cache
def robot_description(robot: str) -> RobotDescription:
    """:func:`mbplan.robots.load` once per name; the model must have only 1-dof joints (nq = nv).

    The returned description is shared: do not modify its models.
    """
    desc = load(robot)
    model = desc.model
    for j in range(1, model.njoints):
        if model.joints[j].nq != 1 or model.joints[j].nv != 1:
            raise RobotModelError(
                f"{robot}: joint {model.names[j]!r} ({model.joints[j].shortname()}) is not a "
                "1-dof revolute/prismatic joint with bounds (nq = nv = 1 required)"
            )
    return desc


def link_names(model: pin.Model) -> list[str]:
    """Name of the link moved by each joint ``1..njoints-1`` (its first body frame)."""
    names = list(model.names[1:])
    for frame in reversed(model.frames):
        if frame.type == pin.FrameType.BODY and frame.parentJoint > 0:
            names[frame.parentJoint - 1] = frame.name
    return names


def link_coms(model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    """World COM of every link ``1..njoints-1`` at ``q``, shape ``(njoints-1, 3)``."""
    pin.forwardKinematics(model, data, q)
    return np.array([data.oMi[j].act(model.inertias[j].lever) for j in range(1, model.njoints)])


def com_clearances(task: ObstacleTask, coms: np.ndarray) -> np.ndarray:
    """Eq. (62) clearance ``‖(x_i, y_i) - c‖ - r`` (m, without margin) of COMs ``(..., 3)`` to
    each cylinder, shape ``(..., n_cylinders)``."""
    if not task.cylinders:
        return np.empty((*coms.shape[:-1], 0))
    centers = np.array([c.center_xy for c in task.cylinders])
    radii = np.array([c.radius for c in task.cylinders])
    return np.linalg.norm(coms[..., None, :2] - centers, axis=-1) - radii


def geometry_distances(
    desc: RobotDescription, q: np.ndarray, obstacles: tuple[Obstacle, ...]
) -> np.ndarray:
    """Signed coal distances (m, < 0: penetration) between each collision geometry of the robot
    at ``q`` and each obstacle, shape ``(n_geometries, n_obstacles)``."""
    geom = desc.collision_model
    gdata = geom.createData()
    pin.updateGeometryPlacements(desc.model, desc.model.createData(), geom, gdata, q)
    request = coal.DistanceRequest()
    out = np.empty((geom.ngeoms, len(obstacles)))
    shapes = [(o.geometry(), o.transform()) for o in obstacles]
    for g, obj in enumerate(geom.geometryObjects):
        M = gdata.oMg[g]
        tf = coal.Transform3s(M.rotation, M.translation)
        for o, (shape, otf) in enumerate(shapes):
            out[g, o] = coal.distance(obj.geometry, tf, shape, otf, request, coal.DistanceResult())
    return out


def _collision(task: ObstacleTask, q: np.ndarray) -> str | None:
    """Why ``q`` violates an obstacle (eq. 62 with margin, or coal penetration), else None."""
    desc = robot_description(task.robot)
    if task.obstacle_constraint == "distance":
        if not task.obstacles:
            return None
        d = pair_distances(task, q)[0]
        i = int(np.argmin(d))
        if d[i] >= task.margin:
            return None
        pairs = task_collision_pairs(task)
        o = int(pairs.obstacle[i])
        return (
            f"collision geometry {pairs.names[i].split('/')[0]!r} is {d[i]:.3f} m from obstacle "
            f"{o} ({task.obstacles[o]}), less than the margin {task.margin:g} m"
        )
    model = desc.model
    names = link_names(model)
    clear = com_clearances(task, link_coms(model, model.createData(), q))
    hits = np.argwhere(clear < task.margin)
    if hits.size:
        i, c = (int(x) for x in hits[0])
        cylinder = task.cylinders[c]
        return (
            f"the COM of link {names[i]!r} is {clear[i, c]:.3f} m from the surface of obstacle "
            f"{task.obstacles.index(cylinder)} ({cylinder}), less than the margin "
            f"{task.margin:g} m (eq. 62)"
        )
    if desc.collision_model is None or not task.obstacles:
        return None
    solids = tuple(o.as_obstacle() if isinstance(o, Cylinder) else o for o in task.obstacles)
    dist = geometry_distances(desc, q, solids)
    hits = np.argwhere(dist < 0.0)
    if hits.size:
        g, o = (int(x) for x in hits[0])
        return (
            f"collision geometry {desc.collision_model.geometryObjects[g].name!r} penetrates "
            f"obstacle {o} ({task.obstacles[o]}) by {-dist[g, o]:.3f} m"
        )
    return None


def validate(task: ObstacleTask) -> None:
    """Raise :class:`InfeasibleRequestError` if the request cannot be met, before any solving:
    ``q0``/``q_target`` outside the joint limits, or ``q0``/``q_target`` overlapping an obstacle
    (a link COM within ``radius + margin`` of a cylinder axis, eq. 62 — knot 1 equals knot 0 at
    rest, so the constraint could not hold — or, with collision geometry, any penetration).
    The message names the link or geometry and the obstacle."""
    for name in ("q0", "q_target"):
        _check_configuration(task, name)


def _check_configuration(task: ObstacleTask, name: str) -> None:
    model = robot_description(task.robot).model
    q = getattr(task, name)
    low, high = model.lowerPositionLimit, model.upperPositionLimit
    bad = np.nonzero((q < low) | (q > high))[0]
    if bad.size:
        j = int(bad[0])
        raise InfeasibleRequestError(
            f"{name}[{j}] = {q[j]:.4f} is outside the limits [{low[j]:.4f}, {high[j]:.4f}] "
            f"of joint {model.names[j + 1]!r}"
        )
    reason = _collision(task, q)
    if reason is not None:
        raise InfeasibleRequestError(f"{name} overlaps an obstacle: {reason}")


def sample_obstacle_cases(
    robot: str = "iiwa",
    n: int = 100,
    seed: int = 0,
    N: int = 40,
    **task_fields: object,
) -> list[ObstacleTask]:
    """``n`` tasks with random starts (Table III): ``q0`` uniform in the central
    :data:`SAMPLING_RANGE` of each joint range (a seeded ``numpy`` Generator), resampled while
    :func:`validate` would reject it (COM inside a cylinder + margin, eq. 62, or robot geometry
    penetrating an obstacle). Target and obstacles are fixed (``task_fields`` are passed on to
    :class:`ObstacleTask`, e.g. ``dt``, ``q_target``, ``obstacles``, ``margin``)."""
    as_int(n, "n", minimum=1, what="number of cases")
    as_int(seed, "seed", minimum=0, what="random seed")
    if "q0" in task_fields:
        raise InputError("q0 is sampled; do not pass it")
    model = robot_description(robot).model
    centre = 0.5 * (model.lowerPositionLimit + model.upperPositionLimit)
    half = 0.5 * SAMPLING_RANGE * (model.upperPositionLimit - model.lowerPositionLimit)
    rng = np.random.default_rng(seed)
    template = ObstacleTask(robot=robot, N=N, q0=centre, **task_fields)  # type: ignore[arg-type]
    _check_configuration(template, "q_target")
    tasks = []
    for case in range(n):
        for _ in range(_MAX_REJECTIONS):
            q0 = rng.uniform(centre - half, centre + half)
            if _collision(template, q0) is None:
                break
        else:
            raise InfeasibleRequestError(
                f"case {case}: no collision-free start in {_MAX_REJECTIONS} samples"
            )
        tasks.append(replace(template, q0=q0))
    return tasks


VIA_CANDIDATES = 256  # random via points tried by the "via" warm start


def joint_interpolation(task: ObstacleTask) -> np.ndarray:
    """Initial guess ``q (N+1, nq)`` shared by every method, with ``q_1 = q_0`` (the arm starts at
    rest, so both eq. (61) and the LGVI give ``q_1 = q_0``).

    ``task.warm_start == "linear"``: linear in joint space from ``q0`` to ``q_target`` over knots
    ``1..N`` (§VIII.C). ``"via"``: the same if every knot keeps clear of the obstacles (+ margin,
    by the task's kind of constraint); otherwise the shortest collision-free two-segment path
    ``q0 → q_via → q_target`` among :data:`VIA_CANDIDATES` seeded random via points (falls back
    to linear if none is collision-free at the knots).
    """
    s = np.concatenate([[0.0], np.linspace(0.0, 1.0, task.N)])
    linear = task.q0 + s[:, None] * (task.q_target - task.q0)
    if task.warm_start == "linear" or _path_clearance(task, linear) >= 0:
        return linear
    model = robot_description(task.robot).model
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    rng = np.random.default_rng(0)
    mid = 0.5 * (task.q0 + task.q_target)
    best, best_length = linear, np.inf
    for _ in range(VIA_CANDIDATES):
        via = np.clip(mid + 0.5 * rng.uniform(-1.0, 1.0, mid.shape) * (hi - lo), lo, hi)
        length = float(np.linalg.norm(via - task.q0) + np.linalg.norm(task.q_target - via))
        if length >= best_length:
            continue
        first = np.minimum(2 * s, 1.0)[:, None]
        second = np.maximum(2 * s - 1.0, 0.0)[:, None]
        path = task.q0 + first * (via - task.q0) + second * (task.q_target - via)
        if _path_clearance(task, path) >= 0:
            best, best_length = path, length
    if best is linear:
        warnings.warn(WarmStartWarning(VIA_FALLBACK), stacklevel=2)
    return best


VIA_FALLBACK = (
    f'warm start "via": none of {VIA_CANDIDATES} via points gives a collision-free path at the '
    "knots; using the linear warm start (make this an error with "
    'warnings.simplefilter("error", mbplan.errors.WarmStartWarning) or --strict-warm-start)'
)


def _path_clearance(task: ObstacleTask, path: np.ndarray) -> float:
    """Smallest clearance minus the margin over the knots of a joint path: eq. (62), or coal
    distances for ``obstacle_constraint = "distance"``."""
    if task.obstacle_constraint == "distance" and task.obstacles:
        return float(np.min(pair_distances(task, path))) - task.margin
    if not task.cylinders:
        return np.inf
    model = robot_description(task.robot).model
    data = model.createData()
    coms = np.array([link_coms(model, data, q) for q in path])
    return float(np.min(com_clearances(task, coms))) - task.margin
