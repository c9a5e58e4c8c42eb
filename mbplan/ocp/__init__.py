"""The problem layer: the scene and the :class:`OCP` itself (robots: :mod:`mbplan.robots`,
residuals: :mod:`mbplan.residuals`)."""

from mbplan.ocp.problem import OCP, Item
from mbplan.ocp.scene import Scene, SceneObject

__all__ = ["OCP", "Item", "Scene", "SceneObject"]
