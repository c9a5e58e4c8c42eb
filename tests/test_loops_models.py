"""The bundled mechanisms with closed loops (fourbar, delta, two_arm_carry): loops, passive
joints, closure rank and mobility as designed, physically sound bodies, a short free motion that
keeps the loops closed; task-file ``[[loop]]`` tables, ``[robot].actuated`` and partial joint
goals, with their errors; the example task files build their OCPs. Nothing here is solved."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import mbplan as mb
from mbplan.cli.main import main
from mbplan.errors import InputError, RobotModelError
from mbplan.robots import MECHANISMS, available_arms, available_robots, load
from mbplan.robots.loops import closure_jacobian, closure_residual, loop_jacobian
from mbplan.robots.mjcf import mjcf_equality_names
from mbplan.robots.robot import robot_from_source
from mbplan.taskfile import load_task

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "tasks"
DELTA_PASSIVE = (
    "platform_x",
    "platform_y",
    "platform_z",
    *(f"leg{i}_elbow_{k}" for i in (1, 2, 3) for k in (1, 2)),
)
# name -> (joints, {loop: (kind, imposed rows, dropped rows)}, passive joints, dof)
DESIGN = {
    "fourbar": (
        3,
        {"coupler_rocker": ("point", ("x", "z"), ("y",))},
        ("coupler_joint", "rocker_joint"),
        1,
    ),
    "delta": (
        12,
        {f"leg{i}_platform": ("point", ("x", "y", "z"), ()) for i in (1, 2, 3)},
        DELTA_PASSIVE,
        3,
    ),
    "two_arm_carry": (12, {"bar_weld": ("weld", ("x", "y", "z", "rx", "ry", "rz"), ())}, (), 6),
}


def test_mechanisms_are_named_robots_but_not_serial_arms(capsys):
    assert set(MECHANISMS) == set(DESIGN)
    assert set(DESIGN) <= set(available_robots())
    assert not set(DESIGN) & set(available_arms())
    assert main(["robots"]) == 0
    listed = capsys.readouterr().out
    assert "fourbar  (3 joints, 2 closure rows: 1 dof; actuated: crank_joint)" in listed
    assert "delta  (12 joints, 9 closure rows: 3 dof" in listed
    assert "two_arm_carry  (12 joints, 6 closure rows: 6 dof" in listed
    assert "(rows y redundant, not imposed)" in listed


@pytest.mark.parametrize("name", sorted(DESIGN))
def test_mechanism_loops_passive_joints_rank_and_mobility(name: str):
    joints, loops, passive, dof = DESIGN[name]
    robot = mb.load_robot(name)
    assert robot.source["kind"] == "name" and robot.nv == joints
    got = {loop.name: (loop.kind, loop.components, loop.dropped) for loop in robot.loops}
    assert got == loops
    assert robot.passive == passive
    q = robot.configuration("neutral")
    np.testing.assert_array_equal(q, np.zeros(robot.nq))  # qpos0 is assembled
    assert np.max(np.abs(closure_residual(robot.model, robot.loops, q))) < 1e-12
    J = closure_jacobian(robot.model, robot.loops, q)
    rows = sum(loop.dim for loop in robot.loops)
    sv = np.linalg.svd(J, compute_uv=False)
    assert J.shape == (rows, joints) and sv[-1] > 1e-2 * sv[0]  # full row rank, far from singular
    assert robot.nv - np.linalg.matrix_rank(J) == dof
    again = robot_from_source(robot.source)  # what a saved plan loads
    assert [lp.describe() for lp in again.loops] == [lp.describe() for lp in robot.loops]
    assert again.passive == robot.passive


@pytest.mark.parametrize("name", sorted(DESIGN))
def test_mechanism_bodies_limits_and_geometry(name: str):
    desc = load(name)
    model = desc.model
    assert desc.name == name and desc.urdf_path == MECHANISMS[name]
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        assert inertia.mass > 0 and np.all(np.linalg.eigvalsh(inertia.inertia) > 0)
    for limits in (model.lowerPositionLimit, model.upperPositionLimit, model.effortLimit):
        assert np.all(np.isfinite(limits))
    assert np.all(model.effortLimit > 0)
    moving = {g.parentJoint for g in desc.collision_model.geometryObjects if g.parentJoint > 0}
    passive_virtual = {"platform_x", "platform_y"} | {f"leg{i}_elbow_1" for i in (1, 2, 3)}
    expected = {j for j in range(1, model.njoints) if model.names[j] not in passive_virtual}
    assert moving == expected  # every real body collides; the delta's virtual links do not


@pytest.mark.parametrize("name", sorted(DESIGN))
def test_mechanism_falls_freely_with_the_loops_closed(name: str):
    """0.1 s from rest under gravity, zero torque: constrained dynamics (KKT of crba/nle and
    the closure Jacobian, Baumgarte-stabilised) keep the loops closed and the energy."""
    robot = mb.load_robot(name, damping=False)
    model, data, loops = robot.model, robot.model.createData(), robot.loops
    q, v, dt = robot.configuration("neutral"), np.zeros(robot.nv), 1e-3
    energy = pin.computePotentialEnergy(model, data, q)
    gaps, drift = [], []
    for _ in range(100):
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.nonLinearEffects(model, data, q, v)
        J = closure_jacobian(model, loops, q)
        Jdot_v = (closure_jacobian(model, loops, q + 1e-6 * v) - J) @ v / 1e-6
        r = closure_residual(model, loops, q)
        m = J.shape[0]
        K = np.block([[M, J.T], [J, np.zeros((m, m))]])
        a = np.linalg.solve(K, np.r_[-h, -Jdot_v - 40 * J @ v - 400 * r])[: robot.nv]
        v = v + dt * a
        q = q + dt * v
        gaps.append(np.max(np.abs(closure_residual(model, loops, q))))
        total = pin.computeKineticEnergy(model, data, q, v) + pin.computePotentialEnergy(
            model, data, q
        )
        drift.append(abs(total - energy))
    fallen = energy - pin.computePotentialEnergy(model, data, q)
    assert fallen > 1e-3  # it moved down
    assert max(gaps) < 1e-3 and max(drift) < 0.05 * fallen
    assert np.all(np.isfinite(q)) and np.max(np.abs(v)) < 50.0


@pytest.mark.parametrize("name", sorted(DESIGN))
def test_mechanism_ocp_builds_from_its_default_start(name: str):
    ocp = mb.OCP(name, N=5, dt=0.05)
    assert ocp.q0.shape == (ocp.robot.nq,)
    assert ("passive" in ocp.names) == bool(DESIGN[name][2])
    ocp.add_constraint("limits", mb.residuals.JointPositionLimits())
    ocp.add_constraint("torque", mb.residuals.JointTorqueLimits())
    with pytest.raises(InputError, match="q0 does not close the loops"):
        mb.OCP(name, N=5, dt=0.05, q0=np.full(ocp.robot.nq, 0.3))


def test_mjcf_closures_keep_their_names_and_unsupported_equalities_are_refused(tmp_path):
    assert mjcf_equality_names(MECHANISMS["delta"]) == [f"leg{i}_platform" for i in (1, 2, 3)]
    text = MECHANISMS["fourbar"].read_text()
    path = tmp_path / "coupled.xml"
    path.write_text(
        text.replace(
            "<equality>", '<equality>\n    <joint joint1="crank_joint" joint2="rocker_joint"/>'
        )
    )
    with pytest.raises(RobotModelError, match=r"equality 'joint' \(<joint>\) is not supported"):
        mb.load_robot(path)


# ------------------------------------------------------------------------------- task files


def _open_fourbar(tmp_path: Path) -> Path:
    """The four-bar's MJCF without its closure and actuators: an open tree."""
    text = MECHANISMS["fourbar"].read_text()
    text = re.sub(r"<equality>.*?</equality>", "", text, flags=re.S)
    text = re.sub(r"<actuator>.*?</actuator>", "", text, flags=re.S)
    path = tmp_path / "open_fourbar.xml"
    path.write_text(text)
    return path


LOOP = """
[[loop]]
name = "close"
kind = "point"
frame1 = "coupler"
placement1 = [0.243607, 0.0, 0.138042]
frame2 = "rocker_tip"
"""


def _task(tmp_path: Path, robot: str = "", loop: str = LOOP, goal: str = "") -> Path:
    robot = robot or 'mjcf = "open_fourbar.xml"\nactuated = ["crank_joint"]'
    goal = goal or 'joints = ["rocker_joint"]\nq = [0.5]\nrest = true\ntolerance = 1e-4'
    text = (
        f"[robot]\n{robot}\n{loop}\n[horizon]\nN = 10\ndt = 0.05\n\n[goal]\n{goal}\n\n"
        "[constraints]\nvelocity_limits = false\n"
    )
    _open_fourbar(tmp_path)
    path = tmp_path / "task.toml"
    path.write_text(text)
    return path


def test_task_file_loops_actuated_joints_and_a_partial_joint_goal(tmp_path):
    task = load_task(_task(tmp_path))
    robot = task.ocp.robot
    (loop,) = robot.loops
    assert (loop.name, loop.kind, loop.components, loop.dropped) == (
        "close",
        "point",
        ("x", "z"),
        ("y",),
    )
    assert robot.passive == ("coupler_joint", "rocker_joint")
    assert robot.source["actuated"] == ["crank_joint"] and robot.source["loops"][0]["name"]
    goal, rest = task.ocp["goal"], task.ocp["rest"]
    assert goal.residual.joints == ("rocker_joint",) and goal.residual.target.tolist() == [0.5]
    assert rest.knots.tolist() == [task.ocp.N] and rest.role == "constraint"
    assert "passive" in task.ocp.names
    again = robot_from_source(robot.source)
    assert [lp.describe() for lp in again.loops] == [loop.describe()]


@pytest.mark.parametrize(
    ("robot", "loop", "goal", "message"),
    [
        (
            "",
            LOOP.replace('"rocker_tip"', '"tip"'),
            "",
            r"\[\[loop\]\]#1\.frame2: .*no frame 'tip'",
        ),
        (
            "",
            LOOP.replace('"rocker_tip"', '"coupler_point"'),
            "",
            r"\[\[loop\]\]#1\.frame2: 'coupler' and 'coupler_point' are on the same body",
        ),
        ("", LOOP.replace('"point"', '"ball"'), "", r"\[\[loop\]\]#1\.kind: 'ball' is not one of"),
        ("", LOOP + "axis = [0, 0, 1]\n", "", r"\[\[loop\]\]#1\.axis: only a revolute closure"),
        ("", LOOP + "anchor = [0, 0, 0]\n", "", r"\[\[loop\]\]#1\.anchor: unknown key"),
        ("", LOOP + LOOP, "", r"\[\[loop\]\]#2\.name: a second loop named 'close'"),
        ("", LOOP.replace("0.138042", "0.4"), "", r"\[\[loop\]\]#1: the loops \['close'\] cannot"),
        (
            'mjcf = "open_fourbar.xml"\nactuated = ["crank"]',
            LOOP,
            "",
            r"\[robot\]\.actuated: 'crank' is not a joint of the robot",
        ),
        ('mjcf = "open_fourbar.xml"\nactuated = []', LOOP, "", r"\[robot\]\.actuated: no joint"),
        ("", LOOP, 'joints = ["rocker"]\nq = [0.5]', r"\[goal\]\.joints: 'rocker' is not a joint"),
        ("", LOOP, 'joints = ["rocker_joint"]', r"\[goal\]\.joints: a goal on some joints needs"),
        ("", LOOP, 'joints = ["rocker_joint"]\nq = [0.5, 0.1]', r"\[goal\]\.q: expected 1 numbers"),
        (
            "",
            LOOP,
            'joints = ["rocker_joint"]\nq = [2.0]',
            r"\[goal\]\.q: joint 'rocker_joint' = 2",
        ),
    ],
)
def test_task_file_loop_and_actuated_errors_name_the_key(tmp_path, robot, loop, goal, message):
    with pytest.raises((InputError, RobotModelError), match=message):
        load_task(_task(tmp_path, robot, loop, goal))


def test_task_file_loops_of_a_named_mechanism_add_to_its_own(tmp_path):
    """A second, redundant closure of the bundled four-bar: every row dropped → refused."""
    extra = LOOP.replace('"close"', '"again"')
    path = _task(tmp_path, 'name = "fourbar"', extra)
    with pytest.raises(
        RobotModelError, match=r"\[\[loop\]\]#1: loop 'again': every row is redundant"
    ):
        load_task(path)


@pytest.mark.parametrize("name", ["fourbar_crank", "delta_obstacle", "two_arm_carry"])
def test_example_task_files_build_their_ocps(name: str):
    task = load_task(EXAMPLES / f"{name}.toml")
    ocp = task.ocp
    robot = ocp.robot
    assert robot.loops and np.max(np.abs(closure_residual(robot.model, robot.loops, ocp.q0))) < 1e-8
    assert {"goal", "rest", "torque_limits"} <= set(ocp.names)
    assert "velocity_limits" not in ocp.names  # MJCF has none


@pytest.mark.parametrize(
    ("name", "joints"),
    [
        ("fourbar_crank", ("crank_joint",)),
        ("delta_obstacle", ("leg1_shoulder", "leg2_shoulder", "leg3_shoulder")),
        ("two_arm_carry", None),
    ],
)
def test_rest_is_imposed_on_independent_joints(name: str, joints: tuple[str, ...] | None):
    """``[goal] rest`` of a loop robot: zero velocity on as many joints as it has dof (the
    actuated ones where they determine the others), which with the closures' ``J v = 0`` rests
    every joint, and no row repeats a closure's (a rank-deficient constraint Jacobian)."""
    ocp = load_task(EXAMPLES / f"{name}.toml").ocp
    robot, rest = ocp.robot, ocp["rest"].residual.joints
    J = loop_jacobian(robot.model, robot.loops, ocp.q0)
    assert len(rest) == robot.nv - np.linalg.matrix_rank(J)
    assert (
        np.linalg.matrix_rank(np.vstack([J, np.eye(robot.nv)[robot.joint_indices(rest)]]))
        == robot.nv
    )
    assert joints is None or rest == joints
