"""The task files of examples/tasks: the iiwa file is the paper's OCP, and every file is planned
through ``mbplan plan TASK.toml`` (in-process) with the RIPM and IPOPT in a reduced size, solved,
verified, saved with its OCP and task file, and replayed from the result file alone."""

import json
from pathlib import Path

import numpy as np
import pytest

import mbplan as mb
from mbplan.cli.main import main
from mbplan.taskfile import load_task
from mbplan.tasks.paper import iiwa_obstacle

EXAMPLES_TASKS = Path(__file__).resolve().parents[1] / "examples" / "tasks"
PANDA = str(EXAMPLES_TASKS / "panda_boxes.toml")
IIWA = str(EXAMPLES_TASKS / "iiwa_obstacle.toml")
UR5 = str(EXAMPLES_TASKS / "ur5_shelf.toml")
MIMIC = str(EXAMPLES_TASKS / "panda_mimic.toml")
FOURBAR = str(EXAMPLES_TASKS / "fourbar_crank.toml")
SOLO = str(EXAMPLES_TASKS / "solo12_tuck.toml")
SQUAT = str(EXAMPLES_TASKS / "solo12_squat.toml")
SOLES = str(EXAMPLES_TASKS / "talos_legs_squat.toml")
FINGERS_LOCKED = '--set=robot.lock=["panda_finger_joint1", "panda_finger_joint2"]'


def _signature(ocp: mb.OCP) -> list[str]:
    """The OCP's items without their names, in a canonical order."""
    items = ocp.to_dict()["items"]
    return sorted(json.dumps({k: v for k, v in i.items() if k != "name"}) for i in items)


def test_iiwa_task_file_is_the_paper_task():
    task = load_task(IIWA)
    paper = iiwa_obstacle()
    assert (task.ocp.N, task.ocp.dt) == (paper.N, paper.dt)
    assert np.array_equal(task.ocp.q0, paper.q0)
    assert task.ocp.scene.to_dict() == paper.scene.to_dict()
    assert _signature(task.ocp) == _signature(paper)
    assert (task.method, task.warm_start, task.tol, task.max_iter) == ("ripm", "via", 1e-6, 500)


def test_mimic_joints_are_coupled_unless_independent():
    coupled = load_task(MIMIC)
    assert coupled.ocp.robot.source["mimic"] == "couple"
    assert type(coupled.ocp["mimic_panda_finger_joint2"].residual).__name__ == "JointCoupling"
    independent = load_task(MIMIC, {"robot.mimic": "independent"})
    assert independent.ocp.names == [n for n in coupled.ocp.names if not n.startswith("mimic_")]
    assert load_task(PANDA).ocp.robot.mimic == ()  # panda_boxes.toml: mimic = "independent"


def test_overrides_replace_keys_and_keep_the_duration():
    ur5 = load_task(UR5, {"horizon.N": 12})
    assert (ur5.ocp.N, ur5.ocp.dt) == (12, 0.25)  # T = 3 s kept
    panda = load_task(PANDA, {"horizon.N": 12, "horizon.dt": 0.125, "solver.method": "ipopt"})
    assert (panda.ocp.N, panda.ocp.dt, panda.method) == (12, 0.125, "ipopt")
    assert panda.ocp.robot.nq == 9  # fingers free
    locked = load_task(PANDA, {"robot.lock": ["panda_finger_joint1", "panda_finger_joint2"]})
    assert locked.ocp.robot.nq == 7
    assert np.array_equal(locked.ocp.q0, panda.ocp.q0[:7])  # the 9-vector q, fingers dropped


CASES = [
    pytest.param(IIWA, "ripm", [], id="iiwa-ripm"),  # full size: ~2 s
    pytest.param(IIWA, "ipopt", [], id="iiwa-ipopt"),
    pytest.param(PANDA, "ipopt", ["--horizon", "12", "--dt", "0.125"], id="panda-ipopt"),
    pytest.param(PANDA, "ripm", ["--horizon", "12", "--dt", "0.125"], id="panda-ripm"),
    pytest.param(
        PANDA, "ripm", ["--horizon", "12", "--dt", "0.125", FINGERS_LOCKED], id="panda-locked-ripm"
    ),
    pytest.param(MIMIC, "ripm", ["--horizon", "12", "--dt", "0.125"], id="panda-mimic-ripm"),
    pytest.param(MIMIC, "ipopt", ["--horizon", "12", "--dt", "0.125"], id="panda-mimic-ipopt"),
    pytest.param(UR5, "ripm", ["--horizon", "12"], id="ur5-ripm"),
    pytest.param(UR5, "ipopt", ["--horizon", "12"], id="ur5-ipopt"),
    pytest.param(FOURBAR, "ripm", [], id="fourbar-ripm"),  # a closed loop, full size
    pytest.param(FOURBAR, "ipopt", [], id="fourbar-ipopt"),
    pytest.param(SOLO, "ripm", [], id="solo12-ripm"),  # a floating base in free flight
    pytest.param(SOLO, "ipopt", [], id="solo12-ipopt"),
    pytest.param(SQUAT, "ripm", [], id="squat-ripm"),  # standing on four [[contact]] feet
    pytest.param(SQUAT, "ipopt", [], id="squat-ipopt"),
    pytest.param(SOLES, "ripm", [], id="talos-soles-ripm"),  # two flat [[contact]] soles
]


@pytest.mark.slow
@pytest.mark.parametrize(("path", "method", "flags"), CASES)
def test_task_file_plans_and_verifies(tmp_path, capsys, path, method, flags):
    out = tmp_path / "plan.npz"
    code = main(["plan", path, "--method", method, "--out", str(out), *flags])
    stdout = capsys.readouterr().out
    assert code == 0, stdout
    assert "verification: passed" in stdout
    result = mb.load_npz(out)
    assert result.success and result.method == method
    assert mb.verify(result).passed  # from the file alone: the OCP travels with the result
    assert result.extra["task_file"]["path"] == path
    assert "[robot]" in result.extra["task_file"]["toml"]
    if result.ocp.robot.loops:  # closed at every knot, by independent forward kinematics
        assert mb.verify(result).closure_residual <= 1e-9
    if "mimic_panda_finger_joint2" in result.ocp.names:  # the fingers coupled at every knot
        assert np.max(np.abs(result.q[:, 7] - result.q[:, 8])) <= 1e-8
    goal = result.ocp["goal"]
    if goal.role == "constraint":
        assert result.violations["goal"] <= goal.tolerance
    else:
        assert result.goal_errors["goal"] <= goal.tolerance


def test_replay_of_a_task_file_plan_needs_only_the_result(tmp_path, capsys):
    """The panda with free fingers (9 joints, not the replay's default iiwa) and its boxes."""
    out, page = tmp_path / "plan.npz", tmp_path / "replay.html"
    flags = ["--horizon", "12", "--dt", "0.125", "--max-iter", "3"]
    assert main(["plan", PANDA, "--method", "ipopt", "--out", str(out), *flags]) == 1
    assert main(["replay", str(out), "--html", str(page)]) == 0
    assert page.stat().st_size > 1_000_000
    assert f"wrote {page}" in capsys.readouterr().out


def test_goal_tolerance_is_the_acceptance_of_the_terminal_constraint():
    """``[goal] tolerance`` without ``weight``: a hard constraint whose violation at the planned
    knots is accepted up to the tolerance (instead of the verifier's default), saved with the
    OCP."""
    from mbplan.verification.report import hard_constraints_met

    ocp = load_task(PANDA, {"horizon.N": 4}).ocp
    goal = ocp["goal"]
    assert (goal.role, goal.tolerance, goal.knots.tolist()) == ("constraint", 1e-3, [4])
    assert mb.OCP.from_dict(ocp.to_dict())["goal"].tolerance == 1e-3
    fine = dict.fromkeys(ocp.names, 0.0)
    assert hard_constraints_met(ocp, {**fine, "goal": 9e-4}) == []
    assert hard_constraints_met(ocp, {**fine, "goal": 2e-3}) == [
        "constraint 'goal' is violated by 0.002 at the planned knots (tolerance 0.001)"
    ]


def test_mesh_obstacle_relative_to_the_task_file(tmp_path):
    """``shape = "mesh"``: the file next to the task, scaled by ``size``; coal measures it."""
    corners = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    stl = "solid cube\n" + "".join(
        "facet normal 0 0 0\nouter loop\n"
        + "".join(f"vertex {' '.join(map(str, corners[i]))}\n" for i in f)
        + "endloop\nendfacet\n"
        for f in faces
    )
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "cube.stl").write_text(stl + "endsolid cube\n")
    text = (EXAMPLES_TASKS / "panda_boxes.toml").read_text()
    text += '\n[[obstacle]]\nname = "cube"\nshape = "mesh"\nmesh = "meshes/cube.stl"\n'
    text += "size = [0.1, 0.1, 0.1]\nxyz = [-0.5, 0.0, 0.0]\n"
    (tmp_path / "task.toml").write_text(text)
    ocp = load_task(tmp_path / "task.toml").ocp
    cube = ocp.scene["cube"]
    assert cube.shape == "mesh" and cube.mesh == str(tmp_path / "meshes" / "cube.stl")
    assert np.allclose(cube.half_extents(), 0.1)  # corners (0, 0, 0)..(0.1, 0.1, 0.1)
    assert ocp["clearance"].residual.objects == ("left", "right", "cube")


@pytest.mark.parametrize(
    ("robot", "arcs", "turns"), [("iiwa", 7, 0), ("ur5", 0, 6), ("so100", 5, 1)]
)
def test_position_limits_rows_per_range_in_maximal_coordinates(robot, arcs, turns):
    """A range below 2π (the iiwa's) is a cosine row; a range of 2π or more (the UR5's elbow,
    ±π, and its other ±2π joints; the so100's wrist roll, ±3.14158, a turn up to the URDF's
    rounding) is counted in turns from a reference (two rows per knot,
    ``tests/test_wrapping_limits.py``). A cosine
    row ``cos(θ - mid) ≥ -1`` for it would be a barrier active at θ - mid = ±π with a zero
    gradient there (the UR5 task took 467 RIPM iterations with it)."""
    from mbplan.formulations.maximal import MaximalNLP
    from mbplan.residuals import JointPositionLimits

    ocp = mb.OCP(robot, N=3).add_constraint("position_limits", JointPositionLimits())
    terms = [t for t in MaximalNLP(ocp, jit=False).problem.terms if "position_limits" in t.name]
    sites = {
        k: sum(len(t.bind["Rc"][1]) for t in terms if t.name.endswith("/turns") == k)
        for k in (False, True)
    }
    assert sites == {False: 3 * arcs, True: 3 * turns}


def test_contact_tables_become_the_ocp_s_contacts(tmp_path):
    task = load_task(SQUAT)
    assert task.ocp.contact_names == ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    assert all(c.first == 0 and c.last == task.ocp.N for c in task.ocp.contacts)
    assert [c.sole for c in load_task(SOLES).ocp.contacts] == [(0.2, 0.1), (0.2, 0.1)]
    text = open(SQUAT).read()
    for table, message in [
        ('frame = "paw"', "no frame 'paw'"),
        ('frame = "FL_FOOT"\nknots = [3]', "expected \\[first, last\\]"),
        ('frame = "FL_FOOT"\nfriction = -1', "must be > 0"),
        ('frame = "FL_FOOT"\nposition = [0, 0, -1]', "from its contact position .* at knot 0"),
        ('frame = "FL_FOOT"\nstance = 1', "unknown key"),
        ('frame = "FL_FOOT"\nsole = [0.1]', "sole"),
        ('frame = "FL_FOOT"\nsole = [0.1, -0.05]', "must be positive"),
    ]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace('frame = "FL_FOOT"', table, 1))
        with pytest.raises(mb.InputError, match=message):
            load_task(str(bad))
