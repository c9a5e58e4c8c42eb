"""What an MJCF file says beyond Pinocchio's model: which joints have an actuator and the names
of its loop closures (``<equality>``)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

from mbplan.errors import RobotModelError

ACTUATOR_TAGS = ("motor", "position", "velocity", "general", "intvelocity", "damper", "cylinder")
CLOSURE_TAGS = ("connect", "weld")
"""The ``<equality>`` elements that are loop closures, in the order Pinocchio lists them."""


def _root(path: str | os.PathLike[str]) -> ET.Element:
    try:
        return ET.parse(os.fspath(path)).getroot()
    except (ET.ParseError, OSError) as err:
        raise RobotModelError(f"MJCF {path}: {err}") from None


def mjcf_actuated(path: str | os.PathLike[str]) -> tuple[str, ...] | None:
    """The joints named by the ``<actuator>`` elements of an MJCF file (None without any
    ``<actuator>`` section: every joint is then actuated). An actuator on a tendon or a site
    cannot be represented: :class:`RobotModelError` naming it."""
    sections = _root(path).findall("actuator")
    if not sections:
        return None
    out: list[str] = []
    for section in sections:
        for element in section:
            if element.tag not in ACTUATOR_TAGS:
                continue
            joint = element.get("joint")
            if joint is None:
                what = element.get("name") or element.tag
                raise RobotModelError(
                    f"MJCF {path}: actuator {what!r} drives no joint (tendon, site or body "
                    "actuators are not supported)"
                )
            if joint not in out:
                out.append(joint)
    return tuple(out)


def mjcf_equality_names(path: str | os.PathLike[str]) -> list[str | None]:
    """The names (None: unnamed) of an MJCF file's ``<connect>`` elements, then of its
    ``<weld>`` ones: the order of Pinocchio's constraint models. Another equality (``joint``,
    ``tendon``, ``distance``, ``flex``) is no loop closure mbplan represents:
    :class:`RobotModelError` naming it."""
    found: dict[str, list[str | None]] = {tag: [] for tag in CLOSURE_TAGS}
    for section in _root(path).findall("equality"):
        for element in section:
            if element.tag in CLOSURE_TAGS:
                found[element.tag].append(element.get("name"))
            elif isinstance(element.tag, str):
                what = element.get("name") or element.tag
                raise RobotModelError(
                    f"MJCF {path}: equality {what!r} (<{element.tag}>) is not supported; loop "
                    f"closures are {' and '.join(f'<{t}>' for t in CLOSURE_TAGS)}"
                )
    return [name for tag in CLOSURE_TAGS for name in found[tag]]
