"""Checks of a URDF file with :mod:`xml.etree` before Pinocchio parses it: every link, joint,
origin, axis, inertia and mimic tag, so that a broken file fails with a
:class:`~mbplan.errors.RobotModelError` naming the offending link or joint rather than with a
parser crash (:func:`validate_urdf`); and the file's ``<mimic>`` tags (:func:`mimic_tags`)."""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from mbplan.errors import InputError, RobotModelError

# A placeholder <inertial> (KDL-era URDFs put one on a root link, e.g. ANYmal's: 1e-6 kg, every
# entry 1e-6 kg m²) weighs nothing next to the body it is merged into: it is not checked for the
# triangle inequality of a rigid body's principal moments.
NEGLIGIBLE_MASS = 1e-5  # kg
NEGLIGIBLE_INERTIA = 1e-5  # kg m²
_URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


def validate_urdf(path: str | os.PathLike[str]) -> None:
    """Check a URDF file's XML, link tree and inertias; raise naming the culprit.

    Rules: well-formed XML with a ``<robot>`` root; unique link and joint names; known joint
    types; a ``<limit>`` with effort and velocity on revolute and prismatic joints; a non-zero
    axis; every joint's parent and child links defined; one root link, every other link the
    child of exactly one joint, no loop; masses finite and non-negative; inertia matrices
    positive semi-definite with principal moments obeying the triangle inequality; finite
    ``<origin>`` s; ``<limit>`` s with lower <= upper and non-negative effort and velocity; a
    ``<mimic>`` naming a defined joint with finite numbers; the child link of a non-fixed joint
    has an ``<inertial>`` with positive mass.  (Positive definiteness of each moving body's inertia, after Pinocchio merges
    the links fixed to it, is checked by :func:`mbplan.multibody.maximal_model`.)
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"URDF file not found: {path}")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise RobotModelError(f"malformed XML in URDF {path}: {err}") from err
    if root.tag != "robot":
        raise RobotModelError(f"URDF {path}: root element is <{root.tag}>, expected <robot>")

    links: dict[str, ET.Element] = {}
    for link in root.findall("link"):
        name = _required_attr(link, "name", f"URDF {path}: a <link>")
        if name in links:
            raise RobotModelError(f"URDF {path}: link {name!r} is defined twice")
        links[name] = link

    parent_joint: dict[str, str] = {}  # child link -> joint
    mimics: dict[str, ET.Element] = {}  # joint -> its <mimic>
    children: dict[str, list[str]] = {}  # parent link -> child links
    joint_names: set[str] = set()
    for joint in root.findall("joint"):
        jname = _required_attr(joint, "name", f"URDF {path}: a <joint>")
        where = f"URDF {path}: joint {jname!r}"
        if jname in joint_names:
            raise RobotModelError(f"URDF {path}: joint {jname!r} is defined twice")
        joint_names.add(jname)
        jtype = joint.get("type")
        if jtype not in _URDF_JOINT_TYPES:
            raise RobotModelError(
                f"{where} has unknown type {jtype!r}; URDF joint types are "
                f"{', '.join(_URDF_JOINT_TYPES)}"
            )
        parent, child = (
            _required_attr(_required_child(joint, tag, where), "link", f"{where} <{tag}>")
            for tag in ("parent", "child")
        )
        for role, link_name in (("parent", parent), ("child", child)):
            if link_name not in links:
                raise RobotModelError(
                    f"{where} has {role} link {link_name!r}, which is not defined"
                )
        if child in parent_joint:
            raise RobotModelError(
                f"URDF {path}: link {child!r} is the child of both joint "
                f"{parent_joint[child]!r} and joint {jname!r}"
            )
        parent_joint[child] = jname
        children.setdefault(parent, []).append(child)
        _check_origin(joint, where)
        if jtype in ("revolute", "prismatic"):
            limit = _required_child(joint, "limit", where)
            for attr in ("effort", "velocity"):
                if _number(limit, attr, where) < 0.0:
                    raise RobotModelError(
                        f"{where}: <limit {attr}={limit.get(attr)!r}> is negative"
                    )
            lower, upper = (
                _number(limit, a, where) if limit.get(a) is not None else 0.0
                for a in ("lower", "upper")
            )
            if lower > upper:
                raise RobotModelError(
                    f"{where}: <limit lower={limit.get('lower')!r} upper={limit.get('upper')!r}> "
                    "is inverted (lower > upper)"
                )
        mimic = joint.find("mimic")
        if mimic is not None:
            mimics[jname] = mimic
        axis = joint.find("axis")
        if jtype != "fixed" and axis is not None:
            _check_axis(axis.get("xyz", "1 0 0"), where)
        if jtype != "fixed":
            _check_moving_link(links[child], f"{where}: its child link {child!r}")

    roots = [name for name in links if name not in parent_joint]
    if len(roots) != 1:
        detail = f"several root links: {', '.join(roots)}" if roots else "no root link"
        raise RobotModelError(
            f"URDF {path}: {detail} (the links must form one tree, every link but the root being "
            "the child of a joint)"
        )
    reached, stack = set(roots), list(roots)
    while stack:
        for child in children.get(stack.pop(), []):
            reached.add(child)
            stack.append(child)
    if len(reached) != len(links):
        loop = sorted(set(links) - reached)
        raise RobotModelError(f"URDF {path}: links {', '.join(loop)} form a kinematic loop")

    for name, link in links.items():
        where = f"URDF {path}: link {name!r}"
        inertial = link.find("inertial")
        if inertial is not None:
            _mass_and_inertia(inertial, where)
        for tag in ("inertial", "visual", "collision"):
            for element in link.findall(tag):
                _check_origin(element, f"{where} <{tag}>")
    for jname, mimic in mimics.items():
        where = f"URDF {path}: joint {jname!r} <mimic>"
        leader = _required_attr(mimic, "joint", where)
        if leader not in joint_names:
            raise RobotModelError(f"{where} follows joint {leader!r}, which is not defined")
        for attr in ("multiplier", "offset"):
            if mimic.get(attr) is not None:
                _number(mimic, attr, where)


def mimic_tags(path: str | os.PathLike[str]) -> dict[str, tuple[str, float, float]]:
    """``{follower: (leader, multiplier, offset)}`` of a URDF's ``<mimic>`` tags (defaults 1
    and 0), for a file :func:`validate_urdf` has checked. A tag on a fixed joint (some
    descriptions, e.g. Talos' grippers, keep one for a simulator plugin) couples no coordinate
    and is not listed."""
    out = {}
    for joint in ET.parse(path).getroot().findall("joint"):
        mimic = joint.find("mimic")
        if mimic is not None and joint.get("type") != "fixed":
            m, o = (float(mimic.get(a, d)) for a, d in (("multiplier", 1.0), ("offset", 0.0)))
            out[str(joint.get("name"))] = (str(mimic.get("joint")), m, o)
    return out


def _check_origin(element: ET.Element, where: str) -> None:
    origin = element.find("origin")
    if origin is None:
        return
    for attr in ("xyz", "rpy"):
        text = origin.get(attr)
        if text is None:
            continue
        try:
            values = [float(x) for x in text.split()]
        except ValueError:
            values = []
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise RobotModelError(
                f"{where} <origin {attr}={text!r}>: expected three finite numbers"
            )


def _check_axis(text: str, where: str) -> None:
    try:
        axis = np.array([float(x) for x in text.split()])
    except ValueError:
        axis = np.array([])
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.any(axis):
        raise RobotModelError(f"{where} has axis {text!r}: expected three numbers, not all zero")


def _check_moving_link(link: ET.Element, where: str) -> None:
    inertial = link.find("inertial")
    if inertial is None:
        raise RobotModelError(f"{where} has no <inertial>: a moving link needs a mass and inertia")
    mass, _ = _mass_and_inertia(inertial, where)
    if mass == 0.0:
        raise RobotModelError(f"{where} has zero mass: a moving link needs a positive mass")


def _mass_and_inertia(inertial: ET.Element, where: str) -> tuple[float, np.ndarray]:
    """Mass and 3x3 inertia of an ``<inertial>``, checked finite, m >= 0 and inertia PSD."""
    mass = _number(_required_child(inertial, "mass", where), "value", where)
    if mass < 0.0:
        raise RobotModelError(f"{where} has negative mass {mass}")
    el = _required_child(inertial, "inertia", where)
    xx, xy, xz, yy, yz, zz = (
        _number(el, k, where) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    )
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    moments = np.linalg.eigvalsh(inertia)
    tol = 1e-12 * max(1.0, abs(moments[-1]))
    if moments[0] < -tol:
        raise RobotModelError(
            f"{where} has a non-positive-definite inertia (principal moments {moments})"
        )
    placeholder = mass <= NEGLIGIBLE_MASS and moments[-1] <= NEGLIGIBLE_INERTIA
    if not placeholder and moments[0] + moments[1] < moments[2] - max(tol, 1e-9 * moments[2]):
        raise RobotModelError(
            f"{where}: <inertia> principal moments {moments} violate the triangle inequality "
            "(I1 + I2 >= I3 holds for every rigid body)"
        )
    return mass, inertia


def _required_child(el: ET.Element, tag: str, where: str) -> ET.Element:
    child = el.find(tag)
    if child is None:
        raise RobotModelError(f"{where} has no <{tag}>")
    return child


def _required_attr(el: ET.Element, attr: str, where: str) -> str:
    value = el.get(attr)
    if not value:
        raise RobotModelError(f"{where} has no {attr!r} attribute")
    return value


def _number(el: ET.Element, attr: str, where: str) -> float:
    text = _required_attr(el, attr, f"{where} <{el.tag}>")
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise RobotModelError(f"{where}: <{el.tag} {attr}={text!r}> is not a finite number")
    return value
