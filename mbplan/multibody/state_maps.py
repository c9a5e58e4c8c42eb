"""Maps between Pinocchio's joint coordinates ``(q, v)`` and maximal coordinates.

Maximal coordinates of body ``i``: orientation ``R[i]`` (body frame -> world), COM position
``p[i]``, body angular velocity ``omega_body[i]`` (body frame, ``R^T dR/dt = omega^``) and COM
velocity ``v_com[i]`` (world frame). A floating base's free-flyer coordinates are its joint
frame's placement, ``q = (position, quaternion x y z w)``, and Pinocchio's local velocity
``v = (R^T d(position)/dt, omega_body)``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.multibody.model import MaximalModel
from mbplan.robots.free_body import quaternions


def body_poses(mm: MaximalModel, q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """World poses of the bodies at configuration ``q``: ``R`` (nb, 3, 3) and ``p`` (nb, 3); at
    configurations ``q (K, nq)``: ``R`` (K, nb, 3, 3) and ``p`` (K, nb, 3)."""
    q = np.asarray(q, dtype=float)
    q = _array(q, (len(q), mm.nq) if q.ndim == 2 else (mm.nq,), "q")
    flat = q.reshape(-1, mm.nq)
    H = np.empty((len(flat), mm.nb, 4, 4))
    data, joints = mm.model.createData(), mm.pin_joint.tolist()
    for k, qk in enumerate(flat):
        pin.forwardKinematics(mm.model, data, qk)
        H[k] = [data.oMi[j].homogeneous for j in joints]  # one 4 × 4 matrix per joint
    R = np.ascontiguousarray(H[:, :, :3, :3])
    p = H[:, :, :3, 3] + np.einsum("kbij,bj->kbi", R, mm.com_in_joint)
    return (R, p) if q.ndim == 2 else (R[0], p[0])


def body_velocities(
    mm: MaximalModel, q: npt.ArrayLike, v: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Body angular velocities (nb, 3, body frame) and COM velocities (nb, 3, world frame)."""
    q = _array(q, (mm.nq,), "q")
    v = _array(v, (mm.nv,), "v")
    data = mm.model.createData()
    pin.forwardKinematics(mm.model, data, q, v)
    R = np.array([data.oMi[j].rotation for j in mm.pin_joint.tolist()])
    omega = np.array([data.v[j].angular for j in mm.pin_joint.tolist()])
    v_origin = np.array([data.v[j].linear for j in mm.pin_joint.tolist()])
    v_com = np.einsum("bij,bj->bi", R, v_origin + np.cross(omega, mm.com_in_joint))
    return omega, v_com


def signed_angle(M: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The angle in ``(-π, π]`` of rotations ``M (..., 3, 3) = exp(θ a)`` about unit axes
    ``axis`` (broadcast against ``M``'s leading shape): ``atan2(aᵀ vee(M - Mᵀ)/2, (tr M - 1)/2)``."""
    skew = M - np.swapaxes(M, -1, -2)
    axial = np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], -1)
    sin = 0.5 * np.sum(axis * axial, axis=-1)
    return np.arctan2(sin, 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1.0))


def joint_positions(
    mm: MaximalModel,
    R: npt.ArrayLike,
    p: npt.ArrayLike | None = None,
    *,
    q_ref: npt.ArrayLike | None = None,
) -> np.ndarray:
    """Pinocchio configuration ``q`` (nq,) of body poses ``(R, p)``; ``p`` needed for prismatic joints.
    For a path of poses ``R (K, nb, 3, 3)``, ``p (K, nb, 3)``: ``q (K, nq)``, knot ``k``'s angles
    in the window centred on knot ``k - 1``'s (knot 0's as for one pose).

    A revolute angle is read from ``R_rel0^T R_p^T R_c = exp(theta [axis_child]^)``; it is taken
    in the 2*pi-window centred on ``q_ref`` (default: the middle of the joint's limits, or 0).
    A continuous joint gives ``(cos theta, sin theta)``.  A prismatic displacement is the distance
    between the two pivot points along the joint axis.
    """
    single = np.ndim(R) == 3
    R = _array(R, (mm.nb, 3, 3) if single else (len(R), mm.nb, 3, 3), "R")
    Rb = R[None] if single else R
    Rp = _from_parent(mm, Rb, np.eye(3), axis=1)
    M = np.einsum("bji,...bjk->...bik", mm.R_rel0, np.einsum("...bji,...bjk->...bik", Rp, Rb))
    theta = signed_angle(M, mm.axis_child)

    if q_ref is None:
        bounded = np.isfinite(mm.lower_position_limit) & np.isfinite(mm.upper_position_limit)
        lo = np.where(bounded, mm.lower_position_limit, 0.0)
        hi = np.where(bounded, mm.upper_position_limit, 0.0)
        center = 0.5 * (lo + hi)
    else:
        center = _array(q_ref, (mm.nq,), "q_ref")[mm.idx_q]
    for k in range(len(theta)):
        theta[k] += 2.0 * np.pi * np.round((center - theta[k]) / (2.0 * np.pi))
        center = theta[k]

    q = np.zeros((len(theta), mm.nq))
    revolute = mm.revolute
    angle = revolute & ~mm.continuous
    q[:, mm.idx_q[angle]] = theta[:, angle]
    q[:, mm.idx_q[mm.continuous]] = np.cos(theta[:, mm.continuous])
    q[:, mm.idx_q[mm.continuous] + 1] = np.sin(theta[:, mm.continuous])
    prismatic, free = mm.prismatic, mm.free
    if prismatic.any() or free.any():
        p = _require(p, (mm.nb, 3) if single else (len(R), mm.nb, 3), "p")
        pb = p[None] if single else p
    if prismatic.any():
        delta = _pivot_separation(mm, Rb, pb, Rp)
        axis_world = np.einsum("...bij,bj->...bi", Rp, mm.axis_parent)
        q[:, mm.idx_q[prismatic]] = np.einsum("...bi,...bi->...b", axis_world, delta)[:, prismatic]
    for b in np.flatnonzero(free):
        i = mm.idx_q[b]
        q[:, i : i + 3] = pb[:, b] - Rb[:, b] @ mm.com_in_joint[b]
        quat = quaternions(Rb[:, b])
        for k in range(1, len(quat)):  # a path's quaternions without sign jumps
            if quat[k] @ quat[k - 1] < 0.0:
                quat[k] = -quat[k]
        q[:, i + 3 : i + 7] = quat
    return q[0] if single else q


def joint_velocities(
    mm: MaximalModel,
    R: npt.ArrayLike,
    omega_body: npt.ArrayLike,
    p: npt.ArrayLike | None = None,
    v_com: npt.ArrayLike | None = None,
) -> np.ndarray:
    """Pinocchio velocity ``v`` (nv,) of body velocities; ``p``, ``v_com`` needed for prismatic joints.

    Revolute: ``axis_child . (omega_c - R_rel^T omega_p)`` with ``R_rel = R_p^T R_c``.  Prismatic:
    time derivative of ``(R_p axis_parent) . (pivot_c - pivot_p)``.
    """
    R = _array(R, (mm.nb, 3, 3), "R")
    omega = _array(omega_body, (mm.nb, 3), "omega_body")
    Rp = _from_parent(mm, R, np.eye(3))
    omega_p = _from_parent(mm, omega, np.zeros(3))
    rel = np.einsum("bji,bjk->bik", Rp, R)
    omega_rel = omega - np.einsum("bji,bj->bi", rel, omega_p)

    v = np.zeros(mm.nv)
    revolute, prismatic, free = mm.revolute, mm.prismatic, mm.free
    v[mm.idx_v[revolute]] = np.einsum("bi,bi->b", mm.axis_child, omega_rel)[revolute]
    if free.any():
        v_com = _require(v_com, (mm.nb, 3), "v_com")
    for b in np.flatnonzero(free):
        i = mm.idx_v[b]
        origin_rate = v_com[b] - R[b] @ np.cross(omega[b], mm.com_in_joint[b])
        v[i : i + 3] = R[b].T @ origin_rate
        v[i + 3 : i + 6] = omega[b]
    if prismatic.any():
        p = _require(p, (mm.nb, 3), "p")
        v_com = _require(v_com, (mm.nb, 3), "v_com")
        v_p = _from_parent(mm, v_com, np.zeros(3))
        delta = _pivot_separation(mm, R, p, Rp)
        delta_dot = (
            np.einsum("bij,bj->bi", R, np.cross(omega, mm.r_child))
            + v_com
            - np.einsum("bij,bj->bi", Rp, np.cross(omega_p, mm.r_parent))
            - v_p
        )
        axis_world = np.einsum("bij,bj->bi", Rp, mm.axis_parent)
        axis_world_dot = np.einsum("bij,bj->bi", Rp, np.cross(omega_p, mm.axis_parent))
        d_dot = np.einsum("bi,bi->b", axis_world_dot, delta) + np.einsum(
            "bi,bi->b", axis_world, delta_dot
        )
        v[mm.idx_v[prismatic]] = d_dot[prismatic]
    return v


def joint_constraint_residuals(mm: MaximalModel, R: npt.ArrayLike, p: npt.ArrayLike) -> np.ndarray:
    """Worst joint constraint residual at each knot of poses ``R (K, nb, 3, 3)``, ``p (K, nb, 3)``:
    ``(K,)``. Revolute: pivot gap (3) and axis ``(R_p perp_i)ᵀ(R_c a)`` (2); prismatic: rotation
    ``vee(M - Mᵀ)/2``, ``M = R_rel0ᵀR_pᵀR_c`` (3), and slide ``perp_iᵀR_pᵀ gap`` (2); a free
    body has none."""
    R, p = np.asarray(R, dtype=float), np.asarray(p, dtype=float)
    out = np.empty(len(R))
    revolute = mm.revolute
    for k, (Rk, pk) in enumerate(zip(R, p, strict=True)):
        Rp = _from_parent(mm, Rk, np.eye(3))
        gap = _pivot_separation(mm, Rk, pk, Rp)
        perp_world = np.einsum("bij,bkj->bki", Rp, mm.perp_parent)
        axis = np.einsum("bki,bij,bj->bk", perp_world, Rk, mm.axis_child)
        M = np.einsum("bji,bjk->bik", mm.R_rel0, np.einsum("bji,bjk->bik", Rp, Rk))
        skew = 0.5 * (M - M.transpose(0, 2, 1))
        rotation = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], 1)
        slide = np.einsum("bki,bi->bk", perp_world, gap)
        rev = np.concatenate([gap, axis], 1)[revolute]
        pri = np.concatenate([rotation, slide], 1)[mm.prismatic]
        out[k] = np.abs(np.concatenate([rev.ravel(), pri.ravel(), [0.0]])).max()
    return out


def _pivot_separation(mm: MaximalModel, R: np.ndarray, p: np.ndarray, Rp: np.ndarray) -> np.ndarray:
    """(..., nb, 3) world vector from the parent's pivot point to the child's (pivot constraint);
    ``R``, ``p``, ``Rp`` with the bodies on the second-to-last axis of ``p``."""
    pp = _from_parent(mm, p, np.zeros(3), axis=p.ndim - 2)
    child = np.einsum("...bij,bj->...bi", R, mm.r_child) + p
    return child - np.einsum("...bij,bj->...bi", Rp, mm.r_parent) - pp


def _from_parent(mm: MaximalModel, x: np.ndarray, world: np.ndarray, axis: int = 0) -> np.ndarray:
    """Per body (on ``axis`` of ``x``), the parent's entry of ``x`` (``world`` for the fixed
    world)."""
    has_parent = (mm.parent >= 0).reshape((-1,) + (1,) * (x.ndim - 1 - axis))
    return np.where(has_parent, np.take(x, np.maximum(mm.parent, 0), axis=axis), world)


def _require(x: npt.ArrayLike | None, shape: tuple[int, ...], name: str) -> np.ndarray:
    if x is None:
        raise InputError(f"{name} is required for a robot with prismatic joints or a floating base")
    return _array(x, shape, name)


def _array(x: npt.ArrayLike, shape: tuple[int, ...], name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != shape:
        raise InputError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} has non-finite entries")
    return a
