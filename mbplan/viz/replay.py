"""Replay robot plans in MeshCat, side by side: live, or as a self-contained HTML page.

Each result is one copy of the robot along y, drawn with its visual meshes and primitives —
a maximal result from its own SO(3)×R³ states, a generalized one by forward kinematics
(:mod:`mbplan.viz.placements`) — in its formulation's tint or its own materials, with the task's
obstacles and a translucent copy at ``q_target``, labelled in the scene and in the legend.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import meshcat
import numpy as np
import pinocchio as pin

from mbplan.errors import InputError, MbplanError, RobotModelError
from mbplan.multibody import MaximalModel, maximal_model
from mbplan.results import PlanResult, load_npz
from mbplan.robots import available_robots
from mbplan.robots.free_body import FreeBody
from mbplan.robots.robot import load_robot
from mbplan.viz.contacts import FORCE_RGBA, force_layer, ground_layer
from mbplan.viz.drone import free_body_scene
from mbplan.viz.page import write_page
from mbplan.viz.placements import generalized_geometry_placements, maximal_geometry_placements
from mbplan.viz.plots import result_label
from mbplan.viz.scene import PAD, Label, Layer, Scene, layer, obstacle_layer
from mbplan.viz.server import serve_until_interrupted, show
from mbplan.viz.shapes import Shape
from mbplan.viz.styles import (
    GOAL_RGBA,
    OBSTACLE_RGBA,
    check_colors,
    formulation_tints,
)


def replay(
    results: Sequence[PlanResult],
    task: Any = None,
    *,
    html: str | os.PathLike[str] | None = None,
    open_browser: bool = True,
    robot: str | None = None,
    frame: int | None = None,
    colors: str = "formulation",
) -> str:
    """Show ``results`` side by side (with ``task``'s obstacles and goal) in a live MeshCat
    viewer and return its URL, or with ``html`` write a static page there and return its path.

    ``task`` (an OCP) defaults to the first result's OCP; ``robot`` is only needed for results
    without one (else :func:`infer_robot`). ``frame`` None plays the animation once; a knot
    index shows that knot, with the animation loaded but paused. ``colors="formulation"`` tints
    each robot by its formulation (:mod:`mbplan.viz.styles`: maximal blue-ish, generalized
    orange-ish); ``"materials"`` keeps the meshes' own materials and colours. The live server
    lives until the Python process exits.
    """
    return show(_robot_scene(results, task, robot, frame, colors), html, open_browser)


def draw_results(
    viewer: meshcat.Visualizer,
    results: Sequence[PlanResult],
    task: Any = None,
    *,
    robot: str | None = None,
    frame: int | None = None,
    colors: str = "formulation",
) -> None:
    """Draw the :func:`replay` scene into any ``meshcat.Visualizer`` (e.g. of a
    :class:`MeshcatServer`)."""
    _robot_scene(results, task, robot, frame, colors)(viewer)


def static_html(
    results: Sequence[PlanResult],
    path: str | os.PathLike[str],
    task: Any = None,
    *,
    robot: str | None = None,
    frame: int | None = None,
    colors: str = "formulation",
) -> Path:
    """Write the :func:`replay` scene of ``results`` as one self-contained HTML page (viewer
    JavaScript and scene inlined, no network needed) to ``path`` atomically; return the path."""
    return write_page(_robot_scene(results, task, robot, frame, colors), path)


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
    colors: str = "formulation",
) -> int:
    """``mbplan replay``: show the ``.npz`` results at ``paths`` side by side.

    The robot is ``robot`` if the results fit it, else inferred from the maximal results' body
    names (:func:`infer_robot`) for files from before the OCP API; a result that carries its OCP
    is drawn with that OCP's robot and scene (old iiwa files: the default iiwa task's scene).
    With ``html`` the static page is written there; otherwise a live viewer is served on
    127.0.0.1, its URL printed (and opened unless ``no_browser``) and the command serves until
    interrupted (Ctrl-C). ``colors`` as in :func:`replay`. Returns the exit status.
    """
    if not paths:
        raise InputError("replay: no result files given")
    results = [read_result(p) for p in paths]
    if all(r.ocp is not None for r in results):
        task, name = results[0].ocp, None  # the scene and robot each plan was made with
    else:  # files from before the OCP API: guess the robot, the iiwa's default task
        from mbplan.tasks.paper import iiwa_obstacle

        name = infer_robot(results, robot)
        task = iiwa_obstacle() if name == "iiwa" else None
    build = _robot_scene(results, task, name, None, colors)
    if html is not None:
        print(f"wrote {write_page(build, html)}")
        return 0
    serve_until_interrupted(build, open_browser=not no_browser)
    return 0


def serve(
    results: Sequence[PlanResult],
    task: Any = None,
    *,
    robot: str | None = None,
    open_browser: bool = True,
    colors: str = "formulation",
) -> None:
    """The :func:`replay` scene served live on 127.0.0.1 until Ctrl-C (the URL printed once the
    scene is loaded): what ``mbplan plan --viz`` and ``mbplan replay`` do."""
    serve_until_interrupted(
        _robot_scene(results, task, robot, None, colors), open_browser=open_browser
    )


# process-wide cache, result-neutral: maximal-coordinate data of the robot loaded by name
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
    colors: str,
) -> Scene:
    """Check the inputs and return the scene builder (layers, labels, animation timing).

    The scene is that of ``task`` (an OCP), else of the first result's OCP."""
    check_colors(colors)
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
    if ocp is not None and isinstance(ocp.robot, FreeBody):
        return free_body_scene(results, ocp, frame)
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
    cache: dict[Any, Shape] = {}  # the copies share their meshes' triangles
    tints = formulation_tints(results)
    copies = [
        _robot_copy(i, r, tint, colors, ocp, goal, desc, mm, cache)
        for i, (r, tint) in enumerate(zip(results, tints, strict=True))
    ]
    extents = [np.concatenate([la.extent() for la in copy_layers]) for copy_layers, _ in copies]
    y_lo = min(e[:, 1].min() for e in extents)
    y_hi = max(e[:, 1].max() for e in extents)
    spacing = 1.15 * (y_hi - y_lo) + 2 * PAD
    layers, labels = [], []
    for i, ((copy_layers, label), points) in enumerate(zip(copies, extents, strict=True)):
        shift = np.eye(4)
        shift[1, 3] = (i - (len(copies) - 1) / 2) * spacing
        layers += [la.shifted(shift) for la in copy_layers]
        size = float(np.max(points.max(axis=0) - points.min(axis=0)))
        top = np.array([points[:, 0].mean(), shift[1, 3] + points[:, 1].mean(), 0.0])
        top[2] = points[:, 2].max() + 0.08 * size + PAD
        labels.append(Label(label.text, label.rgb, top, label.caption))
    if goal is not None:
        labels.append(Label("goal: q_target", GOAL_RGBA[:3]))
    if ocp is not None and len(ocp.scene):
        labels.append(Label("obstacles", OBSTACLE_RGBA[:3]))
    if ocp is not None and ocp.contacts:
        labels.append(Label("contact forces", FORCE_RGBA[:3]))
    title = "mbplan replay: " + " | ".join(result_label(r) for r in results)
    return Scene(title, layers, labels, dt, frame)


def _maximal_of(model: pin.Model) -> MaximalModel:
    from mbplan.formulations.maximal import _maximal as cached

    return cached(model, ())


def _goal_configuration(ocp: Any) -> np.ndarray | None:
    """The target of a terminal full joint-position goal (drawn as a translucent robot; none
    for a floating base, whose goal does not place the base)."""
    if ocp is None or getattr(ocp.robot, "floating", False):
        return None
    from mbplan.residuals import JointPosition

    for item in ocp.items:
        if isinstance(item.residual, JointPosition) and item.residual.joints is None:
            if ocp.N in item.knots:
                return np.asarray(item.residual.target)
    return None


def _robot_copy(
    i: int,
    result: PlanResult,
    tint: tuple[float, float, float],
    colors: str,
    ocp: Any,
    goal: np.ndarray | None,
    desc: Any,
    mm: MaximalModel,
    cache: dict[Any, Shape],
) -> tuple[list[Layer], Label]:
    """Layers of result ``i`` (robot, goal, obstacles) at the origin, and its label."""
    model, visual = desc.model, desc.visual_model
    if result.R is not None and result.p is not None:
        placements = maximal_geometry_placements(mm, visual, result.R, result.p)
    else:
        placements = generalized_geometry_placements(model, visual, result.q)
    rgba = (*tint, 1.0) if colors == "formulation" else None
    layers = [layer(f"robot{i}", visual, placements, rgba, cache)]
    if goal is not None:
        at_goal = generalized_geometry_placements(model, visual, goal[None])
        layers.append(layer(f"goal{i}", visual, at_goal, GOAL_RGBA, cache))
    if ocp is not None and len(ocp.scene):
        layers.append(obstacle_layer(f"obstacles{i}", ocp.scene, OBSTACLE_RGBA))
    if ocp is not None and ocp.contacts and result.contact_forces is not None:
        layers += [ground_layer(f"ground{i}", ocp), force_layer(f"forces{i}", ocp, result)]
    text = f"{result_label(result)}: {result.status}, {result.iterations} iterations"
    return layers, Label(text, tint, caption=result_label(result))
