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

A sole is a weld to the world (the closure rows ``"weld"``) during its stance; its variable
``w = (f, τ)`` (``R⁶``, contact frame ``R_c``) enters the dynamics rows as the world wrench
``(R_c f, R_c τ)`` at the frame's origin (:func:`_sole_forces_function`), exactly, whatever the
sole's orientation at the touchdown knot, so that its cone ``A w ≤ 0``
(:func:`~mbplan.dynamics.friction.wrench_cone`) bounds the wrench the robot feels.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from typing import Any

import casadi as cs
import numpy as np

from mbplan.dynamics.friction import cone_rows
from mbplan.dynamics.joints import constraint_forces
from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.transcription.loops import loop_constraint_function, loop_forces_function
from mbplan.transcription.multibody import dynamics_rows
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block

CONTACT_BLOCK = "contact_force{}"
"""Name of the block of the forces of the ``i``-th contact."""

_POINT = ("point", (0, 1, 2), True, False)  # a point closure, side 1 the world
_WELD = ("weld", (0, 1, 2, 3, 4, 5), True, False)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _cone_function(jit: bool, rows: int, dim: int) -> RiemannianFunction:
    """A cone's rows ``A w`` (``≤ 0``)."""
    name = f"contact_cone_{rows}x{dim}"
    fn = lambda w, A: cs.mtimes(A, w)  # noqa: E731
    return RiemannianFunction(name, [("w", R(dim))], fn, [("A", (rows, dim))], jit=jit)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _sole_forces_function(jit: bool) -> RiemannianFunction:
    """The world wrench ``(R_c f, R_c τ)`` of ``w = (f, τ)`` at the point ``r`` of a body
    ``(R, p)``, into its dynamics rows as a closure's forces (module docstring): the
    ``J(x)ᵀw`` of rows whose derivatives along ``R(I + η^)``, ``p + δp`` are the wrench's
    lever arms, ``R_cᵀ(p + R r)`` and ``½ vee(R_cᵀ(R R̄ᵀ - R̄ Rᵀ)R_c)`` at ``R̄ = R``."""

    def fn(R2, p2, lam, Rc, r2):
        def rows(Rp, pp):
            spin = cs.mtimes([Rc.T, cs.mtimes(Rp, R2.T) - cs.mtimes(R2, Rp.T), Rc])
            turn = 0.5 * cs.vertcat(spin[2, 1], spin[0, 2], spin[1, 0])
            return cs.vertcat(cs.mtimes(Rc.T, pp + cs.mtimes(Rp, r2)), turn)

        ((torque, force),) = constraint_forces(rows, [(R2, p2)], lam)
        return cs.vertcat(-torque, -force)

    variables = [("R2", SO3), ("p2", R(3)), ("lam", R(6))]
    return RiemannianFunction(
        "sole_wrench_forces", variables, fn, [("Rc", (3, 3)), ("r2", 3)], jit=jit
    )


def contact_blocks(contacts: Sequence[Any], N: int) -> list[Block]:
    """One force (wrench) block per contact, knots outside its force knots fixed."""
    blocks = []
    for i, c in enumerate(contacts):
        fixed = np.setdiff1d(np.arange(N + 1), c.held_knots(N) - 1)
        blocks.append(Block(CONTACT_BLOCK.format(i), R(c.dim), N + 1, tuple(fixed)))
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
    for i, c in enumerate(contacts):
        block = CONTACT_BLOCK.format(i)
        b, Rf, r = contact_point(mm, mm.model.getFrameId(c.frame))
        k = c.held_knots(N) - 1
        site = k * nb + b
        params = {"Rf1": c.rotation, "r1": c.position, "Rf2": Rf, "r2": r}
        bind = {"R2": ("R", site), "p2": ("p", site), "lam": (block, k)}
        rows = dynamics_rows(nb, N, k - 1, np.full(len(k), b))
        if c.sole is None:
            forces_fn, force_params = loop_forces_function(jit, _POINT), params
        else:
            forces_fn, force_params = _sole_forces_function(jit), {"Rc": c.rotation, "r2": r}
        terms.append(
            Term(f"contact_{c.name}_forces", "eq", forces_fn, bind, force_params, rows=rows)
        )
        constraint_fn = loop_constraint_function(jit, _POINT if c.sole is None else _WELD)
        bind = {f"{n}2": (n, site) for n in ("R", "F", "p", "v")}
        terms.append(
            Term(f"contact_{c.name}_position", "eq", constraint_fn, bind, params | {"dt": dt})
        )
        A = cone_rows(c.friction, c.sole)
        cone_fn = _cone_function(jit, *A.shape)
        terms.append(Term(f"contact_{c.name}_cone", "ineq", cone_fn, {"w": (block, k)}, {"A": A}))
    return terms


def contact_forces(contacts: Sequence[Any], point: dict, knots: int) -> np.ndarray:
    """The contacts' knot variables ``(knots, nc, d)`` of a point (zero outside their force
    knots; ``d`` 6 if any contact is a sole, its forces' torques zero)."""
    out = np.zeros((knots, len(contacts), max(c.dim for c in contacts)))
    for i, c in enumerate(contacts):
        out[:, i, : c.dim] = np.asarray(point[CONTACT_BLOCK.format(i)]).reshape(knots, c.dim)
    return out
