"""Contacts in the multi-body transcription (:mod:`mbplan.ocp.contacts`, :mod:`.multibody`).

A contact holds a point of one body at a world point, a ball joint to the world that exists
during its stance: its force ``f_k`` (world frame, N) is the multiplier of the constraint
``R r + p - c = 0`` and enters the LGVI like a loop closure's (:mod:`mbplan.transcription.loops`,
whose point-closure functions it uses with the world as side 1): ``f_{m-1}`` adds
``J(x_{m-1})ᵀf_{m-1}`` to the body's dynamics rows of step ``m-2`` and the point is held on the
configuration ``x_m = (R_{m-1} F_{m-1}, p_{m-1} + v_{m-1} Δt)`` for the contact's held knots
``m`` (:meth:`~mbplan.ocp.contacts.Contact.held_knots`). Forces are one block per contact,
``contact_force{i}`` (``R³``), data (zero) at the other knots; the friction pyramid
``A f ≤ 0`` (:func:`~mbplan.dynamics.friction.pyramid`) is an inequality term on them.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from typing import Any

import casadi as cs
import numpy as np

from mbplan.dynamics.friction import pyramid
from mbplan.engine import RiemannianFunction
from mbplan.lie import R
from mbplan.multibody import MaximalModel
from mbplan.transcription.loops import loop_constraint_function, loop_forces_function
from mbplan.transcription.multibody import dynamics_rows
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block

CONTACT_BLOCK = "contact_force{}"
"""Name of the block of the forces of the ``i``-th contact."""

_GROUP = ("point", (0, 1, 2), True, False)  # a point closure, side 1 the world


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _cone_function(jit: bool) -> RiemannianFunction:
    """The friction pyramid's rows ``A f`` (``≤ 0``)."""
    return RiemannianFunction(
        "friction_pyramid", [("f", R(3))], lambda f, A: cs.mtimes(A, f), [("A", (4, 3))], jit=jit
    )


def contact_blocks(contacts: Sequence[Any], N: int) -> list[Block]:
    """One force block per contact, knots outside its force knots fixed."""
    blocks = []
    for i, c in enumerate(contacts):
        fixed = np.setdiff1d(np.arange(N + 1), c.held_knots(N) - 1)
        blocks.append(Block(CONTACT_BLOCK.format(i), R(3), N + 1, tuple(fixed)))
    return blocks


def contact_point(mm: MaximalModel, frame: int) -> tuple[int, np.ndarray, np.ndarray]:
    """The body of a Pinocchio frame, the frame's rotation and origin in that body's frame
    (origin relative to the body's centre of mass)."""
    f = mm.model.frames[frame]
    body = int(np.flatnonzero(np.asarray(mm.pin_joint) == f.parentJoint)[0])
    return body, f.placement.rotation, f.placement.translation - mm.com_in_joint[body]


def contact_terms(
    mm: MaximalModel, contacts: Sequence[Any], N: int, dt: float, jit: bool
) -> list[Term]:
    """The force, constraint and friction terms of every contact
    (:class:`~mbplan.ocp.contacts.Contact`; module docstring)."""
    nb, terms = mm.nb, []
    forces_fn = loop_forces_function(jit, _GROUP)
    constraint_fn = loop_constraint_function(jit, _GROUP)
    for i, c in enumerate(contacts):
        block = CONTACT_BLOCK.format(i)
        b, Rf, r = contact_point(mm, mm.model.getFrameId(c.frame))
        k = c.held_knots(N) - 1
        site = k * nb + b
        params = {"Rf1": np.eye(3), "r1": c.position, "Rf2": Rf, "r2": r}
        bind = {"R2": ("R", site), "p2": ("p", site), "lam": (block, k)}
        rows = dynamics_rows(nb, N, k - 1, np.full(len(k), b))
        terms.append(Term(f"contact_{c.name}_forces", "eq", forces_fn, bind, params, rows=rows))
        bind = {f"{n}2": (n, site) for n in ("R", "F", "p", "v")}
        terms.append(
            Term(f"contact_{c.name}_position", "eq", constraint_fn, bind, params | {"dt": dt})
        )
        cone = {"A": pyramid(c.friction)}
        terms.append(
            Term(f"contact_{c.name}_cone", "ineq", _cone_function(jit), {"f": (block, k)}, cone)
        )
    return terms


def contact_forces(contacts: Sequence[Any], point: dict, knots: int) -> np.ndarray:
    """The contacts' knot forces ``(knots, nc, 3)`` of a point (zero outside their force knots)."""
    out = np.zeros((knots, len(contacts), 3))
    for i in range(len(contacts)):
        out[:, i] = np.asarray(point[CONTACT_BLOCK.format(i)]).reshape(knots, 3)
    return out
