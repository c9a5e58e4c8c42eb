"""Signed distances between a robot's collision geometry and fixed obstacles (coal), with
derivatives in joint space and in maximal coordinates.

For a robot geometry (coal object 1) and an obstacle (object 2), coal returns the signed distance
``d`` (< 0: penetration depth), the witness points ``p₁``, ``p₂`` and the unit normal ``n`` from
object 1 to object 2, with ``d = nᵀ(p₂ - p₁)``. Away from degenerate contacts (parallel faces,
several closest pairs) ``d`` is differentiable and, by the envelope theorem, its first derivative
is that of ``nᵀ(p₂ - p₁)`` with ``n`` fixed and the witness points moving with their bodies::

    δd = nᵀ(δp₂ - δp₁) = -nᵀ δp₁        (the obstacle is fixed).

The constraint ``c = margin - d ≤ 0`` therefore has the gradients

* joint space: ``∂c/∂q = nᵀ J₁(q)``, ``J₁`` the world Jacobian of ``p₁`` held fixed in its link
  (:func:`point_jacobians`);
* maximal coordinates, body pose ``(R, p)`` perturbed as ``(R exp(ω), p + δp)`` with the witness
  point ``a = Rᵀ(p₁ - p)`` in the body frame: ``∂c/∂δp = n``, ``∂c/∂ω = a × (Rᵀ n)``.

Second-order term. The exact Hessian of ``d`` adds to the Hessian of the fixed-witness-point
model ``nᵀ(p₂ - p₁(x))`` the terms of the witness points sliding over the surfaces and of the
normal turning, which depend on the surface curvatures at the contact and are not available from
coal (and jump on polyhedral features). They are dropped: both formulations use the Hessian of
the fixed-witness-point, fixed-normal model, i.e. ``nᵀ ∂²p₁/∂q²`` (:func:`point_hessians`) in
joint space and, in maximal coordinates, from ``p₁(ω) = p + R(I + ω^ + ½ω^²)a``, the
``ω``-block ``½(m aᵀ + a mᵀ) - (mᵀa) I`` with ``m = Rᵀn`` (no ``δp`` terms). This is exact for
the first derivative everywhere smooth and for the Hessian when both surfaces are flat at the
contact; the solvers' globalisation handles the rest (a Gauss–Newton-like treatment).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from mbplan.errors import InputError

# witness points are accurate to about sqrt(tolerance) (gradient errors 3e-6 at 1e-10, 1.5e-7 at
# 1e-14 against finite differences; coal's default 1e-6 is far too loose for derivatives);
# EPA (penetration) fails at 1e-10 on the iiwa's cylinders, hence 1e-8 there.
GJK_TOLERANCE = 1e-13
EPA_TOLERANCE = 1e-8
_FAILED = 1e100  # coal reports a failed GJK/EPA as ±DBL_MAX
# At the tight tolerance GJK occasionally fails or stops at a wrong, finite distance (seen on
# the iiwa's link cylinders: 0.021 m where 1e-9 rad away it is 0.085 m, and errors of 1e-7 to
# 1e-5 m near solutions); a request at CHECK_TOLERANCE is the cross-check, and where the two
# differ by more than _CROSS_CHECK its result is used. (Coal's default request, 1e-6, as the
# check let value jumps of up to 6.5e-6 through, above the RIPM's tol, and
# line searches failed on them.)
CHECK_TOLERANCE = 1e-11
_CROSS_CHECK = 1e-8


@dataclass(frozen=True, eq=False)
class CollisionPairs:
    """Every (robot collision geometry, obstacle) pair, for geometries on moving links.

    Pair ``i`` couples geometry ``geometry[i]`` of the ``pin.GeometryModel``, attached to joint
    ``joint[i]`` at ``placement[i]`` (4x4, joint frame), with obstacle ``obstacle[i]``.
    """

    joint: np.ndarray  # (P,) int
    geometry: np.ndarray  # (P,) int
    obstacle: np.ndarray  # (P,) int
    placement: np.ndarray  # (P, 4, 4)
    names: tuple[str, ...]  # (P,) "geometry/obstacle i"
    robot_shapes: tuple[coal.CollisionGeometry, ...]
    obstacle_shapes: tuple[coal.CollisionGeometry, ...]
    obstacle_transforms: tuple[coal.Transform3s, ...]

    @property
    def size(self) -> int:
        return len(self.joint)


def collision_pairs(
    geometry_model: pin.GeometryModel,
    obstacles: Sequence[tuple[coal.CollisionGeometry, np.ndarray]],
) -> CollisionPairs:
    """Pairs of every geometry attached to a moving joint (``parentJoint > 0``; the base's
    distance cannot change) with every obstacle ``(coal shape, 4x4 world pose)``."""
    geoms = [
        (g, obj) for g, obj in enumerate(geometry_model.geometryObjects) if obj.parentJoint > 0
    ]
    if not geoms:
        raise InputError("the robot has no collision geometry on a moving link")
    rows = [(g, obj, o) for g, obj in geoms for o in range(len(obstacles))]
    return CollisionPairs(
        joint=np.array([obj.parentJoint for _, obj, _ in rows], dtype=np.int64),
        geometry=np.array([g for g, _, _ in rows], dtype=np.int64),
        obstacle=np.array([o for _, _, o in rows], dtype=np.int64),
        placement=np.array([obj.placement.homogeneous for _, obj, _ in rows]).reshape(-1, 4, 4),
        names=tuple(f"{obj.name}/obstacle {o}" for _, obj, o in rows),
        robot_shapes=tuple(obj.geometry for _, obj, _ in rows),
        obstacle_shapes=tuple(obstacles[o][0] for _, _, o in rows),
        obstacle_transforms=tuple(
            coal.Transform3s(obstacles[o][1][:3, :3], obstacles[o][1][:3, 3]) for _, _, o in rows
        ),
    )


@dataclass(frozen=True)
class Contacts:
    """Coal's answer per evaluated pair: ``distance (S,)``, unit ``normal (S, 3)`` from the robot
    geometry to the obstacle and the robot's witness point ``robot_point (S, 3)`` (world)."""

    distance: np.ndarray
    normal: np.ndarray
    robot_point: np.ndarray


def signed_distances(
    pairs: CollisionPairs, pair: np.ndarray, rotation: np.ndarray, translation: np.ndarray
) -> Contacts:
    """Coal distances of pairs ``pair (S,)`` with the robot geometries at world placements
    ``rotation (S, 3, 3)``, ``translation (S, 3)``: the tight request's, unless the check
    request's differs by more than ``_CROSS_CHECK`` or the tight one fails; coal's defaults if
    both fail; :class:`InputError` if that fails too."""
    tight, check = coal.DistanceRequest(), coal.DistanceRequest()
    tight.gjk_tolerance, tight.epa_tolerance = GJK_TOLERANCE, EPA_TOLERANCE
    check.gjk_tolerance, check.epa_tolerance = CHECK_TOLERANCE, EPA_TOLERANCE
    S = len(pair)
    distance, normal, point = np.empty(S), np.empty((S, 3)), np.empty((S, 3))
    for s, i in enumerate(pair.tolist()):
        placement = coal.Transform3s(rotation[s], translation[s])
        found = [r for r in (_distance(pairs, i, placement, q) for q in (tight, check)) if r]
        if not found:
            found = [r for r in [_distance(pairs, i, placement, coal.DistanceRequest())] if r]
        if not found:
            raise InputError(f"coal failed to compute the distance of {pairs.names[i]}")
        d, result = found[0]
        if len(found) == 2 and abs(d - found[1][0]) > _CROSS_CHECK:
            d, result = found[1]  # the tight GJK stopped at a wrong distance
        distance[s] = d
        normal[s] = result.normal
        point[s] = result.getNearestPoint1()
    return Contacts(distance, normal, point)


def _distance(
    pairs: CollisionPairs, i: int, placement: coal.Transform3s, request: coal.DistanceRequest
) -> tuple[float, coal.DistanceResult] | None:
    """Coal's distance of pair ``i`` with its result, ``None`` where GJK/EPA failed."""
    result = coal.DistanceResult()
    d = coal.distance(
        pairs.robot_shapes[i],
        placement,
        pairs.obstacle_shapes[i],
        pairs.obstacle_transforms[i],
        request,
        result,
    )
    return (d, result) if abs(d) < _FAILED else None


# ---------------------------------------------------------------------------- joint space
@dataclass(frozen=True)
class ChainKinematics:
    """Joint placements and world-frame joint Jacobians at ``K`` configurations.

    ``rotation (K, njoints, 3, 3)``, ``translation (K, njoints, 3)`` (``data.oMi``); ``linear``
    and ``angular (K, nv, 3)``: column ``j`` of ``data.J`` (the twist of velocity ``j``, linear
    part at the world origin); ``support (njoints, nv)``: velocity ``j`` moves joint ``i``.
    """

    rotation: np.ndarray
    translation: np.ndarray
    linear: np.ndarray
    angular: np.ndarray
    support: np.ndarray


def chain_kinematics(model: pin.Model, data: pin.Data, q: np.ndarray) -> ChainKinematics:
    """:class:`ChainKinematics` at ``q (K, nq)`` (one ``computeJointJacobians`` per knot)."""
    K = len(q)
    H = np.empty((K, model.njoints, 4, 4))
    twists = np.empty((K, 6, model.nv))
    for k, qk in enumerate(q):
        pin.computeJointJacobians(model, data, qk)
        twists[k] = data.J
        H[k] = [M.homogeneous for M in data.oMi]  # one 4 × 4 matrix per joint
    return ChainKinematics(
        np.ascontiguousarray(H[:, :, :3, :3]),
        np.ascontiguousarray(H[:, :, :3, 3]),
        np.swapaxes(twists[:, :3], 1, 2),
        np.swapaxes(twists[:, 3:], 1, 2),
        joint_support(model),
    )


def joint_support(model: pin.Model) -> np.ndarray:
    """``(njoints, nv)`` bool: velocity ``j`` moves joint ``i`` (its frame and link)."""
    support = np.zeros((model.njoints, model.nv), bool)
    for j in range(1, model.njoints):
        for a in model.supports[j][1:]:
            first = model.joints[a].idx_v
            support[j, first : first + model.joints[a].nv] = True
    return support


def point_jacobians(kin: ChainKinematics, joint: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World Jacobians ``(K, P, nv, 3)`` (``[..., j, :] = ∂p/∂q_j``) of points ``(K, P, 3)``
    fixed in the links of joints ``joint (P,)``: ``v_j + ω_j × p`` for the velocities ``j`` that
    move the link."""
    J = kin.linear[:, None] + np.cross(kin.angular[:, None], points[:, :, None, :])
    return J * kin.support[joint][None, :, :, None]


def point_hessians(kin: ChainKinematics, joint: np.ndarray, jacobians: np.ndarray) -> np.ndarray:
    """Second derivatives ``(K, P, nv, nv, 3)`` of the points of :func:`point_jacobians` for a
    chain of 1-dof joints: ``∂²p/∂q_j∂q_l = ω_min(j,l) × J_max(j,l)`` (a prismatic joint has
    ``ω = 0``) for ``j, l`` moving the link, with the velocity order along the chain."""
    C = np.cross(kin.angular[:, None, :, None, :], jacobians[:, :, None, :, :])
    nv = kin.support.shape[1]
    upper = np.triu(np.ones((nv, nv), bool))[None, None, :, :, None]
    H = np.where(upper, C, np.swapaxes(C, 2, 3))
    moved = kin.support[joint]
    return H * (moved[:, :, None] & moved[:, None, :])[None, ..., None]


def joint_space_contacts(
    pairs: CollisionPairs, kin: ChainKinematics
) -> tuple[Contacts, np.ndarray]:
    """Contacts of every pair at every knot of ``kin`` (fields shaped ``(K, P, …)``) and the
    world Jacobians ``(K, P, nv, 3)`` of the robot witness points."""
    K, P = kin.rotation.shape[0], pairs.size
    R_joint = kin.rotation[:, pairs.joint]  # (K, P, 3, 3)
    rotation = R_joint @ pairs.placement[:, :3, :3]
    translation = kin.translation[:, pairs.joint] + np.einsum(
        "kpij,pj->kpi", R_joint, pairs.placement[:, :3, 3]
    )
    flat = signed_distances(
        pairs, np.tile(np.arange(P), K), rotation.reshape(-1, 3, 3), translation.reshape(-1, 3)
    )
    contacts = Contacts(
        flat.distance.reshape(K, P), flat.normal.reshape(K, P, 3), flat.robot_point.reshape(K, P, 3)
    )
    return contacts, point_jacobians(kin, pairs.joint, contacts.robot_point)
