"""Pinocchio -> maximal-coordinate conversion and the state maps between the two."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from mbplan.errors import InputError, RobotModelError
from mbplan.multibody import (
    MaximalModel,
    body_poses,
    body_velocities,
    joint_positions,
    joint_velocities,
    maximal_model,
    nonstandard_inertia,
)
from mbplan.robots import available_robots, load

ROBOTS = ["iiwa", "panda", "ur5", "kinova", "double_pendulum", "double_pendulum_continuous"]
N_SAMPLES = 10


@cache
def _mm(name: str) -> MaximalModel:
    return maximal_model(name)


def _samples(mm: MaximalModel, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random (q, v) with every revolute angle in its limits and within pi of their middle."""
    rng = np.random.default_rng(seed)
    model = mm.model
    lo = model.lowerPositionLimit.copy()
    hi = model.upperPositionLimit.copy()
    plain = mm.idx_q[mm.revolute & ~mm.continuous]
    mid = 0.5 * (lo[plain] + hi[plain])
    lo[plain] = np.maximum(lo[plain], mid - np.pi + 1e-6)
    hi[plain] = np.minimum(hi[plain], mid + np.pi - 1e-6)
    out = []
    for _ in range(N_SAMPLES):
        q = pin.randomConfiguration(model, lo, hi)
        out.append((q, rng.standard_normal(model.nv)))
    return out


def _from_parent(mm: MaximalModel, x: np.ndarray, world: np.ndarray) -> np.ndarray:
    return np.array([world if k < 0 else x[k] for k in mm.parent])


# -------------------------------------------------------------------------------- the model


@pytest.mark.parametrize("name", available_robots())
def test_every_available_robot_converts(name: str) -> None:
    mm = _mm(name)
    model = mm.model
    assert mm.nb == model.njoints - 1 == model.nv - 5 * int(mm.free.any())
    assert mm.mass.sum() == pytest.approx(pin.computeTotalMass(model), rel=1e-12)
    assert np.all(mm.mass > 0)
    assert np.all(np.linalg.eigvalsh(mm.inertia) > 0)
    assert np.all(mm.parent < np.arange(mm.nb))  # parents come first


def test_iiwa_bodies_and_joints() -> None:
    mm = _mm("iiwa")
    assert mm.body_names == tuple(f"iiwa_link_{i}" for i in range(1, 8))
    assert mm.joint_names == tuple(f"iiwa_joint_{i}" for i in range(1, 8))
    assert mm.joint_types == ("revolute",) * 7
    np.testing.assert_array_equal(mm.parent, [-1, 0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(mm.idx_q, np.arange(7))
    np.testing.assert_allclose(mm.mass, [5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2])
    np.testing.assert_allclose(mm.com_in_joint[0], [0.0, -0.03, 0.12])
    np.testing.assert_allclose(mm.inertia[0], np.diag([0.033, 0.0333, 0.0123]))
    np.testing.assert_allclose(mm.r_parent[0], [0.0, 0.0, 0.1575])  # world anchor of joint 1
    np.testing.assert_allclose(mm.r_child[0], [0.0, 0.03, -0.12])
    np.testing.assert_allclose(mm.axis_parent[0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(mm.axis_child, np.tile([0.0, 0.0, 1.0], (7, 1)))
    # joint 2: parent pivot = joint-2 origin (0, 0, 0.2025) in link 1 minus link-1 COM
    np.testing.assert_allclose(mm.r_parent[1], [0.0, 0.03, 0.2025 - 0.12])
    np.testing.assert_allclose(mm.effort_limit, [320, 320, 176, 176, 110, 40, 40])
    np.testing.assert_allclose(mm.velocity_limit[6], 2.356194490192345)
    np.testing.assert_allclose(mm.upper_position_limit[1], 2.09439510239)
    np.testing.assert_allclose(mm.lower_position_limit[1], -2.09439510239)
    np.testing.assert_allclose(mm.damping, 0.5)
    np.testing.assert_allclose(mm.gravity, [0.0, 0.0, -9.81])
    assert not mm.continuous.any()


def test_panda_prismatic_fingers_and_tree() -> None:
    mm = _mm("panda")
    assert mm.joint_types[-2:] == ("prismatic", "prismatic")
    np.testing.assert_array_equal(mm.parent[-2:], [6, 6])  # both fingers hang on the hand
    np.testing.assert_allclose(mm.axis_child[-2:], [[0, 1, 0], [0, -1, 0]])
    np.testing.assert_allclose(mm.upper_position_limit[-2:], 0.04)


def test_continuous_joints() -> None:
    mm = _mm("double_pendulum_continuous")
    assert mm.continuous.all()
    np.testing.assert_array_equal(mm.idx_q, [0, 2])  # (cos, sin) per joint
    np.testing.assert_array_equal(mm.idx_v, [0, 1])
    assert np.all(np.isneginf(mm.lower_position_limit))
    assert np.all(np.isposinf(mm.upper_position_limit))


@pytest.mark.parametrize("name", ROBOTS)
def test_frames_axes_and_inertias_are_consistent(name: str) -> None:
    mm = _mm(name)
    np.testing.assert_allclose(np.linalg.norm(mm.axis_child, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(np.einsum("bij,bj->bi", mm.R_rel0, mm.axis_child), mm.axis_parent)
    gram = np.einsum("bki,bli->bkl", mm.perp_parent, mm.perp_parent)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(2), gram.shape), atol=1e-15)
    np.testing.assert_allclose(
        np.einsum("bki,bi->bk", mm.perp_parent, mm.axis_parent), 0, atol=1e-15
    )
    rtr = np.einsum("bji,bjk->bik", mm.R_rel0, mm.R_rel0)
    np.testing.assert_allclose(rtr, np.broadcast_to(np.eye(3), rtr.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(mm.R_rel0), 1.0)
    # eq. 33: I_b = tr(J) I3 - J
    J = mm.inertia_nonstandard
    rebuilt = np.trace(J, axis1=1, axis2=2)[:, None, None] * np.eye(3) - J
    np.testing.assert_allclose(rebuilt, mm.inertia, atol=1e-15)
    np.testing.assert_allclose(J, J.transpose(0, 2, 1))
    np.testing.assert_allclose(nonstandard_inertia(mm.inertia[0]), J[0])


def test_model_arrays_are_read_only() -> None:
    mm = _mm("iiwa")
    with pytest.raises(ValueError, match="read-only"):
        mm.mass[0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        mm.r_parent[0, 0] = 1.0


# ------------------------------------------------------------------------- against Pinocchio


@pytest.mark.parametrize("name", ROBOTS)
def test_com_and_kinetic_energy_match_pinocchio(name: str) -> None:
    mm = _mm(name)
    model = mm.model
    data = model.createData()
    for q, v in _samples(mm, seed=1):
        _, p = body_poses(mm, q)
        com = mm.mass @ p / mm.mass.sum()
        np.testing.assert_allclose(com, pin.centerOfMass(model, data, q), rtol=0, atol=1e-10)
        omega, v_com = body_velocities(mm, q, v)
        kinetic = 0.5 * mm.mass @ np.sum(v_com**2, axis=1) + 0.5 * np.einsum(
            "bi,bij,bj->", omega, mm.inertia, omega
        )
        assert kinetic == pytest.approx(pin.computeKineticEnergy(model, data, q, v), abs=1e-10)


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_constraints_hold_at_random_configurations(name: str) -> None:
    """Pivot and axis constraints (§VI.B) for revolute joints; for prismatic joints the relative
    rotation is R_rel0 and the pivots separate along the axis only."""
    mm = _mm(name)
    rev, pri = mm.revolute, ~mm.revolute
    for q, _ in _samples(mm, seed=2):
        R, p = body_poses(mm, q)
        Rp = _from_parent(mm, R, np.eye(3))
        pp = _from_parent(mm, p, np.zeros(3))
        gap = (
            np.einsum("bij,bj->bi", Rp, mm.r_parent)
            + pp
            - np.einsum("bij,bj->bi", R, mm.r_child)
            - p
        )
        np.testing.assert_allclose(gap[rev], 0, atol=1e-12)
        axis_world = np.einsum("bij,bj->bi", R, mm.axis_child)
        perp_world = np.einsum("bij,bkj->bki", Rp, mm.perp_parent)
        np.testing.assert_allclose(np.einsum("bki,bi->bk", perp_world, axis_world), 0, atol=1e-12)
        if pri.any():
            rel = np.einsum("bji,bjk->bik", Rp, R)
            np.testing.assert_allclose(rel[pri], mm.R_rel0[pri], atol=1e-12)
            np.testing.assert_allclose(np.einsum("bki,bi->bk", perp_world, gap)[pri], 0, atol=1e-12)


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_coordinates_round_trip(name: str) -> None:
    mm = _mm(name)
    for q, v in _samples(mm, seed=3):
        R, p = body_poses(mm, q)
        omega, v_com = body_velocities(mm, q, v)
        np.testing.assert_allclose(joint_positions(mm, R, p), q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(joint_velocities(mm, R, omega, p, v_com), v, rtol=0, atol=1e-12)


def test_kinova_angles_beyond_pi_are_recovered_from_the_limit_window() -> None:
    mm = _mm("kinova")
    assert mm.lower_position_limit[2] > 0 and mm.upper_position_limit[2] > np.pi
    q = mm.model.referenceConfigurations["arm_up"].copy()
    q[mm.idx_q[2]] = 5.0
    np.testing.assert_allclose(joint_positions(mm, body_poses(mm, q)[0]), q, atol=1e-12)


@pytest.mark.parametrize("name", ROBOTS)
def test_body_poses_of_a_batch_are_those_of_each_configuration(name: str) -> None:
    mm = _mm(name)
    q = np.array([qk for qk, _ in _samples(mm, seed=5)])
    R, p = body_poses(mm, q)
    assert R.shape == (len(q), mm.nb, 3, 3) and p.shape == (len(q), mm.nb, 3)
    for k, qk in enumerate(q):
        Rk, pk = body_poses(mm, qk)
        np.testing.assert_array_equal(R[k], Rk)
        np.testing.assert_allclose(p[k], pk, rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_positions_of_a_path_follow_each_knot_from_the_last(name: str) -> None:
    """A path of poses gives each knot's ``joint_positions`` with ``q_ref`` the knot before
    (the first's ``q_ref`` given): a joint path winding twice around recovered unwrapped."""
    mm = _mm(name)
    q0 = _samples(mm, seed=6)[0][0]
    angle = mm.revolute & ~mm.continuous
    winding = np.zeros(mm.nq)
    winding[mm.idx_q[angle]] = 4 * np.pi
    if not mm.revolute.all():  # prismatic displacements move a little
        winding[mm.idx_q[~mm.revolute]] = 0.01
    q = q0 + np.linspace(0.0, 1.0, 33)[:, None] * winding
    if mm.continuous.any():  # (cos, sin) pairs of the sampled angles, unchanged
        q[:, mm.idx_q[mm.continuous]] = q0[mm.idx_q[mm.continuous]]
        q[:, mm.idx_q[mm.continuous] + 1] = q0[mm.idx_q[mm.continuous] + 1]
    R, p = body_poses(mm, q)
    path = joint_positions(mm, R, p, q_ref=q[0])
    assert path.shape == q.shape
    np.testing.assert_allclose(path, q, rtol=0, atol=1e-9)
    q_ref = q[0]
    for k in range(len(q)):
        q_ref = joint_positions(mm, R[k], p[k], q_ref=q_ref)
        np.testing.assert_array_equal(path[k], q_ref)


def test_q_ref_selects_the_2pi_branch() -> None:
    mm = _mm("ur5")  # joint limits +-2 pi
    q = np.array([5.5, -4.0, 1.0, -6.0, 3.5, 0.2])
    R, _ = body_poses(mm, q)
    wrapped = joint_positions(mm, R)
    np.testing.assert_allclose(wrapped, np.angle(np.exp(1j * q)), atol=1e-12)
    assert np.all(np.abs(wrapped) <= np.pi)
    np.testing.assert_allclose(joint_positions(mm, R, q_ref=q + 0.5), q, atol=1e-12)


def test_prismatic_joints_need_positions_and_velocities() -> None:
    mm = _mm("panda")
    q, v = _samples(mm, seed=4)[0]
    R, p = body_poses(mm, q)
    omega, _ = body_velocities(mm, q, v)
    with pytest.raises(InputError, match="p is required"):
        joint_positions(mm, R)
    with pytest.raises(InputError, match="v_com is required"):
        joint_velocities(mm, R, omega, p)


def test_state_maps_validate_inputs() -> None:
    mm = _mm("iiwa")
    with pytest.raises(InputError, match=r"q must have shape \(7,\)"):
        body_poses(mm, np.zeros(6))
    with pytest.raises(InputError, match=r"q must have shape \(3, 7\)"):
        body_poses(mm, np.zeros((3, 6)))
    with pytest.raises(InputError, match="non-finite"):
        body_velocities(mm, np.zeros(7), np.full(7, np.nan))
    with pytest.raises(InputError, match=r"R must have shape \(7, 3, 3\)"):
        joint_positions(mm, np.zeros((6, 3, 3)))
    with pytest.raises(InputError, match=r"R must have shape \(4, 7, 3, 3\)"):
        joint_positions(mm, np.zeros((4, 6, 3, 3)))
    with pytest.raises(InputError, match="R has non-finite entries"):
        joint_positions(mm, np.full((4, 7, 3, 3), np.nan))
    panda = _mm("panda")
    R, _ = body_poses(panda, np.tile(panda.model.referenceConfigurations["default"], (3, 1)))
    with pytest.raises(InputError, match=r"p is required"):
        joint_positions(panda, R)


# ---------------------------------------------------------------------------- unsupported


def _single_joint_model(joint: pin.JointModel, inertia: pin.Inertia | None = None) -> pin.Model:
    model = pin.Model()
    model.name = "weird"
    j = model.addJoint(0, joint, pin.SE3.Identity(), "odd_joint")
    inertia = (
        pin.Inertia(1.0, np.zeros(3), np.diag([0.1, 0.2, 0.3])) if inertia is None else inertia
    )
    model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
    return model


@pytest.mark.parametrize(
    "joint",
    [
        pin.JointModelSpherical(),
        pin.JointModelPlanar(),
        pin.JointModelTranslation(),
        pin.JointModelHZ(0.1),
        pin.JointModelUniversal(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),
        pin.JointModelComposite(pin.JointModelRX()),
    ],
    ids=lambda j: j.shortname(),
)
def test_unsupported_joint_types_are_rejected(joint: pin.JointModel) -> None:
    with pytest.raises(RobotModelError, match=f"joint 'odd_joint' is a {joint.shortname()}"):
        maximal_model(_single_joint_model(joint))


def test_mimic_joint_is_rejected(tmp_path: Path) -> None:
    inertial = (
        '<inertial><mass value="1"/>'
        '<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>'
    )
    joints = "".join(
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
        f'<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>{mimic}</joint>'
        for name, parent, child, mimic in [
            ("j1", "base", "a", ""),
            ("j2", "a", "b", '<mimic joint="j1" multiplier="1"/>'),
        ]
    )
    path = tmp_path / "mimic.urdf"
    path.write_text(
        f'<robot name="m"><link name="base"/><link name="a">{inertial}</link>'
        f'<link name="b">{inertial}</link>{joints}</robot>'
    )
    assert maximal_model(path).nb == 2  # load() ignores <mimic>: two independent joints
    with pytest.raises(RobotModelError, match="joint 'j2' is a JointModelMimic"):
        maximal_model(pin.buildModelFromUrdf(str(path), mimic=True))


def test_body_without_mass_or_with_singular_inertia_is_rejected() -> None:
    massless = _single_joint_model(pin.JointModelRZ(), pin.Inertia.Zero())
    with pytest.raises(RobotModelError, match=r"body 'odd_joint' .*joint 'odd_joint'.* mass 0"):
        maximal_model(massless)
    rod = _single_joint_model(pin.JointModelRZ(), pin.Inertia(1.0, np.zeros(3), np.diag([0, 1, 1])))
    with pytest.raises(RobotModelError, match="positive-definite inertia"):
        maximal_model(rod)


def test_model_without_moving_joint_is_rejected() -> None:
    with pytest.raises(RobotModelError, match="no moving joint"):
        maximal_model(pin.Model())


def test_maximal_model_accepts_descriptions_and_models() -> None:
    robot = load("double_pendulum", geometry=False)
    for spec in (robot, robot.model):
        mm = maximal_model(spec)
        assert mm.model is robot.model
        assert mm.nb == 2
