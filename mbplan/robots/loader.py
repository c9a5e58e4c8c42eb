"""Load a robot description (Pinocchio model + geometry) by name, URDF or MJCF path or model.

Every URDF is checked before Pinocchio sees it (:mod:`mbplan.robots.urdf_checks`).
Floating-base robots of example-robot-data get a free-flyer root joint.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

import pinocchio as pin

from mbplan.errors import InputError, RobotModelError
from mbplan.robots.lazy_geometry import LazyGeometry, resolved
from mbplan.robots.urdf_checks import validate_urdf

DATA = Path(__file__).resolve().parent / "data"
IIWA_URDF = DATA / "iiwa14.urdf"

# Mechanisms with closed kinematic loops, bundled as MJCF files (their closures are
# <equality> constraints, their actuated joints the <actuator> ones; see docs/loops.md).
MECHANISMS: dict[str, Path] = {
    "fourbar": DATA / "fourbar.xml",
    "delta": DATA / "delta.xml",
    "two_arm_carry": DATA / "two_arm_carry.xml",
}

# Fixed-base arms of example-robot-data: name -> (description folder, URDF path in it, SRDF).
# The table mirrors the upstream `example_robot_data` loaders, which are no longer part of the
# `example-robot-data` wheel (>= 4.4 ships only the model files).
_ERD_ARMS: dict[str, tuple[str, str, str | None]] = {
    "panda": ("panda_description", "urdf/panda.urdf", "srdf/panda.srdf"),
    "ur3": ("ur_description", "urdf/ur3_robot.urdf", None),
    "ur3_limited": ("ur_description", "urdf/ur3_joint_limited_robot.urdf", None),
    "ur3_gripper": ("ur_description", "urdf/ur3_gripper.urdf", "srdf/ur3_gripper.srdf"),
    "ur5": ("ur_description", "urdf/ur5_robot.urdf", "srdf/ur5.srdf"),
    "ur5_limited": (
        "ur_description",
        "urdf/ur5_joint_limited_robot.urdf",
        "srdf/ur5_joint_limited_robot.srdf",
    ),
    "ur5_gripper": ("ur_description", "urdf/ur5_gripper.urdf", "srdf/ur5_gripper.srdf"),
    "ur10": ("ur_description", "urdf/ur10_robot.urdf", None),
    "ur10_limited": ("ur_description", "urdf/ur10_joint_limited_robot.urdf", None),
    "kinova": ("kinova_description", "robots/kinova.urdf", "srdf/kinova.srdf"),
    "z1": ("z1_description", "urdf/z1.urdf", "srdf/z1.srdf"),
    "xarm7": ("xarm_description", "urdf/xarm7.urdf", "srdf/xarm7.srdf"),
    "so100": ("so_arm_description", "urdf/so100.urdf", None),
    "so101": ("so_arm_description", "urdf/so101.urdf", None),
    "talos_arm": ("talos_data", "robots/talos_left_arm.urdf", None),
    "finger_edu": ("finger_edu_description", "robots/finger_edu.urdf", "srdf/finger_edu.srdf"),
    "asr_twodof": ("asr_twodof_description", "urdf/TwoDofs.urdf", None),
    "double_pendulum": ("double_pendulum_description", "urdf/double_pendulum.urdf", None),
    "double_pendulum_continuous": (
        "double_pendulum_description",
        "urdf/double_pendulum_continuous.urdf",
        None,
    ),
    "double_pendulum_simple": (
        "double_pendulum_description",
        "urdf/double_pendulum_simple.urdf",
        None,
    ),
}

# Floating-base robots of example-robot-data (a free-flyer root joint): name -> (description
# folder, URDF path in it, SRDF, the SRDF posture that becomes the ``default`` configuration),
# as the upstream loaders build them.
_ERD_FLOATING: dict[str, tuple[str, str, str | None, str | None]] = {
    "solo8": ("solo_description", "robots/solo.urdf", "srdf/solo.srdf", "standing"),
    "solo12": ("solo_description", "robots/solo12.urdf", "srdf/solo.srdf", "standing"),
    "anymal": ("anymal_b_simple_description", "robots/anymal.urdf", "srdf/anymal.srdf", "standing"),
    "hyq": ("hyq_description", "robots/hyq_no_sensors.urdf", "srdf/hyq.srdf", "standing"),
    "a1": ("a1_description", "urdf/a1.urdf", "srdf/a1.srdf", "standing"),
    "go1": ("go1_description", "urdf/go1.urdf", "srdf/go1.srdf", "standing"),
    "go2": ("go2_description", "urdf/go2.urdf", "srdf/go2.srdf", "standing"),
    "b1": ("b1_description", "urdf/b1.urdf", "srdf/b1.srdf", "standing"),
    "bolt": ("bolt_description", "robots/bolt.urdf", "srdf/bolt.srdf", "standing"),
    "talos": ("talos_data", "robots/talos_reduced.urdf", "srdf/talos.srdf", "half_sitting"),
    "talos_legs": ("talos_data", "robots/talos_reduced.urdf", "srdf/talos.srdf", "half_sitting"),
    "g1": ("g1_description", "urdf/g1_29dof_rev_1_0.urdf", None, None),
}
# Robots planned with some joints locked at their default configuration: name -> the joints
# kept (talos_legs: Talos with its torso, arms and head rigid, their mass merged).
_KEEP_ONLY: dict[str, tuple[str, ...]] = {
    "talos_legs": tuple(f"leg_{side}_{i}_joint" for side in ("left", "right") for i in range(1, 7)),
}

MJCF_SUFFIXES = (".xml", ".mjcf")


@dataclass(frozen=True, eq=False)
class RobotDescription:
    """A loaded robot: kinematic/inertial model plus optional geometry (``visual``: a model, or
    one loaded when first asked for, :mod:`.lazy_geometry`; :attr:`visual_model` builds it)."""

    name: str
    model: pin.Model
    collision_model: pin.GeometryModel | None
    visual: pin.GeometryModel | LazyGeometry | None
    urdf_path: Path | None

    @property
    def visual_model(self) -> pin.GeometryModel | None:
        """The visual geometry (its meshes read now, the first time)."""
        return resolved(self.visual)


RobotSpec = str | os.PathLike[str] | pin.Model | RobotDescription


def available_robots() -> list[str]:
    """Names accepted by :func:`load`: the serial arms (:func:`available_arms`), the
    mechanisms with closed loops (:data:`MECHANISMS`) and the floating-base robots
    (:func:`available_floating`)."""
    return [*available_arms(), *MECHANISMS, *available_floating()]


def available_floating() -> list[str]:
    """The floating-base robots of example-robot-data (quadrupeds and humanoids): a free-flyer
    root joint, the base a free rigid body."""
    return list(_ERD_FLOATING)


def available_arms() -> list[str]:
    """The serial (loop-free) arms: ``"iiwa"`` and the example-robot-data fixed-base arms."""
    return ["iiwa", *_ERD_ARMS]


def load(
    robot: RobotSpec,
    *,
    collision_model: pin.GeometryModel | None = None,
    visual_model: pin.GeometryModel | None = None,
    geometry: bool = True,
) -> RobotDescription:
    """Load ``robot``: a name from :func:`available_robots`, a URDF or MJCF (``.xml``) path, or a
    ``pinocchio.Model``.

    ``collision_model``/``visual_model`` accompany a ``pinocchio.Model``; ``geometry=False``
    skips loading geometry (and meshes) from a URDF.  A :class:`RobotDescription` is returned
    unchanged.  URDF ``<mimic>`` tags are left out of the model, as by Pinocchio's default: the
    mimicking joint is a joint of its own (:func:`mimic_tags` reads them).  SRDF reference
    configurations of example-robot-data arms are stored in ``model.referenceConfigurations``.
    An MJCF file's loop closures and actuators are not part of the description
    (:func:`mbplan.robots.load_robot` reads them).
    """
    if isinstance(robot, pin.Model):
        return RobotDescription(robot.name, robot, collision_model, visual_model, None)
    if collision_model is not None or visual_model is not None:
        raise InputError("collision_model and visual_model can only accompany a pinocchio.Model")
    if isinstance(robot, RobotDescription):
        return robot
    if not isinstance(robot, str | os.PathLike):
        raise InputError(
            f"cannot load a robot from a {type(robot).__name__}: expected a robot name, "
            "a URDF path or a pinocchio.Model"
        )
    if isinstance(robot, str):
        if robot == "iiwa":
            return _load_urdf(IIWA_URDF, "iiwa", [], geometry)
        if robot in _ERD_ARMS:
            return _load_erd(robot, geometry)
        if robot in MECHANISMS:
            return load_mjcf(MECHANISMS[robot], robot, geometry)[0]
        if robot in _ERD_FLOATING:
            return _load_erd_floating(robot, geometry)
        if Path(robot).suffix.lower() not in (".urdf", *MJCF_SUFFIXES) and not Path(robot).exists():
            raise InputError(
                f"unknown robot {robot!r}: not a URDF or MJCF path and not one of "
                f"{', '.join(available_robots())}"
            )
    path = Path(robot)
    if path.suffix.lower() in MJCF_SUFFIXES:
        return load_mjcf(path, None, geometry)[0]
    return _load_urdf(path, None, [path.resolve().parent], geometry)


def _erd_model_dir() -> Path:
    """The ``share/example-robot-data/robots`` folder installed beside the Python packages."""
    for entry in sys.path:
        candidate = Path(entry or ".", "..", "..", "..", "share", "example-robot-data", "robots")
        if candidate.is_dir():
            return candidate.resolve()
    raise RobotModelError("example-robot-data models not found: install `example-robot-data`")


def _load_erd(name: str, geometry: bool) -> RobotDescription:
    folder, urdf, srdf = _ERD_ARMS[name]
    models = _erd_model_dir()
    desc = _load_urdf(models / folder / urdf, name, [models.parent.parent], geometry)
    if srdf is not None:
        pin.loadReferenceConfigurations(desc.model, str(models / folder / srdf), False)
    return desc


def _load_erd_floating(name: str, geometry: bool) -> RobotDescription:
    from mbplan.robots.locking import reduced_description  # locking reads descriptions

    folder, urdf, srdf, posture = _ERD_FLOATING[name]
    models = _erd_model_dir()
    desc = _load_urdf(models / folder / urdf, name, [models.parent.parent], geometry, True)
    model = desc.model
    if srdf is not None:
        pin.loadReferenceConfigurations(model, str(models / folder / srdf), False)
    if posture is not None:
        model.referenceConfigurations["default"] = model.referenceConfigurations[posture]
    if name in _KEEP_ONLY:
        keep = _KEEP_ONLY[name]
        ref = model.referenceConfigurations["default"]
        locked = {
            n: float(ref[model.joints[j].idx_q])
            for j, n in enumerate(model.names)
            if j > 1 and n not in keep
        }
        desc = reduced_description(desc, locked)
    return desc


def _load_urdf(
    path: Path,
    name: str | None,
    package_dirs: list[Path],
    geometry: bool,
    floating: bool = False,
) -> RobotDescription:
    """The description of the URDF ``path``; ``floating``: with a free-flyer root joint."""
    validate_urdf(path)
    dirs = [str(d) for d in package_dirs]
    types = [pin.GeometryType.COLLISION] if geometry else []
    root = {"root_joint": pin.JointModelFreeFlyer()} if floating else {}
    try:
        model, *geoms = pin.buildModelsFromUrdf(
            str(path), package_dirs=dirs, geometry_types=types, **root
        )
    except (RuntimeError, ValueError) as err:
        raise RobotModelError(f"Pinocchio cannot build a model from {path}: {err}") from err
    if not geometry:
        return RobotDescription(name or model.name, model, None, None, path)
    visual = visual_geometry(model, path, dirs)
    return RobotDescription(name or model.name, model, geoms[0], visual, path)


def visual_geometry(model: pin.Model, path: Path, package_dirs: list[str]) -> LazyGeometry:
    """The visual geometry of the URDF ``path`` for ``model`` (Pinocchio's, built from it), read
    when it is first asked for."""
    kind = pin.GeometryType.VISUAL

    def build() -> pin.GeometryModel:
        try:
            return pin.buildGeomFromUrdf(model, str(path), kind, package_dirs=package_dirs)
        except (RuntimeError, ValueError) as err:
            raise RobotModelError(
                f"Pinocchio cannot read the visual geometry of {path}: {err}"
            ) from err

    return LazyGeometry(build)


def load_mjcf(
    path: str | os.PathLike[str], name: str | None = None, geometry: bool = True
) -> tuple[RobotDescription, list]:
    """The description of an MJCF file (named ``name``, else the file's model name) and its
    ``<equality>`` closures as Pinocchio's constraint models (``<connect>`` ones first, then
    ``<weld>`` ones)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"MJCF file not found: {path}")
    try:
        model, constraints = pin.buildModelsFromMJCF(str(path), contacts=True)[:2]
        geoms = [
            pin.buildGeomFromMJCF(model, str(path), kind)
            for kind in (pin.GeometryType.COLLISION, pin.GeometryType.VISUAL)
            if geometry
        ]
    except (RuntimeError, ValueError) as err:
        raise RobotModelError(f"Pinocchio cannot build a model from MJCF {path}: {err}") from None
    collision, visual = geoms if geometry else (None, None)
    return RobotDescription(name or model.name, model, collision, visual, path), list(constraints)
