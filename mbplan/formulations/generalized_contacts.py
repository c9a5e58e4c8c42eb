"""Contacts in generalized coordinates (:mod:`mbplan.ocp.contacts`): forces as variables of the
generalized NLP (:mod:`mbplan.formulations.generalized`).

Each contact ``i`` adds its world force ``f_{i,k}`` (N) on its intervals ``k``
(:meth:`~mbplan.ocp.contacts.Contact.force_intervals`) to the decision vector and to the
dynamics rows of eq. (61)::

    RNEA(q_k, v_k, a_k) + D v_{k+1} - τ_k - Σ_i J_i(q_k)ᵀ f_{i,k} = 0

(``J_i``: the frame's world-aligned linear Jacobian in Pinocchio's tangent space, ``∂p(q ⊕ δ)/∂δ``
written symbolically, so the Hessian of ``μᵀJ(q)ᵀf`` is CasADi's exact one), the position rows
``p_i(q_m) - c_i = 0`` at its held knots ``m ≤ N`` (a stance to the horizon's end: the frame at
rest, ``J_i(q_N) v_N = 0``) and the friction pyramid ``A f_{i,k} ≤ 0``.

A sole's variable is its wrench ``w = (f, τ)`` in its contact frame ``R_c``: ``J_i`` is then the
frame's world-aligned 6-D Jacobian (the angular rows ``∂ vee(R(q ⊕ δ) R(q)ᵀ)/∂δ``) applied to
the world wrench ``(R_c f, R_c τ)``, the held knots also hold the frame's orientation,
``½ vee(R_cᵀR - RᵀR_c) = 0``, and its cone is the contact wrench cone.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import casadi as cs
import numpy as np
from numpy.typing import ArrayLike

from mbplan.dynamics.friction import cone_rows
from mbplan.formulations.free_flyer import quaternion_matrix
from mbplan.formulations.joint_space import joint_axes, symbolic_placements
from mbplan.robots.robot import Robot


def _perturbed(robot: Robot, q: cs.SX, delta: cs.SX) -> cs.SX:
    """``q ⊕ δ`` to first order in ``δ`` (``nv``): a free flyer's position ``p + R δ_lin`` and
    quaternion ``quat ⊗ (δ_ang/2, 1)``, the other joints ``q_j + δ_j``."""
    model, parts = robot.model, []
    for j, (kind, _) in enumerate(joint_axes(model), start=1):
        iq, iv = model.joints[j].idx_q, model.joints[j].idx_v
        if kind != "free":
            parts.append(q[iq] + delta[iv])
            continue
        quat, lin, ang = q[iq + 3 : iq + 7], delta[iv : iv + 3], delta[iv + 3 : iv + 6] / 2
        u, w = quat[:3], quat[3]
        parts += [
            q[iq : iq + 3] + cs.mtimes(quaternion_matrix(quat), lin),
            w * ang + u + cs.cross(u, ang),
            w - cs.dot(u, ang),
        ]
    return cs.vertcat(*parts)


def _vee(S: cs.SX) -> cs.SX:
    """``vee`` of the skew part of ``S`` (3 × 3)."""
    return 0.5 * cs.vertcat(S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1])


# process-wide cache, result-neutral: CasADi functions of the robot's kinematics and a frame
@lru_cache(maxsize=64)
def frame_functions(robot: Robot, frame: str) -> tuple[cs.Function, cs.Function, cs.Function]:
    """``p(q)`` (3), ``R(q)`` (3 × 3) and ``J(q)`` (6 × nv: linear, then angular, both world
    aligned) of a frame (module docstring)."""
    model = robot.model
    f = model.frames[model.getFrameId(frame)]
    q, delta = cs.SX.sym("q", model.nq), cs.SX.sym("d", model.nv)

    def placement(qq: cs.SX) -> tuple[cs.SX, cs.SX]:
        R, p = symbolic_placements(model, qq)[f.parentJoint]
        return cs.mtimes(R, cs.DM(f.placement.rotation)), p + cs.mtimes(
            R, cs.DM(f.placement.translation)
        )

    R0, p0 = placement(q)
    R1, p1 = placement(_perturbed(robot, q, delta))
    J = cs.jacobian(cs.vertcat(p1, _vee(cs.mtimes(R1, R0.T))), delta)
    J = cs.substitute(J, delta, cs.DM.zeros(model.nv))
    return (
        cs.Function("frame_p", [q], [p0]),
        cs.Function("frame_R", [q], [R0]),
        cs.Function("frame_J", [q], [J]),
    )


class ContactColumns:
    """Where the contact variables sit in the generalized NLP's ``z``: after column ``start``,
    contact by contact, each one's (:attr:`~mbplan.ocp.contacts.Contact.dim` columns) on its
    intervals (:meth:`~mbplan.ocp.contacts.Contact.force_intervals`)."""

    def __init__(self, contacts: Sequence[Any], N: int, start: int) -> None:
        self.N, self.contacts = N, list(contacts)
        self.intervals = [c.force_intervals(N) for c in contacts]
        sizes = [c.dim * len(k) for c, k in zip(contacts, self.intervals, strict=True)]
        self.at = np.cumsum([start, *sizes])
        self.end = int(self.at[-1])
        self.dim = max((c.dim for c in contacts), default=3)

    def index(self, i: int, k: ArrayLike) -> np.ndarray:
        """Columns of contact ``i``'s variables on its intervals ``k``, ``(*k.shape, dim_i)``."""
        d = self.contacts[i].dim
        at = np.searchsorted(self.intervals[i], np.asarray(k))
        return self.at[i] + at[..., None] * d + np.arange(d)

    def forces(self, z: np.ndarray) -> np.ndarray:
        """Every contact's world force (and torque) ``(N, nc, dim)`` per interval (zero where it
        does not act)."""
        out = np.zeros((self.N, len(self.intervals), self.dim))
        for i, (c, k) in enumerate(zip(self.contacts, self.intervals, strict=True)):
            out[k, i, : c.dim] = c.world(z[self.index(i, k)])
        return out

    def pack(self, forces: np.ndarray | None) -> np.ndarray:
        """The columns' values from world ``forces (N, nc, dim)`` (zero if None)."""
        parts = [np.zeros(0)]
        for i, (c, k) in enumerate(zip(self.contacts, self.intervals, strict=True)):
            w = np.zeros((len(k), c.dim)) if forces is None else c.local(forces[k, i, : c.dim])
            parts.append(w.ravel())
        return np.concatenate(parts)


def contact_rows(
    nlp: Any, row: int
) -> tuple[list[tuple[cs.SX, cs.SX, np.ndarray, int, bool]], int]:
    """``(x, rows(x), columns (K, nx) in z, first row, inequality)`` of the contacts' blocks of
    the generalized NLP ``nlp`` (its new rows from ``row`` on), and how many rows they add."""
    out = []
    N, nq, nv, robot = nlp.N, nlp.nq, nlp.nv, nlp.ocp.robot
    q = cs.SX.sym("q", nq)
    for i, c in enumerate(nlp.ocp.contacts):
        d, f = c.dim, cs.SX.sym("f", c.dim)
        p_of, R_of, J_full = frame_functions(robot, c.frame)
        J_of = cs.Function("contact_J", [q], [J_full(q)[:d, :]])
        wrench = cs.mtimes(cs.DM(c.world(np.eye(d)).T), f)  # the world force (and torque)
        k = c.force_intervals(N)
        cols_f = nlp.force_columns.index(i, k)
        first = int(k[0] == 0)
        if first:  # interval 0, at the fixed q0
            force0 = -cs.mtimes(J_of(cs.DM(nlp.ocp.q0)).T, wrench)
            out.append((f, force0, cols_f[:1], N * nv, False))
        inner = k[first:]
        if inner.size:
            x = cs.vertcat(q, f)
            force = -cs.mtimes(J_of(q).T, wrench)
            cols = np.concatenate([nlp.iq(inner), cols_f[first:]], axis=1)
            out.append((x, force, cols, (N + inner[0]) * nv, False))
        A = cone_rows(c.friction, c.sole)
        out.append((f, cs.mtimes(cs.DM(A), f), cols_f, row, True))
        row += len(A) * len(k)
        held = c.held_knots(N)
        knots = held[held <= N]
        if knots.size:
            held_rows = p_of(q) - cs.DM(c.position)
            if c.sole is not None:
                Rc = cs.DM(c.rotation)
                held_rows = cs.vertcat(held_rows, _vee(cs.mtimes(Rc.T, R_of(q))))
            out.append((q, held_rows, nlp.iq(knots), row, False))
            row += d * len(knots)
        if held[-1] == N + 1:  # at rest at the end
            y = cs.SX.sym("y", nq + nv)
            rest = cs.mtimes(J_of(y[:nq]), y[nq:])
            cols = np.concatenate([nlp.iq([N]), nlp.iv([N])], axis=1)
            out.append((y, rest, cols, row, False))
            row += d
    return out, row


def guess_contact_forces(
    nlp: Any, q: np.ndarray, demand: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World contact forces ``(N, nc, dim)`` and torques ``(N, nv)`` with ``τ_k + Σ J_iᵀ
    f_{i,k} = demand_k`` (the inverse dynamics): each interval's forces (wrenches) the
    least-squares balance of the base's rows (the first six), ``τ`` the rest (zero on the
    base)."""
    N, contacts = nlp.N, nlp.ocp.contacts
    forces = np.zeros((N, len(contacts), nlp.force_columns.dim))
    tau = np.array(demand, dtype=float)
    if nlp.chart is None:  # a fixed base carries itself
        return forces, tau
    active = [set(c.force_intervals(N).tolist()) for c in contacts]
    for k in range(N):
        on = [i for i in range(len(contacts)) if k in active[i]]
        if not on:
            continue
        J = [
            np.asarray(frame_functions(nlp.ocp.robot, contacts[i].frame)[2](q[k]))[
                : contacts[i].dim
            ]
            for i in on
        ]
        J_all = np.vstack(J)
        w = np.linalg.lstsq(J_all[:, :6].T, demand[k, :6], rcond=None)[0]
        tau[k] -= J_all.T @ w
        for i, part in zip(on, np.split(w, np.cumsum([len(j) for j in J])[:-1]), strict=True):
            forces[k, i, : len(part)] = part
    tau[:, :6] = 0.0
    return forces, tau
