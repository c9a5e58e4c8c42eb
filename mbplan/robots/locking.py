"""Locking joints of a robot description at given values (``pinocchio.buildReducedModel``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.robots import RobotDescription
from mbplan.robots.lazy_geometry import LazyGeometry


def lock_values(
    desc: RobotDescription, lock: Mapping[str, float] | Sequence[str] | None
) -> dict[str, float]:
    """The values of the joints to lock: ``lock`` maps names to values, or lists names locked
    at the robot's ``default`` configuration (neutral without one); :class:`InputError` naming
    an unknown, multi-dof or non-finite one."""
    if not lock:
        return {}
    model = desc.model
    refs = model.referenceConfigurations
    ref = np.array(refs["default"]) if "default" in refs else pin.neutral(model)
    values = dict(lock) if isinstance(lock, Mapping) else dict.fromkeys(lock)
    out = {}
    for name, value in values.items():
        if not model.existJointName(name):
            raise InputError(
                f"lock: robot {desc.name!r} has no joint {name!r}; joints: {list(model.names[1:])}"
            )
        joint = model.joints[model.getJointId(name)]
        if joint.nq != 1:
            raise InputError(f"lock: joint {name!r} has {joint.nq} coordinates; only 1-dof joints")
        v = float(ref[joint.idx_q]) if value is None else float(value)
        if not np.isfinite(v):
            raise InputError(f"lock: value of joint {name!r} is not finite ({value!r})")
        out[name] = v
    return out


def reduced_description(desc: RobotDescription, locked: dict[str, float]) -> RobotDescription:
    """``desc`` with the ``locked`` joints fixed at their values (``pinocchio.buildReducedModel``
    of the model and its geometries; the reference configurations without them)."""
    model = desc.model
    q = pin.neutral(model)
    refs = model.referenceConfigurations
    if "default" in refs:
        q = np.array(refs["default"])
    ids = []
    for name, value in locked.items():
        j = model.getJointId(name)
        q[model.joints[j].idx_q] = value
        ids.append(j)
    collision = desc.collision_model
    if collision is not None:
        reduced, (collision,) = pin.buildReducedModel(model, [collision], ids, q)
    else:
        reduced = pin.buildReducedModel(model, ids, q)
    visual = desc.visual
    if isinstance(visual, LazyGeometry):  # reduced when it is first asked for
        visual = visual.then(lambda g: pin.buildReducedModel(model, [g], ids, q)[1][0])
    elif visual is not None:
        visual = pin.buildReducedModel(model, [visual], ids, q)[1][0]
    kept = [model.joints[model.getJointId(n)] for n in reduced.names[1:]]
    keep = [i for joint in kept for i in range(joint.idx_q, joint.idx_q + joint.nq)]
    for name in reference_names(refs):  # the reference configurations without the locked joints
        reduced.referenceConfigurations[name] = np.array(refs[name])[keep]
    return RobotDescription(desc.name, reduced, collision, visual, desc.urdf_path)


def reference_names(refs) -> list[str]:
    """Names of Pinocchio's ``referenceConfigurations`` (a std::map without ``keys``)."""
    return [str(pair.key()) if hasattr(pair, "key") else str(pair[0]) for pair in refs]
