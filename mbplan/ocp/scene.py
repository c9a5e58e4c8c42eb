"""The world around a robot: named solids at fixed poses, a ``pinocchio.GeometryModel`` underneath.

Sizes follow coal: box ``(lx, ly, lz)`` full side lengths; cylinder and capsule
``(radius, height)`` along the local z axis (capsule height without the caps); sphere
``(radius,)``; mesh: a file (STL, DAE, OBJ, ... as coal loads it) with a ``scale`` (3,). Every
shape is centred at its pose's origin.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.validation import as_array, as_real, as_rotation

_SIZES: dict[str, tuple[str, ...]] = {
    "box": ("length x", "length y", "length z"),
    "cylinder": ("radius", "height"),
    "sphere": ("radius",),
    "capsule": ("radius", "height"),
    "mesh": ("scale x", "scale y", "scale z"),
}


@dataclass(frozen=True, eq=False)
class SceneObject:
    """One solid: ``shape`` of ``size`` at ``pose`` (4x4, world); ``mesh`` is a file path."""

    name: str
    shape: str
    size: tuple[float, ...]
    pose: np.ndarray
    mesh: str | None = None

    def geometry(self) -> coal.CollisionGeometry:
        """The coal geometry in the object's own frame."""
        s = self.size
        if self.shape == "box":
            return coal.Box(*s)
        if self.shape == "cylinder":
            return coal.Cylinder(*s)
        if self.shape == "capsule":
            return coal.Capsule(*s)
        if self.shape == "sphere":
            return coal.Sphere(*s)
        return coal.MeshLoader().load(str(self.mesh), np.array(s))

    def half_extents(self) -> np.ndarray:
        """Half sizes of a bounding box in the object's frame."""
        s = self.size
        if self.shape == "box":
            return 0.5 * np.array(s)
        if self.shape == "sphere":
            return np.full(3, s[0])
        if self.shape == "mesh":
            mesh = self.geometry()
            mesh.computeLocalAABB()  # coal leaves it unset (±1.8e308) until asked
            aabb = mesh.aabb_local
            return np.maximum(np.abs(aabb.min_), np.abs(aabb.max_))
        cap = s[0] if self.shape == "capsule" else 0.0
        return np.array([s[0], s[0], 0.5 * s[1] + cap])

    def to_dict(self) -> dict[str, Any]:
        out = {"name": self.name, "shape": self.shape, "size": list(self.size)}
        out["pose"] = self.pose.tolist()
        if self.mesh is not None:
            out["mesh"] = self.mesh
        return out

    def __str__(self) -> str:
        x, y, z = self.pose[:3, 3]
        return f"{self.shape} {self.name!r} at ({x:g}, {y:g}, {z:g}) m"


class Scene:
    """Named obstacles; ``add_*`` return the scene, so calls chain."""

    def __init__(self, objects: Sequence[SceneObject] = ()) -> None:
        self._objects: list[SceneObject] = []
        for o in objects:
            self._add(o.name, o.shape, o.size, o.pose, o.mesh)

    def __iter__(self) -> Iterator[SceneObject]:
        return iter(self._objects)

    def __len__(self) -> int:
        return len(self._objects)

    def __getitem__(self, name: str) -> SceneObject:
        for o in self._objects:
            if o.name == name:
                return o
        raise InputError(f"the scene has no object {name!r}; objects: {self.names}")

    @property
    def names(self) -> list[str]:
        return [o.name for o in self._objects]

    def add_box(self, name: str, size: ArrayLike, xyz: ArrayLike = (0, 0, 0), rotation=None):
        return self._add(name, "box", size, _pose(name, xyz, rotation))

    def add_cylinder(
        self, name: str, radius: float, height: float, xyz: ArrayLike = (0, 0, 0), rotation=None
    ):
        return self._add(name, "cylinder", (radius, height), _pose(name, xyz, rotation))

    def add_capsule(
        self, name: str, radius: float, height: float, xyz: ArrayLike = (0, 0, 0), rotation=None
    ):
        return self._add(name, "capsule", (radius, height), _pose(name, xyz, rotation))

    def add_sphere(self, name: str, radius: float, xyz: ArrayLike = (0, 0, 0)):
        return self._add(name, "sphere", (radius,), _pose(name, xyz, None))

    def add_mesh(
        self,
        name: str,
        path: str | os.PathLike[str],
        scale: ArrayLike = (1, 1, 1),
        xyz: ArrayLike = (0, 0, 0),
        rotation=None,
    ):
        if not os.path.isfile(path):
            raise InputError(f"scene object {name!r}: mesh file not found: {path}")
        return self._add(name, "mesh", scale, _pose(name, xyz, rotation), os.fspath(path))

    def _add(self, name, shape, size, pose, mesh=None) -> Scene:
        if not isinstance(name, str) or not name:
            raise InputError(f"scene object name: expected a non-empty string, got {name!r}")
        if name in self.names:
            raise InputError(f"the scene already has an object {name!r}")
        if shape not in _SIZES:
            raise InputError(f"scene object {name!r}: shape {shape!r} not in {list(_SIZES)}")
        labels = _SIZES[shape]
        try:
            values = tuple(size)
        except TypeError:
            raise InputError(f"scene object {name!r}: size must be {labels}") from None
        if len(values) != len(labels):
            raise InputError(f"scene object {name!r}: size of a {shape} is {labels}, got {size}")
        values = tuple(
            as_real(v, f"scene object {name!r} {label}", positive=True)
            for v, label in zip(values, labels, strict=True)
        )
        pose = as_array(pose, (4, 4), f"scene object {name!r} pose")
        as_rotation(pose[:3, :3], f"scene object {name!r} rotation")
        self._objects.append(SceneObject(name, shape, values, pose, mesh))
        return self

    def geometry_model(self) -> pin.GeometryModel:
        """Every object as a ``GeometryObject`` on the universe (joint 0)."""
        gm = pin.GeometryModel()
        for o in self._objects:
            placement = pin.SE3(o.pose[:3, :3], o.pose[:3, 3])
            gm.addGeometryObject(pin.GeometryObject(o.name, 0, placement, o.geometry()))
        return gm

    def to_dict(self) -> list[dict[str, Any]]:
        return [o.to_dict() for o in self._objects]

    @classmethod
    def from_dict(cls, data: Sequence[Mapping[str, Any]]) -> Scene:
        scene = cls()
        for d in data:
            scene._add(d["name"], d["shape"], d["size"], np.array(d["pose"]), d.get("mesh"))
        return scene


def _pose(name: str, xyz: ArrayLike, rotation: ArrayLike | None) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = as_array(xyz, (3,), f"scene object {name!r} xyz")
    if rotation is not None:
        pose[:3, :3] = as_rotation(rotation, f"scene object {name!r} rotation")
    return pose
