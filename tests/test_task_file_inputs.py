"""Malformed task files and URDFs through ``mbplan plan TASK.toml``: one line naming the problem
(and its key and line where the file has them), exit code 2, no traceback, no file written, no
solve started (``no_solves`` from tests/test_inputs.py replaces every solver)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_inputs import _GOOD, _INERTIAL, USAGE, no_solves  # noqa: F401  (fixture)

from mbplan.cli.main import main

BASE = """\
[robot]
name = "iiwa"

[horizon]
N = 10
dt = 0.1

[start]
q = [-0.8, 0.2, 0.5, -1.6, 0.0, 1.0, 0.0]

[goal]
frame = "iiwa_link_ee"
xyz = [0.5, 0.2, 0.6]
rpy = [3.1416, 0.0, 0.0]
tolerance = 1e-3

[[obstacle]]
name = "box"
shape = "box"
size = [0.1, 0.1, 0.1]
xyz = [0.5, -0.5, 0.2]

[constraints]
obstacle = "distance"
margin = 0.02

[solver]
method = "ripm"
"""
START_Q = "q = [-0.8, 0.2, 0.5, -1.6, 0.0, 1.0, 0.0]"
_COLLISION = '<collision><geometry><box size="0.1 0.1 0.2"/></geometry></collision>'
_WITH_COLLISION = _GOOD.replace(
    "</inertial></link>", f"</inertial>{_COLLISION}</link>"
)  # one link with a box
_SECOND = (
    '<link name="hand">{inertial}</link><joint name="j2" type="{type}"><parent link="arm"/>'
    '<child link="hand"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>'
    '<limit lower="-1" upper="1" effort="10" velocity="1"/>{extra}</joint></robot>'
)


def _urdf(joint_type: str = "revolute", extra: str = "", collision: bool = True) -> str:
    base = _WITH_COLLISION if collision else _GOOD
    second = _SECOND.format(inertial=_INERTIAL, type=joint_type, extra=extra)
    return base.replace("</robot>", second)


URDF_TASK = """\
[robot]
urdf = "robot.urdf"
[horizon]
N = 4
dt = 0.1
[goal]
q = [0.5, 0.5]
[[obstacle]]
shape = "sphere"
size = [0.05]
xyz = [1.0, 1.0, 1.0]
"""


def _edit(*pairs: str) -> str:
    text = BASE
    for old, new in zip(pairs[::2], pairs[1::2], strict=True):
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


CASES = [
    # the file and its syntax
    ("", "task.toml: missing table \\[robot\\]", None),
    (_edit("N = 10", "N = "), r"task.toml:5: invalid TOML: Invalid value", None),
    (_edit("dt = 0.1", "dt = 0.1\ndt = 0.2"), r"task.toml:7: invalid TOML: Cannot overwrite", None),
    (_edit("[solver]", "[solvr]"), r"task.toml:27: \[solvr\]: unknown table; known: robot", None),
    (_edit("[[obstacle]]", "[obstacle]"), r"\[obstacle\]: expected \[\[obstacle\]\] tables", None),
    # [robot]
    (_edit('name = "iiwa"', ""), r"task.toml:1: \[robot\]: give exactly one of urdf, name", None),
    (_edit('name = "iiwa"', 'name = "iiwa"\nurdf = "r.urdf"'), "got urdf and name", None),
    (_edit('name = "iiwa"', 'name = "nosuchbot"'), r"\[robot\].name: 'nosuchbot' is not one of iiwa, panda", None),
    (_edit('name = "iiwa"', "name = 7"), r"\[robot\].name: expected a non-empty string, got int 7", None),
    (_edit('name = "iiwa"', 'nmae = "iiwa"'), r"task.toml:2: \[robot\].nmae: unknown key; known: urdf, name", None),
    (_edit('name = "iiwa"', 'urdf = "missing.urdf"'), r"\[robot\].urdf: file not found: .*missing.urdf", None),
    (_edit('name = "iiwa"', 'urdf = "robot.txt"'), r"\[robot\].urdf: 'robot.txt' must end in .urdf", None),
    (_edit('name = "iiwa"', 'mjcf = "scene.xml"'), r"\[robot\].mjcf: file not found", None),
    (_edit('name = "iiwa"', 'name = "iiwa"\npackage_dirs = ["nowhere"]'), r"\[robot\].package_dirs: not a folder: .*nowhere", None),
    (_edit('name = "iiwa"', 'name = "iiwa"\nlock = { iiwa_joint_9 = 0.0 }'), r"\[robot\].lock: robot 'iiwa' has no joint 'iiwa_joint_9'", None),
    (_edit('name = "iiwa"', 'name = "iiwa"\nlock = { iiwa_joint_7 = nan }'), r"task.toml:3: \[robot\].lock.iiwa_joint_7: must be a finite number, got nan", None),
    (_edit('name = "iiwa"', 'name = "iiwa"\nlock = "iiwa_joint_7"'), r"\[robot\].lock: expected a table \{ joint = value \} or a list", None),
    (_edit('name = "iiwa"', 'name = "iiwa"\nmimic = "follow"'), r"\[robot\].mimic: 'follow' is not one of couple, independent", None),
    # [horizon]
    (_edit("[horizon]\nN = 10\ndt = 0.1\n", ""), r"task.toml: missing table \[horizon\]", None),
    (_edit("N = 10\n", ""), r"task.toml:4: \[horizon\]: missing key 'N'", None),
    (_edit("N = 10", "N = 1"), r"task.toml:5: \[horizon\].N: must be an integer >= 2, got 1", None),
    (_edit("N = 10", "N = 10.5"), r"\[horizon\].N: expected an integer, got float 10.5", None),
    (_edit("N = 10", 'N = "ten"'), r"\[horizon\].N: expected an integer, got the string 'ten'", None),
    (_edit("dt = 0.1", "dt = 0"), r"task.toml:6: \[horizon\].dt: must be > 0, got 0", None),
    (_edit("dt = 0.1", "dt = -0.1"), r"\[horizon\].dt: must be > 0, got -0.1", None),
    (_edit("dt = 0.1", "dt = nan"), r"\[horizon\].dt: must be a finite number, got nan", None),
    (_edit("dt = 0.1", "dt = inf"), r"\[horizon\].dt: must be a finite number, got inf", None),
    (_edit("dt = 0.1", "dt = 0.1\nT = 1.0"), r"\[horizon\]: give one of dt \(the step, s\) or T", None),
    # [start]
    (_edit(START_Q, "q = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"), r"task.toml:9: \[start\].q: expected 7 numbers, got 6 \(the joints of 'iiwa': iiwa_joint_1", None),
    (_edit(START_Q, 'q = [0.0, 0.0, "up", 0.0, 0.0, 0.0, 0.0]'), r"\[start\].q: item 3: expected a number, got the string 'up'", None),
    (_edit(START_Q, "q = [nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"), r"\[start\].q: item 1: must be a finite number, got nan", None),
    (_edit(START_Q, 'q = "folded"'), r"\[start\].q: robot 'iiwa' has no configuration 'folded'", None),
    (_edit(START_Q, "q = [0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]"), r"\[start\].q: joint 'iiwa_joint_2' = 3 is outside its limits \[-2.0944, 2.0944\]", None),
    (_edit(START_Q, "q = 0.0"), r"\[start\].q: expected a list of numbers, got float 0.0", None),
    # [goal]
    (_edit('[goal]\nframe = "iiwa_link_ee"\nxyz = [0.5, 0.2, 0.6]\nrpy = [3.1416, 0.0, 0.0]\ntolerance = 1e-3\n', ""), r"missing table \[goal\]", None),
    (_edit('frame = "iiwa_link_ee"\n', ""), r"task.toml:11: \[goal\]: missing key 'frame' \(give q = \[...\], or frame and xyz\)", None),
    (_edit('frame = "iiwa_link_ee"', 'frame = "iiwa_hand"'), r"task.toml:12: \[goal\].frame: robot 'iiwa' has no frame 'iiwa_hand'", None),
    (_edit('frame = "iiwa_link_ee"', 'frame = "iiwa_link_0"'), r"\[goal\].frame: frame 'iiwa_link_0' is fixed to the base", None),
    (_edit("xyz = [0.5, 0.2, 0.6]", "xyz = [0.5, 0.2]"), r"task.toml:13: \[goal\].xyz: expected 3 numbers, got 2", None),
    (_edit("xyz = [0.5, 0.2, 0.6]", 'xyz = "0.5 0.2 0.6"'), r"\[goal\].xyz: expected a list of numbers, got the string", None),
    (_edit("xyz = [0.5, 0.2, 0.6]", "xyz = [3.0, 0.0, 0.5]"), r"task.toml:13: \[goal\].xyz: the goal is outside the workspace: \[3.0, 0.0, 0.5\] is 3.0\d+ m from joint 'iiwa_joint_1', beyond the 1.\d+ m", None),
    (_edit("xyz = [0.5, 0.2, 0.6]", "xyz = [0.0, 0.0, 0.2]"), r"frame goal for 'iiwa_link_ee' at \[0.0, 0.0, 0.2\] is out of reach: best inverse-kinematics error", None),
    (_edit("rpy = [3.1416, 0.0, 0.0]", "rpy = [3.1416, inf, 0.0]"), r"\[goal\].rpy: item 2: must be a finite number, got inf", None),
    (_edit("tolerance = 1e-3", "tolerance = -1e-3"), r"task.toml:15: \[goal\].tolerance: must be > 0", None),
    (_edit("tolerance = 1e-3", "tolerance = 1e-3\nq = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"), r"\[goal\].frame: a joint goal \(q\) takes no frame, xyz or rpy", None),
    (_edit('frame = "iiwa_link_ee"\nxyz = [0.5, 0.2, 0.6]\nrpy = [3.1416, 0.0, 0.0]', "q = [0.0, 0.0, 0.0]"), r"\[goal\].q: expected 7 numbers, got 3", None),
    (_edit('frame = "iiwa_link_ee"\nxyz = [0.5, 0.2, 0.6]\nrpy = [3.1416, 0.0, 0.0]', "q = [0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0]"), r"\[goal\].q: joint 'iiwa_joint_4' = 2.5 is outside its limits", None),
    # [[obstacle]]
    (_edit('shape = "box"', 'shape = "cone"'), r"task.toml:19: \[\[obstacle\]\]#1.shape: 'cone' is not one of box, cylinder, sphere, capsule, mesh", None),
    (_edit('shape = "box"\n', ""), r"task.toml:17: \[\[obstacle\]\]#1: missing key 'shape'", None),
    (_edit("size = [0.1, 0.1, 0.1]", "size = [0.1, -0.1, 0.1]"), r"task.toml:20: \[\[obstacle\]\]#1.size: item 2: must be > 0, got -0.1", None),
    (_edit('shape = "box"\nsize = [0.1, 0.1, 0.1]', 'shape = "cylinder"\nsize = [0.1, 0.1, 0.1]'), r"\[\[obstacle\]\]#1.size: expected 2 numbers, got 3 \(cylinder: radius, height\)", None),
    (_edit("xyz = [0.5, -0.5, 0.2]\n", ""), r"\[\[obstacle\]\]#1: missing key 'xyz'", None),
    (_edit('shape = "box"', 'shape = "mesh"\nmesh = "shelf.stl"'), r"\[\[obstacle\]\]#1.mesh: file not found: .*shelf.stl", None),
    (_edit("[constraints]", '[[obstacle]]\nname = "box"\nshape = "sphere"\nsize = [0.1]\nxyz = [0, 1, 0]\n\n[constraints]'), r"\[\[obstacle\]\]#2.name: a second obstacle named 'box'", None),
    (_edit("xyz = [0.5, -0.5, 0.2]", "xyz = [0.0, 0.0, 0.5]"), r"the start q0 violates constraint 'clearance': geometry 'iiwa_link_\d_0' and scene object 'box' by 0.\d+ \(distance -0.\d+ m", None),
    # [constraints], [solver]
    (_edit('obstacle = "distance"', 'obstacle = "com"'), r"task.toml:19: \[\[obstacle\]\]#1.shape: box 'box' at \(0.5, -0.5, 0.2\) m is not a vertical cylinder, which obstacle = \"com\"", None),
    (_edit('obstacle = "distance"', 'obstacle = "soft"'), r"\[constraints\].obstacle: 'soft' is not one of distance, com", None),
    (_edit("margin = 0.02", "margin = -0.02"), r"task.toml:25: \[constraints\].margin: must be >= 0, got -0.02", None),
    (_edit("margin = 0.02", 'margin = 0.02\nposition_limits = "yes"'), r"\[constraints\].position_limits: expected true or false, got the string 'yes'", None),
    (_edit('method = "ripm"', 'method = "snopt"'), r"task.toml:28: \[solver\].method: 'snopt' is not one of ripm, mlgipm, ipopt", None),
    (_edit('method = "ripm"', 'method = "ripm"\nwarm_start = "ik"'), r"\[solver\].warm_start: 'ik' is not one of linear, via", None),
    (_edit('method = "ripm"', 'method = "ripm"\nmax_iter = -1'), r"\[solver\].max_iter: must be an integer >= 0, got -1", None),
    (_edit('method = "ripm"', 'method = "ripm"\ntol = 0'), r"\[solver\].tol: must be > 0, got 0", None),
    # URDFs named by the task file
    (URDF_TASK, r"\[robot\].urdf: .*joint 'j2' <mimic> follows joint 'j9', which is not defined", _urdf(extra='<mimic joint="j9"/>')),
    (URDF_TASK.replace('urdf"', 'urdf"\nlock = ["j1"]'), r"\[robot\].lock: r: joint 'j2' mimics 'j1', which is locked: lock 'j2' too \(at 0\)", _urdf(extra='<mimic joint="j1"/>')),
    (URDF_TASK, r"\[robot\].urdf: r: joint 'j2' mimics 'j1': a prismatic joint cannot follow a revolute one", _urdf("prismatic", '<mimic joint="j1"/>')),
    (URDF_TASK + "[start]\nq = [0.1, 0.3]\n", r"\[start\].q: joint 'j2' is at 0.3, but it mimics 'j1', which puts it at 0.15", _urdf(extra='<mimic joint="j1" multiplier="0.5" offset="0.1"/>')),
    (URDF_TASK, r"\[robot\].urdf: .*joint 'j2' \(JointModelPlanar\) is not a revolute, continuous or prismatic joint", _urdf("planar")),
    (URDF_TASK, r"\[robot\].urdf: .*joint 'j2' \(JointModelFreeFlyer\) is not a revolute, continuous or prismatic joint", _urdf("floating")),
    (URDF_TASK.replace('urdf"', 'urdf"\nlock = ["j2"]'), r"\[robot\].lock: joint 'j2' has 7 coordinates; only 1-dof joints", _urdf("floating")),
    (URDF_TASK, r"\[constraints\].obstacle: constraint 'clearance': Distance: robot 'r' has no collision geometry", _urdf(collision=False)),
    (URDF_TASK, r"\[robot\].urdf: URDF .*robot.urdf: joint 'j2' <origin xyz='nan 0 0.2'>", _urdf().replace('<origin xyz="0 0 0.2"/><axis', '<origin xyz="nan 0 0.2"/><axis')),
    (URDF_TASK, r"\[robot\].urdf: malformed XML in URDF .*robot.urdf: unclosed token", _urdf()[:-20]),
    (URDF_TASK.replace("[0.5, 0.5]", "[0.5]"), r"\[goal\].q: expected 2 numbers, got 1 \(the joints of 'r': j1, j2\)", _urdf()),
]  # fmt: skip


@pytest.mark.parametrize(("text", "message", "urdf"), CASES, ids=[c[1][:50] for c in CASES])
def test_malformed_task_file_is_one_line(tmp_path, capsys, text, message, urdf):
    task = tmp_path / "task.toml"
    task.write_text(text)
    if urdf is not None:
        (tmp_path / "robot.urdf").write_text(urdf)
    before = sorted(tmp_path.rglob("*"))
    code = main(["plan", str(task), "--out", str(tmp_path / "plan.npz")])
    out, err = capsys.readouterr()
    assert code == USAGE, out + err
    assert "Traceback" not in out + err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("mbplan: error: "), err
    assert re.search(message, lines[0]), (message, lines[0])
    assert sorted(tmp_path.rglob("*")) == before  # no file written


def test_valid_base_task_reaches_the_solver(tmp_path):
    """The battery's files differ from BASE (and the URDF task from a valid URDF) only by their
    error: unedited, each gets as far as the solve, which ``no_solves`` refuses."""
    (tmp_path / "task.toml").write_text(BASE)
    with pytest.raises(AssertionError, match="a solve started"):
        main(["plan", str(tmp_path / "task.toml")])
    (tmp_path / "robot.urdf").write_text(_urdf())
    (tmp_path / "urdf.toml").write_text(URDF_TASK)
    with pytest.raises(AssertionError, match="a solve started"):
        main(["plan", str(tmp_path / "urdf.toml"), "--method", "ipopt"])


FLAG_CASES = [
    (["--set", "horizon.N"], r"--set: expected TABLE.KEY=VALUE, got 'horizon.N'"),
    (["--set", "N=3"], r"--set: expected TABLE.KEY=VALUE, got 'N'"),
    (["--set", "goal.xyz=[1, 2"], r"--set goal.xyz: '\[1, 2' is not a TOML value"),
    (["--set", "goal.xyz=[1, 2]"], r"task.toml: \[goal\].xyz \(from --set\): expected 3 numbers, got 2"),
    (["--set", "solvr.method=ipopt"], r"\[solvr\] \(from --set\): unknown table"),
    (["--method", "snopt"], r"\[solver\].method \(from --method\): 'snopt' is not one of"),
    (["--robot", "panda"], r"--robot is not used with a task file"),
    (["--seed", "3"], r"--seed is not used with a task file"),
    (["--out", "{tmp}/plan.txt"], r"--out: .* must end in .npz"),
]  # fmt: skip


@pytest.mark.parametrize(("flags", "message"), FLAG_CASES, ids=[" ".join(f) for f, _ in FLAG_CASES])
def test_bad_flags_with_a_task_file(tmp_path, capsys, flags, message):
    task = tmp_path / "task.toml"
    task.write_text(BASE)
    code = main(["plan", str(task), *[f.format(tmp=tmp_path) for f in flags]])
    err = capsys.readouterr().err.strip()
    assert code == USAGE and len(err.splitlines()) == 1, err
    assert re.search(message, err), (message, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["task.toml"]


def test_missing_or_binary_task_file(tmp_path, capsys):
    assert main(["plan", str(tmp_path / "none.toml")]) == USAGE
    (tmp_path / "binary.toml").write_bytes(b"\xff\xfe[robot]")
    assert main(["plan", str(tmp_path / "binary.toml")]) == USAGE
    assert main(["plan", "--dt", "0.1"]) == USAGE  # --dt without a task file
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"mbplan: error: {tmp_path / 'none.toml'}: no such task file"
    assert err[1].startswith(f"mbplan: error: {tmp_path / 'binary.toml'}: not a UTF-8 text file")
    assert (
        err[2] == "mbplan: error: --dt and --set apply to a task file (mbplan plan TASK.toml ...)"
    )


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("xyz = [0.5, 0.2, 0.6]", "xyz = [0.5, 0.2]"), "task.toml:13: [goal].xyz: expected 3 numbers, got 2"),
        (("N = 10", "N = "), "task.toml:5: invalid TOML: Invalid value"),
    ],
)  # fmt: skip
def test_malformed_task_file_in_a_real_process(tmp_path, edit, message):
    """The installed entry point (``python -m mbplan``), stderr and exit code as a shell sees."""
    (tmp_path / "task.toml").write_text(_edit(*edit))
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, "-m", "mbplan", "plan", "task.toml", "--out", "plan.npz"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"},
        timeout=120,
    )
    assert proc.returncode == USAGE
    assert proc.stdout == "" and proc.stderr == f"mbplan: error: {message}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["task.toml"]
