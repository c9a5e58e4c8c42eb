"""Contacts: a robot frame held on the ground during a phase of the horizon.

A :class:`Contact` holds frame ``frame`` at the world point ``position`` at the state knots
``knots`` (a contiguous stance ``a … b``). The ground there is the horizontal plane through
``position`` (normal ``+z``). A *point* contact's force ``f`` (world frame, N, applied to the
robot at the frame's origin) is a decision variable of every formulation, held inside the
friction cone ``‖f_xy‖ ≤ μ f_z`` by the hard inequalities of its inscribed pyramid
(:func:`mbplan.dynamics.friction.pyramid`), which also make the normal force unilateral. A
*sole* contact (``sole=(length, width)``: a rectangle centred on the frame's origin, along its
``x`` and ``y``) also holds the frame's orientation, ``rotation``: the one ``q0`` gives it (as
Crocoddyl's 6D contacts hold their initial placement; the ground under the sole is the plane of
its ``x`` and ``y``, which the robot's start should make horizontal); its variable is the wrench ``w = (f, τ)`` about the frame's origin in the
contact frame ``rotation``, inside the contact wrench cone
(:func:`mbplan.dynamics.friction.wrench_cone`: the pyramid, the centre of pressure inside the
sole, the yaw torque the corners' friction can hold; :func:`~mbplan.dynamics.friction.cone_rows`
of its ``friction`` and ``sole``). :meth:`Contact.world` turns the variables
into world forces (and torques).

Timing: the frame is at ``position`` at knots ``a … b`` (:meth:`Contact.held_knots`: those
whose configuration is a variable, and a virtual knot ``N + 1`` for a stance that lasts to the
end, so that the frame ends at rest). The force starts at knot / interval ``a-1``: it stops the
landing frame (the touchdown impulse; plastic impact: zero velocity from knot ``a`` on). In
maximal coordinates the force of knot ``m - 1`` holds knot ``m``; in generalized coordinates
(explicit Euler) the force of interval ``k`` (``a-1 … b-1``, :meth:`Contact.force_intervals`)
moves knot ``k + 2``, the last one pushes off. A stance that starts at knot 0 or 1 holds where
the start puts the frame (``q0``, and ``q0 ⊕ Δt v0``), which :func:`make_contact` checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.validation import as_array, as_real

START_TOLERANCE = 1e-6  # m (rad): how far the start may put a held frame from its contact


def frame_position(model: pin.Model, frame: int, q: np.ndarray) -> np.ndarray:
    """World position of frame ``frame`` at configuration ``q``."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data.oMf[frame].translation.copy()


def frame_rotation(model: pin.Model, frame: int, q: np.ndarray) -> np.ndarray:
    """World rotation of frame ``frame`` at configuration ``q``."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data.oMf[frame].rotation.copy()


def orientation_error(rotation: np.ndarray, R: np.ndarray) -> float:
    """The angle (rad) between rotations ``rotation`` and ``R``."""
    return float(np.linalg.norm(pin.log3(np.asarray(rotation).T @ np.asarray(R))))


def generalized_force(
    model: pin.Model, frames: list[int], q: np.ndarray, forces: np.ndarray
) -> np.ndarray:
    """``Σ J_i(q)ᵀ f_i`` ``(nv,)``: world forces ``forces (n, 3)`` (or wrenches ``(n, 6)``,
    force and torque) at the origins of ``frames`` as joint torques (``J_i``: the frame's
    world-aligned Jacobian)."""
    data = model.createData()
    out = np.zeros(model.nv)
    for fid, f in zip(frames, np.asarray(forces, dtype=float), strict=True):
        if not np.any(f):
            continue
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)[: len(f)]
        out += J.T @ f
    return out


@dataclass(frozen=True, eq=False)
class Contact:
    """A contact (module docstring): ``frame`` at ``position`` over the stance ``knots`` with
    friction coefficient ``friction``; a point, or a sole of ``sole = (length, width)`` held
    at ``rotation``."""

    name: str
    frame: str
    knots: np.ndarray
    position: np.ndarray
    friction: float = 0.7
    sole: tuple[float, float] | None = None
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def dim(self) -> int:
        """Size of its variable: 3 (a point's force) or 6 (a sole's wrench)."""
        return 3 if self.sole is None else 6

    def world(self, w: np.ndarray) -> np.ndarray:
        """World force (and torque) ``(..., dim)`` of its variables ``w (..., dim)``."""
        w = np.asarray(w, dtype=float)
        return (w.reshape(*w.shape[:-1], -1, 3) @ self.rotation.T).reshape(w.shape)

    def local(self, w: np.ndarray) -> np.ndarray:
        """Its variables ``(..., dim)`` of world forces (and torques) ``w`` (:meth:`world`)."""
        w = np.asarray(w, dtype=float)
        return (w.reshape(*w.shape[:-1], -1, 3) @ self.rotation).reshape(w.shape)

    @property
    def first(self) -> int:
        return int(self.knots[0])

    @property
    def last(self) -> int:
        return int(self.knots[-1])

    def held_knots(self, N: int) -> np.ndarray:
        """The knots whose configuration the transcriptions hold at the contact position: the
        stance knots ``≥ 2`` (knots 0 and 1 are the start's) and, for a stance that lasts to
        the horizon's end, the virtual knot ``N + 1`` (``q_N ⊕ Δt v_N``: the frame at rest)."""
        held = self.knots[self.knots >= 2]
        return np.append(held, N + 1) if self.last == N else held

    def force_intervals(self, N: int) -> np.ndarray:
        """The intervals ``a-1 … b-1`` (from 0 on) on which the force acts (explicit Euler: the
        force of interval ``k`` moves knot ``k + 2``)."""
        return np.arange(max(self.first - 1, 0), min(self.last, N))

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "frame": self.frame,
            "knots": self.knots.tolist(),
            "position": self.position.tolist(),
            "friction": self.friction,
        } | ({} if self.sole is None else {"sole": list(self.sole)})


def make_contact(
    robot: Any,
    N: int,
    q0: np.ndarray,
    v0: np.ndarray,
    dt: float,
    name: str,
    frame: str,
    knots: ArrayLike,
    position: ArrayLike | None,
    friction: float,
    sole: ArrayLike | None = None,
) -> Contact:
    """A checked :class:`Contact` of ``robot`` over a horizon of ``N`` steps from ``(q0, v0)``:
    ``position`` defaults to where ``q0`` puts the frame; a sole's ``rotation`` is the frame's
    at ``q0``."""
    where = f"contact {name!r}"
    if not isinstance(frame, str) or not robot.model.existFrame(frame):
        raise InputError(f"{where}: the robot has no frame {frame!r}")
    fid = robot.frame_id(frame)
    if robot.model.frames[fid].parentJoint == 0:
        raise InputError(f"{where}: frame {frame!r} is fixed to the world")
    k = np.asarray(knots)
    if k.size == 0:
        raise InputError(f"{where}: a phase with no knots")
    if not np.issubdtype(k.dtype, np.integer):
        raise InputError(f"{where}: knots must be integers, got {knots!r}")
    k = np.unique(k.astype(np.int64).ravel())
    if k[0] < 0 or k[-1] > N:
        raise InputError(f"{where}: knots {k[0]}..{k[-1]} outside 0..{N}")
    if k.size != k[-1] - k[0] + 1:
        raise InputError(f"{where}: knots must be contiguous (one stance), got {k.tolist()}")
    if k[-1] < 2:
        raise InputError(
            f"{where}: knots {k.tolist()} end before knot 2 (knots 0 and 1 are the start's)"
        )
    mu = as_real(friction, f"{where} friction", positive=True)
    start = frame_position(robot.model, fid, q0)
    p = start if position is None else as_array(position, (3,), f"{where} position")
    size, rotation = None, np.eye(3)
    if sole is not None:
        size = tuple(float(a) for a in as_array(sole, (2,), f"{where} sole"))
        if min(size) <= 0.0:
            raise InputError(f"{where}: sole (length, width) must be positive, got {size}")
        rotation = frame_rotation(robot.model, fid, q0)
    contact = Contact(name, frame, k, np.array(p, dtype=float), mu, size, rotation)
    if contact.first <= 1:
        first = pin.integrate(robot.model, q0, dt * np.asarray(v0, dtype=float))
        for knot, q in ((0, q0), (1, first)):
            if knot < contact.first:
                continue
            gap = float(np.linalg.norm(frame_position(robot.model, fid, q) - contact.position))
            if gap > START_TOLERANCE:
                raise InputError(
                    f"{where}: the start puts frame {frame!r} {gap:.3g} m from its contact "
                    f"position {contact.position.tolist()} at knot {knot}"
                )
            turn = orientation_error(rotation, frame_rotation(robot.model, fid, q))
            if sole is not None and turn > START_TOLERANCE:
                raise InputError(
                    f"{where}: the start turns sole frame {frame!r} {turn:.3g} rad at knot {knot}"
                )
    return contact


def contact_from_dict(data: dict[str, Any]) -> dict[str, Any]:
    """The keyword arguments of :meth:`mbplan.OCP.add_contact` saved by :meth:`Contact.to_dict`."""
    out = {k: data[k] for k in ("name", "frame", "knots", "position", "friction")}
    return out | ({"sole": tuple(data["sole"])} if "sole" in data else {})
