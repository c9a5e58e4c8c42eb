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

Far pairs. With a ``cap`` the distance is ``min(d, cap)``: continuous, and constant with zero
derivatives (a zero normal) above the cap, so the constraint ``margin - min(d, cap) ≤ 0`` has the
feasible set of the uncapped one for ``cap > margin``. A pair whose lower bound (bounding sphere
of one shape against the box of the other, vectorized over all pairs) exceeds the cap is not
sent to coal.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.multibody import coal_pass
from mbplan.multibody.convex import collision_geometry, is_polytope

# witness points are accurate to about sqrt(tolerance) (gradient errors 3e-6 at 1e-10, 1.5e-7 at
# 1e-14 against finite differences; coal's default 1e-6 is far too loose for derivatives);
# EPA (penetration) fails at 1e-10 on the iiwa's cylinders, hence 1e-8 there.
GJK_TOLERANCE = 1e-13
EPA_TOLERANCE = 1e-8
_FAILED = 1e100  # coal reports a failed GJK/EPA as ±DBL_MAX
# At the tight tolerance GJK occasionally fails or stops at a wrong, finite distance on curved
# shapes (seen on the iiwa's link cylinders: 0.021 m where 1e-9 rad away it is 0.085 m, and
# errors of 1e-7 to 1e-5 m near solutions); a request at CHECK_TOLERANCE is the cross-check, and
# where the two differ by more than _CROSS_CHECK its result is used. (Coal's default request,
# 1e-6, as the check let value jumps of up to 6.5e-6 through, above the RIPM's tol, and line
# searches failed on them.)
CHECK_TOLERANCE = 1e-11
_CROSS_CHECK = 1e-8
# Between two convex polytopes GJK ends on the exact closest simplex: at 1e-10 it matched the
# tight request to the last bit on 6,000 random UR5 hull/box placements (1e-8 left errors of
# 3e-9, the duality-gap criterion 2e-9 at 1e-9), so one request, no cross-check.
POLYTOPE_TOLERANCE = 1e-10


# Between polytopes GJK starts from the shapes' bounding-box centres (coal's
# BoundingVolumeGuess; every shape's local AABB is computed, :mod:`mbplan.multibody.convex`):
# the same closest simplex as from coal's default direction (to 3e-16 m on a UR5 shelf
# iteration's 2,457 hull/box sites), in 7 % less time there (one thread). Curved and mesh pairs
# keep the default start, on which their cross-check was tuned.


def _request(gjk_tolerance: float, from_boxes: bool = False) -> coal.DistanceRequest:
    request = coal.DistanceRequest()
    request.gjk_tolerance, request.epa_tolerance = gjk_tolerance, EPA_TOLERANCE
    if from_boxes:
        request.gjk_initial_guess = coal.GJKInitialGuess.BoundingVolumeGuess
    return request


_POLYTOPE = _request(POLYTOPE_TOLERANCE, from_boxes=True)
_TIGHT, _CHECK = _request(GJK_TOLERANCE), _request(CHECK_TOLERANCE)


@dataclass(frozen=True, eq=False)
class CollisionPairs:
    """Every (robot collision geometry, obstacle) pair, for geometries on moving links.

    Pair ``i`` couples geometry ``geometry[i]`` of the ``pin.GeometryModel``, attached to joint
    ``joint[i]`` at ``placement[i]`` (4x4, joint frame), with obstacle ``obstacle[i]`` at
    ``obstacle_rotation[i]``, ``obstacle_translation[i]`` (world). ``*_center``, ``*_half``
    ``(P, 3)``: each shape's local axis-aligned bounding box (in its own frame), for
    :func:`lower_bounds`; ``checked (P,)``: the pair has a curved or mesh shape, whose GJK result
    is cross-checked (two polytopes are not).
    """

    joint: np.ndarray  # (P,) int
    geometry: np.ndarray  # (P,) int
    obstacle: np.ndarray  # (P,) int
    placement: np.ndarray  # (P, 4, 4)
    names: tuple[str, ...]  # (P,) "geometry/obstacle i"
    robot_shapes: tuple[coal.CollisionGeometry, ...]
    obstacle_shapes: tuple[coal.CollisionGeometry, ...]
    obstacle_transforms: tuple[coal.Transform3s, ...]
    obstacle_rotation: np.ndarray  # (P, 3, 3)
    obstacle_translation: np.ndarray  # (P, 3)
    robot_center: np.ndarray
    robot_half: np.ndarray
    obstacle_center: np.ndarray
    obstacle_half: np.ndarray
    checked: np.ndarray  # (P,) bool

    @property
    def size(self) -> int:
        return len(self.joint)


def collision_pairs(
    geometry_model: pin.GeometryModel,
    obstacles: Sequence[tuple[coal.CollisionGeometry, np.ndarray]],
    geometry: str = "convex",
) -> CollisionPairs:
    """Pairs of every geometry attached to a moving joint (``parentJoint > 0``; the base's
    distance cannot change) with every obstacle ``(coal shape, 4x4 world pose)``; meshes as
    their convex hulls or as they are (``geometry``, see :mod:`mbplan.multibody.convex`)."""
    geoms = [
        (g, obj) for g, obj in enumerate(geometry_model.geometryObjects) if obj.parentJoint > 0
    ]
    if not geoms:
        raise InputError("the robot has no collision geometry on a moving link")
    shapes = {
        g: collision_geometry(
            obj.geometry, geometry, f"collision geometry {obj.name!r} (mesh {obj.meshPath!r})"
        )
        for g, obj in geoms
    }
    solids = [
        collision_geometry(shape, geometry, f"obstacle {o}", InputError)
        for o, (shape, _) in enumerate(obstacles)
    ]
    rows = [(g, obj, o) for g, obj in geoms for o in range(len(obstacles))]
    robot, obstacle = [shapes[g] for g, _, _ in rows], [solids[o] for _, _, o in rows]
    pose = np.array([obstacles[o][1] for _, _, o in rows]).reshape(-1, 4, 4)
    (robot_center, robot_half), (obstacle_center, obstacle_half) = map(_boxes, (robot, obstacle))
    return CollisionPairs(
        joint=np.array([obj.parentJoint for _, obj, _ in rows], dtype=np.int64),
        geometry=np.array([g for g, _, _ in rows], dtype=np.int64),
        obstacle=np.array([o for _, _, o in rows], dtype=np.int64),
        placement=np.array([obj.placement.homogeneous for _, obj, _ in rows]).reshape(-1, 4, 4),
        names=tuple(f"{obj.name}/obstacle {o}" for _, obj, o in rows),
        robot_shapes=tuple(robot),
        obstacle_shapes=tuple(obstacle),
        obstacle_transforms=tuple(coal.Transform3s(T[:3, :3], T[:3, 3]) for T in pose),
        obstacle_rotation=pose[:, :3, :3],
        obstacle_translation=pose[:, :3, 3],
        robot_center=robot_center,
        robot_half=robot_half,
        obstacle_center=obstacle_center,
        obstacle_half=obstacle_half,
        checked=np.array(
            [not (is_polytope(a) and is_polytope(b)) for a, b in zip(robot, obstacle, strict=True)]
        ),
    )


def _boxes(shapes: Sequence[coal.CollisionGeometry]) -> tuple[np.ndarray, np.ndarray]:
    """Centers and half extents ``(n, 3)`` of the shapes' local AABBs."""
    lo = np.array([s.aabb_local.min_ for s in shapes]).reshape(-1, 3)
    hi = np.array([s.aabb_local.max_ for s in shapes]).reshape(-1, 3)
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def lower_bounds(
    pairs: CollisionPairs, pair: np.ndarray, rotation: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """Lower bounds ``(S,)`` of the distances of pairs ``pair (S,)`` (robot geometries at
    ``rotation (S, 3, 3)``, ``translation (S, 3)``): the larger of the gaps between one shape's
    bounding sphere (around its AABB) and the other's AABB, each box in its shape's frame."""
    R_o, t_o = pairs.obstacle_rotation[pair], pairs.obstacle_translation[pair]
    c_r, h_r = pairs.robot_center[pair], pairs.robot_half[pair]
    c_o, h_o = pairs.obstacle_center[pair], pairs.obstacle_half[pair]
    robot_center = translation + np.einsum("sij,sj->si", rotation, c_r)
    obstacle_center = t_o + np.einsum("sij,sj->si", R_o, c_o)
    gap_r = _box_gap(np.einsum("sji,sj->si", R_o, robot_center - t_o) - c_o, h_o)
    gap_o = _box_gap(np.einsum("sji,sj->si", rotation, obstacle_center - translation) - c_r, h_r)
    return np.maximum(gap_r - np.linalg.norm(h_r, axis=1), gap_o - np.linalg.norm(h_o, axis=1))


def _box_gap(x: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Distances ``(S,)`` of points ``x (S, 3)`` to the boxes ``|y| ≤ half`` (0 inside)."""
    return np.linalg.norm(np.maximum(np.abs(x) - half, 0.0), axis=1)


@dataclass(frozen=True)
class Contacts:
    """Coal's answer per evaluated pair: ``distance (S,)``, unit ``normal (S, 3)`` from the robot
    geometry to the obstacle and the robot's witness point ``robot_point (S, 3)`` (world).
    A distance capped at ``cap`` (:func:`signed_distances`) has a zero normal."""

    distance: np.ndarray
    normal: np.ndarray
    robot_point: np.ndarray


def signed_distances(
    pairs: CollisionPairs,
    pair: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    cap: float | np.ndarray = np.inf,
) -> Contacts:
    """Coal distances of pairs ``pair (S,)`` with the robot geometries at world placements
    ``rotation (S, 3, 3)``, ``translation (S, 3)``, capped at ``cap`` (scalar or ``(S,)``).

    ``min(d, cap)`` is continuous, and constant (zero normal: zero derivatives) where
    ``d > cap``; a pair whose :func:`lower_bounds` exceeds ``cap`` is not sent to coal. One
    request per polytope pair; a curved or mesh pair's tight request is cross-checked
    (``_CROSS_CHECK``), coal's defaults if both fail, :class:`InputError` if that fails too.
    The pairs sent to coal are asked in one compiled call (:mod:`mbplan.multibody.coal_pass`),
    pair by pair from Python where it is not available."""
    S = len(pair)
    cap = np.broadcast_to(np.asarray(cap, dtype=float), (S,))
    found = coal_pass.site_distances(
        _pass_shapes(pairs), pair, rotation, translation, cap, _tolerances()
    )
    if found is not None:
        return Contacts(*found[:3])
    distance, normal, point = cap.copy(), np.zeros((S, 3)), np.array(translation, dtype=float)
    for s in np.flatnonzero(lower_bounds(pairs, pair, rotation, translation) <= cap).tolist():
        i, placement = int(pair[s]), coal.Transform3s(rotation[s], translation[s])
        d, result = _pair_distance(pairs, i, placement)
        if d < cap[s]:
            distance[s], normal[s], point[s] = d, result.normal, result.getNearestPoint1()
    return Contacts(distance, normal, point)


def _tolerances() -> np.ndarray:
    """The request policy as :mod:`mbplan.multibody.coal_pass` reads it."""
    return np.array(
        [POLYTOPE_TOLERANCE, GJK_TOLERANCE, CHECK_TOLERANCE, EPA_TOLERANCE, _CROSS_CHECK, _FAILED]
    )


def _pass_shapes(pairs: CollisionPairs) -> coal_pass.PairShapes:
    """The pairs as the compiled pass reads them (addresses taken now: they are the live
    objects' own, never stored)."""
    return coal_pass.PairShapes(
        robot=coal_pass.addresses(pairs.robot_shapes),
        obstacle=coal_pass.addresses(pairs.obstacle_shapes),
        checked=pairs.checked,
        robot_box=np.concatenate([pairs.robot_center, pairs.robot_half], axis=1),
        obstacle_box=np.concatenate([pairs.obstacle_center, pairs.obstacle_half], axis=1),
        obstacle_rotation=pairs.obstacle_rotation,
        obstacle_translation=pairs.obstacle_translation,
    )


def _pair_distance(
    pairs: CollisionPairs, i: int, placement: coal.Transform3s
) -> tuple[float, coal.DistanceResult]:
    """Coal's distance of pair ``i`` with its result (the request policy of
    :func:`signed_distances`)."""
    requests = (_TIGHT, _CHECK) if pairs.checked[i] else (_POLYTOPE,)
    found = [r for r in (_distance(pairs, i, placement, q) for q in requests) if r]
    if not found:
        found = [r for r in [_distance(pairs, i, placement, coal.DistanceRequest())] if r]
    if not found:
        raise InputError(f"coal failed to compute the distance of {pairs.names[i]}")
    if len(found) == 2 and abs(found[0][0] - found[1][0]) > _CROSS_CHECK:
        return found[1]  # the tight GJK stopped at a wrong distance
    return found[0]


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
        *_split(H),
        np.swapaxes(twists[:, :3], 1, 2),
        np.swapaxes(twists[:, 3:], 1, 2),
        joint_support(model),
    )


def joint_placements(
    model: pin.Model, data: pin.Data, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``data.oMi`` at ``q (K, nq)`` as :class:`ChainKinematics` holds it, ``rotation (K,
    njoints, 3, 3)`` and ``translation (K, njoints, 3)``, by forward kinematics alone (no
    Jacobians: what the distances' values need)."""
    H = np.empty((len(q), model.njoints, 4, 4))
    for k, qk in enumerate(q):
        pin.forwardKinematics(model, data, qk)
        H[k] = [M.homogeneous for M in data.oMi]
    return _split(H)


def _split(H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotations and translations of homogeneous matrices ``H (..., 4, 4)``."""
    return np.ascontiguousarray(H[..., :3, :3]), np.ascontiguousarray(H[..., :3, 3])


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
    pairs: CollisionPairs, kin: ChainKinematics, cap: float = np.inf
) -> tuple[Contacts, np.ndarray]:
    """Contacts of every pair at every knot of ``kin`` (:func:`placed_contacts`) and the world
    Jacobians ``(K, P, nv, 3)`` of the robot witness points."""
    contacts = placed_contacts(pairs, kin.rotation, kin.translation, cap)
    return contacts, point_jacobians(kin, pairs.joint, contacts.robot_point)


def placed_contacts(
    pairs: CollisionPairs,
    joint_rotation: np.ndarray,
    joint_translation: np.ndarray,
    cap: float = np.inf,
) -> Contacts:
    """Contacts of every pair with the joints at ``joint_rotation (K, njoints, 3, 3)``,
    ``joint_translation (K, njoints, 3)`` (fields shaped ``(K, P, …)``; distances capped at
    ``cap`` as by :func:`signed_distances`)."""
    K, P = joint_rotation.shape[0], pairs.size
    R_joint = joint_rotation[:, pairs.joint]  # (K, P, 3, 3)
    rotation = R_joint @ pairs.placement[:, :3, :3]
    translation = joint_translation[:, pairs.joint] + np.einsum(
        "kpij,pj->kpi", R_joint, pairs.placement[:, :3, 3]
    )
    flat = signed_distances(
        pairs,
        np.tile(np.arange(P), K),
        rotation.reshape(-1, 3, 3),
        translation.reshape(-1, 3),
        cap,
    )
    return Contacts(
        flat.distance.reshape(K, P), flat.normal.reshape(K, P, 3), flat.robot_point.reshape(K, P, 3)
    )
