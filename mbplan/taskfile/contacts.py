"""The ``[[contact]]`` tables of a task file: a frame held at a ground point (or a flat sole)
over a stance (:meth:`mbplan.OCP.add_contact`), every key checked before any solve."""

from __future__ import annotations

from mbplan.errors import InputError
from mbplan.ocp.problem import OCP
from mbplan.taskfile.toml_table import Table

CONTACT_KEYS = ("name", "frame", "knots", "position", "friction", "sole")
FRICTION = 0.7  # default [[contact]].friction


def add_contacts(tables: list[Table], ocp: OCP) -> None:
    """Add the contact of every ``[[contact]]`` table to ``ocp``: ``frame`` (required),
    ``name`` (default: the frame's), ``knots = [first, last]`` (the stance, both included;
    default: the whole horizon), ``position`` (default: where the start puts the frame),
    ``friction``, ``sole = [length, width]`` (a flat sole, 6-D)."""
    for t in tables:
        t.check_keys(CONTACT_KEYS)
        frame = str(t.string("frame", required=True, hint=" (the name of a frame of the robot)"))
        name = t.string("name") or frame
        first, last = 0, ocp.N
        if "knots" in t:
            knots = t.data["knots"]
            if (
                not isinstance(knots, list)
                or len(knots) != 2
                or not all(isinstance(k, int) and not isinstance(k, bool) for k in knots)
            ):
                raise t.error("knots", f"expected [first, last] (two integers), got {knots!r}")
            first, last = knots
        friction = t.number("friction", positive=True)
        try:
            ocp.add_contact(
                name,
                frame,
                range(first, last + 1),
                t.vector("position", 3),
                FRICTION if friction is None else friction,
                t.vector("sole", 2),
            )
        except InputError as err:
            raise t.error(None, str(err)) from None
