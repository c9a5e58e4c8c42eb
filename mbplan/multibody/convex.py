"""Collision geometry for coal distances: triangle meshes as their convex hulls, cached on disk.

A mesh's convex hull contains the mesh, so a distance to the hull is a lower bound of the
distance to the mesh (conservative: a constraint ``d ≥ margin`` on the hull keeps the mesh at
least as far away), and it is exact for a convex mesh. Coal's GJK on two convex polytopes costs a
few µs and converges exactly in finitely many steps, where a distance between a BVH mesh and a
shape traverses the mesh's bounding-volume tree (tens of µs). ``geometry="mesh"`` keeps the
meshes as they are.

Hulls are computed once per mesh (qhull through coal) and stored, in coal's binary format, under
``<mbplan cache>/hulls`` keyed by the hash of the mesh's vertices (file content after scaling).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import coal
import numpy as np

from mbplan.engine.jit import cache_dir
from mbplan.errors import MbplanError, RobotModelError

GEOMETRIES = ("convex", "mesh")
_RANK_TOL = 1e-9  # vertex spread (relative to the largest) below which a mesh is flat


def collision_geometry(
    shape: coal.CollisionGeometry | None,
    kind: str,
    where: str,
    error: type[MbplanError] = RobotModelError,
) -> coal.CollisionGeometry:
    """``shape`` for distance queries: a BVH mesh as its convex hull (``kind="convex"``) or as it
    is (``"mesh"``); other shapes unchanged, with their local AABB computed. A missing, empty,
    flat or unsupported geometry raises ``error`` naming ``where`` (link and file)."""
    if shape is None:
        raise error(f"{where}: no collision geometry (coal could not load it)")
    if isinstance(shape, coal.BVHModelBase):
        vertices = np.asarray(shape.vertices(), dtype=float).reshape(-1, 3)
        problem = _solid_problem(vertices)
        if problem:
            raise error(f"{where}: the mesh is {problem}")
        if kind == "convex":
            shape = _cached_hull(vertices)
    elif not isinstance(shape, coal.ShapeBase):
        raise error(f"{where}: unsupported collision geometry {type(shape).__name__}")
    shape.computeLocalAABB()
    return shape


def is_polytope(shape: coal.CollisionGeometry) -> bool:
    """A convex polytope (a hull or a box): GJK ends on it exactly, without a cross-check."""
    return shape.getNodeType() in (coal.NODE_TYPE.GEOM_CONVEX, coal.NODE_TYPE.GEOM_BOX)


def _solid_problem(vertices: np.ndarray) -> str:
    """Why ``vertices`` bound no volume (empty if they do; qhull would crash on a flat set)."""
    if len(vertices) < 4 or not np.isfinite(vertices).all():
        return f"empty or not finite ({len(vertices)} vertices)"
    spread = np.linalg.svd(vertices - vertices.mean(axis=0), compute_uv=False)
    return "degenerate (flat: no volume)" if spread[-1] <= _RANK_TOL * spread[0] else ""


def _cached_hull(vertices: np.ndarray) -> coal.Convex:
    """The convex hull of ``vertices (n, 3)``, read from or written to the hull cache."""
    key = hashlib.sha256(np.ascontiguousarray(vertices).tobytes()).hexdigest()[:32]
    path = hull_cache_dir() / f"{key}.bin"
    hull = coal.Convex()
    if path.exists():
        hull.loadFromBinary(str(path))
        return hull
    hull = coal.Convex.convexHull(list(vertices), True, "Qt")
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    hull.saveToBinary(str(tmp))
    tmp.replace(path)  # atomic: concurrent processes write the same content
    return hull


def hull_cache_dir() -> Path:
    """``hulls`` beside the JIT cache (``MBPLAN_CACHE_DIR``'s parent)."""
    path = cache_dir().parent / "hulls"
    path.mkdir(parents=True, exist_ok=True)
    return path
