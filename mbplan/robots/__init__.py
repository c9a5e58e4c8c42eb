"""Robot descriptions: the bundled KUKA iiwa 14, example-robot-data arms, URDF files."""

from mbplan.robots.loader import (
    IIWA_URDF,
    RobotDescription,
    RobotSpec,
    available_robots,
    load,
    validate_urdf,
)

__all__ = [
    "IIWA_URDF",
    "RobotDescription",
    "RobotSpec",
    "available_robots",
    "load",
    "validate_urdf",
]
