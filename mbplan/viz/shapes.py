"""MeshCat objects for Pinocchio geometry objects: primitives, triangle meshes, mesh files.

A mesh (STL, OBJ, DAE, or a scene's ``add_mesh`` obstacle) is sent as the indexed triangles coal
loaded — already scaled by ``meshScale`` — with area-weighted vertex normals, quantized into
compact binary arrays (:class:`TriangleMesh`) and drawn in one colour. To keep its own materials, a Collada file is embedded
whole instead (three.js's ColladaLoader reads it in the page, its textures as data URIs). Either
way nothing refers to a file, so a static page stays self-contained.
"""

from __future__ import annotations

import base64
import mimetypes
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack

from mbplan.errors import RobotModelError

Rgba = tuple[float, float, float, float]
_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # three.js: axis y
_COLLADA_NS = "{http://www.collada.org/2005/11/COLLADASchema}"


@dataclass(frozen=True, eq=False)
class Shape:
    """A geometry in its object's frame: what to draw (``geometry`` under ``matrix``, 4x4) and
    its bounding box ``lo``, ``hi`` (3,)."""

    geometry: mg.Geometry
    matrix: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def corners(self) -> np.ndarray:
        """The eight corners ``(8, 3)`` of the bounding box."""
        return np.array(np.meshgrid(*zip(self.lo, self.hi, strict=True))).reshape(3, -1).T


class TriangleMesh(mg.Geometry):
    """Indexed triangles with vertex normals (three.js ``BufferGeometry``), quantized: positions
    as normalized uint16 in their bounding box, which :attr:`matrix` (4x4) maps back to the
    mesh's frame, normals as normalized int8 in that box's frame, indices as uint16 when they
    fit — a third of float32 data, resolution 1/65535 of the box."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        super().__init__()
        vertices = np.asarray(vertices, dtype=float)
        self.faces = np.asarray(faces, dtype=np.uint32)
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        span = np.maximum(hi - lo, 1e-9)
        self.matrix = np.eye(4)
        self.matrix[:3, :3], self.matrix[:3, 3] = np.diag(span), lo
        self.positions = np.rint((vertices - lo) / span * 65535).astype(np.uint16)
        normals = vertex_normals(vertices, self.faces) * span  # normals transform by diag(span)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        self.normals = np.rint(127 * normals).astype(np.int8)

    def lower(self, object_data: Any) -> dict[str, Any]:
        index = self.faces.astype(np.uint16) if len(self.positions) <= 65536 else self.faces
        return {
            "uuid": self.uuid,
            "type": "BufferGeometry",
            "data": {
                "attributes": {
                    "position": _packed(self.positions, normalized=True),
                    "normal": _packed(self.normals, normalized=True),
                },
                "index": _packed(index.reshape(-1, 1)),
            },
        }


_EXT_TYPES = {  # msgpack ext codes of meshcat's viewer (msgpack-lite's typed arrays)
    np.dtype(np.int8): ("Int8Array", 0x11),
    np.dtype(np.uint16): ("Uint16Array", 0x14),
    np.dtype(np.uint32): ("Uint32Array", 0x16),
}


def _packed(array: np.ndarray, normalized: bool = False) -> dict[str, Any]:
    """A three.js buffer attribute of ``array (n, item)``."""
    name, code = _EXT_TYPES[array.dtype]
    data = np.ascontiguousarray(array).tobytes()
    return {
        "itemSize": array.shape[1],
        "type": name,
        "array": umsgpack.Ext(code, data),
        "normalized": normalized,
    }


class ColladaFile(mg.Object):
    """A Collada file embedded whole and drawn with its own materials, scaled by ``scale``."""

    def __init__(self, path: str | Path, scale: np.ndarray) -> None:
        mg.SceneElement.__init__(self)
        path = Path(path)
        self.data = path.read_text(encoding="utf-8", errors="replace")
        self.resources = _texture_uris(path)
        self.matrix = np.diag([*np.asarray(scale, dtype=float).ravel(), 1.0])

    def lower(self) -> dict[str, Any]:
        return {
            "metadata": {"version": 4.5, "type": "Object"},
            "geometries": [],
            "materials": [],
            "object": {
                "uuid": self.uuid,
                "type": "_meshfile_object",
                "format": "dae",
                "data": self.data,
                "resources": self.resources,
                "matrix": self.matrix.T.ravel().tolist(),
            },
        }


class _Mesh(mg.Mesh):
    """A mesh under an intrinsic transform ``matrix`` (4x4)."""

    def __init__(self, shape: Shape, material: mg.Material) -> None:
        super().__init__(shape.geometry, material)
        self.matrix = shape.matrix

    def lower(self) -> dict[str, Any]:
        data = super().lower()
        data["object"]["matrix"] = self.matrix.T.ravel().tolist()  # three.js: column-major
        # the viewer's three.js bounds a normalized (quantized) attribute by its raw integers,
        # which culls meshes wrongly: draw them always
        data["object"]["frustumCulled"] = False
        return data


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals ``(n, 3)`` (float32; +z where no face touches)."""
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    face_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    normals = np.stack(
        [
            sum(np.bincount(f[:, c], weights=face_n[:, axis], minlength=len(v)) for c in range(3))
            for axis in range(3)
        ],
        axis=1,
    )
    length = np.linalg.norm(normals, axis=1)
    normals[length == 0] = (0.0, 0.0, 1.0)
    length[length == 0] = 1.0
    return (normals / length[:, None]).astype(np.float32)


def draw_geometry(
    node: meshcat.Visualizer, obj: pin.GeometryObject, shape: Shape, rgba: Rgba | None
) -> None:
    """Set ``node``'s object to ``obj``'s geometry (its :class:`Shape`) in the object's frame:
    in colour ``rgba``, or with ``rgba`` None in its own materials (a Collada file's unless the
    URDF overrides them, else ``meshColor``)."""
    if rgba is None and _is_collada(obj) and not obj.overrideMaterial:
        node.set_object(ColladaFile(obj.meshPath, obj.meshScale))
        return
    color = tuple(float(c) for c in (obj.meshColor if rgba is None else rgba))
    node.set_object(_Mesh(shape, _material(color)))


def shape_of(obj: pin.GeometryObject, cache: dict[Any, Shape] | None = None) -> Shape:
    """``obj``'s :class:`Shape`; ``cache`` shares a mesh file's triangles between the copies of
    a robot (keyed by path and scale). :class:`RobotModelError` for what MeshCat cannot draw."""
    key = (obj.meshPath, tuple(np.asarray(obj.meshScale, dtype=float).ravel()))
    if cache is None or not obj.meshPath or not isinstance(obj.geometry, coal.BVHModelBase):
        return _shape(obj)
    if key not in cache:
        cache[key] = _shape(obj)
    return cache[key]


def _shape(obj: pin.GeometryObject) -> Shape:
    g = obj.geometry
    if isinstance(g, coal.BVHModelBase | coal.ConvexBase):
        if isinstance(g, coal.BVHModelBase):
            vertices, count, face = g.vertices(), g.num_tris, g.tri_indices
        else:
            count = getattr(g, "num_polygons", 0)
            vertices, face = g.points(), getattr(g, "polygons", None)
        if count:
            faces = np.fromiter(
                (i for k in range(count) for i in _corners(face(k))), np.uint32, 3 * count
            ).reshape(-1, 3)
        else:  # a convex without its polygons: its hull
            faces = _hull(vertices)
        if len(vertices) == 0 or len(faces) == 0:
            raise RobotModelError(f"geometry {obj.name!r}: its mesh has no triangles")
        mesh = TriangleMesh(vertices, faces)
        return Shape(mesh, mesh.matrix, vertices.min(0), vertices.max(0))
    # primitives: meshScale scales them (coal has already scaled a mesh's vertices)
    scale = np.asarray(obj.meshScale, dtype=float).ravel()
    rotation = np.eye(3)
    if isinstance(g, coal.Box):
        geometry, half = mg.Box((2 * g.halfSide).tolist()), np.asarray(g.halfSide)
    elif isinstance(g, coal.Sphere):
        geometry, half = mg.Sphere(g.radius), np.full(3, g.radius)
    elif isinstance(g, coal.Ellipsoid):
        geometry, half = mg.Ellipsoid(np.asarray(g.radii)), np.asarray(g.radii)
    elif isinstance(g, coal.Cylinder | coal.Cone):
        top = g.radius if isinstance(g, coal.Cylinder) else 0.0
        geometry = mg.Cylinder(2 * g.halfLength, radiusTop=top, radiusBottom=g.radius)
        half, rotation = np.array([g.radius, g.radius, g.halfLength]), _Y_TO_Z
    elif isinstance(g, coal.Capsule):
        geometry = TriangleMesh(*capsule_mesh(g.radius, g.halfLength))
        half = np.array([g.radius, g.radius, g.halfLength + g.radius])
    else:
        raise RobotModelError(f"geometry {obj.name!r}: cannot draw a {type(g).__name__} in MeshCat")
    matrix = np.eye(4)
    matrix[:3, :3] = np.diag(scale) @ rotation
    if isinstance(geometry, TriangleMesh):
        matrix = matrix @ geometry.matrix
    half = half * np.abs(scale)
    return Shape(geometry, matrix, -half, half)


def capsule_mesh(radius: float, half_length: float, n: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a capsule along z: two hemispheres of ``n // 2`` rings joined
    by a cylinder, ``n`` points per ring."""
    rings = n // 2
    theta = np.concatenate([np.linspace(0, np.pi / 2, rings), np.linspace(np.pi / 2, np.pi, rings)])
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    z = radius * np.cos(theta) + np.where(np.arange(2 * rings) < rings, half_length, -half_length)
    rho = radius * np.sin(theta)
    vertices = np.stack(
        [np.outer(rho, np.cos(phi)), np.outer(rho, np.sin(phi)), np.repeat(z[:, None], n, 1)],
        axis=-1,
    ).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(2 * rings - 1), np.arange(n), indexing="ij")
    a, b = i * n + j, i * n + (j + 1) % n
    c, d = a + n, b + n
    faces = np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)]).reshape(-1, 3)
    return vertices, faces


def _hull(points: np.ndarray) -> np.ndarray:
    """Outward-wound triangles of the convex hull of ``points``."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return np.zeros((0, 3), dtype=np.uint32)
    faces = hull.simplices.copy()
    v = points[faces]
    outward = np.einsum(
        "fi,fi->f", np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), hull.equations[:, :3]
    )
    faces[outward < 0] = faces[outward < 0][:, ::-1]
    return faces.astype(np.uint32)


def _corners(triangle: Any) -> tuple[int, int, int]:
    return int(triangle[0]), int(triangle[1]), int(triangle[2])


def _material(rgba: Rgba) -> mg.MeshPhongMaterial:
    r, g, b = (int(v) for v in np.rint(255 * np.clip(np.asarray(rgba[:3], dtype=float), 0, 1)))
    color = r << 16 | g << 8 | b
    opacity = float(rgba[3])
    return mg.MeshPhongMaterial(color=color, opacity=opacity, transparent=opacity < 1.0)


def _is_collada(obj: pin.GeometryObject) -> bool:
    return bool(obj.meshPath) and Path(obj.meshPath).suffix.lower() == ".dae"


def _texture_uris(path: Path) -> dict[str, str]:
    """The images a Collada file refers to that exist beside it, as data URIs by reference."""
    try:
        images = ET.parse(path).getroot().find(f"{_COLLADA_NS}library_images")
    except ET.ParseError:
        return {}
    out = {}
    for element in [] if images is None else images.iter(f"{_COLLADA_NS}init_from"):
        ref = (element.text or "").strip()
        file = (path.parent / ref.removeprefix("file://")).resolve()
        if ref and file.is_file():
            mime = mimetypes.guess_type(file.name)[0] or "image/png"
            out[ref] = f"data:{mime};base64,{base64.b64encode(file.read_bytes()).decode('ascii')}"
    return out
