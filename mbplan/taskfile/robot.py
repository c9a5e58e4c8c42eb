"""The ``[robot]`` table of a task file: which robot, its package folders, locked joints,
whether URDF ``<mimic>`` joints follow their leaders (``mimic = "couple"``, the default) or are
planned as joints of their own (``"independent"``), which joints are actuated; and the loop
closures of the ``[[loop]]`` tables (:mod:`.loops`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError, RobotModelError
from mbplan.robots import available_robots, load
from mbplan.robots.robot import MIMIC_MODES, Robot, load_robot
from mbplan.taskfile.loops import loop_key, read_actuated, read_loops
from mbplan.taskfile.toml_table import Document, Table

ROBOT_KEYS = ("urdf", "name", "mjcf", "package_dirs", "lock", "mimic", "actuated")
_SUFFIXES = {"urdf": (".urdf",), "mjcf": (".xml", ".mjcf")}


def read_robot(doc: Document) -> tuple[Robot, list[str] | None]:
    """The robot of ``[robot]`` and, if every joint of the unlocked robot is 1-dof, the joint
    names of the unlocked robot (a ``q`` may list them all)."""
    t = doc.table("robot", required=True, what=" (with urdf, name or mjcf)")
    t.check_keys(ROBOT_KEYS)
    given = [k for k in ("urdf", "name", "mjcf") if k in t]
    if len(given) != 1:
        got = f", got {' and '.join(given)}" if given else ""
        raise t.error(None, f"give exactly one of urdf, name (see `mbplan robots`), mjcf{got}")
    kind = given[0]
    base = doc.path.parent
    if kind == "name":
        spec: str | Path = t.string("name", choices=available_robots())  # type: ignore[assignment]
    else:
        spec = base / str(t.string(kind))
        if spec.suffix.lower() not in _SUFFIXES[kind]:
            raise t.error(kind, f"{spec.name!r} must end in {' or '.join(_SUFFIXES[kind])}")
        if not spec.is_file():
            raise t.error(kind, f"file not found: {spec}")
    dirs = [base / d for d in t.strings("package_dirs") or []]
    for d in dirs:
        if not d.is_dir():
            raise t.error("package_dirs", f"not a folder: {d}")
    lock = _lock(t)
    mimic = t.string("mimic", choices=MIMIC_MODES) or "couple"
    try:
        robot = load_robot(spec, package_dirs=dirs, lock=lock, mimic=mimic)
    except (InputError, RobotModelError) as err:
        text = str(err)
        key = "lock" if text.startswith("lock:") or "is locked" in text else kind
        raise type(err)(f"{doc.where(('robot', key))}: {text.removeprefix('lock: ')}") from None
    model = _unreduced(spec, kind)
    actuated = read_actuated(t, list(model.names[1:]))
    loops = read_loops(doc.tables("loop"), robot)
    if loops or actuated is not None:
        try:
            robot = load_robot(
                spec, package_dirs=dirs, lock=lock, mimic=mimic, loops=loops, actuated=actuated
            )
        except (InputError, RobotModelError) as err:  # the closures cannot close, or are void
            raise type(err)(f"{doc.where(loop_key(loops, str(err)))}: {err}") from None
    one_dof = all(model.joints[j].nq == 1 for j in range(1, model.njoints))
    return robot, list(model.names[1:]) if one_dof else None


def _lock(t: Table) -> dict[str, float | None] | None:
    value = t.data.get("lock")
    if value is None:
        return None
    if isinstance(value, list):
        names = t.strings("lock") or []
        return dict.fromkeys(names)
    if not isinstance(value, dict):
        raise t.error("lock", "expected a table { joint = value } or a list of joint names")
    sub = Table(t.doc, (*t.key, "lock"), value)
    return {name: sub.number(name, minimum=-np.inf) for name in value}


def _unreduced(spec: str | Path, kind: str) -> pin.Model:
    """The model without locked joints."""
    if kind == "mjcf":
        return pin.buildModelFromMJCF(str(spec))
    return load(spec, geometry=False).model
