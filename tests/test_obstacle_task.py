"""Manipulator obstacle task (RIPM paper §VIII.C, eq. 62): data, sampling, validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.tasks.obstacle import (
    IIWA_CYLINDER,
    IIWA_START,
    IIWA_TARGET,
    SAMPLING_RANGE,
    Cylinder,
    Obstacle,
    ObstacleTask,
    com_clearances,
    geometry_distances,
    joint_interpolation,
    link_coms,
    link_names,
    robot_description,
    sample_obstacle_cases,
    validate,
)

DESC = robot_description("iiwa")
MODEL = DESC.model


def _coms(q: np.ndarray) -> np.ndarray:
    return link_coms(MODEL, MODEL.createData(), q)


def _path_clearance(task: ObstacleTask) -> float:
    return min(com_clearances(task, _coms(q)).min() for q in joint_interpolation(task))


def test_defaults_come_from_the_urdf_and_the_paper() -> None:
    task = ObstacleTask()
    assert task.N == 40 and task.dt == pytest.approx(0.075)
    np.testing.assert_array_equal(task.torque_limit, MODEL.effortLimit)
    np.testing.assert_array_equal(task.velocity_limit, MODEL.velocityLimit)
    np.testing.assert_array_equal(task.q0, IIWA_START)
    np.testing.assert_array_equal(task.q_target, IIWA_TARGET)
    assert task.obstacles == (IIWA_CYLINDER,) and task.cylinders == (IIWA_CYLINDER,)
    assert not task.q0.flags.writeable
    validate(task)
    # the straight joint-space path from the default start runs through the cylinder
    assert _path_clearance(task) < 0.0


def test_sampler_is_reproducible_within_limits_and_collision_free() -> None:
    a = sample_obstacle_cases(n=12, seed=3)
    b = sample_obstacle_cases("iiwa", 12, 3)
    c = sample_obstacle_cases(n=12, seed=4)
    q0 = np.array([t.q0 for t in a])
    np.testing.assert_array_equal(q0, [t.q0 for t in b])
    assert not np.allclose(q0, [t.q0 for t in c])
    low, high = MODEL.lowerPositionLimit, MODEL.upperPositionLimit
    centre, half = 0.5 * (low + high), 0.5 * SAMPLING_RANGE * (high - low)
    assert np.all(np.abs(q0 - centre) <= half)
    assert np.ptp(q0, axis=0).min() > 0.5 * half.min()  # spread over the range
    solid = IIWA_CYLINDER.as_obstacle()
    for task in a:
        assert task.N == 40 and np.array_equal(task.q_target, IIWA_TARGET)
        validate(task)
        assert com_clearances(task, _coms(task.q0)).min() >= task.margin
        assert geometry_distances(DESC, task.q0, (solid,)).min() >= 0.0
    short = sample_obstacle_cases(n=2, seed=3, N=10, dt=0.3, margin=0.05)
    assert [t.N for t in short] == [10, 10] and short[0].margin == 0.05


def test_about_half_of_the_sampled_straight_paths_cross_the_obstacle() -> None:
    cases = sample_obstacle_cases(n=40, seed=0)
    crossing = np.mean([_path_clearance(t) < 0.0 for t in cases])
    assert 0.3 < crossing < 0.7


def test_start_overlapping_an_obstacle_is_infeasible_naming_link_and_obstacle() -> None:
    com4 = _coms(np.array(IIWA_START))[3]
    blocker = Cylinder((com4[0] + 0.05, com4[1]), 0.1)
    task = ObstacleTask(obstacles=(IIWA_CYLINDER, blocker))
    with pytest.raises(InfeasibleRequestError, match=r"q0 .*'iiwa_link_4'.*obstacle 1"):
        validate(task)
    # a margin violation alone (COMs outside the radius) is infeasible too: q_1 = q_0 at rest
    clearance = min(
        com_clearances(ObstacleTask(), _coms(np.array(q))).min() for q in (IIWA_START, IIWA_TARGET)
    )
    assert clearance > 0.05
    with pytest.raises(InfeasibleRequestError, match="less than the margin"):
        validate(ObstacleTask(margin=clearance + 0.01))
    validate(ObstacleTask(margin=clearance - 0.01))


def test_geometry_overlap_target_and_limits_are_checked() -> None:
    # a box at the end effector: no eq.-62 cylinder, but the robot's geometry penetrates it
    pin_data = MODEL.createData()
    ee = link_coms(MODEL, pin_data, np.array(IIWA_START))[-1]
    pose = np.eye(4)
    pose[:3, 3] = ee + np.array([0.0, 0.0, 0.08])
    box = Obstacle("box", pose, (0.1, 0.1, 0.05))
    with pytest.raises(
        InfeasibleRequestError, match=r"geometry 'iiwa_link_\d_0'.*obstacle 0 \(box"
    ):
        validate(ObstacleTask(obstacles=(box,)))
    target_com = _coms(np.array(IIWA_TARGET))[4]
    with pytest.raises(InfeasibleRequestError, match="q_target overlaps"):
        validate(ObstacleTask(obstacles=(Cylinder(tuple(target_com[:2]), 0.05),)))
    q0 = np.array(IIWA_START)
    q0[1] = 2.5
    with pytest.raises(InfeasibleRequestError, match=r"q0\[1\] = 2.5.*'iiwa_joint_2'"):
        validate(ObstacleTask(q0=q0))
    with pytest.raises(InfeasibleRequestError, match="target"):
        sample_obstacle_cases(n=1, obstacles=(Cylinder(tuple(target_com[:2]), 0.05),))


def test_bad_input_is_rejected() -> None:
    with pytest.raises(InputError, match="q0: contains NaN"):
        ObstacleTask(q0=[np.nan] * 7)
    with pytest.raises(InputError, match="q_target: expected shape"):
        ObstacleTask(q_target=np.zeros(6))
    with pytest.raises(InputError, match="N: horizon"):
        ObstacleTask(N=1)
    with pytest.raises(InputError, match="dt"):
        ObstacleTask(dt=0.0)
    with pytest.raises(InputError, match="torque_limit"):
        ObstacleTask(torque_limit=np.zeros(7))
    with pytest.raises(InputError, match="obstacles\\[0\\]"):
        ObstacleTask(obstacles=((0.4, 0.2, 0.1),))  # type: ignore[arg-type]
    with pytest.raises(InputError, match="z_max"):
        Cylinder((0.0, 0.0), 0.1, z_min=1.0, z_max=0.5)
    with pytest.raises(InputError, match="radius"):
        Cylinder((0.0, 0.0), -0.1)
    with pytest.raises(InputError, match="not one of"):
        Obstacle("cone", np.eye(4), (0.1, 0.2))  # type: ignore[arg-type]
    with pytest.raises(InputError, match="expected"):
        Obstacle("capsule", np.eye(4), (0.1,))
    with pytest.raises(InputError, match="rotation"):
        Obstacle("sphere", np.diag([1.0, 1.0, -1.0, 1.0]), (0.1,))
    with pytest.raises(InputError, match="q0 is sampled"):
        sample_obstacle_cases(n=1, q0=np.zeros(7))
    with pytest.raises(InputError, match="n: number"):
        sample_obstacle_cases(n=0)
    with pytest.raises(InputError, match="unknown robot"):
        ObstacleTask(robot="no-such-robot")
    with pytest.raises(InputError, match="q0: required"):
        ObstacleTask(robot="ur5")


def test_joint_interpolation_starts_at_rest() -> None:
    task = ObstacleTask(N=8)
    q = joint_interpolation(task)
    assert q.shape == (9, 7)
    np.testing.assert_array_equal(q[0], task.q0)
    np.testing.assert_array_equal(q[1], task.q0)  # q_1 = q_0 + v_0 Δt with v_0 = 0
    np.testing.assert_allclose(q[-1], task.q_target, atol=1e-15)
    np.testing.assert_allclose(np.diff(q[1:], 2, axis=0), 0.0, atol=1e-14)


def test_link_names_coms_and_distances() -> None:
    assert link_names(MODEL) == [f"iiwa_link_{i}" for i in range(1, 8)]
    coms = _coms(np.zeros(7))
    assert coms.shape == (7, 3) and np.allclose(coms[:, :2], 0.0, atol=0.05)  # upright arm
    cyl = Cylinder((0.5, 0.0), 0.1)
    task = dataclasses.replace(ObstacleTask(), obstacles=(cyl,))
    np.testing.assert_allclose(
        com_clearances(task, coms)[:, 0], np.hypot(coms[:, 0] - 0.5, coms[:, 1]) - 0.1
    )
    sphere = Obstacle("sphere", np.eye(4), (0.05,))  # at the base: inside link 0's geometry
    far_pose = np.eye(4)
    far_pose[0, 3] = 5.0
    far = Obstacle("capsule", far_pose, (0.1, 0.2))
    d = geometry_distances(DESC, np.zeros(7), (sphere, far))
    assert d.shape == (DESC.collision_model.ngeoms, 2)
    assert d[:, 0].min() < 0.0 and d[:, 1].min() > 4.0


def test_via_warm_start_is_collision_free_where_linear_is_not():
    """Case 0 (seed 0): the linear guess drives links through the cylinder; the "via" guess keeps
    every COM outside it (+ margin) at every knot, starts at q0 and ends at q_target."""
    from mbplan.tasks.obstacle import _path_clearance, joint_interpolation, sample_obstacle_cases

    linear_task, via_task = (
        sample_obstacle_cases("iiwa", 1, 0, warm_start=w)[0] for w in ("linear", "via")
    )
    linear, via = joint_interpolation(linear_task), joint_interpolation(via_task)
    assert _path_clearance(linear_task, linear) < 0
    assert _path_clearance(via_task, via) >= 0
    np.testing.assert_allclose(
        via[[0, 1, -1]], [via_task.q0, via_task.q0, via_task.q_target], atol=1e-12
    )
    # Deterministic: the same guess twice.
    np.testing.assert_array_equal(via, joint_interpolation(via_task))


def test_bad_warm_start_is_named():
    with pytest.raises(InputError, match="warm_start"):
        ObstacleTask(warm_start="rrt")
