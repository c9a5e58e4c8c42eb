"""Robot loading: bundled iiwa URDF, example-robot-data arms, URDF validation errors."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from mbplan.errors import InputError, RobotModelError
from mbplan.robots import (
    IIWA_URDF,
    RobotDescription,
    available_floating,
    available_robots,
    load,
    validate_urdf,
)

REPO = Path(__file__).resolve().parent.parent


def _generator():
    spec = importlib.util.spec_from_file_location(
        "make_iiwa14_urdf", REPO / "robots" / "make_iiwa14_urdf.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ---------------------------------------------------------------------------- supported robots


def test_available_robots_lists_iiwa_and_example_robot_data_arms() -> None:
    names = available_robots()
    assert names[0] == "iiwa"
    assert {"panda", "ur5", "kinova", "z1", "double_pendulum"} <= set(names)
    assert len(names) == len(set(names))


@pytest.mark.slow
@pytest.mark.parametrize("name", available_robots())
def test_every_available_robot_loads_with_geometry(name: str) -> None:
    robot = load(name)
    assert isinstance(robot, RobotDescription)
    assert robot.name == name
    assert robot.urdf_path is not None and robot.urdf_path.is_file()
    model = robot.model
    assert model.njoints >= 3  # universe + at least two moving joints
    first = 2 if name in available_floating() else 1  # a floating base's free flyer, then
    assert all(model.joints[j].nv == 1 for j in range(first, model.njoints))  # 1-dof joints
    assert isinstance(robot.visual_model, pin.GeometryModel) and robot.visual_model.ngeoms > 0
    assert isinstance(robot.collision_model, pin.GeometryModel)
    for geom in [*robot.visual_model.geometryObjects, *robot.collision_model.geometryObjects]:
        assert 0 <= geom.parentJoint < model.njoints


def test_geometry_can_be_skipped() -> None:
    robot = load("panda", geometry=False)
    assert robot.collision_model is None and robot.visual_model is None
    assert robot.model.nq == 9


def test_srdf_reference_configuration_is_loaded() -> None:
    model = load("panda", geometry=False).model
    ref = model.referenceConfigurations["default"]
    assert ref.shape == (9,)
    assert ref[3] == pytest.approx(-2.35619, abs=1e-5)


def test_load_accepts_paths_models_and_descriptions() -> None:
    from_str = load(str(IIWA_URDF))
    from_path = load(IIWA_URDF, geometry=False)
    assert from_str.name == from_path.name == "iiwa14"  # the URDF <robot name>
    assert from_path.urdf_path == IIWA_URDF

    model = from_str.model
    wrapped = load(model, collision_model=from_str.collision_model)
    assert wrapped.model is model and wrapped.name == "iiwa14"
    assert wrapped.collision_model is from_str.collision_model and wrapped.visual_model is None
    assert wrapped.urdf_path is None
    assert load(wrapped) is wrapped
    with pytest.raises(InputError, match=r"only accompany a pinocchio\.Model"):
        load("iiwa", visual_model=from_str.visual_model)


# ------------------------------------------------------------------------------ bundled iiwa 14


def test_iiwa_model_values() -> None:
    robot = load("iiwa")
    model = robot.model
    assert model.nq == model.nv == 7
    assert [model.joints[j].shortname() for j in range(1, 8)] == ["JointModelRZ"] * 7
    masses = [model.inertias[j].mass for j in range(1, 8)]
    np.testing.assert_allclose(masses, [5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2])
    assert model.inertias[0].mass == pytest.approx(5.0)  # iiwa_link_0, welded to the world
    np.testing.assert_allclose(model.upperEffortLimit, [320, 320, 176, 176, 110, 40, 40])
    np.testing.assert_allclose(model.upperVelocityLimit[:2], np.deg2rad(85.0))
    np.testing.assert_allclose(model.upperPositionLimit[6], 3.05432619099)
    np.testing.assert_allclose(model.damping, 0.5)
    np.testing.assert_allclose(model.jointPlacements[1].translation, [0, 0, 0.1575])
    assert model.existFrame("iiwa_link_ee")


def test_iiwa_geometry_is_primitive_and_usable_by_coal() -> None:
    robot = load("iiwa")
    collision = robot.collision_model
    assert collision.ngeoms == robot.visual_model.ngeoms == 8  # one shape per link 0..7
    assert all(
        isinstance(g.geometry, coal.Cylinder | coal.Sphere) for g in collision.geometryObjects
    )
    names = [g.name for g in collision.geometryObjects]
    base, flange = names.index("iiwa_link_0_0"), names.index("iiwa_link_7_0")
    collision.addCollisionPair(pin.CollisionPair(base, flange))
    data, geom_data = robot.model.createData(), collision.createData()
    pin.computeDistances(robot.model, data, collision, geom_data, pin.neutral(robot.model))
    # Arm straight up: flange sphere (r 0.053) at z ~ 1.26 m, base cylinder top at z = 0.155 m.
    assert 0.95 < geom_data.distanceResults[0].min_distance < 1.15


def test_iiwa_urdf_is_shipped_with_licences_and_linked_from_robots_folder() -> None:
    assert IIWA_URDF.is_file()
    assert (REPO / "robots" / "iiwa14.urdf").read_bytes() == IIWA_URDF.read_bytes()
    for suffix in ("drake", "iiwa_stack"):
        licence = f"iiwa14_parameters.LICENSE-{suffix}.txt"
        assert (IIWA_URDF.parent / licence).is_file()
        assert (REPO / "robots" / licence).read_bytes() == (IIWA_URDF.parent / licence).read_bytes()
    head = IIWA_URDF.read_text()[:2000]
    assert "Drake" in head and "iiwa_stack" in head and "BSD" in head


def test_iiwa_urdf_is_reproducible_from_the_parameter_file(tmp_path: Path) -> None:
    gen = _generator()
    if not gen.DEFAULT_JSON.is_file():
        pytest.skip(f"parameter file {gen.DEFAULT_JSON} not present")
    assert gen.main(["--check"]) == 0
    assert gen.main(["--check", "--out", str(tmp_path)]) == 1  # the check does detect a change
    assert gen.main(["--out", str(tmp_path)]) == 0
    assert (tmp_path / "iiwa14.urdf").read_bytes() == IIWA_URDF.read_bytes()


# ------------------------------------------------------------------------------------- errors

_INERTIAL = (
    '<inertial><mass value="{m}"/>'
    '<inertia ixx="{i}" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>'
)


def _link(name: str, mass: float | str | None = 1.0, ixx: float = 0.1) -> str:
    inertial = "" if mass is None else _INERTIAL.format(m=mass, i=ixx)
    return f'<link name="{name}">{inertial}</link>'


def _joint(name: str, parent: str, child: str, jtype: str = "revolute", extra: str = "") -> str:
    return (
        f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
        f'<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>{extra}</joint>'
    )


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "robot.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="test">{body}</robot>\n')
    return path


def test_small_valid_urdf_loads(tmp_path: Path) -> None:
    path = _write(tmp_path, _link("base", None) + _link("arm") + _joint("shoulder", "base", "arm"))
    robot = load(path)
    assert robot.name == "test" and robot.model.nq == 1


def test_unknown_robot_name_lists_available_names() -> None:
    with pytest.raises(InputError, match="unknown robot 'pandaa'") as info:
        load("pandaa")
    assert all(name in str(info.value) for name in available_robots())


def test_wrong_robot_type() -> None:
    with pytest.raises(InputError, match="int"):
        load(42)  # type: ignore[arg-type]


def test_missing_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.urdf"
    with pytest.raises(InputError, match=r"not found.*nope\.urdf"):
        load(missing)
    with pytest.raises(InputError, match=r"nope\.urdf"):
        load(str(missing))


BASE = _link("base", None)
ARM = _link("arm")
SHOULDER = _joint("shoulder", "base", "arm")


@pytest.mark.parametrize(
    ("body", "message"),
    [
        pytest.param(BASE + "<link name='arm'>", "malformed XML", id="malformed-xml"),
        pytest.param(
            BASE + _link("arm", None) + SHOULDER,
            "joint 'shoulder'.*child link 'arm' has no <inertial>",
            id="missing-inertial",
        ),
        pytest.param(
            BASE + _link("arm", 0.0) + SHOULDER,
            "joint 'shoulder'.*child link 'arm' has zero mass",
            id="zero-mass",
        ),
        pytest.param(
            _link("base", -1.0) + ARM + SHOULDER,
            "link 'base' has negative mass",
            id="negative-mass",
        ),
        pytest.param(
            BASE + _link("arm", 1.0, ixx=-0.5) + SHOULDER,
            "child link 'arm' has a non-positive-definite inertia",
            id="non-pd-inertia",
        ),
        pytest.param(
            BASE + _link("arm", "heavy") + SHOULDER,
            "child link 'arm'.*'heavy'.*not a finite number",
            id="non-numeric-mass",
        ),
        pytest.param(
            BASE + ARM + _joint("shoulder", "base", "arm", "ball"),
            "joint 'shoulder' has unknown type 'ball'",
            id="unknown-joint-type",
        ),
        pytest.param(
            BASE + ARM + _joint("shoulder", "base", "ghost"),
            "joint 'shoulder' has child link 'ghost', which is not defined",
            id="undefined-child",
        ),
        pytest.param(
            BASE + ARM + _joint("shoulder", "torso", "arm"),
            "joint 'shoulder' has parent link 'torso', which is not defined",
            id="undefined-parent",
        ),
        pytest.param(
            BASE
            + ARM
            + _link("other", None)
            + _link("fore")
            + SHOULDER
            + _joint("elbow", "other", "fore"),
            "several root links: base, other",
            id="multiple-roots",
        ),
        pytest.param(
            BASE + ARM + _joint("a", "base", "arm") + _joint("b", "base", "arm"),
            "link 'arm' is the child of both joint 'a' and joint 'b'",
            id="two-parents",
        ),
        pytest.param(
            BASE + ARM + _link("fore") + _joint("a", "fore", "arm") + _joint("b", "arm", "fore"),
            "links arm, fore form a kinematic loop",
            id="kinematic-loop",
        ),
        pytest.param(BASE + _link("base"), "link 'base' is defined twice", id="duplicate-link"),
        pytest.param(
            BASE
            + ARM
            + SHOULDER.replace('<limit lower="-1" upper="1" effort="1" velocity="1"/>', ""),
            "joint 'shoulder' has no <limit>",
            id="missing-limit",
        ),
        pytest.param(
            BASE + ARM + SHOULDER.replace('xyz="0 0 1"', 'xyz="0 0 0"'),
            "joint 'shoulder' has axis '0 0 0'",
            id="zero-axis",
        ),
    ],
)
def test_broken_urdf_raises_robot_model_error(tmp_path: Path, body: str, message: str) -> None:
    path = _write(tmp_path, body)
    with pytest.raises(RobotModelError, match=message):
        validate_urdf(path)
    with pytest.raises(RobotModelError, match=message):
        load(path)


def test_wrong_root_element(tmp_path: Path) -> None:
    path = tmp_path / "robot.urdf"
    path.write_text("<sdf><model name='x'/></sdf>")
    with pytest.raises(RobotModelError, match="root element is <sdf>"):
        load(path)
