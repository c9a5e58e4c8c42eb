"""Forward dynamics of a robot with loop closures in generalized coordinates: the reference the
maximal-coordinate LGVI is validated against.

Each closure (:mod:`mbplan.robots.loops`) becomes Pinocchio rigid constraints between its two
frames: a point closure a 3-D contact (``CONTACT_3D``), a weld a 6-D one (``CONTACT_6D``) and a
revolute closure two 3-D contacts, at the frames' origins and :data:`REVOLUTE_SPAN` along their
common ``z`` axis. Redundant rows (a planar mechanism's out-of-plane rows, the revolute pair's
along the axis) leave the constraint forces indeterminate but not the accelerations, which
:func:`pinocchio.constraintDynamics` finds with its proximal iterations (:data:`PROXIMAL`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from mbplan.robots.loops import Loop, loop_jacobian

REVOLUTE_SPAN = 0.1  # m: second contact of a revolute closure, along the frames' z axis
PROXIMAL = (1e-13, 1e-10, 100)  # accuracy, proximal μ, iterations of constraintDynamics


def constraint_models(model: pin.Model, loops: Sequence[Loop]) -> list[pin.RigidConstraintModel]:
    """Pinocchio's rigid constraints of ``loops`` (module docstring)."""
    kinds = {"point": pin.ContactType.CONTACT_3D, "weld": pin.ContactType.CONTACT_6D}
    out = []
    for loop in loops:
        j1, j2 = model.getJointId(loop.joint1), model.getJointId(loop.joint2)
        pairs = [(loop.placement1, loop.placement2)]
        if loop.kind == "revolute":
            shift = np.eye(4)
            shift[2, 3] = REVOLUTE_SPAN
            pairs.append((loop.placement1 @ shift, loop.placement2 @ shift))
        for M1, M2 in pairs:
            out.append(
                pin.RigidConstraintModel(
                    kinds.get(loop.kind, pin.ContactType.CONTACT_3D),
                    model,
                    j1,
                    pin.SE3(M1),
                    j2,
                    pin.SE3(M2),
                    pin.ReferenceFrame.LOCAL,
                )
            )
    return out


class ClosedLoopDynamics:
    """``q̈(q, v, τ)`` of ``model`` under the closures ``loops`` and the model's viscous joint
    damping ``-D v`` (:func:`pinocchio.constraintDynamics`, module docstring)."""

    def __init__(self, model: pin.Model, loops: Sequence[Loop]) -> None:
        self.model, self.data = model, model.createData()
        self.constraints = pin.StdVec_RigidConstraintModel(constraint_models(model, loops))
        self.constraint_data = pin.StdVec_RigidConstraintData(
            [c.createData() for c in self.constraints]
        )
        pin.initConstraintDynamics(model, self.data, self.constraints, self.constraint_data)
        self.settings = pin.ProximalSettings(*PROXIMAL)

    def __call__(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        force = np.asarray(tau, dtype=float) - self.model.damping * v
        return pin.constraintDynamics(
            self.model,
            self.data,
            q,
            v,
            force,
            self.constraints,
            self.constraint_data,
            self.settings,
        ).copy()


def closed_loop_actuation(
    model: pin.Model, loops: Sequence[Loop], active: np.ndarray, q: np.ndarray, tau: np.ndarray
) -> np.ndarray:
    """The joint torques ``u`` (zero but on the ``active`` joints, velocity indices) with
    ``u + Jᵀf = τ`` for some closure forces ``f`` (``J``:
    :func:`~mbplan.robots.loops.loop_jacobian` at ``q``; least squares): what the actuators
    apply for the generalized force ``τ`` of the closed mechanism."""
    J = loop_jacobian(model, loops, q)
    basis = np.hstack([np.eye(model.nv)[:, active], J.T])
    out = np.zeros(model.nv)
    out[active] = np.linalg.lstsq(basis, tau, rcond=None)[0][: len(active)]
    return out
