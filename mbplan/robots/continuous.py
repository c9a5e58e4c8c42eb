"""Continuous joints in an OCP: an unbounded angle ``θ`` instead of Pinocchio's ``(cos θ, sin θ)``.

A continuous joint (Pinocchio's ``JointModelRUBX/Y/Z``, ``RevoluteUnboundedUnaligned``: nq = 2,
nv = 1) becomes, when a :class:`~mbplan.robots.robot.Robot` is loaded, a revolute joint about the
same axis without position limits (``JointModelRX/Y/Z``, ``RevoluteUnaligned``, limits ±inf), so
every OCP configuration has one coordinate per joint (nq = nv) and the dynamics are unchanged.
:func:`to_angles` and :func:`from_angles` convert configurations of the original model.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError

if TYPE_CHECKING:
    from mbplan.robots.robot import Robot

_ALIGNED = {
    "JointModelRUBX": pin.JointModelRX,
    "JointModelRUBY": pin.JointModelRY,
    "JointModelRUBZ": pin.JointModelRZ,
}
_UNALIGNED = "JointModelRevoluteUnboundedUnaligned"
_PER_DOF = (
    "armature",
    "rotorInertia",
    "rotorGearRatio",
    "friction",
    "damping",
    "lowerDryFrictionLimit",
    "upperDryFrictionLimit",
    "lowerEffortLimit",
    "upperEffortLimit",
    "lowerVelocityLimit",
    "upperVelocityLimit",
)


def is_continuous(model: pin.Model, j: int) -> bool:
    """Whether joint ``j`` of ``model`` is a continuous (unbounded revolute) joint."""
    return model.joints[j].shortname() in (*_ALIGNED, _UNALIGNED)


def _revolute(joint: pin.JointModel) -> pin.JointModel:
    name = joint.shortname()
    if name in _ALIGNED:
        return _ALIGNED[name]()
    data = joint.createData()
    joint.calc(data, np.array([1.0, 0.0]))
    return pin.JointModelRevoluteUnaligned(np.array(data.S).ravel()[3:])


def unbounded_revolute_model(model: pin.Model) -> tuple[pin.Model, tuple[str, ...]]:
    """``model`` with every continuous joint replaced by an unbounded revolute joint (same joint,
    body and frame indices, so geometry models stay valid), and the names of those joints."""
    names = tuple(model.names[j] for j in range(1, model.njoints) if is_continuous(model, j))
    if not names:
        return model, ()
    out = pin.Model()
    out.name = model.name
    out.gravity = model.gravity
    for j in range(1, model.njoints):
        joint = model.joints[j]
        iq, iv, nq = model.idx_qs[j], model.idx_vs[j], model.nqs[j]
        vs = slice(iv, iv + model.nvs[j])
        if is_continuous(model, j):
            joint, lo, hi = _revolute(joint), np.full(1, -np.inf), np.full(1, np.inf)
        else:
            lo = model.lowerPositionLimit[iq : iq + nq]
            hi = model.upperPositionLimit[iq : iq + nq]
        jid = out.addJoint(
            model.parents[j],
            joint,
            model.jointPlacements[j],
            model.names[j],
            model.upperEffortLimit[vs],
            model.upperVelocityLimit[vs],
            lo,
            hi,
        )
        out.appendBodyToJoint(jid, model.inertias[j], pin.SE3.Identity())
    for frame in list(model.frames)[1:]:
        out.addFrame(pin.Frame(frame), False)
    for field in _PER_DOF:  # velocity-sized: the same in both models
        setattr(out, field, np.array(getattr(model, field)))
    return out, names


def to_angles(model: pin.Model, q: np.ndarray) -> np.ndarray:
    """A configuration of ``model`` (continuous joints as ``(cos, sin)``) as one coordinate per
    joint (``θ = atan2(sin, cos)`` in ``(-π, π]``): ``(..., nq) -> (..., nv)``."""
    return _per_joint(
        model,
        q,
        (model.idx_qs, model.nqs, model.nq, "a configuration of"),
        lambda x, i: np.arctan2(x[..., i + 1], x[..., i])[..., None],
    )


def from_angles(model: pin.Model, theta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_angles`: ``(..., nv) -> (..., nq)`` of ``model``."""
    return _per_joint(
        model,
        theta,
        (model.idx_vs, model.nvs, model.nv, "joint coordinates:"),
        lambda x, i: np.stack([np.cos(x[..., i]), np.sin(x[..., i])], axis=-1),
    )


def _per_joint(model: pin.Model, x, layout, continuous) -> np.ndarray:
    """``x`` joint by joint: ``continuous(x, index)`` for continuous joints, else the entries."""
    index, width, n, what = layout
    x = np.asarray(x, dtype=float)
    if x.shape[-1:] != (n,):
        raise InputError(f"expected {what} {n} entries for {model.name!r}, got shape {x.shape}")
    cols = [
        continuous(x, index[j])
        if is_continuous(model, j)
        else x[..., index[j] : index[j] + width[j]]
        for j in range(1, model.njoints)
    ]
    return np.concatenate(cols, axis=-1)


def joint_ranges(robot: Robot, center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Finite ranges ``(lo, hi)`` to sample or clip configurations in: the position limits, and
    ``center ± π`` for the continuous joints (warm starts, inverse kinematics)."""
    lo = np.array(robot.model.lowerPositionLimit, dtype=float)
    hi = np.array(robot.model.upperPositionLimit, dtype=float)
    idx = robot.q_of_v[robot.joint_indices(robot.continuous)]
    lo[idx], hi[idx] = center[idx] - np.pi, center[idx] + np.pi
    return lo, hi
