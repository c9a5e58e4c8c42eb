"""Sole contacts: a flat rectangular foot held in place and orientation, its wrench a decision
variable inside the contact wrench cone, in both formulations; the cone's closed form, exact
derivatives, plans verified by the replay, the touchdown, and inputs refused by name."""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pinocchio as pin
import pytest
from fd import check_generalized_derivatives, check_problem_derivatives
from scipy.optimize import linprog

import mbplan as mb
from mbplan.dynamics.friction import wrench_cone, wrench_cone_edges, wrench_cone_violation
from mbplan.errors import InputError
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.maximal import MaximalNLP
from mbplan.ocp.contacts import frame_position
from mbplan.residuals import ComPosition, JointPosition, JointTorque, JointVelocity
from mbplan.robots.configuration import integrate

SOLES = ("left_sole_link", "right_sole_link")
SIZE = (0.2, 0.1)  # about talos' sole (Crocoddyl's biped example bounds a 0.1 m x 0.05 m one)


@cache
def _robot() -> mb.Robot:
    return mb.load_robot("talos_legs")


def _start() -> np.ndarray:
    return _robot().configuration("half_sitting")


def _regularised(ocp: mb.OCP, torque: bool) -> mb.OCP:
    """Near the start's posture, slow, with small torques (``torque``: a torque cost)."""
    robot, q0 = ocp.robot, ocp.q0
    joints = robot.q_of_v[robot.joint_indices(None)]
    ocp.add_cost("posture", JointPosition(q0[joints]), 1.0)
    ocp.add_cost("velocity", JointVelocity(), 1e-2)
    return ocp.add_cost("torque", JointTorque(), 1e-5) if torque else ocp


def _sway_ocp(N: int = 20, dt: float = 0.03, torque: bool = True) -> mb.OCP:
    """Both soles on the ground, the centre of mass moved 5 cm to the left over
    the last five intervals."""
    q0 = _start()
    ocp = mb.OCP(_robot(), N=N, dt=dt, q0=q0)
    for sole in SOLES:
        ocp.add_contact(sole, sole, range(N + 1), sole=SIZE)
    com = pin.centerOfMass(_robot().model, _robot().model.createData(), q0)
    ocp.add_cost(
        "com", ComPosition(com + np.array([0.0, 0.05, 0.0])), 1e4, range(max(N - 5, 1), N + 1)
    )
    return _regularised(ocp, torque)


def _drop_ocp(N: int = 12, dt: float = 0.02, land: int = 5, torque: bool = True) -> mb.OCP:
    """Released 1 cm above the ground: both soles land flat at knot ``land`` and stay."""
    q0 = _start()
    ground = [frame_position(_robot().model, _robot().frame_id(s), q0) for s in SOLES]
    q0 = q0.copy()
    q0[2] += 0.01
    ocp = mb.OCP(_robot(), N=N, dt=dt, q0=q0)
    for sole, p in zip(SOLES, ground, strict=True):
        ocp.add_contact(sole, sole, range(land, N + 1), position=p, sole=SIZE)
    return _regularised(ocp, torque)


# --------------------------------------------------------------------------- the cone


def test_the_wrench_cone_is_the_wrenches_of_the_corners_pyramids() -> None:
    """Caron et al.'s closed form equals the cone of the corners' pyramid edges: every
    combination of the edges is inside it, and a wrench inside it is a combination (LP)."""
    A, G = wrench_cone(0.7, *SIZE), wrench_cone_edges(0.7, *SIZE)
    rng = np.random.default_rng(0)
    assert np.max(rng.random((500, 16)) @ G @ A.T) <= 1e-12
    inside = 0
    for _ in range(300):
        w = rng.random(16) @ G + 0.3 * rng.standard_normal(6)
        decomposable = linprog(np.zeros(16), A_eq=G.T, b_eq=w, bounds=(0, None)).status == 0
        assert decomposable == bool(np.all(A @ w <= 1e-9))
        inside += decomposable
    assert 50 < inside < 250  # both sides sampled


def test_the_wrench_cone_is_crocoddyl_s() -> None:
    """Row for row Crocoddyl's ``WrenchCone`` (its inscribed pyramid, box = (length, width)),
    whose one more row, ``f_z ≥ 0``, the pyramid implies."""
    crocoddyl = pytest.importorskip("crocoddyl")
    theirs = crocoddyl.WrenchCone(np.eye(3), 0.7, np.array([0.1, 0.05]), 4, True).A
    ours = wrench_cone(0.7, 0.1, 0.05)
    assert len(theirs) == len(ours) + 1
    for row in ours:
        assert np.min(np.abs(theirs - row).max(axis=1)) < 1e-12, row


def test_the_centre_of_pressure_stays_in_the_sole() -> None:
    """A vertical force at a point of the sole plane: inside the rectangle it is in the cone,
    1 cm outside it leaves it by its lever arm times the force."""
    length, width = SIZE
    for x, y, inside in [(0.09, 0.04, True), (-0.09, -0.04, True), (0.11, 0.0, False)]:
        f = np.array([0.0, 0.0, 100.0])
        w = np.concatenate([f, np.cross([x, y, 0.0], f)])
        violation = wrench_cone_violation(w, 0.7, length, width)
        assert (violation == 0.0) == inside
    w = np.concatenate([[0.0, 0.0, 100.0], np.cross([0.11, 0.0, 0.0], [0.0, 0.0, 100.0])])
    assert wrench_cone_violation(w, 0.7, length, width) == pytest.approx(1.0, rel=1e-9)


# --------------------------------------------------------------------------- derivatives


def test_the_maximal_sole_terms_have_exact_riemannian_derivatives() -> None:
    """The wrench in the dynamics rows, the weld to the world and the wrench cone: the whole
    problem's gradient, Jacobians and Lagrangian Hessian along the retraction."""
    ocp = _drop_ocp(N=4, land=2)
    nlp = MaximalNLP(ocp, jit=False)
    point = nlp.initial_point(np.tile(ocp.q0, (5, 1)))
    rng = np.random.default_rng(1)
    point = nlp.problem.retract(point, 0.05 * rng.standard_normal(nlp.problem.n))
    check_problem_derivatives(nlp.problem, point, rng)


@pytest.mark.parametrize("task", ["stance", "landing"])
def test_the_generalized_sole_rows_have_exact_derivatives(task: str) -> None:
    """``-J(q)ᵀ(R_c f, R_c τ)`` in the dynamics rows, the held placements, the rest at the end
    and the wrench cone against central differences (no torque cost: the torques of a random
    path make an objective whose central differences lose digits)."""
    ocp = _sway_ocp(N=4, torque=False) if task == "stance" else _drop_ocp(4, land=2, torque=False)
    nlp = GeneralizedNLP(ocp)
    rng = np.random.default_rng(3)
    model = _robot().model
    path = np.array([integrate(model, ocp.q0, 0.1 * rng.standard_normal(18)) for _ in range(5)])
    z = nlp.initial_guess(path) + 0.05 * rng.standard_normal(nlp.n)
    check_generalized_derivatives(nlp, z, rng.standard_normal(nlp.m))


# --------------------------------------------------------------------------- plans


@cache
def _sway_plans() -> dict[str, mb.PlanResult]:
    return {m: mb.plan(_sway_ocp(), m, warm_start="linear") for m in ("ripm", "ipopt")}


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_a_biped_shifts_its_weight_on_its_soles(method: str) -> None:
    """Both methods plan and verify; the soles carry the robot (their vertical impulse is
    gravity's plus the momentum gained), more of it on the left sole once the centre of mass is over it, the wrenches
    inside their cones."""
    result = _sway_plans()[method]
    assert result.success, result.message
    check = mb.verify(result)
    assert check.passed, check.reasons
    assert result.contact_forces.shape == (20, 2, 6)
    model = _robot().model
    mass = sum(i.mass for i in model.inertias)
    data = model.createData()
    pin.centerOfMass(model, data, result.q[-1], result.v[-1])
    impulse = result.contact_forces[:, :, 2].sum() * result.dt
    gravity = mass * 9.81 * 20 * result.dt
    assert abs(impulse - gravity - mass * data.vcom[0][2]) < 0.05 * gravity
    left, right = result.contact_forces[12:18, :, 2].mean(axis=0)  # over the left foot
    assert left > 1.5 * right
    assert check.violations["left_sole_link.orientation"] < 1e-6
    assert check.violations["left_sole_link.cone"] < 1e-6


def test_the_formulations_agree_on_the_soles_wrenches() -> None:
    """The same task in maximal and generalized coordinates: the mean wrenches over the plan
    agree to 3 % of the weight (forces) and 5 % of the weight × half a sole's width (torques)."""
    ripm, ipopt = (_sway_plans()[m].contact_forces.mean(axis=0) for m in ("ripm", "ipopt"))
    weight = sum(i.mass for i in _robot().model.inertias) * 9.81
    np.testing.assert_allclose(ripm[:, :3], ipopt[:, :3], atol=0.03 * weight)
    np.testing.assert_allclose(ripm[:, 3:], ipopt[:, 3:], atol=0.05 * weight * 0.05)


def test_a_centre_of_pressure_off_the_sole_fails_the_verification() -> None:
    result = _sway_plans()["ipopt"]
    forces = result.contact_forces.copy()
    forces[:, 0, 4] -= 0.2 * forces[:, 0, 2]  # the pressure 0.2 m ahead: off the sole
    check = mb.verify(dataclasses.replace(result, contact_forces=forces))
    assert not check.passed
    assert any("contact wrench cone" in r for r in check.reasons)


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_soles_land_flat_and_stay(method: str) -> None:
    """Falling 1 cm: no wrench in the air, the soles land at knot 5 and stay still and flat."""
    ocp = _drop_ocp()
    result = mb.plan(ocp, method, warm_start="linear")
    assert result.success, result.message
    assert mb.verify(result).passed
    model, data = _robot().model, _robot().model.createData()
    fid = _robot().frame_id(SOLES[0])
    speeds = []
    for k in range(ocp.N + 1):
        pin.forwardKinematics(model, data, result.q[k], result.v[k])
        pin.updateFramePlacements(model, data)
        v = pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        speeds.append(np.linalg.norm(v.vector))
    speeds = np.array(speeds)
    assert speeds[3] > 0.2  # falling
    assert np.all(speeds[6:] < 0.15 * speeds[3]), speeds
    assert np.all(result.contact_forces[:3] == 0.0)
    assert np.all(result.contact_forces[4, :, 2] > 0.0)


# --------------------------------------------------------------------------- inputs


def test_a_plan_with_soles_round_trips_through_npz(tmp_path) -> None:
    result = _sway_plans()["ripm"]
    loaded = mb.load_npz(result.save(tmp_path / "sway.npz"))
    np.testing.assert_array_equal(loaded.contact_forces, result.contact_forces)
    assert loaded.ocp.contacts[0].sole == SIZE
    np.testing.assert_array_equal(loaded.ocp.contacts[0].rotation, result.ocp.contacts[0].rotation)


@pytest.mark.parametrize(
    ("sole", "message"),
    [((0.2, 0.0), "must be positive"), ((0.2,), "sole"), ((0.2, -0.1), "must be positive")],
)
def test_bad_soles_are_refused_by_name(sole, message: str) -> None:
    ocp = mb.OCP(_robot(), N=10, dt=0.03, q0=_start())
    with pytest.raises(InputError, match=rf"contact 'left'.*{message}"):
        ocp.add_contact("left", SOLES[0], range(11), sole=sole)


def test_a_sole_turned_at_the_start_is_refused() -> None:
    """Held from knot 0 where the start's velocity turns it by knot 1 about its own vertical
    (the base's twist's screw axis through the sole's origin: it does not move)."""
    q0 = _start()
    sole = frame_position(_robot().model, _robot().frame_id(SOLES[0]), q0)
    omega = np.array([0.0, 0.0, 0.5])
    v0 = np.zeros(18)
    v0[:3], v0[3:6] = -np.cross(omega, sole - q0[:3]), omega  # the base's orientation is I
    ocp = mb.OCP(_robot(), N=10, dt=0.03, q0=q0, v0=v0)
    with pytest.raises(InputError, match=r"contact 'left'.*turns sole frame .* 0.015 rad"):
        ocp.add_contact("left", SOLES[0], range(11), sole=SIZE)
