"""The robot of an optimal control problem: a Pinocchio model with its geometry and its source.

:func:`load_robot` accepts what the Pinocchio ecosystem passes around — a robot name
(:func:`mbplan.robots.available_robots`), a URDF path (with ``package_dirs`` for ``package://``
meshes), an MJCF path, or a ``pinocchio.Model`` (with optional geometry models) — and can lock
joints at given values (``pinocchio.buildReducedModel``). URDF viscous joint damping
(``<dynamics damping>``, the generalized force ``-D q̇``) is read into ``model.damping``, which
every formulation and the verifier apply; ``damping=False`` zeroes it (the paper tasks: the
papers' dynamics have none). URDF ``<mimic>`` joints are couplings ``q_f = m q_l + o``
(:class:`Mimic`) that every :class:`~mbplan.OCP` of the robot imposes (``mimic="couple"``) or
joints of their own (``"independent"``). A robot with closed kinematic loops is its spanning tree
plus :class:`~mbplan.robots.loops.Loop` closures (MJCF ``<equality>`` ``<connect>``/``<weld>``, or
``loops=``); joints without an actuator (MJCF ``<actuator>``, or ``actuated=``) are passive: every
OCP of the robot keeps their torque at zero. The :class:`Robot` remembers how it was made
(:attr:`Robot.source`), so a saved plan can load it again.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError, RobotModelError
from mbplan.robots import RobotDescription, load
from mbplan.robots.continuous import to_angles, unbounded_revolute_model
from mbplan.robots.free_body import FreeBody
from mbplan.robots.joints import is_floating_root
from mbplan.robots.lazy_geometry import LazyGeometry, resolved
from mbplan.robots.loader import MECHANISMS, MJCF_SUFFIXES, load_mjcf, visual_geometry
from mbplan.robots.locking import lock_values, reduced_description, reference_names
from mbplan.robots.loops import (
    Loop,
    close_loops,
    independent_joints,
    loop_from_spec,
    loops_from_constraints,
    resolve_loops,
)
from mbplan.robots.mimic import MIMIC_MODES, Mimic, mimic_couplings, mimic_tags_of
from mbplan.robots.mjcf import mjcf_actuated, mjcf_equality_names


@dataclass(frozen=True, eq=False)
class Robot:
    """A fixed-base robot: ``model`` (1-dof joints only; ``model.damping`` the viscous joint
    damping every formulation applies), collision and visual geometry (may be None; the visual
    meshes are read when first drawn: :attr:`visual_model`), its ``source``
    (JSON-serialisable, see :func:`load_robot`), the locked joints, the continuous joints
    (revolute without limits in ``model``: :mod:`mbplan.robots.continuous`), the mimic
    couplings its OCPs impose, its loop closures and its passive (unactuated) joints."""

    name: str
    model: pin.Model
    collision_model: pin.GeometryModel | None
    visual: pin.GeometryModel | LazyGeometry | None
    source: dict[str, Any]
    locked: dict[str, float] = field(default_factory=dict)
    continuous: tuple[str, ...] = ()
    mimic: tuple[Mimic, ...] = ()
    loops: tuple[Loop, ...] = ()
    passive: tuple[str, ...] = ()

    @property
    def visual_model(self) -> pin.GeometryModel | None:
        """The visual geometry (its meshes read now, the first time)."""
        return resolved(self.visual)

    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def nv(self) -> int:
        return self.model.nv

    def configuration(self, name: str) -> np.ndarray:
        """A named reference configuration (SRDF), ``"neutral"`` or ``"default"``, with the
        mimic followers where their leaders put them (:meth:`coupled`) and the loops closed
        nearby (:func:`~mbplan.robots.loops.close_loops`)."""
        refs = self.model.referenceConfigurations
        if name in refs:
            return self.closed(self.coupled(np.array(refs[name], dtype=float)))
        if name == "neutral":
            return self.closed(self.coupled(pin.neutral(self.model)))
        raise InputError(
            f"robot {self.name!r} has no configuration {name!r}; known: "
            f"{', '.join(['neutral', *reference_names(refs)])}"
        )

    def frame_id(self, frame: str) -> int:
        """Index of frame ``frame``; :class:`InputError` listing similar names if unknown."""
        if not self.model.existFrame(frame):
            names = [f.name for f in self.model.frames]
            hint = [n for n in names if frame.split("_")[-1] in n][:8] or names[-8:]
            raise InputError(f"robot {self.name!r} has no frame {frame!r} (e.g. {hint})")
        return self.model.getFrameId(frame)

    def closed(self, q: np.ndarray) -> np.ndarray:
        """The configuration nearest ``q`` that closes the loops (``q`` if there are none)."""
        return close_loops(self.model, self.loops, q)[0] if self.loops else np.asarray(q)

    def independent_joints(self, q: np.ndarray) -> tuple[str, ...]:
        """Joints whose velocities determine all the others' through the loops at ``q``
        (:func:`~mbplan.robots.loops.independent_joints`: the actuated ones where they do); a
        velocity condition on every joint, e.g. rest at the last knot, is imposed on these
        alone (``JointVelocity(joints=robot.independent_joints(q))``) to keep the constraint
        Jacobian of full rank. Every joint without loops."""
        passive = self.joint_indices(self.passive)
        keep = independent_joints(self.model, self.loops, np.asarray(q, dtype=float), passive)
        return tuple(n for n in self.joint_names if self.joint_indices((n,))[0] in keep)

    def coupled(self, q: np.ndarray) -> np.ndarray:
        """``q`` with every mimic follower at ``multiplier · q[leader] + offset``."""
        out = np.array(q, dtype=float)
        for c in self.mimic:
            lead, follow = self.q_of_v[self.joint_indices((c.leader, c.follower))]
            out[follow] = c.multiplier * out[lead] + c.offset
        return out

    @property
    def floating(self) -> bool:
        """Whether the robot has a floating base (a free-flyer root joint: the first 7
        coordinates of ``q`` are the base's position and quaternion, the first 6 of ``v`` its
        local velocity)."""
        return self.model.njoints > 1 and is_floating_root(self.model, 1)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The 1-dof joints (every joint but a floating base's free flyer), in model order."""
        return tuple(self.model.names[2 if self.floating else 1 :])

    @property
    def q_of_v(self) -> np.ndarray:
        """(nv,) the configuration index of each 1-dof joint's velocity index (``-1`` on a
        floating base's six)."""
        out = -np.ones(self.nv, np.int64)
        for j in range(2 if self.floating else 1, self.model.njoints):
            out[self.model.joints[j].idx_v] = self.model.joints[j].idx_q
        return out

    def joint_name(self, index: int) -> str:
        """The name of the 1-dof joint with velocity index ``index``."""
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            if joint.idx_v == int(index) and joint.nv == 1:
                return self.model.names[j]
        raise InputError(f"robot {self.name!r} has no 1-dof joint at velocity index {index}")

    def joint_indices(self, joints: Sequence[str] | None) -> np.ndarray:
        """Velocity indices of ``joints`` (every 1-dof joint if None: not a floating base's);
        :class:`InputError` on an unknown name or the floating base's joint."""
        if joints is None:
            joints = self.joint_names
        out = []
        for j in joints:
            if not self.model.existJointName(j):
                locked = " (it is locked)" if j in self.locked else ""
                raise InputError(
                    f"robot {self.name!r} has no joint {j!r}{locked}; joints: "
                    f"{list(self.joint_names)}"
                )
            jid = self.model.getJointId(j)
            if self.model.joints[jid].nv != 1:
                raise InputError(
                    f"robot {self.name!r}: {j!r} is its floating base, not a 1-dof joint (use "
                    "the base's frame residuals); joints: "
                    f"{list(self.joint_names)}"
                )
            out.append(self.model.joints[jid].idx_v)
        return np.array(out, dtype=np.int64)


def load_robot(
    robot: str | os.PathLike[str] | pin.Model | RobotDescription | Robot | FreeBody,
    *,
    package_dirs: Sequence[str | os.PathLike[str]] = (),
    lock: Mapping[str, float] | Sequence[str] | None = None,
    collision_model: pin.GeometryModel | None = None,
    visual_model: pin.GeometryModel | None = None,
    damping: bool = True,
    mimic: str = "couple",
    loops: Sequence[Loop | Mapping[str, Any]] = (),
    actuated: Sequence[str] | None = None,
) -> Robot | FreeBody:
    """Load ``robot`` (name, ``.urdf`` or ``.xml`` MJCF path, ``pinocchio.Model``) and lock the
    joints ``lock`` (names at their reference value: the SRDF ``default`` configuration if any,
    else neutral; or a mapping name → value). Continuous joints become unbounded revolute joints
    (one angle each, :mod:`mbplan.robots.continuous`); every other joint must be 1-dof (nq = nv).
    ``damping=False``: the robot's ``model.damping`` is zeroed (on a copy of the model).
    ``mimic``: ``"couple"`` records a URDF's ``<mimic>`` joints as :class:`Mimic` couplings
    (:class:`RobotModelError` for a pair of different kinds or a chain; :class:`InputError` for
    a locked leader of a free follower; a locked follower needs none), ``"independent"`` plans
    them as joints of their own. ``loops``: closures besides an MJCF file's ``<equality>``
    ones, :class:`~mbplan.robots.loops.Loop` or mappings (:func:`~mbplan.robots.loops.loop_from_spec`:
    two frames by name, the kind, placements); their redundant rows are dropped and reported
    (:func:`~mbplan.robots.loops.resolve_loops`). ``actuated``: the joints with an actuator (default:
    an MJCF file's ``<actuator>`` joints if it has any, else every joint); the others are
    passive. A :class:`~mbplan.robots.free_body.FreeBody` or a :class:`Robot` is returned as
    is."""
    if mimic not in MIMIC_MODES:
        raise InputError(f"mimic: expected one of {', '.join(MIMIC_MODES)}, got {mimic!r}")
    if isinstance(robot, FreeBody):
        return robot
    plain = not loops and actuated is None
    if isinstance(robot, str | os.PathLike) and collision_model is None and visual_model is None:
        names = dict(lock) if isinstance(lock, Mapping) else dict.fromkeys(lock or ())
        frozen = tuple(sorted(names.items(), key=lambda kv: kv[0])) or None
        dirs = tuple(os.fspath(d) for d in package_dirs)
        if plain:
            return _cached(os.fspath(robot), dirs, frozen, bool(damping), mimic)
    extra = (tuple(loops), None if actuated is None else tuple(actuated))
    return _load(robot, package_dirs, lock, collision_model, visual_model, damping, mimic, *extra)


def _load(
    robot,
    package_dirs,
    lock,
    collision_model,
    visual_model,
    damping=True,
    mimic="couple",
    loops: tuple = (),
    actuated: tuple[str, ...] | None = None,
) -> Robot:
    if isinstance(robot, Robot):
        given = lock or package_dirs or loops or actuated is not None
        if given or collision_model is not None or visual_model is not None:
            raise InputError("load_robot: a Robot is returned as is; pass no other argument")
        if not damping and np.any(robot.model.damping):
            raise InputError(
                "load_robot: damping=False with a Robot whose model has damping; load it "
                "again with damping=False"
            )
        return robot
    file_loops: list[Loop] = []
    file_actuated: tuple[str, ...] | None = None
    if isinstance(robot, pin.Model):
        desc = load(robot, collision_model=collision_model, visual_model=visual_model)
        source: dict[str, Any] = {"kind": "model", "name": robot.name}
    elif isinstance(robot, RobotDescription):
        desc = robot
        source = (
            {"kind": "urdf", "path": str(robot.urdf_path)}
            if robot.urdf_path is not None
            else {"kind": "model", "name": robot.name}
        )
    elif isinstance(robot, str | os.PathLike):
        desc, source, file_loops, file_actuated = _load_path(robot, package_dirs)
    else:
        raise InputError(
            f"cannot load a robot from a {type(robot).__name__}: expected a robot name, a URDF or "
            "MJCF path or a pinocchio.Model"
        )
    desc, continuous = _unbounded(desc)
    locked = lock_values(desc, lock)
    for loop in file_loops:
        carried = [j for j in (loop.joint1, loop.joint2) if j in locked]
        if carried:
            raise InputError(f"lock: joint {carried[0]!r} carries the loop {loop.name!r}")
    if locked:
        source = {**source, "lock": locked}
        desc = reduced_description(desc, locked)
    _check_joints(desc)
    given_loops = [loop_from_spec(desc.model, s, i) for i, s in enumerate(loops)]
    if given_loops:
        source = {**source, "loops": [loop.to_dict() for loop in given_loops]}
    if actuated is not None:
        source = {**source, "actuated": list(actuated)}
    passive = _passive(desc.model, actuated if actuated is not None else file_actuated, locked)
    if not damping:
        model = pin.Model(desc.model)  # a copy: the caller's (or the cached) model is untouched
        model.damping[:] = 0.0
        desc = RobotDescription(desc.name, model, desc.collision_model, desc.visual, desc.urdf_path)
    tags = mimic_tags_of(desc)
    couplings = mimic_couplings(desc, tags, locked) if mimic == "couple" else ()
    source = {**source, "damping": bool(damping)} | ({"mimic": mimic} if tags else {})
    continuous = tuple(n for n in continuous if n not in locked)
    robot = Robot(
        desc.name,
        desc.model,
        desc.collision_model,
        desc.visual,
        source,
        locked,
        continuous,
        couplings,
        passive=passive,
    )
    all_loops = [*file_loops, *given_loops]
    if not all_loops:
        return robot
    if robot.floating:
        raise RobotModelError(
            f"{desc.name}: loop closures on a floating-base robot are not supported (its "
            "closures would be contacts, which mbplan does not model yet); "
            f"loops: {', '.join(loop.name for loop in all_loops)}"
        )
    refs = desc.model.referenceConfigurations
    q_ref = robot.configuration("default" if "default" in refs else "neutral")
    return replace(robot, loops=resolve_loops(desc.model, all_loops, q_ref))


def _passive(
    model: pin.Model, actuated: Sequence[str] | None, locked: Mapping[str, float]
) -> tuple[str, ...]:
    """The unlocked joints not in ``actuated`` (none if ``actuated`` is None)."""
    if actuated is None:
        return ()
    names = list(model.names[2 if is_floating_root(model, 1) else 1 :])
    for name in actuated:
        if name not in names and name not in locked:
            raise InputError(f"actuated: {name!r} is not a joint of the robot; joints: {names}")
    return tuple(n for n in names if n not in actuated)


def _unbounded(desc: RobotDescription) -> tuple[RobotDescription, tuple[str, ...]]:
    """``desc`` with its continuous joints as unbounded revolute joints (reference configurations
    converted to angles)."""
    model, names = unbounded_revolute_model(desc.model)
    if not names:
        return desc, ()
    refs = desc.model.referenceConfigurations
    for name in reference_names(refs):
        model.referenceConfigurations[name] = to_angles(desc.model, np.array(refs[name]))
    return RobotDescription(
        desc.name, model, desc.collision_model, desc.visual, desc.urdf_path
    ), names


def robot_from_source(source: Mapping[str, Any]) -> Robot | FreeBody:
    """Load the robot again from :attr:`Robot.source` (what a saved plan stores). A source
    without ``damping`` is from before mbplan applied joint damping: loaded without it; one
    without ``mimic``, from before mimic couplings: its mimic joints independent."""
    kind = source.get("kind")
    if kind == "free_body":
        return FreeBody.from_source(source)
    options = {
        "lock": source.get("lock") or None,
        "damping": bool(source.get("damping", False)),
        "mimic": source.get("mimic", "independent"),
        "loops": source.get("loops", ()),
        "actuated": source.get("actuated"),
    }
    if kind == "name":
        return load_robot(source["name"], **options)
    if kind in ("urdf", "mjcf"):
        return load_robot(source["path"], package_dirs=source.get("package_dirs", ()), **options)
    raise InputError(
        f"the robot was an in-memory pinocchio.Model ({source.get('name')!r}) and cannot be "
        "loaded from the file: pass the OCP (or the robot) explicitly"
    )


# process-wide cache, result-neutral: robot loading by name: the model of the file alone
@cache
def _cached(
    spec: str, package_dirs: tuple[str, ...], lock: tuple | None, damping: bool, mimic: str
) -> Robot:
    """One :class:`Robot` per (path or name, package_dirs, lock, damping, mimic): shared, do not
    modify."""
    return _load(spec, package_dirs, dict(lock) if lock else None, None, None, damping, mimic)


def _load_path(
    robot: str | os.PathLike[str], package_dirs: Sequence[str | os.PathLike[str]]
) -> tuple[RobotDescription, dict[str, Any], list[Loop], tuple[str, ...] | None]:
    """The description and source of a name or path, an MJCF file's loops and actuated joints
    (None: the file has no ``<actuator>``)."""
    path = Path(robot)
    dirs = [str(Path(d).resolve()) for d in package_dirs]
    if isinstance(robot, str) and robot in MECHANISMS:
        desc, loops, actuated = _mjcf(MECHANISMS[robot], robot)
        return desc, {"kind": "name", "name": robot}, loops, actuated
    if path.suffix.lower() in MJCF_SUFFIXES:
        desc, loops, actuated = _mjcf(path, None)
        return desc, {"kind": "mjcf", "path": str(path.resolve())}, loops, actuated
    if isinstance(robot, str) and path.suffix.lower() != ".urdf":
        return load(robot), {"kind": "name", "name": robot}, [], None
    if not dirs:
        return load(path), {"kind": "urdf", "path": str(path.resolve())}, [], None
    if not path.is_file():
        raise InputError(f"URDF file not found: {path}")
    try:
        model, collision = pin.buildModelsFromUrdf(
            str(path), package_dirs=dirs, geometry_types=[pin.GeometryType.COLLISION]
        )
    except (RuntimeError, ValueError) as err:
        raise RobotModelError(f"Pinocchio cannot build a model from {path}: {err}") from None
    visual = visual_geometry(model, path, dirs)
    desc = RobotDescription(model.name, model, collision, visual, path)
    return desc, {"kind": "urdf", "path": str(path.resolve()), "package_dirs": dirs}, [], None


def _mjcf(
    path: Path, name: str | None
) -> tuple[RobotDescription, list[Loop], tuple[str, ...] | None]:
    """An MJCF file's description, its ``<equality>`` loops (named as in the file) and its
    actuated joints (None: no ``<actuator>``)."""
    desc, constraints = load_mjcf(path, name)
    loops = loops_from_constraints(desc.model, constraints)
    names = mjcf_equality_names(path)
    if len(names) == len(loops):
        loops = [replace(loop, name=n or loop.name) for loop, n in zip(loops, names, strict=True)]
    return desc, loops, mjcf_actuated(path)


def _check_joints(desc: RobotDescription) -> None:
    model = desc.model
    for j in range(1, model.njoints):
        if is_floating_root(model, j):
            continue
        if model.joints[j].nq != 1 or model.joints[j].nv != 1:
            raise RobotModelError(
                f"{desc.name}: joint {model.names[j]!r} ({model.joints[j].shortname()}) is not a "
                "revolute, continuous or prismatic joint, nor a free-flyer joint on the world "
                "(lock it)"
            )
