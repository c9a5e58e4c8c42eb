"""Coal signed-distance constraints on maximal-coordinate body poses.

``c = margin - d(R, p) ≤ 0`` for one (robot geometry, obstacle) pair of
:class:`~mbplan.multibody.collision.CollisionPairs` per site, with the body pose ``(R, p)``
(joint-frame orientation, COM position) of the link that carries the geometry. Gradient and
fixed-witness-point Hessian as derived in :mod:`mbplan.multibody.collision`: with
``a = Rᵀ(p₁ - p)`` and ``m = Rᵀn``, ``∂c/∂ω = a × m``, ``∂c/∂δp = n`` and the ``ω``-block
``½(m aᵀ + a mᵀ) - (mᵀa) I``.

Between knots (:func:`interval_distance_function`) the poses are
:func:`~mbplan.transcription.intervals.interval_pose` of knot ``k``'s ``(R, p, F, v)`` at the
fractions ``s - δ, s, s + δ`` of the interval; coal gives the distances and witness points
there, and three rows keep the line through the distances at ``s ∓ δ`` above the margin at both
ends of the interval (``σ = 0, 1``) and the distance at ``s`` above it: where the distance is
convex along the interval (a point moving on a line, a convex obstacle) the line lies below it
outside ``[s - δ, s + δ]``, so the margin holds along the interval up to dips between the
samples (:data:`~mbplan.transcription.intervals.SECANT_HALF_WIDTH`). The rows are fixed linear
combinations of the distances, so their derivatives are the same combinations of the
fixed-witness-point model ``nᵀ(p_s + R_s a)``'s at each sample, through the interpolation, by
CasADi (:func:`_interval_witness_model`).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import casadi as cs
import numpy as np

from mbplan.engine import CallbackFunction, RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.multibody.collision import CollisionPairs, Contacts, signed_distances
from mbplan.transcription.intervals import INTERVAL_ROWS, interval_pose, secant_weights

_LOWER = np.tril_indices(3)


def pair_bodies(mm: MaximalModel, pairs: CollisionPairs) -> np.ndarray:
    """The body ``(P,)`` that carries the robot geometry of each pair."""
    body_of_joint = {int(j): b for b, j in enumerate(mm.pin_joint)}
    missing = sorted({int(j) for j in pairs.joint} - set(body_of_joint))
    if missing:
        raise InputError(f"collision geometry on Pinocchio joints {missing}, which move no body")
    return np.array([body_of_joint[int(j)] for j in pairs.joint], dtype=np.int64)


def _body_contacts(
    mm: MaximalModel, pairs: CollisionPairs
) -> Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], Contacts]:
    """``contacts(pair, R, p, cap)``: coal's capped contacts of each site's pair with its link's
    body at ``(R, p)``."""
    body = pair_bodies(mm, pairs)
    rotation = pairs.placement[:, :3, :3]  # geometry in the body frame: the joint's orientation
    offset = pairs.placement[:, :3, 3] - mm.com_in_joint[body]  # and the COM as origin

    def contacts(pair: np.ndarray, Rb: np.ndarray, pb: np.ndarray, cap: np.ndarray) -> Contacts:
        pose_t = pb + np.einsum("kij,kj->ki", Rb, offset[pair])
        return signed_distances(pairs, pair, Rb @ rotation[pair], pose_t, cap)

    return contacts


def distance_constraint_function(
    mm: MaximalModel, pairs: CollisionPairs, activation: float = np.inf
) -> CallbackFunction:
    """``margin - min(d, margin + activation)`` of pair ``pair`` with its link's body at
    ``(R, p)``; parameters ``pair`` (index into ``pairs``) and ``margin`` (m)."""
    body_contacts = _body_contacts(mm, pairs)

    def evaluate(variables, parameters, multipliers, order):
        Rb, pb = variables["R"], variables["p"]
        pair = parameters[:, 0].astype(np.int64)
        contacts = body_contacts(pair, Rb, pb, parameters[:, 1] + activation)
        outs = [(parameters[:, 1] - contacts.distance)[:, None]]
        if order == 0:
            return outs
        a = np.einsum("kji,kj->ki", Rb, contacts.robot_point - pb)
        m = np.einsum("kji,kj->ki", Rb, contacts.normal)
        outs.append(np.concatenate([np.cross(a, m), contacts.normal], axis=1))
        if order == 2:
            H = 0.5 * (m[:, :, None] * a[:, None, :] + a[:, :, None] * m[:, None, :])
            H -= np.einsum("ki,ki->k", m, a)[:, None, None] * np.eye(3)
            outs.append(multipliers[:, :1] * H[:, _LOWER[0], _LOWER[1]])
        return outs

    return CallbackFunction(
        "coal_distance",
        [("R", SO3), ("p", R(3))],
        [("pair", 1), ("margin", 1)],
        m=1,
        jacobian_pattern=(np.zeros(6, np.int64), np.arange(6)),
        hessian_pattern=_LOWER,
        evaluate=evaluate,
    )


SECANT_REACH = 0.25
"""m: distances between knots are computed up to this beyond the rows' cap, so that a secant
row reaches its cap continuously (up to link speeds of about ``0.25/Δt``)."""


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _interval_witness_model(jit: bool) -> RiemannianFunction:
    """``nᵀ(p_s + R_s a)`` of the pose ``(R_s, p_s)`` between knots
    (:func:`~mbplan.transcription.intervals.interval_pose`) with the witness point ``a`` (body
    frame) and the normal ``n`` fixed: the derivatives of ``margin - d`` there."""

    def model(R, p, F, v, a, n, s, h):
        Rs, ps = interval_pose(R, p, F, v, s, h)
        return cs.dot(n, ps + cs.mtimes(Rs, a))

    variables = [("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3))]
    parameters = [("a", 3), ("n", 3), ("s", 1), ("h", 1)]
    return RiemannianFunction("interval_witness", variables, model, parameters, jit=jit)


def interval_distance_function(
    mm: MaximalModel, pairs: CollisionPairs, activation: float = np.inf, jit: bool = False
) -> CallbackFunction:
    """The rows between knots ``margin - min(ℓ_i, margin + activation)`` of pair ``pair`` on
    interval ``k`` from knot ``(R, p, F, v)``: ``ℓ_0, ℓ_1`` the line through the distances at the
    fractions ``s ∓ δ`` of the interval at its ends, ``ℓ_2`` the distance at ``s``
    (:func:`~mbplan.transcription.intervals.secant_weights`). Where the distance along the
    interval is convex (a point moving on a line, a convex obstacle) the line lies below it
    outside ``[s - δ, s + δ]``, so rows ``≤ 0`` keep the margin along the interval but for dips
    between the samples. Parameters ``pair``, ``margin`` (m), the centre ``s`` and ``Δt`` (s)."""
    body_contacts = _body_contacts(mm, pairs)
    witness = _interval_witness_model(jit)

    def evaluate(variables, parameters, multipliers, order):
        K = len(parameters)
        pair, margin = parameters[:, 0].astype(np.int64), parameters[:, 1]
        s, dt = parameters[:, 2], parameters[:, 3]
        cap = margin + activation
        samples, weights = secant_weights(s)
        S = samples.shape[1]
        # the samples as one batch of S·K sites: sample j of site k is row j·K + k
        every = {n: np.concatenate([x] * S) for n, x in variables.items()}
        t = samples.T.ravel()
        h = t * np.tile(dt, S)
        Rt, pt = interval_pose(every["R"], every["p"], every["F"], every["v"], t, h)
        contacts = body_contacts(np.tile(pair, S), Rt, pt, np.tile(cap + SECANT_REACH, S))
        line = np.einsum("kij,kj->ki", weights, contacts.distance.reshape(S, K).T)
        active = line < cap[:, None]
        outs = [margin[:, None] - np.minimum(line, cap[:, None])]
        if order == 0:
            return outs
        # row i = Σ_j w_ij (margin - d_j): its derivatives are Σ_j w_ij ∂(nⱼᵀ p₁ⱼ)
        w = weights * active[:, :, None]
        a = np.einsum("kji,kj->ki", Rt, contacts.robot_point - pt)
        model = {"a": a, "n": contacts.normal, "s": t, "h": h}
        if order == 1:
            J = witness.jacobian(every, model)[1]
        else:
            mu = np.einsum("ki,kij->jk", multipliers, w).reshape(-1, 1)
            _, J, H = witness.hessian(every, model, mu)
        jac = np.einsum("kij,jkn->kin", w, J.reshape(S, K, -1)).reshape(K, -1)
        return [*outs, jac] if order == 1 else [*outs, jac, H.reshape(S, K, -1).sum(axis=0)]

    return CallbackFunction(
        "coal_interval_distance",
        [("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3))],
        [("pair", 1), ("margin", 1), ("s", 1), ("dt", 1)],
        m=INTERVAL_ROWS,
        jacobian_pattern=(
            np.repeat(np.arange(INTERVAL_ROWS), witness.jac_nnz),
            np.tile(witness.jac_cols, INTERVAL_ROWS),
        ),
        hessian_pattern=(witness.hess_rows, witness.hess_cols),
        evaluate=evaluate,
    )
