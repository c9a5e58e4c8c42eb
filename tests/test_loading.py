"""Robots from MJCF files (Pinocchio's parser) and scene meshes (coal) in distance constraints."""

from __future__ import annotations

import coal
import numpy as np
import pytest

import mbplan as mb
from mbplan import residuals as res
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.joint_space import evaluate
from mbplan.robots.robot import robot_from_source
from mbplan.tasks.paper import IIWA_START

ARM = """<mujoco model="tiny_arm">
  <compiler angle="radian"/>
  <worldbody>
    <body name="link1" pos="0 0 0.1">
      <joint name="shoulder" type="hinge" axis="0 0 1" range="-2 2" damping="0.3"/>
      <geom name="link1_geom" type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
      <body name="link2" pos="0.3 0 0">
        <joint name="elbow" type="hinge" axis="0 1 0" range="-2.5 2.5" damping="0.2"/>
        <geom name="link2_geom" type="box" pos="0.12 0 0" size="0.12 0.02 0.02" mass="0.5"/>
        <site name="tip" pos="0.25 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

# a unit cube centred at the origin: 8 vertices, 12 outward triangles
CUBE_V = [(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
CUBE_F = [
    (1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2),
    (3, 4, 8), (3, 8, 7), (1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4),
]  # fmt: skip


@pytest.fixture
def arm(tmp_path):
    path = tmp_path / "arm.xml"
    path.write_text(ARM)
    return path


def test_mjcf_arm_loads_with_joints_limits_damping_and_geometry(arm) -> None:
    robot = mb.load_robot(arm)
    model = robot.model
    assert robot.nq == 2 and list(model.names[1:]) == ["shoulder", "elbow"]
    np.testing.assert_allclose(model.lowerPositionLimit, [-2.0, -2.5])
    np.testing.assert_allclose(model.upperPositionLimit, [2.0, 2.5])
    np.testing.assert_allclose(model.damping, [0.3, 0.2])
    np.testing.assert_allclose(model.inertias[1].mass + model.inertias[2].mass, 1.5)
    assert {g.name for g in robot.collision_model.geometryObjects} == {"link1_geom", "link2_geom"}
    assert robot.source == {"kind": "mjcf", "path": str(arm.resolve()), "damping": True}
    again = robot_from_source(mb.load_robot(arm, damping=False).source)
    assert again.nq == 2 and not np.any(again.model.damping)
    # the tip site is a frame: at q = 0 the arm is stretched along x at z = 0.1
    ocp = mb.OCP(robot, N=2, q0=np.zeros(2))
    tip = res.FrameTranslation("tip", [0.55, 0.0, 0.1])
    value = evaluate(robot, ocp.scene, tip, np.zeros((1, 2)), np.zeros((1, 2)), None)
    np.testing.assert_allclose(value, 0.0, atol=1e-12)


@pytest.mark.parametrize("method", ["ipopt", "ripm"])
def test_mjcf_arm_plans_a_frame_goal_and_verifies(arm, method: str) -> None:
    # the maximal LGVI does not apply joint damping on this branch: RIPM plans it undamped
    robot = mb.load_robot(arm, damping=method != "ripm")
    ocp = mb.OCP(robot, N=10, dt=0.05, q0=np.zeros(2))
    ocp.add_cost("v", res.JointVelocity(), 1e-2)
    ocp.add_cost("tau", res.JointTorque(), 1e-3)
    reach = 0.3 + 0.25 * np.cos(0.6)  # shoulder yaw 0.8 rad, elbow pitch 0.6 rad
    goal = [reach * np.cos(0.8), reach * np.sin(0.8), 0.1 - 0.25 * np.sin(0.6)]
    ocp.add_terminal_constraint("tip", res.FrameTranslation("tip", goal))
    ocp.add_constraint("q_limits", res.JointPositionLimits())
    result = mb.plan(ocp, method, warm_start="linear")
    assert result.success, result.message
    assert mb.verify(ocp, result).passed


def test_missing_mjcf_is_named(tmp_path) -> None:
    with pytest.raises(mb.InputError, match="MJCF file not found"):
        mb.load_robot(tmp_path / "nothing.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body>")
    with pytest.raises(mb.MbplanError, match="MJCF"):
        mb.load_robot(bad)


def write_cube(path, kind: str) -> None:
    """The unit cube as an OBJ or an ASCII STL file."""
    if kind == "obj":
        lines = [f"v {x} {y} {z}" for x, y, z in CUBE_V]
        lines += [f"f {a} {b} {c}" for a, b, c in CUBE_F]
    else:
        lines = ["solid cube"]
        for face in CUBE_F:
            a, b, c = (np.array(CUBE_V[i - 1]) for i in face)
            n = np.cross(b - a, c - a)
            lines += [f"facet normal {' '.join(map(str, n / np.linalg.norm(n)))}", "outer loop"]
            lines += [f"vertex {p[0]} {p[1]} {p[2]}" for p in (a, b, c)]
            lines += ["endloop", "endfacet"]
        lines.append("endsolid cube")
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("kind", ["obj", "stl"])
def test_scene_mesh_in_a_distance_constraint_equals_the_box(tmp_path, kind: str) -> None:
    """A scaled cube mesh gives the distances of the same box, in the joint-space residual
    (what IPOPT and the verifier evaluate) and in the generalized NLP's constraint rows."""
    path = tmp_path / f"cube.{kind}"
    write_cube(path, kind)
    size, xyz = (0.2, 0.3, 0.4), (0.45, 0.3, 0.5)
    mesh = mb.Scene().add_mesh("crate", path, scale=size, xyz=xyz)
    box = mb.Scene().add_box("crate", size, xyz)
    assert isinstance(mesh["crate"].geometry(), coal.BVHModelBase)
    np.testing.assert_allclose(mesh["crate"].half_extents(), 0.5 * np.array(size), atol=1e-12)
    rng = np.random.default_rng(0)
    q = np.asarray(IIWA_START) + 0.3 * rng.standard_normal((5, 7))
    d_mesh, d_box = (
        evaluate(mb.load_robot("iiwa"), s, res.Distance(0.02).resolve(
            mb.load_robot("iiwa"), s), q, None, None)
        for s in (mesh, box)
    )  # fmt: skip
    assert np.all(d_box < 0.02 - 1e-3)  # every pair is outside: the cube's surface is the box's
    np.testing.assert_allclose(d_mesh, d_box, atol=1e-6)
    ocp = mb.OCP("iiwa", mesh, N=2, dt=0.05, q0=IIWA_START)
    ocp.add_constraint("clearance", res.Distance(0.02))
    nlp = GeneralizedNLP(ocp)
    z = nlp.initial_guess(np.vstack([IIWA_START, q[:2]]))
    row0 = nlp.own[0].row0  # the knot rows (the rows between knots follow)
    rows = nlp.constraints(z)[row0 : row0 + 2 * d_box.shape[1]]
    np.testing.assert_allclose(rows, d_box[:2].ravel(), atol=1e-6)
    with pytest.raises(mb.InputError, match="mesh file not found"):
        mb.Scene().add_mesh("crate", tmp_path / "missing.stl")
