"""Loop closures: a robot is a spanning tree of joints plus closures between two of its bodies.

A :class:`Loop` holds a frame ``M₁`` on joint ``joint1`` and a frame ``M₂`` on joint ``joint2``
(placements in the joints' frames; ``"universe"`` is the world) together. Its residual is
expressed in frame 1 (``(R₁, p₁) = oMj₁ M₁``, ``(R₂, p₂) = oMj₂ M₂``):

* ``"point"`` (a ball joint, MJCF ``<connect>``): ``R₁ᵀ(p₂ - p₁)``, rows ``x, y, z``;
* ``"revolute"`` (a hinge about the frames' common ``z`` axis): the point rows and the ``x, y``
  components of ``R₁ᵀR₂ e_z``, rows ``ax, ay``;
* ``"weld"`` (MJCF ``<weld>``): the point rows and ``vee(M - Mᵀ)/2`` with ``M = R₁ᵀR₂``, rows
  ``rx, ry, rz``.

A closure's rows may be *redundant* with the tree and the other closures (a planar four-bar's
point closure: its out-of-plane row vanishes identically). Redundant rows make the constraint
Jacobian rank deficient and their forces indeterminate, so :func:`resolve_loops` finds them on
the closed reference configuration and keeps only independent rows
(:attr:`Loop.components`, :attr:`Loop.dropped`, reported by ``mbplan robots`` and ``plan``).

The joint velocities of a closed robot are dependent too (``J v = 0``): a condition on every
joint's velocity, such as rest at the last knot, repeats the closures' rows.
:func:`independent_joints` finds joints whose velocities determine all the others', on which
such a condition is imposed once.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin
import scipy.linalg

from mbplan.errors import InputError, RobotModelError

LOOP_KINDS: dict[str, tuple[str, ...]] = {
    "point": ("x", "y", "z"),
    "revolute": ("x", "y", "z", "ax", "ay"),
    "weld": ("x", "y", "z", "rx", "ry", "rz"),
}
"""Every loop kind and the names of its rows (module docstring)."""

CLOSE_TOLERANCE = 1e-9  # m or rad: a configuration closes a loop when its residual is below
RANK_TOLERANCE = 1e-8  # relative singular value below which a closure row is redundant


@dataclass(frozen=True, eq=False)
class Loop:
    """A loop closure (module docstring): ``kind``, the joints (Pinocchio names) and the frames'
    placements ``(4, 4)`` in them, and the ``components`` (row names of ``kind``) it imposes."""

    name: str
    kind: str
    joint1: str
    placement1: np.ndarray
    joint2: str
    placement2: np.ndarray
    components: tuple[str, ...] = ()
    dropped: tuple[str, ...] = ()

    @property
    def rows(self) -> np.ndarray:
        """Indices of :attr:`components` among the rows of :data:`LOOP_KINDS` ``[kind]``."""
        names = LOOP_KINDS[self.kind]
        return np.array([names.index(c) for c in self.components], dtype=np.int64)

    @property
    def dim(self) -> int:
        return len(self.components)

    def describe(self) -> str:
        """One line: kind, joints, rows kept and dropped."""
        out = f"{self.name}: {self.kind} closure {self.joint1!r} - {self.joint2!r}"
        if self.dropped:
            out += f" (rows {', '.join(self.dropped)} redundant, not imposed)"
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": self.kind,
            "joint1": self.joint1,
            "placement1": self.placement1.tolist(),
            "joint2": self.joint2,
            "placement2": self.placement2.tolist(),
        }


def loop_residual(kind: str, R1: Any, p1: Any, R2: Any, p2: Any, xp: Any = np) -> Any:
    """All rows of :data:`LOOP_KINDS` ``[kind]`` (module docstring) of frames ``(R₁, p₁)`` and
    ``(R₂, p₂)``; ``xp``: ``numpy`` or ``casadi`` (with ``mtimes``/``vertcat``)."""
    if xp is np:
        mul, cat = np.matmul, lambda parts: np.concatenate([np.ravel(a) for a in parts])
    else:
        mul, cat = xp.mtimes, lambda parts: xp.vertcat(*parts)
    rows = [mul(R1.T, p2 - p1)]
    if kind == "revolute":
        z = mul(mul(R1.T, R2), np.array([0.0, 0.0, 1.0]))
        rows.append(z[0:2])
    elif kind == "weld":
        M = mul(R1.T, R2)
        rows.append(0.5 * cat([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]]))
    return cat(rows)


def frame_placements(model: pin.Model, data: pin.Data, loop: Loop) -> tuple[pin.SE3, pin.SE3]:
    """World placements of the loop's two frames (``data.oMi`` up to date)."""
    out = []
    for joint, placement in ((loop.joint1, loop.placement1), (loop.joint2, loop.placement2)):
        out.append(data.oMi[model.getJointId(joint)] * pin.SE3(placement))
    return out[0], out[1]


def closure_residual(model: pin.Model, loops: Sequence[Loop], q: np.ndarray) -> np.ndarray:
    """The imposed rows of every loop at ``q`` (stacked)."""
    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(q, dtype=float))
    parts = [np.zeros(0)]
    for loop in loops:
        M1, M2 = frame_placements(model, data, loop)
        full = loop_residual(loop.kind, M1.rotation, M1.translation, M2.rotation, M2.translation)
        parts.append(full[loop.rows])
    return np.concatenate(parts)


def closure_jacobian(
    model: pin.Model, loops: Sequence[Loop], q: np.ndarray, step: float = 1e-7
) -> np.ndarray:
    """``∂r/∂q`` ``(m, nq)`` of :func:`closure_residual` by central differences (1-dof joints:
    ``q`` is its own tangent space)."""
    q = np.asarray(q, dtype=float)
    cols = []
    for i in range(q.size):
        e = np.zeros_like(q)
        e[i] = step
        cols.append(
            (closure_residual(model, loops, q + e) - closure_residual(model, loops, q - e))
            / (2 * step)
        )
    return np.stack(cols, axis=1) if cols else np.zeros((0, 0))


def close_loops(
    model: pin.Model,
    loops: Sequence[Loop],
    q: np.ndarray,
    *,
    fixed: Sequence[int] = (),
    iterations: int = 50,
    tolerance: float = CLOSE_TOLERANCE,
) -> tuple[np.ndarray, float]:
    """The configuration nearest ``q`` (Gauss–Newton, minimum-norm steps) that closes every
    loop to ``tolerance``, keeping the coordinates ``fixed``; returns it and its largest
    residual."""
    q = np.array(q, dtype=float)
    free = np.setdiff1d(np.arange(q.size), np.asarray(fixed, dtype=np.int64))
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    exact = model.nq == model.nv  # 1-dof joints: loop_jacobian's columns are q's
    for _ in range(iterations if free.size else 0):
        r = closure_residual(model, loops, q)
        if r.size == 0 or np.max(np.abs(r)) < tolerance:
            break
        J = loop_jacobian(model, loops, q) if exact else closure_jacobian(model, loops, q)
        J = J[:, free]
        q[free] -= np.linalg.lstsq(J, r, rcond=None)[0]
        q = np.where(np.isfinite(lo) & np.isfinite(hi), np.clip(q, lo, hi), q)
    r = closure_residual(model, loops, q)
    return q, float(np.max(np.abs(r), initial=0.0))


def refuse_loops(robot: Any, method: str) -> None:
    """:class:`InputError` naming the loops of ``robot`` (a method for open chains only)."""
    loops = getattr(robot, "loops", ())
    if loops:
        described = "; ".join(loop.describe() for loop in loops)
        raise InputError(
            f"{method} cannot plan {robot.name!r}: its dynamics have no loop closures, and the "
            f"robot has closed kinematic loops ({described}); plan it with ripm or ipopt"
        )


def loop_from_spec(model: pin.Model, spec: Loop | Mapping[str, Any], index: int) -> Loop:
    """A :class:`Loop` from a mapping ``{frame1, frame2, kind, name?, placement1?,
    placement2?, axis?}`` (frames by name, their placements ``[x, y, z]`` or ``(4, 4)`` relative
    to the frames; ``axis``: a revolute closure's axis in frame 1, default ``z``) or of
    :meth:`Loop.to_dict` (what :attr:`Robot.source` stores), or checked."""
    if isinstance(spec, Loop):
        return _checked(model, spec)
    if not isinstance(spec, Mapping):
        raise InputError(f"loop {index}: expected a mapping or a Loop, got {type(spec).__name__}")
    if "joint1" in spec:  # Loop.to_dict(): joints and (4, 4) placements
        return _from_dict(model, spec, index)
    known = {"name", "kind", "frame1", "frame2", "placement1", "placement2", "axis"}
    unknown = sorted(set(spec) - known)
    if unknown:
        raise InputError(f"loop {index}: unknown keys {unknown}; known: {sorted(known)}")
    name = str(spec.get("name", f"loop{index}"))
    kind = spec.get("kind", "point")
    frames = []
    for side in ("1", "2"):
        frame = spec.get(f"frame{side}")
        if not isinstance(frame, str) or not model.existFrame(frame):
            raise InputError(f"loop {name!r}: frame{side} {frame!r} is not a frame of the robot")
        f = model.frames[model.getFrameId(frame)]
        offset = _placement(spec.get(f"placement{side}"), f"loop {name!r}: placement{side}")
        frames.append((model.names[f.parentJoint], f.placement.homogeneous @ offset))
    axis = spec.get("axis")
    if axis is not None:
        if kind != "revolute":
            raise InputError(f"loop {name!r}: an axis is given, but the kind is {kind!r}")
        align = _align_z(np.asarray(axis, dtype=float), f"loop {name!r}: axis")
        frames = [(j, M @ align) for j, M in frames]
    loop = Loop(name, kind, frames[0][0], frames[0][1], frames[1][0], frames[1][1])
    return _checked(model, loop)


def _from_dict(model: pin.Model, spec: Mapping[str, Any], index: int) -> Loop:
    """The :class:`Loop` of :meth:`Loop.to_dict`, checked."""
    known = {"name", "kind", "joint1", "placement1", "joint2", "placement2"}
    if set(spec) != known:
        raise InputError(f"loop {index}: expected the keys {sorted(known)}, got {sorted(spec)}")
    parts = {k: spec[k] for k in ("name", "kind", "joint1", "joint2")}
    placements = {k: np.asarray(spec[k], dtype=float) for k in ("placement1", "placement2")}
    return _checked(model, Loop(**parts, **placements))


def loops_from_constraints(model: pin.Model, constraints: Sequence[Any]) -> list[Loop]:
    """Loops of Pinocchio's ``RigidConstraintModel`` list (MJCF ``<connect>``: 3D, ``<weld>``:
    6D)."""
    out = []
    for i, c in enumerate(constraints):
        kind = {"CONTACT_3D": "point", "CONTACT_6D": "weld"}.get(str(c.type).split(".")[-1])
        if kind is None:
            raise RobotModelError(f"constraint {c.name!r}: unsupported type {c.type}")
        name = c.name or f"loop{i}"
        loop = Loop(
            name,
            kind,
            model.names[c.joint1_id],
            np.array(c.joint1_placement.homogeneous),
            model.names[c.joint2_id],
            np.array(c.joint2_placement.homogeneous),
        )
        out.append(_checked(model, loop))
    return out


def resolve_loops(model: pin.Model, loops: Sequence[Loop], q_ref: np.ndarray) -> tuple[Loop, ...]:
    """``loops`` with their redundant rows dropped (module docstring), judged on ``q_ref``
    closed by :func:`close_loops`; :class:`RobotModelError` if the loops cannot close there or a
    loop keeps no row."""
    if not loops:
        return ()
    names = [loop.name for loop in loops]
    if len(set(names)) != len(names):
        raise InputError(f"loop names must be unique: {names}")
    full = [replace(loop, components=LOOP_KINDS[loop.kind], dropped=()) for loop in loops]
    q, gap = close_loops(model, full, q_ref)
    if gap > 1e-6:
        raise RobotModelError(
            f"the loops {names} cannot all close near the reference configuration (residual "
            f"{gap:.3g} after Gauss-Newton): check the frames and placements"
        )
    J = closure_jacobian(model, full, q)
    scale = max(1.0, float(np.max(np.abs(J), initial=0.0)))
    kept_rows: list[np.ndarray] = []
    out, row = [], 0
    for loop in full:
        keep, drop = [], []
        for c in loop.components:
            trial = np.vstack([*kept_rows, J[row]])
            if np.linalg.matrix_rank(trial, tol=RANK_TOLERANCE * scale) == trial.shape[0]:
                kept_rows.append(J[row])
                keep.append(c)
            else:
                drop.append(c)
            row += 1
        if not keep:
            raise RobotModelError(
                f"loop {loop.name!r}: every row is redundant with the tree and the other loops"
            )
        out.append(replace(loop, components=tuple(keep), dropped=tuple(drop)))
    return tuple(out)


def _checked(model: pin.Model, loop: Loop) -> Loop:
    where = f"loop {loop.name!r}"
    if loop.kind not in LOOP_KINDS:
        raise InputError(f"{where}: kind {loop.kind!r} is not one of {', '.join(LOOP_KINDS)}")
    for joint in (loop.joint1, loop.joint2):
        if not model.existJointName(joint):
            raise InputError(f"{where}: joint {joint!r} is not a joint of the robot")
    if loop.joint1 == loop.joint2:
        raise InputError(
            f"{where}: both frames are on the body of joint {loop.joint1!r}; a closure joins two "
            "different bodies"
        )
    placements = []
    for side, M in (("1", loop.placement1), ("2", loop.placement2)):
        placements.append(_placement(M, f"{where}: placement{side}"))
    components = loop.components or LOOP_KINDS[loop.kind]
    bad = [c for c in components if c not in LOOP_KINDS[loop.kind]]
    if bad:
        raise InputError(f"{where}: rows {bad} are not rows of a {loop.kind} closure")
    return replace(loop, placement1=placements[0], placement2=placements[1], components=components)


def _placement(value: Any, what: str) -> np.ndarray:
    """``None`` (identity), ``[x, y, z]`` or a ``(4, 4)`` rigid transform, checked."""
    if value is None:
        return np.eye(4)
    M = np.asarray(value, dtype=float)
    if M.shape == (3,):
        out = np.eye(4)
        out[:3, 3] = M
        M = out
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise InputError(f"{what}: expected [x, y, z] or a finite 4x4 transform, got {value!r}")
    R = M[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0.0:
        raise InputError(f"{what}: the rotation block is not a rotation matrix")
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"{what}: the last row must be [0, 0, 0, 1]")
    return M


def _align_z(axis: np.ndarray, what: str) -> np.ndarray:
    """A transform whose rotation takes ``z`` to the unit vector of ``axis``."""
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-12:
        raise InputError(f"{what}: expected a nonzero 3-vector, got {axis.tolist()}")
    a = axis / np.linalg.norm(axis)
    helper = np.eye(3)[np.argmin(np.abs(a))]
    x = np.cross(helper, a)
    x /= np.linalg.norm(x)
    out = np.eye(4)
    out[:3, :3] = np.column_stack([x, np.cross(a, x), a])
    return out


def loop_jacobian(model: pin.Model, loops: Sequence[Loop], q: np.ndarray) -> np.ndarray:
    """``∂r/∂q`` ``(m, nv)`` of :func:`closure_residual`, exact (Pinocchio's joint Jacobians).

    With each frame's world velocity ``(v_i, ω_i)`` and ``w = R₁ᵀ(ω₂ - ω₁)``, ``M = R₁ᵀR₂``:
    point rows ``R₁ᵀ(v₂ - v₁ + (p₂ - p₁) × ω₁)``, axis rows the ``x, y`` of ``-(M e_z) × w``,
    rotation rows ``(tr(M) I - M) w / 2``."""
    data = model.createData()
    pin.computeJointJacobians(model, data, np.asarray(q, dtype=float))
    parts = [np.zeros((0, model.nv))]
    for loop in loops:
        frames = []
        for joint, placement in ((loop.joint1, loop.placement1), (loop.joint2, loop.placement2)):
            jid = model.getJointId(joint)
            M = data.oMi[jid] * pin.SE3(placement)
            J = pin.getJointJacobian(model, data, jid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            lever = M.translation - data.oMi[jid].translation
            v = J[:3] - pin.skew(lever) @ J[3:]  # the frame origin's velocity
            frames.append((M.rotation, M.translation, v, J[3:]))
        (R1, p1, v1, w1), (R2, p2, v2, w2) = frames
        rows = [R1.T @ (v2 - v1 + pin.skew(p2 - p1) @ w1)]
        w, Mrel = R1.T @ (w2 - w1), R1.T @ R2
        if loop.kind == "revolute":
            rows.append((-pin.skew(Mrel[:, 2]) @ w)[:2])
        elif loop.kind == "weld":
            rows.append(0.5 * (np.trace(Mrel) * np.eye(3) - Mrel) @ w)
        parts.append(np.vstack(rows)[loop.rows])
    return np.vstack(parts)


def independent_joints(
    model: pin.Model, loops: Sequence[Loop], q: np.ndarray, passive: Sequence[int] = ()
) -> np.ndarray:
    """Velocity indices of a largest set of joints whose velocities determine every other
    joint's through the closures at ``q`` (``J v = 0``, ``J`` of :func:`loop_jacobian`): all
    joints but a well-conditioned dependent set, as many as ``J`` has rank, chosen by
    column-pivoted QR among the ``passive`` velocity indices first, then among the others (the
    actuated joints stay independent where the passive ones take up the closures). ``v = 0`` on
    them is ``v = 0`` on every joint while the dependent joints' columns of ``J`` stay
    invertible, with no row repeating a closure's (every joint without loops)."""
    nv = model.nv
    J = loop_jacobian(model, loops, q) if loops else np.zeros((0, nv))
    tol = RANK_TOLERANCE * max(1.0, float(np.max(np.abs(J), initial=0.0)))
    first = np.unique(np.asarray(passive, dtype=np.int64))
    basis = np.zeros((J.shape[0], 0))
    dependent: list[int] = []
    for group in (first, np.setdiff1d(np.arange(nv), first)):
        if not group.size or basis.shape[1] == J.shape[0]:
            continue
        cols = J[:, group] - basis @ (basis.T @ J[:, group])
        Q, R, piv = scipy.linalg.qr(cols, mode="economic", pivoting=True)
        rank = int(np.sum(np.abs(np.diag(R)) > tol))
        dependent += group[piv[:rank]].tolist()
        basis = np.hstack([basis, Q[:, :rank]])
    return np.setdiff1d(np.arange(nv), dependent)
