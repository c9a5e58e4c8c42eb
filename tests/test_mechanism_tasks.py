"""The closed-loop mechanisms' tasks (:mod:`mbplan.tasks.mechanisms`): case 0 is the example task
file's OCP, the randomized cases are reproducible, closed and within reach."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from mbplan.errors import InputError
from mbplan.planning.initial_guess import path_clearance
from mbplan.robots.loops import closure_residual
from mbplan.taskfile import load_task
from mbplan.tasks import mechanisms as mech

TASK_FILES = Path(__file__).resolve().parents[1] / "examples" / "tasks"
FILES = {"fourbar": "fourbar_crank", "delta": "delta_obstacle", "two_arm_carry": "two_arm_carry"}


@pytest.mark.parametrize("mechanism", mech.MECHANISMS)
def test_case_zero_is_the_example_task_file(mechanism: str):
    task = load_task(TASK_FILES / f"{FILES[mechanism]}.toml")
    ocp = mech.mechanism_case(mechanism, 0)
    mine, theirs = ocp.to_dict(), task.ocp.to_dict()
    np.testing.assert_allclose(mine.pop("q0"), theirs.pop("q0"), atol=1e-9)  # the file rounds
    assert mine == theirs
    assert task.warm_start == mech.WARM_START


@pytest.mark.parametrize("mechanism", mech.MECHANISMS)
def test_randomized_cases_are_reproducible_closed_and_distinct(mechanism: str):
    cases = [mech.mechanism_case(mechanism, i, seed=3) for i in (1, 2)]
    again = mech.mechanism_case(mechanism, 2, seed=3).to_dict()
    assert cases[1].to_dict() == again  # a case depends on (seed, index) only
    goals = [c["goal"].residual.to_dict() for c in cases]
    assert goals[0] != goals[1] != mech.mechanism_case(mechanism, 0)["goal"].residual.to_dict()
    for ocp in cases:
        robot = ocp.robot
        assert np.max(np.abs(closure_residual(robot.model, robot.loops, ocp.q0))) < 1e-9
        assert path_clearance(ocp, ocp.q0[None]) <= 0.0


def test_fourbar_goals_lie_in_the_rocker_swing():
    lo, hi = mech.rocker_range()
    assert lo == pytest.approx(np.radians(-10.4), abs=2e-3)  # the MJCF's comment
    assert hi == pytest.approx(np.radians(38.1), abs=2e-3)
    for i in range(1, 20):
        (goal,) = mech.mechanism_case("fourbar", i)["goal"].residual.target
        assert lo + mech.ROCKER_MARGIN <= goal <= hi - mech.ROCKER_MARGIN
        assert abs(goal) >= mech.ROCKER_MIN_MOVE


def test_delta_moves_its_platform_past_the_box_and_two_arm_goals_are_reachable():
    ocp = mech.mechanism_case("delta", 1)
    data = ocp.robot.model.createData()
    pin.framesForwardKinematics(ocp.robot.model, data, ocp.q0)
    start = data.oMf[ocp.robot.frame_id("platform")].translation
    goal = ocp["goal"].residual.translation
    assert start[0] < -mech.DELTA_X[0] + 1e-9 and goal[0] >= mech.DELTA_X[0]
    two = mech.mechanism_case("two_arm_carry", 1)["goal"].residual
    assert mech.bar_pose_reachable(pin.SE3(two.rotation, two.translation))
    assert not mech.bar_pose_reachable(mech.bar_goal((0.0, 0.0, 2.0)))  # 1.5 m above the arms


def test_unknown_mechanism_is_named():
    with pytest.raises(InputError, match="unknown mechanism 'stewart'; choose from fourbar"):
        mech.mechanism_case("stewart", 0)
