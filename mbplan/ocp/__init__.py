"""The problem layer: robot, scene, residual library and the :class:`OCP` itself."""

from mbplan.ocp import body_residuals, residuals
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
    "body_residuals",
    "load_robot",
    "residuals",
]
