"""Bad input, on the command line and through the API: one line naming the problem, the
expected exit code, no traceback, no file left, and no solve started (the solver backends are
replaced by a function that fails the test if it is called)."""

import json
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import mbplan.benchmarks.harness as harness
from mbplan.benchmarks.harness import Job, run_jobs
from mbplan.cli.main import main
from mbplan.cli.support import run_command
from mbplan.errors import InputError, MbplanError, RobotModelError, WarmStartWarning
from mbplan.ocp import Scene
from mbplan.planning.initial_guess import initial_path
from mbplan.planning.solve import METHODS, Method, plan
from mbplan.results import PlanResult, load_npz, save_npz
from mbplan.robots import load
from mbplan.solvers import RIPMOptions
from mbplan.tasks.drone import DockingTask
from mbplan.tasks.paper import (
    IIWA_START,
    IIWA_TARGET,
    add_obstacle_constraint,
    drone_docking,
    iiwa_obstacle,
    iiwa_obstacle_starts,
    tracking_ocp,
)


def _no_solve(*args, **kwargs):
    raise AssertionError("a solve started although the input is invalid")


@pytest.fixture(autouse=True)
def no_solves(monkeypatch):
    for name, method in list(METHODS.items()):
        monkeypatch.setitem(METHODS, name, Method(method.formulation, _no_solve, method.check))
    monkeypatch.setattr(harness, "_execute", _no_solve)


def _result(nq: int = 7, N: int = 4) -> PlanResult:
    return PlanResult(
        "test", "ok", True, "", 1, 0.1, 0.1, 0.1, np.zeros((N + 1, nq)), np.zeros((N + 1, nq)),
        np.zeros((N, nq)), 0.1,
    )  # fmt: skip


def _setup(tmp: Path) -> None:
    """Files the cases refer to: a folder, a plain file, a 3-joint result, junk .npz files and a
    bench folder made with another configuration."""
    (tmp / "folder.npz").mkdir()
    (tmp / "folder.html").mkdir()
    (tmp / "folder.png").mkdir()
    (tmp / "file").write_text("x")
    save_npz(_result(nq=3), tmp / "three.npz")
    save_npz(_result(), tmp / "seven.npz")
    (tmp / "text.npz").write_text("not a zip")
    np.savez(tmp / "partial.npz", q=np.zeros((2, 7)))
    np.savez(tmp / "objects.npz", a=np.array([{"x": 1}], dtype=object))
    whole = (tmp / "seven.npz").read_bytes()
    (tmp / "truncated.npz").write_bytes(whole[: len(whole) // 2])
    with np.load(tmp / "seven.npz") as data:  # a result whose q is an object (pickled) array
        fields = {k: data[k] for k in data.files}
    np.savez(tmp / "object_q.npz", **{**fields, "q": np.array([None], dtype=object)})
    other = tmp / "other-config"
    other.mkdir()
    (other / "results.config.json").write_text(json.dumps({"hash": "0", "config": {"seed": 5}}))
    (other / "results.jsonl").write_text('{"case": 0, "method": "ripm", "config": "0"}\n')


USAGE = 2  # exit code of a usage error
CLI_CASES = [
    # plan: numbers
    (["plan", "--seed", "-1"], "--seed: must be >= 0"),
    (["plan", "--seed", "1.5"], "--seed: expected an integer"),
    (["plan", "--seed", "abc"], "--seed: expected an integer"),
    (["plan", "--horizon", "0"], "--horizon: must be >= 2"),
    (["plan", "--horizon", "1"], "--horizon: must be >= 2"),
    (["plan", "--horizon", "2.5"], "--horizon: expected an integer"),
    pytest.param(  # builds the 10⁸-knot task before the memory estimate refuses it
        ["plan", "--horizon", "100000000"],
        r"N=100000000: .* needs about .* GB \(estimate\)",
        marks=pytest.mark.slow,
    ),
    (["plan", "--method", "ipopt", "--horizon", "10000000"], r"needs about .* GB \(estimate\)"),
    (["plan", "--tol", "0"], "--tol: must be a finite number > 0"),
    (["plan", "--tol=-1e-6"], "--tol: must be a finite number > 0"),
    (["plan", "--tol", "nan"], "--tol: must be a finite number > 0"),
    (["plan", "--tol", "inf"], "--tol: must be a finite number > 0"),
    (["plan", "--tol", "tight"], "--tol: expected a number"),
    (["plan", "--max-iter", "-1"], "--max-iter: must be >= 0"),
    (["plan", "--max-iter", "2.5"], "--max-iter: expected an integer"),
    # plan: names
    (["plan", "--method", "snopt"], "unknown method 'snopt'"),
    (["plan", "--task", "juggling"], "unknown task 'juggling'"),
    (["plan", "--robot", "nosuchbot"], "unknown robot 'nosuchbot'"),
    (["plan", "--robot", "panda"], "obstacle task is defined for the iiwa; for 'panda'"),
    (["plan", "--robot", "{tmp}/missing.urdf"], "URDF file not found"),
    (["plan", "--robot", "{tmp}/file"], "malformed XML in URDF .*file"),
    (["plan", "--warm-start", "magic"], "--warm-start: invalid choice"),
    (["plan", "--constraint", "soft"], "--constraint: invalid choice"),
    # plan: output paths, checked before solving
    (["plan", "--out", "{tmp}/plan.txt"], "--out: .* must end in .npz"),
    (["plan", "--out", "{tmp}/plan"], "--out: .* must end in .npz, got 'no suffix'"),
    (["plan", "--out", "{tmp}/folder.npz"], "--out: .* is a directory"),
    (["plan", "--out", "{tmp}/file/plan.npz"], "--out: .*file is a file"),
    (["plan", "--out", "{tmp}/file/deeper/plan.npz"], "--out: .*file is a file"),
    (["plan", "--html", "{tmp}/page.txt"], "--html: .* must end in .html"),
    (["plan", "--html", "{tmp}/folder.html"], "--html: .* is a directory"),
    (["plan", "--out", "{tmp}/ok.npz", "--html", "{tmp}/file/p.html"], "--html: .*is a file"),
    # replay
    (["replay", "{tmp}/missing.npz"], "no such result file"),
    (["replay", "{tmp}/text.npz"], "not a PlanResult .npz file"),
    (["replay", "{tmp}/partial.npz"], "lacks the fields"),
    (["replay", "{tmp}/truncated.npz"], r"truncated\.npz is not a PlanResult .npz file"),
    (["replay", "{tmp}/objects.npz"], r"objects\.npz: not a PlanResult .npz file: it lacks"),
    (["replay", "{tmp}/object_q.npz"], r"object_q\.npz: .*field 'q' is not what save_npz writes"),
    (["replay", "{tmp}/folder.npz"], "no such result file"),
    (["replay", "{tmp}/three.npz", "--robot", "iiwa"], r"\[3\] joints\) do not fit robot 'iiwa'"),
    (["replay", "{tmp}/seven.npz", "--html", "{tmp}/page.txt"], "--html: .* must end in .html"),
    (["replay", "{tmp}/seven.npz", "--html", "{tmp}/file/p.html"], "--html: .*is a file"),
    # plot
    (["plot", "convergence", "{tmp}/missing.npz"], "no such result file"),
    (["plot", "convergence", "{tmp}/seven.npz", "--out", "{tmp}/x.jpg"], "must end in .png"),
    (["plot", "trajectories", "{tmp}/seven.npz", "--out", "{tmp}/folder.png"], "is a directory"),
    (["plot", "histogram", "{tmp}/seven.npz"], "invalid choice: 'histogram'"),
    # validate-dynamics
    (["validate-dynamics", "--duration", "0"], "--duration: must be a finite number > 0"),
    (["validate-dynamics", "--duration", "nan"], "--duration: must be a finite number > 0"),
    (["validate-dynamics", "--duration", "-1"], "--duration: must be a finite number > 0"),
    (["validate-dynamics", "--duration", "0.3"], "dt=0.008 must divide T=0.3"),
    (["validate-dynamics", "--robot", "iiwa,iiwa"], "--robot: expected distinct"),
    (["validate-dynamics", "--robot", "nosuchbot"], "nosuchbot"),
    (["validate-dynamics", "--seed", "-3"], "--seed: must be >= 0"),
    (["validate-dynamics", "--out", "{tmp}/file"], "--out: .*file is a file, expected a directory"),
    # bench engine / chain
    (["bench", "engine", "--knots", "0,10"], "--knots: must be >= 1"),
    (["bench", "engine", "--knots", "1,,10"], "--knots: expected comma-separated integers"),
    (["bench", "engine", "--knots", "ten"], "--knots: expected an integer"),
    (["bench", "engine", "--seed", "-1"], "--seed: must be >= 0"),
    (["bench", "engine", "--out", "{tmp}/file"], "--out: .* is a file"),
    (["bench", "chain", "--horizon", "0"], "--horizon: must be >= 1"),
    (["bench", "chain", "--out", "{tmp}/file/sub"], "--out: .*file is a file"),
    # bench drone-docking
    (["bench", "drone-docking", "--n", "0"], "--n: must be >= 1"),
    (["bench", "drone-docking", "--methods", "ripm,bogus", "--out", "{tmp}/d"], "unknown methods"),
    (["bench", "drone-docking", "--methods", "ripm,ripm"], "--methods: expected distinct"),
    (["bench", "drone-docking", "--tol", "0"], "--tol: must be a finite number > 0"),
    (["bench", "drone-docking", "--workers", "0"], "--workers: must be >= 1"),
    (["bench", "drone-docking", "--out", "{tmp}/file"], "--out: .* is a file"),
    # bench iiwa-obstacle
    (["bench", "iiwa-obstacle", "--n", "-5"], "--n: must be >= 1"),
    (["bench", "iiwa-obstacle", "--horizon", "1"], "--horizon: must be >= 2"),
    (["bench", "iiwa-obstacle", "--seed", "-1"], "--seed: must be >= 0"),
    (["bench", "iiwa-obstacle", "--methods", "snopt", "--out", "{tmp}/i"], "unknown methods"),
    (["bench", "iiwa-obstacle", "--methods", ","], "--methods: expected distinct"),
    (["bench", "iiwa-obstacle", "--warm-start", "x"], "--warm-start: invalid choice"),
    (["bench", "iiwa-obstacle", "--workers", "0"], "--workers: must be >= 1"),
    (
        ["bench", "iiwa-obstacle", "--n", "1", "--out", "{tmp}/other-config"],
        r"holds results of another configuration \(N \(unset\) -> 40; .*seed 5 -> 0",
    ),
    # no command
    ([], "usage: mbplan"),
    (["bench"], "usage: mbplan"),
]


@pytest.mark.parametrize(
    ("argv", "message"),
    CLI_CASES,
    ids=[" ".join(getattr(c, "values", c)[0])[:60] or "no command" for c in CLI_CASES],
)
def test_cli_refuses_bad_input(tmp_path, capsys, argv, message):
    _setup(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    code = main([a.format(tmp=tmp_path) for a in argv])
    out, err = capsys.readouterr()
    assert code == USAGE
    assert "Traceback" not in out + err
    if argv and argv != ["bench"]:
        assert len(err.strip().splitlines()[-1:]) == 1
        last = err.strip().splitlines()[-1]
        assert last.startswith(("mbplan: error:", "mbplan ")), err
        assert re.search(message, last), (message, err)
        lines = err.strip().splitlines()
        assert all(line.startswith(("mbplan: warning:", "mbplan")) for line in lines), err
        assert sum(": error:" in line for line in lines) == 1, err  # one error line
        assert "pickle" not in last, err  # never the advice to unpickle an untrusted file
    else:
        assert message in out + err
    assert sorted(tmp_path.rglob("*")) == before  # no file left


def test_ctrl_c_during_the_solve(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setitem(METHODS, "ripm", Method("maximal", interrupted))
    code = main(["plan", "--horizon", "5", "--out", str(tmp_path / "p.npz")])
    err = capsys.readouterr().err
    assert code == 130
    assert err.strip() == "mbplan: interrupted (SIGINT); no partial output was written"
    assert not list(tmp_path.iterdir())


def test_warm_start_fallback_is_a_warning_or_an_error():
    scene = Scene().add_cylinder("wall", 2.0, 1.5, (0.0, 0.0, 0.75))
    blocked = add_obstacle_constraint(
        tracking_ocp("iiwa", IIWA_START, IIWA_TARGET, scene, N=5), "com"
    )
    with pytest.warns(WarmStartWarning, match="using the linear warm start"):
        q = initial_path(blocked, "via")
    assert np.allclose(q[-1], IIWA_TARGET)
    with warnings.catch_warnings():
        warnings.simplefilter("error", WarmStartWarning)
        with pytest.raises(WarmStartWarning):
            initial_path(blocked, "via")


def test_run_command_exit_codes(capsys):
    def warm_start_error():
        raise WarmStartWarning("no via point")

    def disk_full():
        raise OSError(28, "No space left on device", "/x/results.jsonl")

    def warns():
        warnings.warn(WarmStartWarning("fell back"), stacklevel=1)
        return 1

    assert run_command(warm_start_error) == 2
    assert run_command(disk_full) == 1
    assert run_command(warns) == 1
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "mbplan: error: no via point",
        "mbplan: error: No space left on device: /x/results.jsonl",
        "mbplan: warning: fell back",
    ]


TASK = iiwa_obstacle(N=5)
DOCKING_WITH_CYLINDER = drone_docking(DockingTask(obstacles=((2.0, 2.0, 0.3),)))
API_CASES = [
    (
        lambda: plan(DOCKING_WITH_CYLINDER, "ms-ilqr"),
        r"ms-ilqr cannot impose constraint 'cylinder_0' \(ComOutsideCylinder\)",
    ),
    (lambda: plan(TASK, "ss-ilqr"), "ss-ilqr plans free bodies .* robot 'iiwa'"),
    (lambda: plan(TASK, "snopt"), "unknown method 'snopt'"),
    (lambda: plan(TASK, "ripm", tol=0.0), "tol: must be finite and > 0"),
    (lambda: plan(TASK, "ripm", tol=float("nan")), "tol: must be finite"),
    (lambda: plan(TASK, "ripm", max_iter=2.5), "max_iter: iteration limit must be an integer"),
    (lambda: plan(TASK, "ipopt", max_iter=-1), "max_iter: iteration limit must be an integer"),
    (lambda: plan("iiwa", "ripm"), "expected an OCP, got str"),
    (lambda: plan(iiwa_obstacle(N=10**6), "ripm"), r"GB \(estimate\)"),
    (lambda: iiwa_obstacle(N=1), "N: horizon must be an integer >= 2"),
    (lambda: iiwa_obstacle(N=2.5), "N: horizon must be an integer >= 2"),
    (lambda: iiwa_obstacle(dt=0.0), "dt: must be finite and > 0"),
    (lambda: iiwa_obstacle(dt=float("inf")), "dt: must be finite and > 0"),
    (lambda: plan(TASK, "ripm", warm_start="magic"), "warm_start: expected 'linear', 'via'"),
    (lambda: iiwa_obstacle_starts(1, -1), "seed: random seed must be an integer >= 0"),
    (lambda: iiwa_obstacle_starts(1, 0.5), "seed: random seed must be an integer >= 0"),
    (lambda: iiwa_obstacle_starts(0, 0), "n: number of cases must be an integer >= 1"),
    (lambda: RIPMOptions(max_iter=2.5), r"max_iter=2.5 \(expected int\)"),
    (lambda: RIPMOptions(max_iter=True), r"max_iter=True \(expected int\)"),
    (lambda: RIPMOptions(tol="1e-6"), r"tol='1e-6' \(expected float\)"),
    (lambda: RIPMOptions(restoration=1), r"restoration=1 \(expected bool\)"),
    (lambda: RIPMOptions(tol=-1.0), "out of range: tol=-1.0"),
    (lambda: RIPMOptions().replace(maxiter=3), "unknown RIPM option"),
    (lambda: save_npz(_result(), "{tmp}/r.txt"), "must end in .npz"),
    (lambda: save_npz(_result(), "{tmp}/folder.npz"), "is a directory"),
    (lambda: save_npz(_result(), "{tmp}/file/r.npz"), "file is a file"),
    (lambda: save_npz("result", "{tmp}/r.npz"), "expected a PlanResult, got str"),
    (lambda: load_npz("{tmp}/missing.npz"), "no such result file"),
    (lambda: load_npz("{tmp}/text.npz"), "not a PlanResult .npz file"),
    (lambda: load_npz("{tmp}/partial.npz"), "lacks the fields"),
    (lambda: run_jobs([Job(0, "a", dict, ())] * 2, Path("{tmp}/j/r.jsonl")), "given twice"),
]


@pytest.mark.parametrize(("call", "message"), API_CASES)
def test_api_refuses_bad_input(tmp_path, monkeypatch, call, message):
    _setup(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    real_path, real_save, real_load = Path, save_npz, load_npz
    # The cases name files under {tmp}: resolve them here.
    fmt = lambda p: str(p).format(tmp=tmp_path)  # noqa: E731
    monkeypatch.setitem(call.__globals__, "Path", lambda p: real_path(fmt(p)))
    monkeypatch.setitem(call.__globals__, "save_npz", lambda r, p: real_save(r, fmt(p)))
    monkeypatch.setitem(call.__globals__, "load_npz", lambda p: real_load(fmt(p)))
    with pytest.raises(MbplanError, match=message):
        call()
    assert sorted(tmp_path.rglob("*")) == before


def test_memory_limit_can_be_set(monkeypatch):
    monkeypatch.setenv("MBPLAN_MEMORY_LIMIT_GB", "0.5")
    with pytest.raises(InputError, match=r"N=400: .*more than the 0.5 GB available"):
        plan(iiwa_obstacle(N=400), "ripm")


# --- malformed URDFs: the message names the element -------------------------------------------

_INERTIAL = (
    '<inertial><origin xyz="0 0 0.1" rpy="0 0 0"/><mass value="1"/>'
    '<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>'
)
_JOINT = (
    '<joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>'
    '<origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 0 1"/>'
    '<limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
)
_GOOD = f'<robot name="r"><link name="base"/><link name="arm">{_INERTIAL}</link>{_JOINT}</robot>'

URDF_CASES = [
    (('<origin xyz="0 0 0.2"', '<origin xyz="nan 0 0.2"'), r"joint 'j1' <origin xyz='nan 0 0.2'>"),
    (('rpy="0 0 0"/><axis', 'rpy="0 inf 0"/><axis'), r"joint 'j1' <origin rpy='0 inf 0'>"),
    (('<origin xyz="0 0 0.1"', '<origin xyz="0 0.1"'), r"link 'arm' <inertial> <origin xyz='0 0.1'>"),
    (('lower="-1" upper="1"', 'lower="1" upper="-1"'), r"joint 'j1': <limit lower='1' upper='-1'> is inverted"),
    (('lower="-1"', 'lower="nan"'), r"joint 'j1': <limit lower='nan'> is not a finite number"),
    (('effort="10"', 'effort="-10"'), r"joint 'j1': <limit effort='-10'> is negative"),
    (('velocity="1"', 'velocity="abc"'), r"joint 'j1': <limit velocity='abc'> is not a finite"),
    (('<limit lower="-1" upper="1" effort="10" velocity="1"/>', ""), r"joint 'j1' has no <limit>"),
    (('izz="0.1"', 'izz="0.3"'), r"link 'arm'.*<inertia> .* violate the triangle inequality"),
    (('ixx="0.1" ixy="0"', 'ixx="0.1" ixy="0.5"'), r"link 'arm'.*non-positive-definite inertia"),
    (('<mass value="1"/>', '<mass value="nan"/>'), r"link 'arm'.*<mass value='nan'>"),
    (('<mass value="1"/>', '<mass value="-1"/>'), r"link 'arm'.* negative mass"),
    (('<mass value="1"/>', '<mass value="0"/>'), r"child link 'arm' has zero mass"),
    (('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), r"joint 'j1' has axis '0 0 0'"),
    (('type="revolute"', 'type="ball"'), r"joint 'j1' has unknown type 'ball'"),
    (('<parent link="base"/>', '<parent link="ground"/>'), r"joint 'j1' has parent link 'ground'"),
    (('<link name="base"/>', '<link name="base"/><link name="base"/>'), r"link 'base' is defined twice"),
    (('</joint>', '<mimic joint="j0" multiplier="1"/></joint>'), r"joint 'j1' <mimic> follows joint 'j0', which is not defined"),
    (('</joint>', '<mimic joint="j1" multiplier="nan"/></joint>'), r"joint 'j1' <mimic>: <mimic multiplier='nan'>"),
    (('</robot>', ""), r"malformed XML"),
    (('<robot name="r">', '<robt name="r">'), r"malformed XML|root element is <robt>"),
]  # fmt: skip


@pytest.mark.parametrize(("edit", "message"), URDF_CASES, ids=[m[:40] for _, m in URDF_CASES])
def test_malformed_urdf_names_the_element(tmp_path, edit, message):
    old, new = edit
    assert old in _GOOD
    path = tmp_path / "robot.urdf"
    path.write_text(_GOOD.replace(old, new, 1))
    with pytest.raises(RobotModelError, match=message):
        load(path)


def two_joint_urdf(mimic: str = "", kind: str = "revolute") -> str:
    """``_GOOD`` and a second joint ``j2`` (of type ``kind``, ``mimic`` inside it) to a hand."""
    second = _JOINT.replace('"j1"', '"j2"').replace('link="base"', 'link="arm"')
    second = second.replace('link="arm"/><origin', 'link="hand"/><origin')
    second = second.replace('type="revolute"', f'type="{kind}"')
    return _GOOD.replace(
        "</robot>",
        f'<link name="hand">{_INERTIAL}</link>'
        + second.replace("</joint>", f"{mimic}</joint>")
        + "</robot>",
    )


def test_valid_urdf_with_a_mimic_joint_loads_with_both_joints(tmp_path):
    path = tmp_path / "robot.urdf"
    path.write_text(_GOOD)
    assert load(path).model.nq == 1
    path.write_text(two_joint_urdf('<mimic joint="j1"/>'))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load(path).model.nq == 2  # the coupling is the OCP's (tests/test_mimic.py)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes everywhere")
def test_unwritable_output_folder(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    assert main(["plan", "--out", str(locked / "p.npz")]) == USAGE
    assert "permission denied" in capsys.readouterr().err


def test_save_npz_write_failure_is_an_mbplan_error_and_leaves_no_file(tmp_path, monkeypatch):
    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    with pytest.raises(InputError, match=r"cannot write .*r\.npz: No space left on device"):
        save_npz(_result(), tmp_path / "r.npz")
    assert not list(tmp_path.iterdir())
