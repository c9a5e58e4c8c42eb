"""Replay a quadrotor's flight: the vehicle along its SO(3)×R³ poses, its path, the goal pose
and the docking task's vertical cylinder obstacles."""

from __future__ import annotations

import os
from collections.abc import Sequence

import coal
import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.ocp.scene import Scene as ObstacleScene
from mbplan.viz.camera import direction
from mbplan.viz.scene import Label, Scene, layer, obstacle_layer
from mbplan.viz.server import show
from mbplan.viz.styles import GOAL_RGBA, OBSTACLE_RGBA

_PATH_COLOR = 0x555555
_DRONE_ELEVATION = 50.0  # degrees; the drone is seen from the side of its start-to-goal line
_DRONE_ARM = 0.175  # m, arm length of QuadrotorParams' vehicle (Drake's QuadrotorPlant)
_DRONE_HEADROOM = 0.3  # m, obstacle cylinders rise from the floor this far above the flight


def drone_replay(
    R: ArrayLike,
    p: ArrayLike,
    obstacles: Sequence[tuple[float, float, float]] = (),
    html: str | os.PathLike[str] | None = None,
    *,
    goal: tuple[ArrayLike, ArrayLike] | None = None,
    dt: float = 0.05,
    open_browser: bool = True,
    frame: int | None = None,
) -> str:
    """Animate a quadrotor (cross with rotors, front rotor red, thrust axis yellow) at
    ``(R_k, p_k)``, ``R (N+1, 3, 3)``, ``p (N+1, 3)``, knots ``dt`` apart, with its flown path,
    a translucent copy at ``goal = (R_goal, p_goal)`` (default: identity at the origin, the
    :class:`~mbplan.tasks.drone.DockingTask` default) and vertical cylinder ``obstacles``:
    ``(x_c, y_c, r)`` as in ``DockingTask.obstacles``, standing on the floor below the flight
    (``r`` includes the vehicle's radius, so the drawn vehicle may overlap one), or
    ``(x_c, y_c, r)``. The camera looks across the start-to-goal line. Returns the live viewer's
    URL, or with ``html`` the static page's path (``frame`` and the server's lifetime as in
    :func:`replay`)."""
    return show(_drone_scene(R, p, obstacles, goal, dt, frame), html, open_browser)


def draw_drone(
    viewer: meshcat.Visualizer,
    R: ArrayLike,
    p: ArrayLike,
    obstacles: Sequence[tuple[float, float, float]] = (),
    *,
    goal: tuple[ArrayLike, ArrayLike] | None = None,
    dt: float = 0.05,
    frame: int | None = None,
) -> None:
    """Draw the :func:`drone_replay` scene into any ``meshcat.Visualizer``."""
    _drone_scene(R, p, obstacles, goal, dt, frame)(viewer)


def free_body_scene(results: Sequence, ocp, frame: int | None = None) -> Scene:
    """The :func:`drone_replay` scene of a free-body plan (a :class:`~mbplan.PlanResult` whose
    OCP's robot is a :class:`~mbplan.FreeBody`): its flight, the terminal orientation and
    position targets of the OCP as the goal, the OCP's scene cylinders as obstacles."""
    from mbplan.residuals import BodyOrientation, BodyPosition
    from mbplan.robots.free_body import rotations

    if len(results) != 1:
        raise InputError(f"replay: free-body plans are drawn one at a time, got {len(results)}")
    q = np.asarray(results[0].q, dtype=float)
    if q.ndim != 2 or q.shape[1] != 7:
        raise InputError(f"replay: a free-body plan has q (N+1, 7), got {q.shape}")
    R_goal, p_goal = np.eye(3), np.zeros(3)
    for item in ocp.items:
        if ocp.N in item.knots and isinstance(item.residual, BodyOrientation):
            R_goal = np.asarray(item.residual.rotation)
        if ocp.N in item.knots and isinstance(item.residual, BodyPosition):
            p_goal = np.asarray(item.residual.translation)
    cylinders = [
        (o.pose[0, 3], o.pose[1, 3], o.size[0]) for o in ocp.scene if o.shape == "cylinder"
    ]
    return _drone_scene(
        rotations(q[:, 3:]), q[:, :3], cylinders, (R_goal, p_goal), results[0].dt, frame
    )


def _drone_scene(
    R: ArrayLike,
    p: ArrayLike,
    obstacles: Sequence[tuple[float, float, float]],
    goal: tuple[ArrayLike, ArrayLike] | None,
    dt: float,
    frame: int | None,
) -> Scene:
    R, p = np.asarray(R, dtype=float), np.asarray(p, dtype=float)
    if R.ndim != 3 or R.shape[1:] != (3, 3) or p.shape != (len(R), 3) or len(R) == 0:
        raise InputError(
            f"drone_replay: expected R (N+1, 3, 3), p (N+1, 3); got {R.shape}, {p.shape}"
        )
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(p))):
        raise InputError("drone_replay: R or p contains NaN or inf")
    R_goal, p_goal = (np.eye(3), np.zeros(3)) if goal is None else (np.asarray(g) for g in goal)
    if np.shape(R_goal) != (3, 3) or np.shape(p_goal) != (3,):
        raise InputError("drone_replay: goal must be (R_goal (3, 3), p_goal (3,))")
    if not (isinstance(dt, int | float) and dt > 0):
        raise InputError(f"drone_replay: dt must be > 0, got {dt!r}")
    body = _drone_geometry()
    poses = np.zeros((len(R) + 1, 4, 4))
    poses[:, 3, 3] = 1.0
    poses[:-1, :3, :3], poses[:-1, :3, 3] = R, p
    poses[-1, :3, :3], poses[-1, :3, 3] = R_goal, p_goal
    local = np.array([o.placement.homogeneous for o in body.geometryObjects])
    placed = poses[:, None] @ local
    layers = [layer("drone", body, placed[:-1], None), layer("goal", body, placed[-1:], GOAL_RGBA)]
    extent = np.concatenate([la.extent() for la in layers])
    labels = [
        Label("quadrotor (front rotor red)", (0.3, 0.3, 0.3)),
        Label("goal", GOAL_RGBA[:3]),
    ]
    if len(obstacles):
        z_lo, z_hi = extent[:, 2].min(), extent[:, 2].max() + _DRONE_HEADROOM
        scene = ObstacleScene()
        for k, o in enumerate(obstacles):
            x, y, r = _drone_cylinder(o)
            scene.add_cylinder(f"obstacle{k}", r, z_hi - z_lo, (x, y, 0.5 * (z_lo + z_hi)))
        layers.append(obstacle_layer("obstacles", scene, OBSTACLE_RGBA))
        labels.append(Label("obstacles", OBSTACLE_RGBA[:3]))

    def path_line(vis: meshcat.Visualizer) -> None:
        line = mg.Line(mg.PointsGeometry(p.T), mg.LineBasicMaterial(color=_PATH_COLOR))
        vis["mbplan/path"].set_object(line)

    travel = p_goal[:2] - p[0, :2]  # seen from its side, running left to right on screen
    azimuth = np.degrees(np.arctan2(-travel[0], travel[1])) if np.any(travel) else 0.0
    view = direction(_DRONE_ELEVATION, azimuth)
    floor = float(extent[:, 2].min())
    title = "mbplan replay: quadrotor docking"
    return Scene(title, layers, labels, dt, frame, path_line, floor, view)


def _drone_cylinder(obstacle: tuple[float, float, float]) -> tuple[float, float, float]:
    try:
        x, y, r = (float(v) for v in obstacle)
    except (TypeError, ValueError):
        raise InputError(f"drone obstacle {obstacle!r}: expected (x_c, y_c, r)") from None
    return x, y, r


def _drone_geometry() -> pin.GeometryModel:
    """A quadrotor in its body frame: two crossed arms, a hub, four rotor discs (the +x one red)
    and a short rod along the thrust axis (body z)."""
    L = _DRONE_ARM
    parts: list[tuple[str, coal.ShapeBase, tuple[float, float, float], tuple[float, ...]]] = [
        ("arm_x", coal.Box(2 * L, 0.02, 0.012), (0.0, 0.0, 0.0), (0.25, 0.25, 0.25, 1.0)),
        ("arm_y", coal.Box(0.02, 2 * L, 0.012), (0.0, 0.0, 0.0), (0.25, 0.25, 0.25, 1.0)),
        ("hub", coal.Box(0.08, 0.08, 0.035), (0.0, 0.0, 0.0), (0.15, 0.15, 0.15, 1.0)),
        ("thrust", coal.Cylinder(0.008, 0.14), (0.0, 0.0, 0.08), (0.95, 0.8, 0.1, 1.0)),
    ]
    for k, (x, y) in enumerate(((L, 0.0), (0.0, L), (-L, 0.0), (0.0, -L))):
        color = (0.9, 0.15, 0.1, 1.0) if k == 0 else (0.2, 0.35, 0.8, 1.0)
        parts.append((f"rotor{k}", coal.Cylinder(0.07, 0.01), (x, y, 0.015), color))
    geometry = pin.GeometryModel()
    for name, shape, xyz, color in parts:
        obj = pin.GeometryObject(name, 0, pin.SE3(np.eye(3), np.array(xyz)), shape)
        obj.meshColor = np.array(color)
        geometry.addGeometryObject(obj)
    return geometry
