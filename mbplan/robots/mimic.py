"""URDF ``<mimic>`` joints as couplings ``q_f = m q_l + o`` of a robot (:class:`Mimic`), which
every OCP of the robot imposes (``mimic="couple"``) or plans as joints of their own
(``"independent"``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mbplan.errors import InputError, RobotModelError
from mbplan.robots import RobotDescription
from mbplan.robots.joints import joint_kind
from mbplan.robots.urdf_checks import mimic_tags

MIMIC_MODES = ("couple", "independent")


@dataclass(frozen=True)
class Mimic:
    """A coupling ``q[follower] = multiplier · q[leader] + offset`` (a URDF ``<mimic>``)."""

    follower: str
    leader: str
    multiplier: float = 1.0
    offset: float = 0.0


def mimic_tags_of(desc: RobotDescription) -> dict[str, tuple[str, float, float]]:
    """:func:`~mbplan.robots.urdf_checks.mimic_tags` of ``desc``'s URDF (none without one)."""
    path = desc.urdf_path
    if path is None or Path(path).suffix.lower() != ".urdf":
        return {}
    return mimic_tags(path)


def mimic_couplings(
    desc: RobotDescription, tags: dict[str, tuple[str, float, float]], locked: dict[str, float]
) -> tuple[Mimic, ...]:
    """The :class:`Mimic` couplings of the URDF ``tags`` among ``desc``'s (unlocked) joints."""
    model, out = desc.model, []
    for follower, (leader, m, o) in tags.items():
        if follower in locked:
            continue
        where = f"{desc.name}: joint {follower!r} mimics {leader!r}"
        if leader in locked:
            raise InputError(
                f"{where}, which is locked: lock {follower!r} too (at {m * locked[leader] + o:g}) "
                "or plan it as an independent joint (mimic='independent')"
            )
        if leader in tags:
            raise RobotModelError(f"{where}, which mimics {tags[leader][0]!r}: not supported")
        kinds = []
        for name in (leader, follower):
            if not model.existJointName(name):
                raise RobotModelError(f"{where}: {name!r} is not a 1-dof joint of the model")
            kinds.append(joint_kind(model, model.getJointId(name))[0])
        if kinds[0] != kinds[1]:
            raise RobotModelError(
                f"{where}: a {kinds[1]} joint cannot follow a {kinds[0]} one (plan it as an "
                "independent joint: mimic='independent')"
            )
        out.append(Mimic(follower, leader, m, o))
    return tuple(out)
