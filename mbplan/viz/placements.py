"""World placements of a visual ``GeometryModel``'s objects along a trajectory.

A maximal-coordinate solution is drawn straight from its SO(3)×R³ states: body ``b``'s frame is at
its centre of mass with the orientation of its joint frame, so a visual geometry attached to that
joint at ``placement_g`` is at ``oMg = [R_b, p_b] · [I, -com_in_joint_b] · placement_g``, and the
viewer shows what the solver produced, joint-constraint violations included. A generalized
solution goes through Pinocchio's forward kinematics.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from mbplan.errors import InputError, RobotModelError
from mbplan.multibody import MaximalModel


def maximal_geometry_placements(
    mm: MaximalModel, geometry: pin.GeometryModel, R: ArrayLike, p: ArrayLike
) -> np.ndarray:
    """World placements ``(..., ngeom, 4, 4)`` of the objects of ``geometry`` (attached to
    ``mm.model``'s joints) from body poses ``R (..., nb, 3, 3)``, ``p (..., nb, 3)`` (module
    docstring); objects on the universe stay at their placement."""
    R, p = np.asarray(R, dtype=float), np.asarray(p, dtype=float)
    nb = mm.nb
    if R.shape[-3:] != (nb, 3, 3) or p.shape[-2:] != (nb, 3) or R.shape[:-3] != p.shape[:-2]:
        raise InputError(
            f"expected R (..., {nb}, 3, 3) and p (..., {nb}, 3) for {mm.name!r}, got "
            f"{R.shape} and {p.shape}"
        )
    body = {int(j): b for b, j in enumerate(mm.pin_joint)}
    body_frames = np.zeros((*R.shape[:-2], 4, 4))
    body_frames[..., :3, :3] = R
    body_frames[..., :3, 3] = p - np.einsum("...bij,bj->...bi", R, mm.com_in_joint)
    body_frames[..., 3, 3] = 1.0
    out = np.empty((*R.shape[:-3], geometry.ngeoms, 4, 4))
    for g, obj in enumerate(geometry.geometryObjects):
        placement = obj.placement.homogeneous
        if obj.parentJoint == 0:
            out[..., g, :, :] = placement
        elif obj.parentJoint in body:
            out[..., g, :, :] = body_frames[..., body[obj.parentJoint], :, :] @ placement
        else:
            raise RobotModelError(
                f"geometry {obj.name!r} hangs on joint {obj.parentJoint}, which moves no body of "
                f"{mm.name!r}"
            )
    return out


def generalized_geometry_placements(
    model: pin.Model, geometry: pin.GeometryModel, q: ArrayLike
) -> np.ndarray:
    """World placements ``(K, ngeom, 4, 4)`` of the objects of ``geometry`` at the
    configurations ``q (K, nq)`` (Pinocchio forward kinematics)."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != model.nq:
        raise InputError(f"expected q (K, {model.nq}) for {model.name!r}, got {q.shape}")
    data, gdata = model.createData(), geometry.createData()
    out = np.empty((len(q), geometry.ngeoms, 4, 4))
    for k, qk in enumerate(q):
        pin.updateGeometryPlacements(model, data, geometry, gdata, qk)
        out[k] = [M.homogeneous for M in gdata.oMg]
    return out
