"""Contacts in the independent check of a plan (:mod:`mbplan.verification.multibody`).

A plan with contacts (:meth:`mbplan.OCP.add_contact`) carries its contact forces
(``result.contact_forces``, and ``contact_forces_knots`` for the LGVI). The replay applies them as
world forces at the contact frames, ``τ + Σ J_i(q)ᵀ f_i`` with the frames' Jacobians at the
replayed configuration, held over each interval (eq. 61), or, for the LGVI, with its knot
torques as impulses at the knots (:func:`kick`; :mod:`mbplan.verification.multibody` says why).
The checks, by contact name:

* ``<name>.position`` (m): the frame's distance from its contact position at every stance knot
  of the plan (no slip, no lift-off); at most :data:`SLIP_TOLERANCE`;
* ``<name>.slip`` (m): the same along the replayed motion of every stance interval, at most
  :data:`SLIP_TOLERANCE` plus twice the frame's distance between the replay's end and the
  explicit-Euler step's (the discretisation error there, as the deviation thresholds of
  :mod:`mbplan.verification.multibody` allow it): explicit Euler's held forces move a light
  foot by about 1.5 mm within a 20 ms interval; the LGVI's replay, whose feet move freely
  between its impulses, sags by up to ``⅛Δt²|a|`` (:func:`impulse_sag`; ``g Δt²/8``: 0.5 mm at
  20 ms, 1.1 mm at 30 ms), which its threshold adds; ``<name>.slip_ratio`` is the largest slip
  over its threshold;
* ``<name>.cone`` (N): the largest violation of the friction cone ``‖f_xy‖ ≤ μ f_z`` by the
  planned forces, at most :data:`~mbplan.residuals.base.CONSTRAINT_TOLERANCE` ``· max(1, |f|)``;
  for a sole, of its contact wrench cone (:func:`~mbplan.dynamics.friction.wrench_cone_violation`
  of the world wrench turned into the contact frame);
* ``<name>.orientation`` (rad, soles): the frame's angle from its held orientation at every
  stance knot, at most :data:`SLIP_TOLERANCE`.

Soles' wrenches are world forces and torques about the frame's origin, ``(…, 6)``, applied
through the frame's 6-D world-aligned Jacobian.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from mbplan.dynamics.friction import cone_violation, wrench_cone_violation
from mbplan.ocp.contacts import (
    frame_position,
    frame_rotation,
    generalized_force,
    orientation_error,
)
from mbplan.ocp.problem import OCP
from mbplan.residuals.base import CONSTRAINT_TOLERANCE
from mbplan.results import PlanResult
from mbplan.simulation.reference import damped_aba, mass_matrix

SLIP_TOLERANCE = 1e-3  # m: how far a held frame may move from its contact position


def frame_ids(ocp: OCP) -> list[int]:
    return [ocp.robot.model.getFrameId(c.frame) for c in ocp.contacts]


def kick(
    ocp: OCP, q: np.ndarray, v: np.ndarray, tau: np.ndarray, forces: np.ndarray, dt: float
) -> np.ndarray:
    """``v + M(q)⁻¹ (τ + Σ J_i(q)ᵀ f_i) Δt``: the velocity after the impulses of the torques
    ``τ`` and the contact forces ``f`` over ``Δt``."""
    model = ocp.robot.model
    impulse = (tau + generalized_force(model, frame_ids(ocp), q, forces)) * dt
    return v + np.linalg.solve(mass_matrix(model, model.createData(), q), impulse)


def contact_dynamics(ocp: OCP) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """``acceleration(q, v, u)`` for :func:`~mbplan.simulation.reference.integrate_aba` with
    ``u = (τ, f)``: ABA (with the joints' damping) under ``τ + Σ J_i(q)ᵀ f_i``."""
    model = ocp.robot.model
    data, frames, nv = model.createData(), frame_ids(ocp), model.nv

    def acceleration(q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        forces = u[nv:].reshape(len(frames), -1)
        return damped_aba(model, data, q, v, u[:nv] + generalized_force(model, frames, q, forces))

    return acceleration


def contact_violations(ocp: OCP, q: np.ndarray, forces: np.ndarray | None) -> dict[str, float]:
    """``<name>.position`` at the planned stance knots and ``<name>.cone`` of the planned
    forces ``(N, nc, 3)`` (module docstring; a plan without forces violates every cone by
    ``inf``)."""
    if not ocp.contacts:
        return {}
    model, out = ocp.robot.model, {}
    for i, c in enumerate(ocp.contacts):
        fid = model.getFrameId(c.frame)
        gaps = [np.linalg.norm(frame_position(model, fid, q[k]) - c.position) for k in c.knots]
        out[f"{c.name}.position"] = float(max(gaps))
        if c.sole is not None:
            turns = [
                orientation_error(c.rotation, frame_rotation(model, fid, q[k])) for k in c.knots
            ]
            out[f"{c.name}.orientation"] = float(max(turns))
        if forces is None:
            out[f"{c.name}.cone"] = float("inf")
            continue
        if c.sole is None:
            out[f"{c.name}.cone"] = float(np.max(cone_violation(forces[:, i, :3], c.friction)))
        else:
            local = c.local(forces[:, i])
            out[f"{c.name}.cone"] = float(np.max(wrench_cone_violation(local, c.friction, *c.sole)))
    return out


def impulse_sag(ocp: OCP, result: PlanResult) -> np.ndarray:
    """``⅛Δt²|a_i|`` ``(N, nc)``: how far the replay's free motion between two impulses
    (:func:`kick`) carries each contact frame from the chord of its ends, ``a_i`` the frame's
    acceleration with no torque or contact force after the interval's first impulse (gravity,
    the joints' velocities): the impulse replay's own excursion, not the plan's slip."""
    model = ocp.robot.model
    data, frames = model.createData(), frame_ids(ocp)
    out = np.zeros((ocp.N, len(frames)))
    for k in range(ocp.N):
        q = result.q[k]
        v = kick(
            ocp, q, result.v[k], result.tau_knots[k], result.contact_forces_knots[k], 0.5 * ocp.dt
        )
        a = damped_aba(model, data, q, v, np.zeros(model.nv))
        pin.forwardKinematics(model, data, q, v, a)
        for i, fid in enumerate(frames):
            acc = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            out[k, i] = 0.125 * ocp.dt**2 * np.linalg.norm(acc.linear)
    return out


def replay_slip(
    ocp: OCP, path: np.ndarray, q_euler: np.ndarray, sag: np.ndarray | None = None
) -> dict[str, float]:
    """``<name>.slip`` and ``<name>.slip_ratio`` (module docstring) along the replayed substeps
    ``path (N, S+1, nq)`` of every stance interval, the explicit-Euler steps ``q_euler (N, nq)``
    from the planned knots; an impulse replay's :func:`impulse_sag` ``(N, nc)`` is allowed on
    top of the threshold."""
    if not ocp.contacts:
        return {}
    model, out = ocp.robot.model, {}
    for i, c in enumerate(ocp.contacts):
        fid = model.getFrameId(c.frame)
        slip, ratio = 0.0, 0.0
        for k in range(c.first, c.last):
            gap = max(np.linalg.norm(frame_position(model, fid, qs) - c.position) for qs in path[k])
            euler = frame_position(model, fid, q_euler[k]) - frame_position(model, fid, path[k, -1])
            allowed = SLIP_TOLERANCE + 2.0 * np.linalg.norm(euler)
            allowed += 0.0 if sag is None else sag[k, i]
            slip = max(slip, gap)
            ratio = max(ratio, gap / allowed)
        out[f"{c.name}.slip"], out[f"{c.name}.slip_ratio"] = float(slip), float(ratio)
    return out


def contact_reasons(ocp: OCP, violations: dict[str, float], forces: np.ndarray | None) -> list[str]:
    """Reasons the contacts fail the checks of the module docstring."""
    reasons = []
    scale = 1.0 if forces is None or not forces.size else max(1.0, float(np.abs(forces).max()))
    for c in ocp.contacts:
        slip = violations[f"{c.name}.position"]
        if slip > SLIP_TOLERANCE:
            reasons.append(
                f"contact {c.name!r}: frame {c.frame!r} is {slip:.3g} m from its contact "
                f"position during its stance (tolerance {SLIP_TOLERANCE:g} m)"
            )
        turn = violations.get(f"{c.name}.orientation", 0.0)
        if turn > SLIP_TOLERANCE:
            reasons.append(
                f"contact {c.name!r}: sole frame {c.frame!r} turns {turn:.3g} rad from its "
                f"orientation during its stance (tolerance {SLIP_TOLERANCE:g} rad)"
            )
        ratio = violations.get(f"{c.name}.slip_ratio", 0.0)
        if ratio > 1.0:
            reasons.append(
                f"contact {c.name!r}: the replayed motion moves frame {c.frame!r} "
                f"{violations[f'{c.name}.slip']:.3g} m during its stance, {ratio:.3g} times its "
                f"threshold ({SLIP_TOLERANCE:g} m plus twice the explicit-Euler error)"
            )
        cone = violations[f"{c.name}.cone"]
        if cone > CONSTRAINT_TOLERANCE * scale:
            cone_name = "friction cone" if c.sole is None else "contact wrench cone"
            reasons.append(
                f"contact {c.name!r}: its force leaves the {cone_name} (mu = {c.friction:g}) "
                f"by {cone:.3g} N"
            )
    return reasons


def with_contact_forces(ocp: OCP, result: PlanResult, k: int, tau: np.ndarray) -> np.ndarray:
    """``τ + Σ J_i(q_k)ᵀ f_i`` with interval ``k``'s mean contact forces (the Euler step)."""
    if not ocp.contacts:
        return tau
    q = result.q[k]
    return tau + generalized_force(ocp.robot.model, frame_ids(ocp), q, result.contact_forces[k])
