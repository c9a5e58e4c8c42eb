"""The problem layer: robot, scene and the :class:`OCP` itself (residuals: :mod:`mbplan.residuals`)."""

from mbplan.ocp.free_body import FreeBody
from mbplan.ocp.problem import OCP, Item
from mbplan.ocp.robot import Robot, load_robot
from mbplan.ocp.scene import Scene, SceneObject

__all__ = [
    "OCP",
    "FreeBody",
    "Item",
    "Robot",
    "Scene",
    "SceneObject",
    "load_robot",
]
