"""Replay planned trajectories in MeshCat, live or as a self-contained HTML page.

A maximal-coordinate solution is drawn straight from its SO(3)×R³ states: body ``b``'s frame is at
its centre of mass with the orientation of its joint frame, so a visual geometry attached to that
joint at ``placement_g`` (Pinocchio's visual ``GeometryModel``) is at::

    oMg = [R_b, p_b] · [I, -com_in_joint_b] · placement_g

and the viewer shows what the solver produced, joint-constraint violations included. A
generalized-coordinate solution goes through Pinocchio's forward kinematics. Several results stand
side by side along y, each in its own colour and labelled (a text texture in the scene and the
page's legend), each with the task's obstacles and a translucent copy of the robot at
``q_target``. The animation has one frame per knot: play it and scrub its time in the viewer's
"Animations" panel ("Open Controls").

meshcat 0.3.2 notes: its orbit controls always look at the world origin, so the scene and the
ground grid are shifted to put the scene's centre there (the world axes are hidden), and the
camera is placed by the ``position`` and ``fov`` properties of
``/Cameras/default/rotated/<object>`` (a y-up frame). There is no text primitive: labels are PNG
textures. A live viewer runs its own MeshCat
server in a subprocess that listens on 127.0.0.1 only (HTTP, websocket and ZMQ); a static page
inlines the viewer's JavaScript and the scene and needs no network.
"""

from __future__ import annotations

import atexit
import base64
import contextlib
import functools
import html as html_lib
import io
import os
import subprocess
import sys
import threading
import webbrowser
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import coal
import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack
from meshcat.animation import Animation
from numpy.typing import ArrayLike
from PIL import Image, ImageDraw, ImageFont
from pinocchio.visualize import MeshcatVisualizer

from mbplan.errors import InputError, MbplanError, RobotModelError
from mbplan.multibody import MaximalModel, maximal_model
from mbplan.ocp.robot import load_robot
from mbplan.ocp.scene import Scene
from mbplan.results import PlanResult, load_npz
from mbplan.robots import available_robots
from mbplan.validation import output_file
from mbplan.viz.plots import result_label, write_atomic

HOST = "127.0.0.1"  # the only interface the live server listens on
_VIEWER_JS = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
# per result: redder than green, unlike the blue background, the grey grid and the green goal
_COLORS = ((0.95, 0.5, 0.1), (0.6, 0.3, 0.85), (0.9, 0.75, 0.1), (0.85, 0.35, 0.55))
_GOAL_RGBA = (0.2, 0.8, 0.3, 0.3)
_OBSTACLE_RGBA = (0.85, 0.2, 0.2, 0.35)
_PATH_COLOR = 0x555555
_FOV = 40.0  # degrees, vertical (meshcat's default 75° distorts side-by-side robots)
_TAN_HALF_FOV = np.tan(np.radians(_FOV) / 2)
_ASPECT = 16 / 9  # screen aspect the camera distance is chosen for
_ROBOT_VIEW = (25.0, 10.0)  # degrees: elevation and azimuth of the camera seen from the scene
_DRONE_ELEVATION = 50.0  # degrees; the drone is seen from the side of its start-to-goal line
_LABEL_PX = 48  # font size of in-scene labels (texture pixels)
_PAD = 0.15  # m around geometry origins when framing and spacing the scene
_DRONE_ARM = 0.175  # m, arm length of QuadrotorParams' vehicle (Drake's QuadrotorPlant)
_DRONE_HEADROOM = 0.3  # m, obstacle cylinders rise from the floor this far above the flight

Rgba = tuple[float, float, float, float]


@dataclass(frozen=True, eq=False)
class _Layer:
    """Geometry under node ``mbplan/<name>`` at world placements ``(K, ngeom, 4, 4)`` per knot
    (``K = 1``: static); ``rgba`` None keeps each geometry's own colour."""

    name: str
    model: pin.Model
    geometry: pin.GeometryModel
    placements: np.ndarray
    rgba: Rgba | None
    extent: np.ndarray  # (n, 3) world points the camera must see


@dataclass(frozen=True, eq=False)
class _Label:
    """A legend entry; with ``position`` also ``caption`` as text in the scene there."""

    text: str
    rgb: tuple[float, float, float]
    position: np.ndarray | None = None
    caption: str = ""


# --- geometry placements -------------------------------------------------------------------------


def maximal_geometry_placements(
    mm: MaximalModel, geometry: pin.GeometryModel, R: ArrayLike, p: ArrayLike
) -> np.ndarray:
    """World placements ``(..., ngeom, 4, 4)`` of the objects of ``geometry`` (attached to
    ``mm.model``'s joints) from body poses ``R (..., nb, 3, 3)``, ``p (..., nb, 3)`` (module
    docstring); objects on the universe stay at their placement."""
    R, p = np.asarray(R, dtype=float), np.asarray(p, dtype=float)
    nb = mm.nb
    if R.shape[-3:] != (nb, 3, 3) or p.shape[-2:] != (nb, 3) or R.shape[:-3] != p.shape[:-2]:
        raise InputError(
            f"expected R (..., {nb}, 3, 3) and p (..., {nb}, 3) for {mm.name!r}, got "
            f"{R.shape} and {p.shape}"
        )
    body = {int(j): b for b, j in enumerate(mm.pin_joint)}
    body_frames = np.zeros((*R.shape[:-2], 4, 4))
    body_frames[..., :3, :3] = R
    body_frames[..., :3, 3] = p - np.einsum("...bij,bj->...bi", R, mm.com_in_joint)
    body_frames[..., 3, 3] = 1.0
    out = np.empty((*R.shape[:-3], geometry.ngeoms, 4, 4))
    for g, obj in enumerate(geometry.geometryObjects):
        placement = obj.placement.homogeneous
        if obj.parentJoint == 0:
            out[..., g, :, :] = placement
        elif obj.parentJoint in body:
            out[..., g, :, :] = body_frames[..., body[obj.parentJoint], :, :] @ placement
        else:
            raise RobotModelError(
                f"geometry {obj.name!r} hangs on joint {obj.parentJoint}, which moves no body of "
                f"{mm.name!r}"
            )
    return out


def generalized_geometry_placements(
    model: pin.Model, geometry: pin.GeometryModel, q: ArrayLike
) -> np.ndarray:
    """World placements ``(K, ngeom, 4, 4)`` of the objects of ``geometry`` at the
    configurations ``q (K, nq)`` (Pinocchio forward kinematics)."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != model.nq:
        raise InputError(f"expected q (K, {model.nq}) for {model.name!r}, got {q.shape}")
    data, gdata = model.createData(), geometry.createData()
    out = np.empty((len(q), geometry.ngeoms, 4, 4))
    for k, qk in enumerate(q):
        pin.updateGeometryPlacements(model, data, geometry, gdata, qk)
        out[k] = [M.homogeneous for M in gdata.oMg]
    return out


# --- robot results -------------------------------------------------------------------------------


def replay(
    results: Sequence[PlanResult],
    task: Any = None,
    *,
    html: str | os.PathLike[str] | None = None,
    open_browser: bool = True,
    robot: str | None = None,
    frame: int | None = None,
) -> str:
    """Show ``results`` side by side (with ``task``'s obstacles and goal) in a live MeshCat
    viewer and return its URL, or with ``html`` write a static page there and return its path.

    ``task`` (an OCP) defaults to the first result's OCP; ``robot`` is only needed for results
    without one (else :func:`infer_robot`). ``frame`` None plays the
    animation once; a knot index shows that knot, with the animation loaded but paused. The
    live server lives until the Python process exits.
    """
    return _show(_robot_scene(results, task, robot, frame), html, open_browser)


def draw_results(
    viewer: meshcat.Visualizer,
    results: Sequence[PlanResult],
    task: Any = None,
    *,
    robot: str | None = None,
    frame: int | None = None,
) -> None:
    """Draw the :func:`replay` scene into any ``meshcat.Visualizer`` (e.g. of a
    :class:`MeshcatServer`)."""
    _robot_scene(results, task, robot, frame)(viewer)


def static_html(
    results: Sequence[PlanResult],
    path: str | os.PathLike[str],
    task: Any = None,
    *,
    robot: str | None = None,
    frame: int | None = None,
) -> Path:
    """Write the :func:`replay` scene of ``results`` as one self-contained HTML page (viewer
    JavaScript and scene inlined, no network needed) to ``path`` atomically; return the path."""
    return _write_page(_robot_scene(results, task, robot, frame), path)


def infer_robot(results: Sequence[PlanResult], default: str = "iiwa") -> str:
    """The robot ``results`` were planned for: ``default`` if every result fits it (joint count
    and, for maximal results, body names), else the one available robot whose body names match
    the maximal results' ``body_names``. :class:`InputError` if none or several do (e.g. the UR
    arms share their link names)."""
    if all(_fits(r, default) for r in results):
        return default
    matches = []
    if any(r.body_names is not None for r in results):
        matches = [n for n in available_robots() if all(_fits(r, n) for r in results)]
    if len(matches) == 1:
        return matches[0]
    joints = sorted({r.q.shape[1] for r in results})
    found = f"robots {', '.join(matches)} all match" if matches else "no available robot matches"
    raise InputError(
        f"the results ({joints} joints) do not fit robot {default!r} and {found} their body "
        "names: give the robot explicitly"
    )


def read_result(path: str | os.PathLike[str]) -> PlanResult:
    """:func:`mbplan.results.load_npz` (an :class:`InputError` naming the file for a missing,
    unreadable or incomplete one)."""
    return load_npz(path)


def replay_main(
    paths: Sequence[str | os.PathLike[str]],
    html: str | os.PathLike[str] | None,
    no_browser: bool,
    robot: str = "iiwa",
) -> int:
    """``mbplan replay``: show the ``.npz`` results at ``paths`` side by side.

    The robot is ``robot`` if the results fit it, else inferred from the maximal results' body
    names (:func:`infer_robot`) for files from before the OCP API; a result that carries its OCP
    is drawn with that OCP's robot and scene (old iiwa files: the default iiwa task's scene). With ``html`` the static page is written there; otherwise a live viewer is
    served on 127.0.0.1, its URL printed (and opened unless ``no_browser``) and the command
    serves until interrupted (Ctrl-C). Returns the exit status.
    """
    if not paths:
        raise InputError("replay: no result files given")
    results = [read_result(p) for p in paths]
    if all(r.ocp is not None for r in results):
        task, name = results[0].ocp, None  # the scene and robot each plan was made with
    else:  # files from before the OCP API: guess the robot, the iiwa's default task
        from mbplan.paper import iiwa_obstacle

        name = infer_robot(results, robot)
        task = iiwa_obstacle() if name == "iiwa" else None
    build = _robot_scene(results, task, name, None)
    if html is not None:
        print(f"wrote {_write_page(build, html)}")
        return 0
    _serve_until_interrupted(build, open_browser=not no_browser)
    return 0


def serve(
    results: Sequence[PlanResult],
    task: Any = None,
    *,
    robot: str | None = None,
    open_browser: bool = True,
) -> None:
    """The :func:`replay` scene served live on 127.0.0.1 until Ctrl-C (the URL printed once the
    scene is loaded): what ``mbplan plan --viz`` and ``mbplan replay`` do."""
    _serve_until_interrupted(_robot_scene(results, task, robot, None), open_browser=open_browser)


def _serve_until_interrupted(scene: _Scene, open_browser: bool) -> None:
    # Ctrl-C from the moment the URL can be printed ends serving quietly.
    with MeshcatServer() as server, contextlib.suppress(KeyboardInterrupt):
        scene(server.viewer)
        print(f"MeshCat viewer at {server.url} (Ctrl-C stops the server)", flush=True)
        if open_browser:
            webbrowser.open(server.url)
        server.wait()


@functools.cache
def _maximal(robot: str) -> MaximalModel:
    return maximal_model(robot)


def _fits(result: PlanResult, robot: str) -> bool:
    try:
        mm = _maximal(robot)
    except MbplanError:
        return False
    return (
        result.q.shape[1] == mm.nq
        and (result.body_names is None or tuple(result.body_names) == mm.body_names)
        and (result.R is None or result.R.shape[1:] == (mm.nb, 3, 3))
    )


def _scene_ocp(task: Any) -> Any:
    """``task`` if it is an OCP (or None)."""
    from mbplan.ocp.problem import OCP

    if task is None or isinstance(task, OCP):
        return task
    raise InputError(f"task: expected an OCP, got {type(task).__name__}")


def _robot_scene(
    results: Sequence[PlanResult],
    task: Any,
    robot: str | None,
    frame: int | None,
) -> _Scene:
    """Check the inputs and return the scene builder (layers, labels, animation timing).

    The scene is that of ``task`` (an OCP), else of the first result's OCP."""
    results = list(results)
    if not results:
        raise InputError("replay: no results given")
    for i, result in enumerate(results):
        if not isinstance(result, PlanResult):
            raise InputError(f"results[{i}]: expected a PlanResult, got {type(result).__name__}")
    ocp = _scene_ocp(task)
    if ocp is None and robot is None and results[0].ocp is not None:
        ocp = results[0].ocp
    if ocp is not None and robot is not None and robot != ocp.robot.name:
        raise InputError(f"robot {robot!r} differs from the task's robot {ocp.robot.name!r}")
    desc = ocp.robot if ocp is not None else load_robot(robot or infer_robot(results))
    if desc.visual_model is None or desc.visual_model.ngeoms == 0:
        raise RobotModelError(f"robot {desc.name!r} has no visual geometry to draw")
    mm = _maximal_of(desc.model)
    dt = results[0].dt
    for result in results:
        fits = result.q.shape[1] == mm.nq and (
            result.body_names is None or tuple(result.body_names) == mm.body_names
        )
        if not fits:
            raise InputError(
                f"{result_label(result)}: {result.q.shape[1]} joints"
                + (f", bodies {result.body_names}" if result.body_names else "")
                + f" do not fit robot {desc.name!r}"
            )
        if not np.isclose(result.dt, dt, rtol=1e-9, atol=0.0):
            raise InputError(f"results have different time steps ({result.dt} and {dt} s)")
    goal = _goal_configuration(ocp)
    copies = [_robot_copy(i, r, ocp, goal, desc, mm) for i, r in enumerate(results)]
    y_lo = min(p[:, 1].min() for layers, _ in copies for p in (la.extent for la in layers))
    y_hi = max(p[:, 1].max() for layers, _ in copies for p in (la.extent for la in layers))
    spacing = y_hi - y_lo + 4 * _PAD
    layers, labels = [], []
    for i, (copy_layers, label) in enumerate(copies):
        shift = np.eye(4)
        shift[1, 3] = (i - (len(copies) - 1) / 2) * spacing
        layers += [_shifted(layer, shift) for layer in copy_layers]
        points = np.concatenate([la.extent for la in copy_layers])
        top = np.array([points[:, 0].mean(), shift[1, 3] + points[:, 1].mean(), 0.0])
        top[2] = points[:, 2].max() + 2 * _PAD
        labels.append(_Label(label.text, label.rgb, top, label.caption))
    if goal is not None:
        labels.append(_Label("goal: q_target", _GOAL_RGBA[:3]))
    if ocp is not None and len(ocp.scene):
        labels.append(_Label("obstacles", _OBSTACLE_RGBA[:3]))
    title = "mbplan replay: " + " | ".join(result_label(r) for r in results)
    return _Scene(title, layers, labels, dt, frame)


def _maximal_of(model: pin.Model) -> MaximalModel:
    from mbplan.formulations.maximal import _maximal as cached

    return cached(model)


def _goal_configuration(ocp: Any) -> np.ndarray | None:
    """The target of a terminal full joint-position goal (drawn as a translucent robot)."""
    if ocp is None:
        return None
    from mbplan.ocp.residuals import JointPosition

    for item in ocp.items:
        if isinstance(item.residual, JointPosition) and item.residual.joints is None:
            if ocp.N in item.knots:
                return np.asarray(item.residual.target)
    return None


def _robot_copy(
    i: int,
    result: PlanResult,
    ocp: Any,
    goal: np.ndarray | None,
    desc: Any,
    mm: MaximalModel,
) -> tuple[list[_Layer], _Label]:
    """Layers of result ``i`` (robot, goal, obstacles) at the origin, and its label."""
    model, visual = desc.model, desc.visual_model
    if result.R is not None and result.p is not None:
        placements = maximal_geometry_placements(mm, visual, result.R, result.p)
    else:
        placements = generalized_geometry_placements(model, visual, result.q)
    rgb = _COLORS[i % len(_COLORS)]
    layers = [_Layer(f"robot{i}", model, visual, placements, (*rgb, 1.0), _origins(placements))]
    if goal is not None:
        at_goal = generalized_geometry_placements(model, visual, goal[None])
        layers.append(_Layer(f"goal{i}", model, visual, at_goal, _GOAL_RGBA, _origins(at_goal)))
    if ocp is not None and len(ocp.scene):
        layers.append(_obstacle_layer(f"obstacles{i}", ocp.scene))
    text = f"{result_label(result)}: {result.status}, {result.iterations} iterations"
    return layers, _Label(text, rgb, caption=result_label(result))


def _origins(placements: np.ndarray) -> np.ndarray:
    return placements[..., :3, 3].reshape(-1, 3)


def _shifted(layer: _Layer, shift: np.ndarray) -> _Layer:
    return _Layer(
        layer.name,
        layer.model,
        layer.geometry,
        shift @ layer.placements,
        layer.rgba,
        layer.extent + shift[:3, 3],
    )


def _obstacle_layer(name: str, scene: Any) -> _Layer:
    """The scene's objects as geometry on the universe."""
    geometry = scene.geometry_model()
    corners = []
    for o in scene:
        half = o.half_extents()
        box = np.array(np.meshgrid(*[(-h, h) for h in half])).reshape(3, -1).T
        corners.append(box @ o.pose[:3, :3].T + o.pose[:3, 3])
    placements = np.array([[o.placement.homogeneous for o in geometry.geometryObjects]])
    return _Layer(name, pin.Model(), geometry, placements, _OBSTACLE_RGBA, np.concatenate(corners))


# --- drone ---------------------------------------------------------------------------------------


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
    return _show(_drone_scene(R, p, obstacles, goal, dt, frame), html, open_browser)


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


def _drone_scene(
    R: ArrayLike,
    p: ArrayLike,
    obstacles: Sequence[tuple[float, float, float]],
    goal: tuple[ArrayLike, ArrayLike] | None,
    dt: float,
    frame: int | None,
) -> _Scene:
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
    reach = np.linalg.norm(local[:, :3, 3], axis=1).max() + 0.1
    extent = np.concatenate(
        [poses[:, :3, 3] + d for d in reach * np.vstack([np.eye(3), -np.eye(3)])]
    )
    layers = [
        _Layer("drone", pin.Model(), body, placed[:-1], None, extent),
        _Layer("goal", pin.Model(), body, placed[-1:], _GOAL_RGBA, extent[-1:]),
    ]
    labels = [
        _Label("quadrotor (front rotor red)", (0.3, 0.3, 0.3)),
        _Label("goal", _GOAL_RGBA[:3]),
    ]
    if len(obstacles):
        z_lo, z_hi = extent[:, 2].min(), extent[:, 2].max() + _DRONE_HEADROOM
        scene = Scene()
        for k, o in enumerate(obstacles):
            x, y, r = _drone_cylinder(o)
            scene.add_cylinder(f"obstacle{k}", r, z_hi - z_lo, (x, y, 0.5 * (z_lo + z_hi)))
        layers.append(_obstacle_layer("obstacles", scene))
        labels.append(_Label("obstacles", _OBSTACLE_RGBA[:3]))

    def path_line(vis: meshcat.Visualizer) -> None:
        line = mg.Line(mg.PointsGeometry(p.T), mg.LineBasicMaterial(color=_PATH_COLOR))
        vis["mbplan/path"].set_object(line)

    travel = p_goal[:2] - p[0, :2]  # seen from its side, running left to right on screen
    azimuth = np.degrees(np.arctan2(-travel[0], travel[1])) if np.any(travel) else 0.0
    view = _direction(_DRONE_ELEVATION, azimuth)
    floor = float(extent[:, 2].min())
    title = "mbplan replay: quadrotor docking"
    return _Scene(title, layers, labels, dt, frame, path_line, floor, view)


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


# --- scene, static page, live server ------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Scene:
    """Everything to draw; calling it draws into a meshcat visualizer."""

    title: str
    layers: list[_Layer]
    labels: list[_Label]
    dt: float
    frame: int | None
    extra: Callable[[meshcat.Visualizer], None] | None = None  # draws more under "mbplan"
    floor: float = 0.0  # z of the ground grid
    view: np.ndarray = field(default_factory=lambda: _direction(*_ROBOT_VIEW))  # to the camera

    def __post_init__(self) -> None:
        knots = max(len(layer.placements) for layer in self.layers)
        if self.frame is not None and (
            not isinstance(self.frame, int | np.integer) or not -knots <= self.frame < knots
        ):
            raise InputError(
                f"frame: expected a knot index in [{-knots}, {knots}), got {self.frame!r}"
            )

    def __call__(self, vis: meshcat.Visualizer) -> None:
        knots = max(len(layer.placements) for layer in self.layers)
        shown = 0 if self.frame is None else int(self.frame) % knots
        points = np.concatenate(
            [layer.extent for layer in self.layers]
            + [label.position[None] for label in self.labels if label.position is not None]
        )
        lo, hi = points.min(axis=0) - _PAD, points.max(axis=0) + _PAD
        shift = np.eye(4)
        shift[:3, 3] = -0.5 * (lo + hi)
        vis["mbplan"].set_transform(shift)
        grid = shift.copy()
        grid[2, 3] += self.floor
        vis["/Grid"].set_transform(grid)
        vis["/Axes"].set_property("visible", False)
        animation = Animation(default_framerate=1.0 / self.dt)
        for layer in self.layers:
            _draw_layer(vis, layer, shown, animation, knots)
        if self.extra is not None:
            self.extra(vis)
        size = float(np.max(hi - lo))
        for k, label in enumerate(self.labels):
            if label.position is not None:
                _draw_label(vis[f"mbplan/labels/{k}"], label, 0.025 * size, self.view)
        offset = _camera_offset(points + shift[:3, 3], self.view)
        camera = vis["/Cameras/default/rotated/<object>"]
        camera.set_property("fov", _FOV)
        camera.set_property("position", [offset[0], offset[2], -offset[1]])  # a y-up frame
        if animation.clips:
            vis.set_animation(animation, play=self.frame is None, repetitions=1)


def _direction(elevation: float, azimuth: float) -> np.ndarray:
    """Unit vector at ``elevation`` above the xy plane and ``azimuth`` from x (degrees)."""
    e, a = np.radians(elevation), np.radians(azimuth)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _camera_offset(points: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Camera position relative to the origin, along the unit vector ``d``, at the closest
    distance with all ``points`` (relative to the origin) in view on an ``_ASPECT`` screen."""
    right = np.cross(-d, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -d)
    distance = points @ d + np.maximum(
        np.abs(points @ up) / _TAN_HALF_FOV, np.abs(points @ right) / (_TAN_HALF_FOV * _ASPECT)
    )
    return 1.1 * distance.max() * d


def _draw_layer(
    vis: meshcat.Visualizer, layer: _Layer, shown: int, animation: Animation, knots: int
) -> None:
    """Load the layer's geometry (Pinocchio's MeshCat loader), place it at knot ``shown`` and,
    if it moves, add one animation frame per knot (the last knot held)."""
    viz = MeshcatVisualizer(layer.model, None, layer.geometry)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(f"mbplan/{layer.name}", visual_color=layer.rgba)
    last = len(layer.placements) - 1
    for g, obj in enumerate(layer.geometry.geometryObjects):
        node = viz.getViewerNodeName(obj, pin.GeometryType.VISUAL)
        scale = np.append(np.asarray(obj.meshScale, dtype=float).ravel(), 1.0)
        vis[node].set_transform(layer.placements[min(shown, last), g] * scale)
        if last == 0:
            continue
        for k in range(knots):
            with animation.at_frame(vis, k) as frame:
                frame[node].set_transform(layer.placements[min(k, last), g])
                if np.any(scale != 1.0):
                    frame[node].set_property("scale", "vector3", scale[:3].tolist())


def _draw_label(node: meshcat.Visualizer, label: _Label, height: float, d: np.ndarray) -> None:
    """``label.caption`` (a PNG texture on a flat box), letters ``height`` tall, centred at
    ``label.position`` and facing the camera."""
    font = ImageFont.load_default(size=_LABEL_PX)
    left, top, right, bottom = font.getbbox(label.caption)
    # power-of-two sizes: WebGL would otherwise resample the texture (blurred text)
    size = (1 << (right - left + 8).bit_length(), 1 << (bottom - top + 8).bit_length())
    rgb = tuple(round(255 * c) for c in label.rgb)
    image = Image.new("RGBA", size, (*rgb, 0))  # the text colour, so that edges blend cleanly
    xy = ((size[0] - right - left) // 2, (size[1] - bottom - top) // 2)
    ImageDraw.Draw(image).text(xy, label.caption, font=font, fill=(*rgb, 255))
    png = io.BytesIO()
    image.save(png, format="PNG")
    height *= size[1] / (bottom - top)
    width = height * size[0] / size[1]
    texture = mg.ImageTexture(mg.PngImage(png.getvalue()))
    # a flat box: three.js maps its +x face with the image's left-to-right along -z, top along +y
    node.set_object(
        mg.Box([0.0, height, width]), mg.MeshBasicMaterial(map=texture, transparent=True, side=0)
    )
    up = np.array([0.0, 0.0, 1.0]) - d[2] * d
    up /= np.linalg.norm(up)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([d, up, -np.cross(up, d)])
    pose[:3, 3] = label.position
    node.set_transform(pose)


class _Recorder:
    """A meshcat window that records the commands (for a static page) instead of sending them."""

    def __init__(self) -> None:
        self.commands: list[bytes] = []

    def send(self, command: Any) -> None:
        self.commands.append(umsgpack.packb(command.lower()))


_PAGE = """<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#legend {{ position: absolute; bottom: 8px; left: 8px; padding: 6px 10px; font: 14px sans-serif;
  background: rgba(255, 255, 255, 0.8); border-radius: 4px; }}
#legend span {{ display: inline-block; width: 12px; height: 12px; margin-right: 6px; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="legend">{legend}</div>
<script>
{viewer_js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
for (const command of [{commands}]) {{
  viewer.handle_command_bytearray(Uint8Array.from(atob(command), (c) => c.charCodeAt(0)));
}}
</script>
</body>
</html>
"""


def _write_page(scene: _Scene, path: str | os.PathLike[str]) -> Path:
    """Draw ``scene`` into a recorder and write the static page atomically."""
    path = output_file(path, (".html", ".htm"), "static page")
    recorder = _Recorder()
    scene(meshcat.Visualizer(window=recorder))
    legend = "<br>".join(
        f'<span style="background: rgb({", ".join(str(round(255 * c)) for c in label.rgb)})">'
        f"</span>{html_lib.escape(label.text)}"
        for label in scene.labels
    )
    page = _PAGE.format(
        title=html_lib.escape(scene.title),
        legend=legend,
        viewer_js=_VIEWER_JS.read_text(encoding="utf-8"),
        commands=",".join(f'"{base64.b64encode(c).decode("ascii")}"' for c in recorder.commands),
    )
    return write_atomic(path, page.encode("utf-8"))


class MeshcatServer:
    """A MeshCat server in a subprocess listening on 127.0.0.1 only (HTTP, websocket, ZMQ).

    ``viewer`` (a ``meshcat.Visualizer``) sends to it; ``url`` is the page to open. Close it or
    use it as a context manager; it is killed when Python exits anyway.
    """

    def __init__(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-u", "-c", "from mbplan.viz.meshcat_replay import _serve; _serve()"],
            stdin=subprocess.PIPE,  # the server exits when this pipe closes (we exit or die)
            stdout=subprocess.PIPE,
            start_new_session=True,  # Ctrl-C at an interactive prompt does not stop it
        )
        atexit.register(self.close)
        try:
            zmq_url = self._read("zmq_url=")
            self.url = self._read("web_url=")
            with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints the URL
                self.viewer = meshcat.Visualizer(zmq_url=zmq_url)
        except BaseException:
            self.close()
            raise

    def _read(self, prefix: str) -> str:
        assert self._proc.stdout is not None
        line = self._proc.stdout.readline().decode("utf-8").strip()
        if not line.startswith(prefix):
            self._proc.kill()
            raise MbplanError(
                f"the MeshCat server did not start (exit code {self._proc.wait()}, output {line!r})"
            )
        return line[len(prefix) :]

    @property
    def pid(self) -> int:
        """Process id of the server."""
        return self._proc.pid

    def wait(self) -> int:
        """Block until the server exits; return its exit code."""
        return self._proc.wait()

    def close(self) -> None:
        """Stop the server (idempotent)."""
        atexit.unregister(self.close)
        if self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        for pipe in (self._proc.stdin, self._proc.stdout):
            if pipe is not None:
                pipe.close()

    def __enter__(self) -> MeshcatServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_LIVE: list[MeshcatServer] = []  # servers of replay()/drone_replay(), alive until exit


def _show(scene: _Scene, html: str | os.PathLike[str] | None, open_browser: bool) -> str:
    """Write ``scene``'s static page to ``html`` or serve it live; return the path or URL."""
    if html is not None:
        path = _write_page(scene, html)
        location, url = str(path), path.resolve().as_uri()
    else:
        server = MeshcatServer()
        _LIVE.append(server)
        scene(server.viewer)
        location = url = server.url
    if open_browser:
        webbrowser.open(url)
    return location


def _serve() -> None:
    """Entry point of the :class:`MeshcatServer` subprocess: meshcat's bridge with the HTTP and
    websocket server bound to 127.0.0.1 (its ZMQ socket already is). It exits when its stdin
    closes, i.e. when the parent exits, even if the parent is killed."""
    import tornado.web
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    def exit_on_eof() -> None:
        sys.stdin.buffer.read()
        os._exit(0)

    threading.Thread(target=exit_on_eof, daemon=True).start()

    class LocalBridge(ZMQWebSocketBridge):
        def make_app(self) -> tornado.web.Application:
            app = super().make_app()
            app.listen = functools.partial(app.listen, address=HOST)
            return app

    bridge = LocalBridge(host=HOST)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    bridge.run()
