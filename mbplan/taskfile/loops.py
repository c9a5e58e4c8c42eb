"""The ``[[loop]]`` tables of a task file (loop closures besides a robot file's own) and the
``actuated`` joints of its ``[robot]`` table, checked against the loaded robot before the
closures are resolved (:func:`mbplan.robots.loops.loop_from_spec`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from mbplan.errors import InputError
from mbplan.robots.loops import LOOP_KINDS, loop_from_spec
from mbplan.robots.robot import Robot
from mbplan.taskfile.toml_table import Key, Table

LOOP_KEYS = ("name", "kind", "frame1", "frame2", "placement1", "placement2", "axis")


def read_loops(tables: list[Table], robot: Robot) -> list[dict[str, Any]]:
    """The loop specifications of the ``[[loop]]`` tables (mappings of
    :func:`~mbplan.robots.loops.loop_from_spec`), every key checked against ``robot`` (the
    robot without these loops)."""
    model = robot.model
    taken = {loop.name for loop in robot.loops}
    out = []
    for i, t in enumerate(tables):
        t.check_keys(LOOP_KEYS)
        name = t.string("name") or f"loop_{i + 1}"
        if name in taken:
            raise t.error("name", f"a second loop named {name!r} (names must be unique)")
        taken.add(name)
        kind = t.string("kind", choices=tuple(LOOP_KINDS)) or "point"
        spec: dict[str, Any] = {"name": name, "kind": kind}
        joints = []
        for side in ("1", "2"):
            key = f"frame{side}"
            frame = str(t.string(key, required=True, hint=" (the name of a frame of the robot)"))
            try:
                fid = robot.frame_id(frame)
            except InputError as err:
                raise t.error(key, str(err)) from None
            joints.append(model.frames[fid].parentJoint)
            spec[key] = frame
            spec[f"placement{side}"] = t.vector(f"placement{side}", 3)
        if joints[0] == joints[1]:
            raise t.error(
                "frame2",
                f"{spec['frame1']!r} and {spec['frame2']!r} are on the same body (of joint "
                f"{model.names[joints[0]]!r}): a closure joins two different bodies",
            )
        if "axis" in t:
            if kind != "revolute":
                raise t.error("axis", f"only a revolute closure has an axis, not a {kind!r} one")
            axis = t.vector("axis", 3)
            if not np.any(axis):
                raise t.error("axis", "expected a nonzero direction, got [0, 0, 0]")
            spec["axis"] = axis
        try:
            loop_from_spec(model, spec, i)
        except InputError as err:
            raise t.error(None, str(err)) from None
        out.append({k: v for k, v in spec.items() if v is not None})
    return out


def read_actuated(t: Table, joints: list[str]) -> list[str] | None:
    """``[robot].actuated``: the joints with an actuator, each one of ``joints`` (the joints of
    the unlocked robot); None if absent (the robot file's actuators, else every joint)."""
    names = t.strings("actuated")
    if names is None:
        return None
    if not names:
        raise t.error("actuated", "no joint is actuated: the robot cannot move")
    for name in names:
        if name not in joints:
            raise t.error("actuated", f"{name!r} is not a joint of the robot; joints: {joints}")
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise t.error("actuated", f"joints {twice} are listed twice")
    return names


def loop_key(specs: list[dict[str, Any]], message: str) -> Key:
    """The key an error of resolving the loops ``specs`` belongs to: the ``[[loop]]`` table
    of the loop it names (else the first), or ``[robot].actuated`` without loop tables."""
    if not specs:
        return ("robot", "actuated")
    named = [i for i, spec in enumerate(specs) if f"loop {spec['name']!r}" in message]
    return ("loop", named[0] if named else 0)
