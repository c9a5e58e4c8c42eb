"""Coal signed-distance constraints on maximal-coordinate body poses.

``c = margin - d(R, p) ≤ 0`` for one (robot geometry, obstacle) pair of
:class:`~mbplan.multibody.collision.CollisionPairs` per site, with the body pose ``(R, p)``
(joint-frame orientation, COM position) of the link that carries the geometry. Gradient and
fixed-witness-point Hessian as derived in :mod:`mbplan.multibody.collision`: with
``a = Rᵀ(p₁ - p)`` and ``m = Rᵀn``, ``∂c/∂ω = a × m``, ``∂c/∂δp = n`` and the ``ω``-block
``½(m aᵀ + a mᵀ) - (mᵀa) I``.
"""

from __future__ import annotations

import numpy as np

from mbplan.engine import CallbackFunction
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.multibody.collision import CollisionPairs, signed_distances

_LOWER = np.tril_indices(3)


def pair_bodies(mm: MaximalModel, pairs: CollisionPairs) -> np.ndarray:
    """The body ``(P,)`` that carries the robot geometry of each pair."""
    body_of_joint = {int(j): b for b, j in enumerate(mm.pin_joint)}
    missing = sorted({int(j) for j in pairs.joint} - set(body_of_joint))
    if missing:
        raise InputError(f"collision geometry on Pinocchio joints {missing}, which move no body")
    return np.array([body_of_joint[int(j)] for j in pairs.joint], dtype=np.int64)


def distance_constraint_function(
    mm: MaximalModel, pairs: CollisionPairs, activation: float = np.inf
) -> CallbackFunction:
    """``margin - min(d, margin + activation)`` of pair ``pair`` with its link's body at
    ``(R, p)``; parameters ``pair`` (index into ``pairs``) and ``margin`` (m)."""
    body = pair_bodies(mm, pairs)
    rotation = pairs.placement[:, :3, :3]  # geometry in the body frame: the joint's orientation
    offset = pairs.placement[:, :3, 3] - mm.com_in_joint[body]  # and the COM as origin

    def evaluate(variables, parameters, multipliers, order):
        Rb, pb = variables["R"], variables["p"]
        pair = parameters[:, 0].astype(np.int64)
        contacts = signed_distances(
            pairs,
            pair,
            Rb @ rotation[pair],
            pb + np.einsum("kij,kj->ki", Rb, offset[pair]),
            parameters[:, 1] + activation,
        )
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
