"""Coal signed-distance constraints on maximal-coordinate body poses.

``c = margin - d(R, p) ≤ 0`` for one (robot geometry, obstacle) pair of
:class:`~mbplan.multibody.collision.CollisionPairs` per site, with the body pose ``(R, p)``
(joint-frame orientation, COM position) of the link that carries the geometry. Gradient and
fixed-witness-point Hessian as derived in :mod:`mbplan.multibody.collision`: with
``a = Rᵀ(p₁ - p)`` and ``m = Rᵀn``, ``∂c/∂ω = a × m``, ``∂c/∂δp = n`` and the ``ω``-block
``½(m aᵀ + a mᵀ) - (mᵀa) I``.

Between knots (:func:`interval_distance_function`) the pose is
:func:`~mbplan.transcription.intervals.interval_pose` of knot ``k``'s ``(R, p, F, v)``; coal gives
the witness point there, and the derivatives are those of the same fixed-witness-point model
``nᵀ(p_s + R_s a)`` through the interpolation, by CasADi (:func:`_interval_witness_model`).
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
from mbplan.transcription.intervals import interval_pose

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
    """``margin - min(d, margin + activation)`` of pair ``pair`` with its link's body at the
    fraction ``s`` of the interval from knot ``(R, p, F, v)``; parameters ``pair``, ``margin``
    (m), ``s`` and ``h = sΔt`` (s)."""
    body_contacts = _body_contacts(mm, pairs)
    witness = _interval_witness_model(jit)

    def evaluate(variables, parameters, multipliers, order):
        Rb, pb, F, v = (variables[n] for n in ("R", "p", "F", "v"))
        pair = parameters[:, 0].astype(np.int64)
        Rs, ps = interval_pose(Rb, pb, F, v, parameters[:, 2], parameters[:, 3])
        contacts = body_contacts(pair, Rs, ps, parameters[:, 1] + activation)
        outs = [(parameters[:, 1] - contacts.distance)[:, None]]
        if order == 0:
            return outs
        a = np.einsum("kji,kj->ki", Rs, contacts.robot_point - ps)
        model = {"a": a, "n": contacts.normal, "s": parameters[:, 2], "h": parameters[:, 3]}
        if order == 1:
            return [*outs, witness.jacobian(variables, model)[1]]
        return [*outs, *witness.hessian(variables, model, multipliers)[1:]]

    return CallbackFunction(
        "coal_interval_distance",
        [("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3))],
        [("pair", 1), ("margin", 1), ("s", 1), ("h", 1)],
        m=1,
        jacobian_pattern=(witness.jac_rows, witness.jac_cols),
        hessian_pattern=(witness.hess_rows, witness.hess_cols),
        evaluate=evaluate,
    )
