"""The problem layer: robot, scene, residual library and the :class:`OCP` itself."""

from mbplan.ocp import residuals
from mbplan.ocp.problem import OCP, Item
from mbplan.ocp.robot import Robot, load_robot
from mbplan.ocp.scene import Scene, SceneObject

__all__ = ["OCP", "Item", "Robot", "Scene", "SceneObject", "load_robot", "residuals"]
