"""The ground and the contact forces of a plan with contacts (:meth:`mbplan.OCP.add_contact`), as
replay layers: a thin slab under the contact points, and per contact an arrow (a thin cylinder)
from its frame along its world force, :data:`ARROW_LENGTH` long for the plan's largest force,
at every knot (the LGVI's knot forces; eq. (61)'s interval forces at the interval's first knot).
"""

from __future__ import annotations

from typing import Any

import coal
import numpy as np
import pinocchio as pin

from mbplan.ocp.contacts import frame_position
from mbplan.results import PlanResult
from mbplan.viz.scene import Layer, layer
from mbplan.viz.shapes import Rgba, shape_of

ARROW_LENGTH = 0.3  # m: the largest force's arrow
ARROW_RADIUS = 0.006  # m
GROUND_MARGIN = 0.25  # m around the contact points
GROUND_THICKNESS = 0.004  # m
GROUND_RGBA: Rgba = (0.55, 0.55, 0.58, 1.0)
FORCE_RGBA: Rgba = (0.9, 0.15, 0.1, 1.0)


def ground_layer(name: str, ocp: Any) -> Layer:
    """A static slab whose top is the lowest contact position's height, under every contact
    point with :data:`GROUND_MARGIN` around."""
    points = np.array([c.position for c in ocp.contacts])
    lo, hi = points.min(axis=0) - GROUND_MARGIN, points.max(axis=0) + GROUND_MARGIN
    size = [hi[0] - lo[0], hi[1] - lo[1], GROUND_THICKNESS]
    geometry = pin.GeometryModel()
    centre = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.0])
    centre[2] = points[:, 2].min() - 0.5 * GROUND_THICKNESS
    geometry.addGeometryObject(
        pin.GeometryObject("ground", 0, pin.SE3(np.eye(3), centre), coal.Box(*size))
    )
    return layer(name, geometry, np.array([[pin.SE3(np.eye(3), centre).homogeneous]]), GROUND_RGBA)


def _along(direction: np.ndarray) -> np.ndarray:
    """A rotation whose ``z`` axis is the unit ``direction`` (``z`` itself for a zero one)."""
    n = np.linalg.norm(direction)
    if n == 0.0:
        return np.eye(3)
    z = direction / n
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def force_layer(name: str, ocp: Any, result: PlanResult) -> Layer:
    """An arrow per contact at every knot (module docstring), scaled to its force."""
    model = ocp.robot.model
    forces = result.contact_forces_knots
    if forces is None:
        forces = np.concatenate([result.contact_forces, result.contact_forces[-1:]])
    forces = forces[..., :3]  # a sole's torque is not drawn
    largest = float(np.max(np.linalg.norm(forces, axis=-1), initial=0.0))
    scale = ARROW_LENGTH / largest if largest > 0.0 else 0.0
    geometry = pin.GeometryModel()
    for c in ocp.contacts:
        obj = pin.GeometryObject(f"force_{c.name}", 0, pin.SE3.Identity(), coal.Cylinder(1.0, 1.0))
        geometry.addGeometryObject(obj)
    knots, nc = len(result.q), len(ocp.contacts)
    placements = np.tile(np.eye(4), (knots, nc, 1, 1))
    scales = np.full((knots, nc, 3), ARROW_RADIUS)
    for i, c in enumerate(ocp.contacts):
        fid = model.getFrameId(c.frame)
        for k in range(knots):
            arrow = scale * forces[k, i]
            placements[k, i, :3, :3] = _along(arrow)
            placements[k, i, :3, 3] = frame_position(model, fid, result.q[k]) + 0.5 * arrow
            scales[k, i, 2] = max(float(np.linalg.norm(arrow)), 1e-6)
    objects = list(geometry.geometryObjects)
    return Layer(name, objects, [shape_of(o) for o in objects], placements, FORCE_RGBA, scales)
