"""The paper's iiwa obstacle task as OCPs (:mod:`mbplan.tasks.paper`): defaults, sampler, start
checks and the warm starts."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import mbplan as mb
from mbplan.formulations.joint_space import evaluate
from mbplan.planning.initial_guess import VIA_CANDIDATES, initial_path, path_clearance
from mbplan.planning.solve import check_start
from mbplan.robots.continuous import joint_ranges
from mbplan.tasks.paper import (
    IIWA_CYLINDER,
    IIWA_START,
    IIWA_TARGET,
    SAMPLING_RANGE,
    add_obstacle_constraint,
    iiwa_obstacle,
    iiwa_obstacle_cases,
    tracking_ocp,
)

MODEL = mb.load_robot("iiwa").model


def _coms(q: np.ndarray) -> np.ndarray:
    data = MODEL.createData()
    pin.forwardKinematics(MODEL, data, q)
    return np.array([data.oMi[j].act(MODEL.inertias[j].lever) for j in range(1, MODEL.njoints)])


def test_defaults_come_from_the_urdf_and_the_paper() -> None:
    ocp = iiwa_obstacle()
    assert ocp.N == 40 and ocp.dt == pytest.approx(0.075)
    np.testing.assert_array_equal(ocp["torque_limits"].residual.upper, MODEL.effortLimit)
    np.testing.assert_array_equal(ocp["velocity_limits"].residual.upper, MODEL.velocityLimit)
    np.testing.assert_array_equal(ocp.q0, IIWA_START)
    np.testing.assert_array_equal(ocp["joint_position_terminal"].residual.target, IIWA_TARGET)
    (cylinder,) = ocp.scene
    assert cylinder.shape == "cylinder" and cylinder.size[0] == IIWA_CYLINDER[1]
    np.testing.assert_array_equal(cylinder.pose[:2, 3], IIWA_CYLINDER[0])
    assert not ocp.q0.flags.writeable
    check_start(ocp)
    # the straight joint-space path from the default start runs through the cylinder
    assert path_clearance(ocp, initial_path(ocp, "linear")) > 0.0


def test_sampler_is_reproducible_within_limits_and_collision_free() -> None:
    a, b, c = iiwa_obstacle_cases(12, 3), iiwa_obstacle_cases(12, 3), iiwa_obstacle_cases(12, 4)
    q0 = np.array([t.q0 for t in a])
    np.testing.assert_array_equal(q0, [t.q0 for t in b])
    assert not np.allclose(q0, [t.q0 for t in c])
    low, high = MODEL.lowerPositionLimit, MODEL.upperPositionLimit
    centre, half = 0.5 * (low + high), 0.5 * SAMPLING_RANGE * (high - low)
    assert np.all(np.abs(q0 - centre) <= half)
    assert np.ptp(q0, axis=0).min() > 0.5 * half.min()  # spread over the range
    touch = mb.residuals.Distance(0.0)
    for ocp in a:
        check_start(ocp)
        assert path_clearance(ocp, ocp.q0[None]) <= 0.0
        r = touch.resolve(ocp.robot, ocp.scene)
        assert evaluate(ocp.robot, ocp.scene, r, ocp.q0[None], None, None).max() <= 0.0
    assert [o.N for o in iiwa_obstacle_cases(2, 3, N=10)] == [10, 10]


def test_about_half_of_the_sampled_straight_paths_cross_the_obstacle() -> None:
    cases = iiwa_obstacle_cases(40, 0)
    crossing = np.mean([path_clearance(o, initial_path(o, "linear")) > 0.0 for o in cases])
    assert 0.3 < crossing < 0.7


def test_start_overlapping_an_obstacle_is_infeasible_naming_link_and_obstacle() -> None:
    com4 = _coms(np.array(IIWA_START))[3]
    scene = mb.Scene().add_cylinder("blocker", 0.1, 1.5, (com4[0] + 0.05, com4[1], 0.75))
    ocp = add_obstacle_constraint(tracking_ocp("iiwa", IIWA_START, IIWA_TARGET, scene), "com")
    with pytest.raises(mb.InfeasibleRequestError, match=r"q0 .*'iiwa_joint_4'.*'blocker'"):
        check_start(ocp)
    q0 = np.array(IIWA_START)
    q0[1] = 2.5
    with pytest.raises(mb.InfeasibleRequestError, match=r"upper limit of joint 'iiwa_joint_2'"):
        check_start(tracking_ocp("iiwa", q0, IIWA_TARGET))


def test_bad_input_is_rejected() -> None:
    with pytest.raises(mb.InputError, match="q0: contains NaN"):
        iiwa_obstacle(np.full(7, np.nan))
    with pytest.raises(mb.InputError, match="expected shape"):
        tracking_ocp("iiwa", IIWA_START, np.zeros(6))
    with pytest.raises(mb.InputError, match="N: horizon"):
        iiwa_obstacle(N=1)
    with pytest.raises(mb.InputError, match="dt"):
        iiwa_obstacle(dt=-1.0)
    with pytest.raises(mb.InputError, match="radius"):
        mb.Scene().add_cylinder("c", -0.1, 1.0)
    with pytest.raises(mb.InputError, match="rotation"):
        mb.Scene().add_box("b", (1, 1, 1), rotation=2 * np.eye(3))
    with pytest.raises(mb.InputError, match="n: number"):
        iiwa_obstacle_cases(0)
    with pytest.raises(mb.InputError, match="unknown robot"):
        mb.OCP("r2d2")


def test_joint_interpolation_starts_at_rest() -> None:
    ocp = iiwa_obstacle(N=8)
    q = initial_path(ocp, "linear")
    assert q.shape == (9, 7)
    np.testing.assert_array_equal(q[0], ocp.q0)
    np.testing.assert_array_equal(q[1], ocp.q0)  # q_1 = q_0 + v_0 Δt with v_0 = 0
    np.testing.assert_allclose(q[-1], IIWA_TARGET, atol=1e-15)
    np.testing.assert_allclose(np.diff(q[1:], 2, axis=0), 0.0, atol=1e-14)


def test_via_warm_start_is_collision_free_where_linear_is_not() -> None:
    """Case 0 (seed 0): the linear guess drives links through the cylinder; the "via" guess keeps
    every COM outside it (+ margin) at every knot, starts at q0 and ends at the target."""
    ocp = iiwa_obstacle_cases(1, 0)[0]
    linear, via = initial_path(ocp, "linear"), initial_path(ocp, "via")
    assert path_clearance(ocp, linear) > 0 and path_clearance(ocp, via) <= 0
    np.testing.assert_allclose(via[[0, 1, -1]], [ocp.q0, ocp.q0, IIWA_TARGET], atol=1e-12)
    np.testing.assert_array_equal(via, initial_path(ocp, "via"))  # deterministic
    with pytest.raises(mb.InputError, match="warm_start"):
        initial_path(ocp, "rrt")
    # the shortest clear one of the VIA_CANDIDATES seeded via points: every shorter one collides
    mid = 0.5 * (ocp.q0 + IIWA_TARGET)
    lo, hi = joint_ranges(ocp.robot, mid)
    rng = np.random.default_rng(0)
    vias = np.clip(mid + 0.5 * rng.uniform(-1, 1, (VIA_CANDIDATES, 7)) * (hi - lo), lo, hi)
    length = np.linalg.norm(vias - ocp.q0, axis=1) + np.linalg.norm(IIWA_TARGET - vias, axis=1)
    s = np.concatenate([[0.0], np.linspace(0.0, 1.0, ocp.N)])
    k = int(np.flatnonzero(s <= 0.5)[-1])  # on the first leg: q_k = q0 + 2 s_k (via - q0)
    point = ocp.q0 + (via[k] - ocp.q0) / (2 * s[k])
    chosen = int(np.argmin(np.abs(vias - point).sum(axis=1)))
    np.testing.assert_allclose(vias[chosen], point, atol=1e-10)
    for v in vias[length < length[chosen]]:
        path = ocp.q0 + np.minimum(2 * s, 1)[:, None] * (v - ocp.q0)
        path += np.maximum(2 * s - 1, 0)[:, None] * (IIWA_TARGET - v)
        assert path_clearance(ocp, path) > 0


@pytest.mark.parametrize("constraint", ["com", "distance"])
def test_path_clearances_of_a_batch_are_each_paths_own(constraint: str) -> None:
    """The via search's batched check (all paths' knots in one evaluation per obstacle
    constraint) gives every path exactly its own :func:`path_clearance`, clear or not."""
    from mbplan.planning.initial_guess import path_clearances
    from mbplan.tasks.speed import iiwa_task

    ocp = iiwa_task(2, constraint=constraint)
    linear = initial_path(ocp, "linear")
    rng = np.random.default_rng(1)
    paths = (
        linear
        + 0.3 * rng.standard_normal((5, 1, ocp.robot.nq)) * np.linspace(0, 1, ocp.N + 1)[:, None]
    )
    paths = np.concatenate([paths, initial_path(ocp, "via")[None]])
    each = [path_clearance(ocp, p) for p in paths]
    np.testing.assert_array_equal(path_clearances(ocp, paths), each)
    assert each[-1] <= 0.0 < max(each[:-1])  # the batch mixes clear and colliding paths


def test_frame_goal_warm_start_uses_inverse_kinematics() -> None:
    """A terminal frame goal: the warm start ends at a configuration that reaches it."""
    goal = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0.0, 0.0), np.array([0.5, 0.2, 0.4]))
    ocp = mb.OCP("iiwa", N=6).add_terminal_constraint(
        "ee", mb.residuals.FramePlacement("iiwa_link_ee", goal)
    )
    q = initial_path(ocp, "linear")
    r = evaluate(ocp.robot, ocp.scene, ocp["ee"].residual, q[-1:], q[-1:], None)
    assert np.abs(r).max() < 1e-6
    assert np.all(q[-1] >= MODEL.lowerPositionLimit) and np.all(q[-1] <= MODEL.upperPositionLimit)
