"""The robustness benchmark's task families (:mod:`mbplan.tasks.robustness`) and its command
line: every family draws reproducible cases with the properties its docstring promises; bad
requests are named before any solve."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mbplan.benchmarks import families, robustness
from mbplan.cli.main import build_parser, main
from mbplan.errors import InputError
from mbplan.formulations.joint_space import evaluate
from mbplan.residuals import Distance
from mbplan.tasks import robustness as tasks
from mbplan.tasks.arm_sweep import joint_ranges


def _item(ocp, name):
    return next(i for i in ocp.constraints if i.name == name)


@pytest.mark.parametrize("name", list(robustness.FAMILIES))
def test_every_family_draws_the_same_case_twice_and_different_cases(name):
    case = robustness.FAMILIES[name].case
    a, b, c = case(2, 0), case(2, 0), case(4, 0)
    assert a.to_dict() == b.to_dict()
    assert a.to_dict() != c.to_dict()
    assert case(2, 1).to_dict() != a.to_dict()


def test_graded_chain_limits_fall_along_the_chain_and_the_goal_is_holdable():
    for index, n in enumerate(tasks.CHAIN_LINKS):
        ocp = tasks.graded_chain_case(index)
        model = ocp.robot.model
        assert model.nq == n
        assert np.allclose(model.effortLimit, np.linspace(*tasks.CHAIN_EFFORT, n), atol=1e-3)
        assert np.allclose(model.velocityLimit, tasks.CHAIN_VELOCITY)
        assert sum(model.inertias[j].mass for j in range(1, n + 1)) == pytest.approx(16.0)
        goal = next(i for i in ocp.costs if i.name == "joint_position_terminal").residual.target
        hold = pin.computeGeneralizedGravity(model, model.createData(), goal)
        assert np.all(np.abs(hold) <= tasks.CHAIN_HOLD_FRACTION * model.effortLimit)
        assert (ocp.N, ocp.dt) == (tasks.CHAIN_N, tasks.CHAIN_DT)


@pytest.mark.parametrize("index", range(6))
def test_arm_boxes_cycles_the_mesh_arms_and_keeps_start_and_goal_clear(index):
    ocp = tasks.arm_boxes_case(index)
    robot = ocp.robot
    assert robot.name == tasks.MESH_ARMS[index]
    assert 1 <= len(ocp.scene) <= 3
    assert _item(ocp, "clearance").residual.margin == tasks.MARGIN
    start = np.array([ocp.q0])
    rows = Distance(tasks.BOX_CLEARANCE).resolve(robot, ocp.scene)
    assert np.max(evaluate(robot, ocp.scene, rows, start, None, None)) <= 0
    # 3 s, stretched by ARM_SPEED / (the slowest joint's velocity limit) for a slower arm
    slowest = float(np.min(robot.model.velocityLimit))
    horizon = tasks.ARM_N * tasks.ARM_DT * max(1.0, tasks.ARM_SPEED / slowest)
    assert ocp.dt == tasks.ARM_DT
    assert horizon - 1e-9 <= ocp.N * ocp.dt < horizon + ocp.dt
    assert (ocp.N > tasks.ARM_N) == (robot.name in ("kinova", "so100"))


def test_near_limits_puts_half_the_goal_joints_next_to_a_limit():
    for index in range(len(tasks.ARMS)):
        ocp = tasks.near_limits_case(index)
        lo, hi = joint_ranges(ocp.robot)
        goal = _item(ocp, "goal").residual.target
        gap = tasks.LIMIT_GAP * (hi - lo)
        near = np.isclose(goal, lo + gap) | np.isclose(goal, hi - gap)
        assert near.sum() >= ocp.robot.nq // 2
        assert np.all((goal >= lo) & (goal <= hi))


def test_rest_goal_ends_at_rest_and_near_singular_is_more_singular_than_its_start():
    ocp = tasks.rest_goal_case(0)
    assert list(_item(ocp, "rest").knots) == [ocp.N]
    for index in range(4):
        ocp = tasks.near_singular_case(index)
        model, data = ocp.robot.model, ocp.robot.model.createData()
        goal = _item(ocp, "goal").residual
        fid = model.getFrameId(goal.frame)

        def sigma(q, fid=fid, model=model, data=data):
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            return np.linalg.svd(J, compute_uv=False)[min(6, model.nv) - 1]

        pin.framesForwardKinematics(model, data, ocp.q0)
        assert not np.allclose(data.oMf[fid].homogeneous, goal.placement)
        assert sigma(ocp.q0) > 0


def test_robustness_cli_parses_its_options():
    args = build_parser().parse_args(["bench", "robustness"])
    assert (args.n, args.seed, args.methods, args.tol, args.max_iter) == (
        20,
        0,
        ("ripm", "ipopt"),
        1e-6,
        500,
    )
    assert args.families == tuple(robustness.FAMILIES)
    assert args.func.__qualname__.startswith("_bench_suite")


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--families", "juggling"], "unknown family 'juggling'"),
        (["--families", "rest_goal,rest_goal"], "expected distinct comma-separated names"),
        (["--methods", "snopt"], "unknown method 'snopt'"),
        (["--n", "0"], "--n: must be >= 1, got 0"),
    ],
)
def test_robustness_bad_input_is_named_before_any_solve(tmp_path, capsys, flags, message):
    out = tmp_path / "robustness"
    assert main(["bench", "robustness", "--families", "rest_goal", *flags, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not list(out.glob("*.jsonl"))


def test_a_family_run_refuses_bad_requests_before_any_solve(tmp_path):
    with pytest.raises(InputError, match="random seed"):
        families.run(robustness.SUITE, tmp_path, seed=-1, families=("rest_goal",))
    with pytest.raises(InputError, match="distinct family names"):
        families.run(robustness.SUITE, tmp_path, families=("rest_goal", "rest_goal"))
    with pytest.raises(InputError, match="unknown family 'juggling'"):
        families.run(robustness.SUITE, tmp_path, families=("juggling",))
    assert not list(tmp_path.glob("*.jsonl"))
