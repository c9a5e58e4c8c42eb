"""What an MJCF file says beyond Pinocchio's model: which joints have an actuator."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

from mbplan.errors import RobotModelError

ACTUATOR_TAGS = ("motor", "position", "velocity", "general", "intvelocity", "damper", "cylinder")


def mjcf_actuated(path: str | os.PathLike[str]) -> tuple[str, ...] | None:
    """The joints named by the ``<actuator>`` elements of an MJCF file (None without any
    ``<actuator>`` section: every joint is then actuated). An actuator on a tendon or a site
    cannot be represented: :class:`RobotModelError` naming it."""
    try:
        root = ET.parse(os.fspath(path)).getroot()
    except (ET.ParseError, OSError) as err:
        raise RobotModelError(f"MJCF {path}: {err}") from None
    sections = root.findall("actuator")
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
