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
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import casadi as cs
import numpy as np
from numpy.typing import ArrayLike

from mbplan.dynamics.friction import pyramid
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


# process-wide cache, result-neutral: CasADi functions of the robot's kinematics and a frame
@lru_cache(maxsize=64)
def frame_functions(robot: Robot, frame: str) -> tuple[cs.Function, cs.Function]:
    """``p(q)`` (3) and ``J(q)`` (3 × nv) of a frame's origin (module docstring)."""
    model = robot.model
    f = model.frames[model.getFrameId(frame)]
    q, delta = cs.SX.sym("q", model.nq), cs.SX.sym("d", model.nv)

    def position(qq: cs.SX) -> cs.SX:
        R, p = symbolic_placements(model, qq)[f.parentJoint]
        return p + cs.mtimes(R, cs.DM(f.placement.translation))

    J = cs.jacobian(position(_perturbed(robot, q, delta)), delta)
    J = cs.substitute(J, delta, cs.DM.zeros(model.nv))
    return cs.Function("frame_p", [q], [position(q)]), cs.Function("frame_J", [q], [J])


class ContactColumns:
    """Where the contact forces sit in the generalized NLP's ``z``: after column ``start``,
    contact by contact, each force on its intervals
    (:meth:`~mbplan.ocp.contacts.Contact.force_intervals`), 3 columns per interval."""

    def __init__(self, contacts: Sequence[Any], N: int, start: int) -> None:
        self.N = N
        self.intervals = [c.force_intervals(N) for c in contacts]
        self.at = np.cumsum([start] + [3 * len(k) for k in self.intervals])
        self.end = int(self.at[-1])

    def index(self, i: int, k: ArrayLike) -> np.ndarray:
        """Columns of contact ``i``'s force on its intervals ``k``, shape ``(*k.shape, 3)``."""
        at = np.searchsorted(self.intervals[i], np.asarray(k))
        return self.at[i] + at[..., None] * 3 + np.arange(3)

    def forces(self, z: np.ndarray) -> np.ndarray:
        """Every contact's force ``(N, nc, 3)`` per interval (zero where it does not act)."""
        out = np.zeros((self.N, len(self.intervals), 3))
        for i, k in enumerate(self.intervals):
            out[k, i] = z[self.index(i, k)]
        return out

    def pack(self, forces: np.ndarray | None) -> np.ndarray:
        """The columns' values from ``forces (N, nc, 3)`` (zero if None)."""
        parts = [np.zeros(0)]
        for i, k in enumerate(self.intervals):
            parts.append(np.zeros(3 * len(k)) if forces is None else forces[k, i].ravel())
        return np.concatenate(parts)


def contact_rows(
    nlp: Any, row: int
) -> tuple[list[tuple[cs.SX, cs.SX, np.ndarray, int, bool]], int]:
    """``(x, rows(x), columns (K, nx) in z, first row, inequality)`` of the contacts' blocks of
    the generalized NLP ``nlp`` (its new rows from ``row`` on), and how many rows they add."""
    out = []
    N, nq, nv, robot = nlp.N, nlp.nq, nlp.nv, nlp.ocp.robot
    q, f = cs.SX.sym("q", nq), cs.SX.sym("f", 3)
    for i, c in enumerate(nlp.ocp.contacts):
        p_of, J_of = frame_functions(robot, c.frame)
        k = c.force_intervals(N)
        cols_f = nlp.force_columns.index(i, k)
        first = int(k[0] == 0)
        if first:  # interval 0, at the fixed q0
            force0 = -cs.mtimes(J_of(cs.DM(nlp.ocp.q0)).T, f)
            out.append((f, force0, cols_f[:1], N * nv, False))
        inner = k[first:]
        if inner.size:
            x = cs.vertcat(q, f)
            force = -cs.mtimes(J_of(q).T, f)
            cols = np.concatenate([nlp.iq(inner), cols_f[first:]], axis=1)
            out.append((x, force, cols, (N + inner[0]) * nv, False))
        out.append((f, cs.mtimes(cs.DM(pyramid(c.friction)), f), cols_f, row, True))
        row += 4 * len(k)
        held = c.held_knots(N)
        knots = held[held <= N]
        if knots.size:
            out.append((q, p_of(q) - cs.DM(c.position), nlp.iq(knots), row, False))
            row += 3 * len(knots)
        if held[-1] == N + 1:  # at rest at the end
            y = cs.SX.sym("y", nq + nv)
            rest = cs.mtimes(J_of(y[:nq]), y[nq:])
            cols = np.concatenate([nlp.iq([N]), nlp.iv([N])], axis=1)
            out.append((y, rest, cols, row, False))
            row += 3
    return out, row


def guess_contact_forces(
    nlp: Any, q: np.ndarray, demand: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Contact forces ``(N, nc, 3)`` and torques ``(N, nv)`` with ``τ_k + Σ J_iᵀ f_{i,k} =
    demand_k`` (the inverse dynamics): each interval's forces the least-squares balance of the
    base's rows (the first six), ``τ`` the rest (zero on the base)."""
    N, contacts = nlp.N, nlp.ocp.contacts
    forces = np.zeros((N, len(contacts), 3))
    tau = np.array(demand, dtype=float)
    if nlp.chart is None:  # a fixed base carries itself
        return forces, tau
    active = [set(c.force_intervals(N).tolist()) for c in contacts]
    for k in range(N):
        on = [i for i in range(len(contacts)) if k in active[i]]
        if not on:
            continue
        jacobians = [frame_functions(nlp.ocp.robot, contacts[i].frame)[1] for i in on]
        J = np.vstack([np.asarray(J_of(q[k])) for J_of in jacobians])
        forces[k, on] = np.linalg.lstsq(J[:, :6].T, demand[k, :6], rcond=None)[0].reshape(-1, 3)
        tau[k] -= J.T @ forces[k, on].ravel()
    tau[:, :6] = 0.0
    return forces, tau
