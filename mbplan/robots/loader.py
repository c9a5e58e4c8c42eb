"""Load a robot description (Pinocchio model + geometry) by name, URDF or MJCF path or model.

Every URDF is checked with :mod:`xml.etree` before Pinocchio sees it, so that a
broken file fails with a :class:`~mbplan.errors.RobotModelError` naming the
offending link or joint rather than with a parser crash.
"""

from __future__ import annotations

import math
import os
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError, RobotModelError
from mbplan.robots.lazy_geometry import LazyGeometry, resolved

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
# A placeholder <inertial> (KDL-era URDFs put one on a root link, e.g. ANYmal's: 1e-6 kg, every
# entry 1e-6 kg m²) weighs nothing next to the body it is merged into: it is not checked for the
# triangle inequality of a rigid body's principal moments.
NEGLIGIBLE_MASS = 1e-5  # kg
NEGLIGIBLE_INERTIA = 1e-5  # kg m²
_URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


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


def validate_urdf(path: str | os.PathLike[str]) -> None:
    """Check a URDF file's XML, link tree and inertias; raise naming the culprit.

    Rules: well-formed XML with a ``<robot>`` root; unique link and joint names; known joint
    types; a ``<limit>`` with effort and velocity on revolute and prismatic joints; a non-zero
    axis; every joint's parent and child links defined; one root link, every other link the
    child of exactly one joint, no loop; masses finite and non-negative; inertia matrices
    positive semi-definite with principal moments obeying the triangle inequality; finite
    ``<origin>`` s; ``<limit>`` s with lower <= upper and non-negative effort and velocity; a
    ``<mimic>`` naming a defined joint with finite numbers; the child link of a non-fixed joint
    has an ``<inertial>`` with positive mass.  (Positive definiteness of each moving body's inertia, after Pinocchio merges
    the links fixed to it, is checked by :func:`mbplan.multibody.maximal_model`.)
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"URDF file not found: {path}")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise RobotModelError(f"malformed XML in URDF {path}: {err}") from err
    if root.tag != "robot":
        raise RobotModelError(f"URDF {path}: root element is <{root.tag}>, expected <robot>")

    links: dict[str, ET.Element] = {}
    for link in root.findall("link"):
        name = _required_attr(link, "name", f"URDF {path}: a <link>")
        if name in links:
            raise RobotModelError(f"URDF {path}: link {name!r} is defined twice")
        links[name] = link

    parent_joint: dict[str, str] = {}  # child link -> joint
    mimics: dict[str, ET.Element] = {}  # joint -> its <mimic>
    children: dict[str, list[str]] = {}  # parent link -> child links
    joint_names: set[str] = set()
    for joint in root.findall("joint"):
        jname = _required_attr(joint, "name", f"URDF {path}: a <joint>")
        where = f"URDF {path}: joint {jname!r}"
        if jname in joint_names:
            raise RobotModelError(f"URDF {path}: joint {jname!r} is defined twice")
        joint_names.add(jname)
        jtype = joint.get("type")
        if jtype not in _URDF_JOINT_TYPES:
            raise RobotModelError(
                f"{where} has unknown type {jtype!r}; URDF joint types are "
                f"{', '.join(_URDF_JOINT_TYPES)}"
            )
        parent, child = (
            _required_attr(_required_child(joint, tag, where), "link", f"{where} <{tag}>")
            for tag in ("parent", "child")
        )
        for role, link_name in (("parent", parent), ("child", child)):
            if link_name not in links:
                raise RobotModelError(
                    f"{where} has {role} link {link_name!r}, which is not defined"
                )
        if child in parent_joint:
            raise RobotModelError(
                f"URDF {path}: link {child!r} is the child of both joint "
                f"{parent_joint[child]!r} and joint {jname!r}"
            )
        parent_joint[child] = jname
        children.setdefault(parent, []).append(child)
        _check_origin(joint, where)
        if jtype in ("revolute", "prismatic"):
            limit = _required_child(joint, "limit", where)
            for attr in ("effort", "velocity"):
                if _number(limit, attr, where) < 0.0:
                    raise RobotModelError(
                        f"{where}: <limit {attr}={limit.get(attr)!r}> is negative"
                    )
            lower, upper = (
                _number(limit, a, where) if limit.get(a) is not None else 0.0
                for a in ("lower", "upper")
            )
            if lower > upper:
                raise RobotModelError(
                    f"{where}: <limit lower={limit.get('lower')!r} upper={limit.get('upper')!r}> "
                    "is inverted (lower > upper)"
                )
        mimic = joint.find("mimic")
        if mimic is not None:
            mimics[jname] = mimic
        axis = joint.find("axis")
        if jtype != "fixed" and axis is not None:
            _check_axis(axis.get("xyz", "1 0 0"), where)
        if jtype != "fixed":
            _check_moving_link(links[child], f"{where}: its child link {child!r}")

    roots = [name for name in links if name not in parent_joint]
    if len(roots) != 1:
        detail = f"several root links: {', '.join(roots)}" if roots else "no root link"
        raise RobotModelError(
            f"URDF {path}: {detail} (the links must form one tree, every link but the root being "
            "the child of a joint)"
        )
    reached, stack = set(roots), list(roots)
    while stack:
        for child in children.get(stack.pop(), []):
            reached.add(child)
            stack.append(child)
    if len(reached) != len(links):
        loop = sorted(set(links) - reached)
        raise RobotModelError(f"URDF {path}: links {', '.join(loop)} form a kinematic loop")

    for name, link in links.items():
        where = f"URDF {path}: link {name!r}"
        inertial = link.find("inertial")
        if inertial is not None:
            _mass_and_inertia(inertial, where)
        for tag in ("inertial", "visual", "collision"):
            for element in link.findall(tag):
                _check_origin(element, f"{where} <{tag}>")
    for jname, mimic in mimics.items():
        where = f"URDF {path}: joint {jname!r} <mimic>"
        leader = _required_attr(mimic, "joint", where)
        if leader not in joint_names:
            raise RobotModelError(f"{where} follows joint {leader!r}, which is not defined")
        for attr in ("multiplier", "offset"):
            if mimic.get(attr) is not None:
                _number(mimic, attr, where)


def mimic_tags(path: str | os.PathLike[str]) -> dict[str, tuple[str, float, float]]:
    """``{follower: (leader, multiplier, offset)}`` of a URDF's ``<mimic>`` tags (defaults 1
    and 0), for a file :func:`validate_urdf` has checked. A tag on a fixed joint (some
    descriptions, e.g. Talos' grippers, keep one for a simulator plugin) couples no coordinate
    and is not listed."""
    out = {}
    for joint in ET.parse(path).getroot().findall("joint"):
        mimic = joint.find("mimic")
        if mimic is not None and joint.get("type") != "fixed":
            m, o = (float(mimic.get(a, d)) for a, d in (("multiplier", 1.0), ("offset", 0.0)))
            out[str(joint.get("name"))] = (str(mimic.get("joint")), m, o)
    return out


def _check_origin(element: ET.Element, where: str) -> None:
    origin = element.find("origin")
    if origin is None:
        return
    for attr in ("xyz", "rpy"):
        text = origin.get(attr)
        if text is None:
            continue
        try:
            values = [float(x) for x in text.split()]
        except ValueError:
            values = []
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise RobotModelError(
                f"{where} <origin {attr}={text!r}>: expected three finite numbers"
            )


def _check_axis(text: str, where: str) -> None:
    try:
        axis = np.array([float(x) for x in text.split()])
    except ValueError:
        axis = np.array([])
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.any(axis):
        raise RobotModelError(f"{where} has axis {text!r}: expected three numbers, not all zero")


def _check_moving_link(link: ET.Element, where: str) -> None:
    inertial = link.find("inertial")
    if inertial is None:
        raise RobotModelError(f"{where} has no <inertial>: a moving link needs a mass and inertia")
    mass, _ = _mass_and_inertia(inertial, where)
    if mass == 0.0:
        raise RobotModelError(f"{where} has zero mass: a moving link needs a positive mass")


def _mass_and_inertia(inertial: ET.Element, where: str) -> tuple[float, np.ndarray]:
    """Mass and 3x3 inertia of an ``<inertial>``, checked finite, m >= 0 and inertia PSD."""
    mass = _number(_required_child(inertial, "mass", where), "value", where)
    if mass < 0.0:
        raise RobotModelError(f"{where} has negative mass {mass}")
    el = _required_child(inertial, "inertia", where)
    xx, xy, xz, yy, yz, zz = (
        _number(el, k, where) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    )
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    moments = np.linalg.eigvalsh(inertia)
    tol = 1e-12 * max(1.0, abs(moments[-1]))
    if moments[0] < -tol:
        raise RobotModelError(
            f"{where} has a non-positive-definite inertia (principal moments {moments})"
        )
    placeholder = mass <= NEGLIGIBLE_MASS and moments[-1] <= NEGLIGIBLE_INERTIA
    if not placeholder and moments[0] + moments[1] < moments[2] - max(tol, 1e-9 * moments[2]):
        raise RobotModelError(
            f"{where}: <inertia> principal moments {moments} violate the triangle inequality "
            "(I1 + I2 >= I3 holds for every rigid body)"
        )
    return mass, inertia


def _required_child(el: ET.Element, tag: str, where: str) -> ET.Element:
    child = el.find(tag)
    if child is None:
        raise RobotModelError(f"{where} has no <{tag}>")
    return child


def _required_attr(el: ET.Element, attr: str, where: str) -> str:
    value = el.get(attr)
    if not value:
        raise RobotModelError(f"{where} has no {attr!r} attribute")
    return value


def _number(el: ET.Element, attr: str, where: str) -> float:
    text = _required_attr(el, attr, f"{where} <{el.tag}>")
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise RobotModelError(f"{where}: <{el.tag} {attr}={text!r}> is not a finite number")
    return value
