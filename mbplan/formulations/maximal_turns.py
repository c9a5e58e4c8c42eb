"""Position limits of revolute joints whose range is a turn or more (less
:data:`~mbplan.residuals.limits.TURN_ROUNDING`), in maximal coordinates: the references their
rows count the turns from.

A rotation forgets the turns, so :class:`~mbplan.residuals.JointPositionLimits` bounds
``θ = θ_ref + Δ`` per knot, ``Δ ∈ (-π, π]`` the signed angle of the joint's relative rotation
from ``R_rel0 exp(θ_ref a)``. The references are a chart: moving ``θ_ref`` to ``θ_ref + Δ`` leaves
``θ`` and its derivatives unchanged while ``|Δ| < π``. A solve starts from references at the
warm start's angles (:func:`center_turns`); the RIPM moves them along its iterates
(:func:`follow_turns`, its problem's ``accept``), so the rows count the turns the iterates make,
as a plan's reported angles (unwrapped from knot to knot) count them along the knots. A plan
whose angles still left its references (a solver without ``accept``: MLG-IPM) solves again from
references at its angles (:func:`~mbplan.planning.methods.solve_ripm_maximal`'s rounds).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mbplan.multibody.state_maps import signed_angle
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Point

FOLLOW = 0.5 * np.pi  # references farther than this from an accepted iterate follow it


def _turn_terms(nlp: Any) -> list[Term]:
    return [t for t in nlp.problem.terms if "theta_ref" in t.parameters]


def _set_turns(nlp: Any, term: Term, at: np.ndarray, theta: np.ndarray) -> None:
    """Move the references of ``term``'s sites ``at`` (a mask) to the angles ``theta``."""
    body = term.bind["Rc"][1] % nlp.mm.nb
    ref = np.array(np.broadcast_to(term.parameters["theta_ref"], body.shape))
    ref[at] = theta[at]
    nlp.problem.set_parameters(term.name, {"theta_ref": ref, "R_ref": nlp.about_axis(body, ref)})


def center_turns(nlp: Any, q: np.ndarray, beyond: float = 0.0) -> bool:
    """Set the references of a :class:`~mbplan.formulations.maximal.MaximalNLP`'s turn-counting
    rows to the angles of the joint path ``q (N+1, nq)`` where they differ by more than
    ``beyond`` (a solve's warm start: all; a plan: where the rows' turns disagree with its
    reported angles). Whether any reference moved."""
    mm, moved = nlp.mm, False
    for term in _turn_terms(nlp):
        flat = term.bind["Rc"][1]
        theta = np.asarray(q, dtype=float)[flat // mm.nb, mm.idx_q[flat % mm.nb]]
        at = np.abs(theta - term.parameters["theta_ref"]) > beyond
        if at.any():
            _set_turns(nlp, term, at, theta)
            moved = True
    return moved


def follow_turns(nlp: Any, point: Point) -> None:
    """References farther than :data:`FOLLOW` from the accepted ``point``'s angles move to them
    (the angle ``θ_ref + Δ`` unchanged: only the chart moves)."""
    R = np.asarray(point["R"]).reshape(-1, 3, 3)
    for term in _turn_terms(nlp):
        rel = R[term.bind["Rc"][1]]
        if "Rp" in term.bind:
            rel = np.swapaxes(R[term.bind["Rp"][1]], -1, -2) @ rel
        E = np.swapaxes(term.parameters["R_ref"], -1, -2) @ rel
        delta = signed_angle(E, term.parameters["a"])
        at = np.abs(delta) > FOLLOW
        if at.any():
            _set_turns(nlp, term, at, term.parameters["theta_ref"] + delta)
