"""Robots: descriptions (the bundled KUKA iiwa 14 and mechanisms with closed loops,
example-robot-data arms, URDF and MJCF files; :mod:`.loader`), loop closures (:mod:`.loops`),
the planning model of a robot (:class:`Robot`, :func:`load_robot`; :mod:`.robot`), continuous joints as unbounded angles (:mod:`.continuous`) and the free rigid
body (:class:`FreeBody`; :mod:`.free_body`)."""

from mbplan.robots.free_body import FreeBody
from mbplan.robots.loader import (
    IIWA_URDF,
    MECHANISMS,
    RobotDescription,
    RobotSpec,
    available_arms,
    available_floating,
    available_robots,
    load,
    validate_urdf,
)
from mbplan.robots.robot import Robot, load_robot

__all__ = [
    "IIWA_URDF",
    "MECHANISMS",
    "FreeBody",
    "Robot",
    "RobotDescription",
    "RobotSpec",
    "available_arms",
    "available_floating",
    "available_robots",
    "load",
    "load_robot",
    "validate_urdf",
]
