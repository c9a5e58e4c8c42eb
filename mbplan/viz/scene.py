"""A replay scene: geometry layers placed per knot, labels, the animation and the camera.

One animation frame per knot: play it and scrub its time in the viewer's "Animations" panel
("Open Controls"). meshcat 0.3.2 has no text primitive: labels are PNG textures on flat boxes,
turned towards the camera. The scene and the ground grid are shifted to put the scene's centre
at the origin, which meshcat's orbit controls look at (:mod:`mbplan.viz.camera`).
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation
from PIL import Image, ImageDraw, ImageFont

from mbplan.errors import InputError
from mbplan.ocp.scene import Scene as ObstacleScene
from mbplan.viz.camera import FOV, bounding_box, camera_offset, direction, place_camera
from mbplan.viz.shapes import Rgba, Shape, draw_geometry, shape_of

ROBOT_VIEW = (25.0, 10.0)  # degrees: elevation and azimuth of the camera seen from the scene
PAD = 0.05  # m around the geometry's bounding box when framing and spacing the scene
_LABEL_PX = 48  # font size of in-scene labels (texture pixels)
_LABEL_SCREEN = 0.035  # height of their letters, as a share of the screen's
_BACKGROUND = ((0.93, 0.94, 0.96), (0.62, 0.66, 0.72))  # top and bottom: robots of any tint show


@dataclass(frozen=True, eq=False)
class Layer:
    """Geometry under node ``mbplan/<name>/visuals`` at world placements ``(K, ngeom, 4, 4)``
    per knot (``K = 1``: static), each scaled along its own axes by ``scales (K, ngeom, 3)``
    (None: not scaled; an arrow's length); ``rgba`` None keeps each geometry's own material."""

    name: str
    objects: list[pin.GeometryObject]
    shapes: list[Shape]
    placements: np.ndarray
    rgba: Rgba | None
    scales: np.ndarray | None = None

    def extent(self) -> np.ndarray:
        """World corners ``(n, 3)`` of every geometry's bounding box at every knot."""
        corners = np.array([s.corners() for s in self.shapes])[None]  # (1, ngeom, 8, 3)
        if self.scales is not None:
            corners = corners * self.scales[:, :, None, :]
        R, p = self.placements[..., :3, :3], self.placements[..., :3, 3]
        return (np.einsum("kgij,kgcj->kgci", R, corners) + p[:, :, None]).reshape(-1, 3)

    def shifted(self, shift: np.ndarray) -> Layer:
        """The layer moved by the world transform ``shift`` (4x4)."""
        return Layer(
            self.name, self.objects, self.shapes, shift @ self.placements, self.rgba, self.scales
        )


def layer(
    name: str,
    geometry: pin.GeometryModel,
    placements: np.ndarray,
    rgba: Rgba | None,
    cache: dict[Any, Shape] | None = None,
) -> Layer:
    """The :class:`Layer` of ``geometry``'s objects (shapes shared through ``cache``)."""
    objects = list(geometry.geometryObjects)
    shapes = [shape_of(obj, cache) for obj in objects]
    return Layer(name, objects, shapes, np.asarray(placements, dtype=float), rgba)


@dataclass(frozen=True, eq=False)
class Label:
    """A legend entry; with ``position`` also ``caption`` as text in the scene there."""

    text: str
    rgb: tuple[float, float, float]
    position: np.ndarray | None = None
    caption: str = ""


@dataclass(frozen=True, eq=False)
class Scene:
    """Everything to draw; calling it draws into a meshcat visualizer."""

    title: str
    layers: list[Layer]
    labels: list[Label]
    dt: float
    frame: int | None
    extra: Callable[[meshcat.Visualizer], None] | None = None  # draws more under "mbplan"
    floor: float = 0.0  # z of the ground grid
    view: np.ndarray = field(default_factory=lambda: direction(*ROBOT_VIEW))  # to the camera

    def __post_init__(self) -> None:
        knots = self.knots
        if self.frame is not None and (
            not isinstance(self.frame, int | np.integer) or not -knots <= self.frame < knots
        ):
            raise InputError(
                f"frame: expected a knot index in [{-knots}, {knots}), got {self.frame!r}"
            )

    @property
    def knots(self) -> int:
        return max(len(la.placements) for la in self.layers)

    def __call__(self, vis: meshcat.Visualizer) -> None:
        shown = 0 if self.frame is None else int(self.frame) % self.knots
        points = np.concatenate([la.extent() for la in self.layers])
        lo, hi = bounding_box(points)
        # the labels' letters: a fixed share of the screen's height at the geometry's framing
        distance = np.linalg.norm(camera_offset(points - 0.5 * (lo + hi), self.view))
        height = _LABEL_SCREEN * 2 * distance * np.tan(np.radians(FOV) / 2)
        quads = [
            (k, _LabelQuad(label, height, self.view))
            for k, label in enumerate(self.labels)
            if label.position is not None
        ]
        points = np.concatenate([points, *(q.corners() for _, q in quads)])
        lo, hi = bounding_box(points, PAD)
        shift = np.eye(4)
        shift[:3, 3] = -0.5 * (lo + hi)
        vis["mbplan"].set_transform(shift)
        grid = shift.copy()
        grid[2, 3] += self.floor
        vis["/Grid"].set_transform(grid)
        vis["/Axes"].set_property("visible", False)
        vis["/Background"].set_property("top_color", list(_BACKGROUND[0]))
        vis["/Background"].set_property("bottom_color", list(_BACKGROUND[1]))
        animation = Animation(default_framerate=1.0 / self.dt)
        for la in self.layers:
            _draw_layer(vis, la, shown, animation, self.knots)
        if self.extra is not None:
            self.extra(vis)
        for k, quad in quads:
            quad.draw(vis[f"mbplan/labels/{k}"])
        place_camera(vis, camera_offset(points + shift[:3, 3], self.view))
        if animation.clips:
            vis.set_animation(animation, play=self.frame is None, repetitions=1)


def node_name(layer_name: str, obj: pin.GeometryObject) -> str:
    """The meshcat path of ``obj`` in layer ``layer_name``."""
    return f"mbplan/{layer_name}/visuals/{obj.name}"


def _draw_layer(
    vis: meshcat.Visualizer, la: Layer, shown: int, animation: Animation, knots: int
) -> None:
    """Load the layer's geometry, place it at knot ``shown`` and, if it moves, add one
    animation frame per knot (the last knot held)."""
    last = len(la.placements) - 1
    for g, (obj, shape) in enumerate(zip(la.objects, la.shapes, strict=True)):
        node = node_name(la.name, obj)
        draw_geometry(vis[node], obj, shape, la.rgba)
        vis[node].set_transform(la.placements[min(shown, last), g])
        if la.scales is not None:
            vis[node].set_property("scale", la.scales[min(shown, last), g].tolist())
        if last == 0:
            continue
        for k in range(knots):
            with animation.at_frame(vis, k) as frame:
                frame[node].set_transform(la.placements[min(k, last), g])
                if la.scales is not None:
                    frame[node].set_property(
                        "scale", "vector3", la.scales[min(k, last), g].tolist()
                    )


class _LabelQuad:
    """``label.caption`` as a PNG texture on a flat box, letters ``height`` tall, centred at
    ``label.position`` and facing the camera along ``d``."""

    def __init__(self, label: Label, height: float, d: np.ndarray) -> None:
        font = ImageFont.load_default(size=_LABEL_PX)
        left, top, right, bottom = font.getbbox(label.caption)
        # power-of-two sizes: WebGL would otherwise resample the texture (blurred text)
        size = (1 << (right - left + 8).bit_length(), 1 << (bottom - top + 8).bit_length())
        rgb = tuple(round(255 * c) for c in label.rgb)
        image = Image.new("RGBA", size, (*rgb, 0))  # the text colour: edges blend cleanly
        xy = ((size[0] - right - left) // 2, (size[1] - bottom - top) // 2)
        ImageDraw.Draw(image).text(xy, label.caption, font=font, fill=(*rgb, 255))
        png = io.BytesIO()
        image.save(png, format="PNG")
        self.png = png.getvalue()
        self.height = height * size[1] / (bottom - top)
        self.width = self.height * size[0] / size[1]
        up = np.array([0.0, 0.0, 1.0]) - d[2] * d
        up /= np.linalg.norm(up)
        self.pose = np.eye(4)
        self.pose[:3, :3] = np.column_stack([d, up, -np.cross(up, d)])
        self.pose[:3, 3] = label.position

    def corners(self) -> np.ndarray:
        """The quad's four corners ``(4, 3)`` in the world."""
        half = np.array([[0.0, y, z] for y in (-1, 1) for z in (-1, 1)]) / 2
        local = half * [0.0, self.height, self.width]
        return local @ self.pose[:3, :3].T + self.pose[:3, 3]

    def draw(self, node: meshcat.Visualizer) -> None:
        texture = mg.ImageTexture(mg.PngImage(self.png))
        # a flat box: three.js maps its +x face with the image's left-to-right along -z, top +y
        node.set_object(
            mg.Box([0.0, self.height, self.width]),
            mg.MeshBasicMaterial(map=texture, transparent=True, side=0),
        )
        node.set_transform(self.pose)


def obstacle_layer(name: str, obstacles: ObstacleScene, rgba: Rgba) -> Layer:
    """The objects of an :class:`mbplan.Scene` (primitives and ``add_mesh`` meshes), static."""
    geometry = obstacles.geometry_model()
    placements = np.array([[o.placement.homogeneous for o in geometry.geometryObjects]])
    return layer(name, geometry, placements, rgba)
