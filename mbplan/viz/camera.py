"""Camera framing: where to put meshcat's camera so that a set of points fills the view.

meshcat 0.3.2 has no ``set_cam_pos``, and its orbit controls always look at the world origin: the
scene is shifted to put the centre of its bounding box there, and the camera is placed by the
``position`` and ``fov`` properties of ``/Cameras/default/rotated/<object>`` (a y-up frame).
"""

from __future__ import annotations

import meshcat
import numpy as np
from numpy.typing import ArrayLike

from mbplan.errors import InputError

FOV = 40.0  # degrees, vertical (meshcat's default 75° distorts side-by-side robots)
ASPECT = 16 / 9  # screen aspect the camera distance is chosen for
MARGIN = 1.1  # the camera backs off this factor beyond the tightest fit


def direction(elevation: float, azimuth: float) -> np.ndarray:
    """Unit vector at ``elevation`` above the xy plane and ``azimuth`` from x (degrees)."""
    e, a = np.radians(elevation), np.radians(azimuth)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def bounding_box(points: ArrayLike, pad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Corners ``lo``, ``hi`` of the axis-aligned box around ``points (n, 3)``, grown by ``pad``."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(points) == 0 or not np.all(np.isfinite(points)):
        raise InputError("camera: no finite points to frame")
    return points.min(axis=0) - pad, points.max(axis=0) + pad


def camera_offset(
    points: ArrayLike, view: ArrayLike, fov: float = FOV, aspect: float = ASPECT
) -> np.ndarray:
    """Camera position, looking at the origin from along the unit vector ``view``, at the
    closest distance (times :data:`MARGIN`) that has every point of ``points (n, 3)`` (relative
    to the origin) inside a ``fov``-degree (vertical) view on an ``aspect`` screen."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    d = np.asarray(view, dtype=float)
    d = d / np.linalg.norm(d)
    right = np.cross(-d, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:  # looking straight down or up: screen up is +y
        right = np.cross([0.0, 1.0, 0.0], -d)
    right /= np.linalg.norm(right)
    up = np.cross(right, -d)
    tan_half = np.tan(np.radians(fov) / 2)
    distance = points @ d + np.maximum(
        np.abs(points @ up) / tan_half, np.abs(points @ right) / (tan_half * aspect)
    )
    return MARGIN * max(float(distance.max()), 1e-3) * d


def place_camera(vis: meshcat.Visualizer, offset: np.ndarray, fov: float = FOV) -> None:
    """Put meshcat's default camera at ``offset`` (z-up world, relative to the origin)."""
    camera = vis["/Cameras/default/rotated/<object>"]
    camera.set_property("fov", fov)
    camera.set_property("position", [offset[0], offset[2], -offset[1]])  # a y-up frame
