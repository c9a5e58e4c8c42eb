"""Velocity limits of a maximal-coordinate plan with contacts, kept at the knot velocities it
reports.

The LGVI bounds each interval's step ``θ_{k+1} - θ_k`` (:mod:`mbplan.formulations.maximal_joints`):
its secant velocity ``w_k``. With contacts, a plan reports at knot ``k`` the velocity midway
through the knot's impulse (:func:`~mbplan.formulations.maximal.impulse_midpoint_velocities`),
``½(w_{k-1} + w_k) + c_k``, whose correction ``c_k`` (the unforced accelerations' change across
the impulse) is first order where an impulse reverses a light leg: at a landing it carries the
knot velocity past a limit both secants respect. :func:`tighten_velocity_limits` lowers the
bounds of the two secants around every such knot by its excess; solved again from the plan,
the correction hardly moves, so a few rounds (:data:`ROUNDS`) bring every reported velocity
inside its limit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mbplan.formulations.maximal_joints import joint_term_name
from mbplan.residuals.limits import JointVelocityLimits

ROUNDS = 4  # re-solves with tightened secant bounds, at most
MARGIN = 1.5  # each round tightens by this factor times the excess ...
SLACK = 1e-4  # ... plus this (rad/s, m/s): the reported velocities land inside the limits


def velocity_excess(nlp: Any, v: np.ndarray) -> dict[str, np.ndarray]:
    """Per velocity-limit constraint of ``nlp.ocp``, the excess ``max(0, |v| - limit)``
    ``(N+1, nv)`` of the knot velocities ``v`` over its limits (zero off its knots and on the
    entries it does not limit)."""
    out = {}
    for item in nlp.ocp.constraints:
        r = item.residual
        if not isinstance(r, JointVelocityLimits):
            continue
        limited = r.indices(nlp.ocp.robot)
        e = np.zeros_like(v)
        rows = v[np.ix_(item.knots, limited)]
        e[np.ix_(item.knots, limited)] = np.maximum(
            np.maximum(r.lower[limited] - rows, rows - r.upper[limited]), 0.0
        )
        out[item.name] = e
    return out


def tighten_velocity_limits(nlp: Any, v: np.ndarray) -> float:
    """Lower the secant bounds of ``nlp``'s velocity-limit terms around every knot whose
    reported velocity ``v (N+1, nv)`` exceeds its limit (module docstring); the largest excess
    (0: nothing to tighten)."""
    mm, dt, problem = nlp.mm, nlp.ocp.dt, nlp.problem
    largest = 0.0
    for name, excess in velocity_excess(nlp, v).items():
        if not excess.any():
            continue
        largest = max(largest, float(excess.max()))
        # the secant w_k enters the knot velocities of k and k+1
        around = excess.copy()
        around[:-1] = np.maximum(excess[:-1], excess[1:])
        names = {
            joint_term_name(name, jtype, world)
            for jtype in ("revolute", "prismatic")
            for world in (True, False)
        }
        for term in (t for t in problem.terms if t.name in names):
            flat = term.bind["Rc"][1]
            knot, body = flat // mm.nb, flat % mm.nb
            cut = MARGIN * around[knot, mm.idx_v[body]]
            cut = np.where(cut > 0, cut + SLACK, 0.0)
            if "cos_step" in term.parameters:
                step = np.arccos(np.broadcast_to(term.parameters["cos_step"], cut.shape)) / dt
                step = np.maximum(step - cut, 0.0)
                problem.set_parameters(term.name, {"cos_step": np.cos(step * dt)})
            else:
                lo = np.broadcast_to(term.parameters["lo"], cut.shape)
                hi = np.broadcast_to(term.parameters["hi"], cut.shape)
                mid = 0.5 * (lo + hi)
                problem.set_parameters(
                    term.name, {"lo": np.minimum(lo + cut, mid), "hi": np.maximum(hi - cut, mid)}
                )
    return largest
