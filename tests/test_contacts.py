"""Contacts: a frame held at a ground point with its force a decision variable, in both
formulations; exact derivatives, plans verified by the replay with the contact forces, the
touchdown impulse, and inputs refused by name."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from fd import check_generalized_derivatives, check_problem_derivatives
from test_viz import page_commands

import mbplan as mb
from mbplan.dynamics.friction import pyramid, pyramid_edges
from mbplan.errors import InputError
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.maximal import MaximalNLP
from mbplan.ocp.contacts import frame_position
from mbplan.residuals import FrameTranslation, JointTorque
from mbplan.robots.configuration import integrate

FEET = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")


@cache
def _robot() -> mb.Robot:
    return mb.load_robot("solo12")


def _standing() -> np.ndarray:
    return _robot().configuration("standing")


def _base(q: np.ndarray) -> np.ndarray:
    model = _robot().model
    return frame_position(model, model.getFrameId("base_link"), q)


def _lift_ocp(N: int = 20, dt: float = 0.02) -> mb.OCP:
    """Standing on four feet, the base raised 4 cm and moved 2 cm forward at the last knot."""
    q0 = _standing()
    ocp = mb.OCP(_robot(), N=N, dt=dt, q0=q0)
    for foot in FEET:
        ocp.add_contact(foot, foot, range(N + 1))
    ocp.add_cost("effort", JointTorque(), 1e-3)
    goal = FrameTranslation("base_link", _base(q0) + np.array([0.02, 0.0, 0.04]))
    return ocp.add_cost("lift", goal, 10.0, knots="terminal")


def _drop_ocp(N: int = 16, dt: float = 0.01, land: int = 6) -> mb.OCP:
    """Released 1 cm above the ground, falling: the feet land at knot ``land`` and stay."""
    q0 = _standing()
    ground = [frame_position(_robot().model, _robot().frame_id(f), q0) for f in FEET]
    q0 = q0.copy()
    q0[2] += 0.01
    ocp = mb.OCP(_robot(), N=N, dt=dt, q0=q0)
    for foot, p in zip(FEET, ground, strict=True):
        ocp.add_contact(foot, foot, range(land, N + 1), position=p)
    ocp.add_cost("effort", JointTorque(), 1e-3)
    return ocp


def _weight(robot: mb.Robot) -> float:
    return sum(inertia.mass for inertia in robot.model.inertias) * 9.81


# --------------------------------------------------------------------------- derivatives


def test_the_maximal_contact_terms_have_exact_riemannian_derivatives() -> None:
    """Forces in the dynamics rows, the held point and the friction pyramid: the whole
    problem's gradient, Jacobians and Lagrangian Hessian along the retraction."""
    ocp = _drop_ocp(N=4, dt=0.02, land=2)
    nlp = MaximalNLP(ocp, jit=False)
    path = np.array([integrate(_robot().model, ocp.q0, np.zeros(18)) for _ in range(5)])
    point = nlp.initial_point(path)
    rng = np.random.default_rng(1)
    point = nlp.problem.retract(point, 0.05 * rng.standard_normal(nlp.problem.n))
    check_problem_derivatives(nlp.problem, point, rng)


@pytest.mark.parametrize("task", ["stance", "landing"])
def test_the_generalized_contact_rows_have_exact_derivatives(task: str) -> None:
    """``-J(q)ᵀf`` in the dynamics rows (at the fixed ``q0`` too), the held positions, the rest
    at the end and the pyramid against central differences, off the quaternions' unit sphere
    too."""
    ocp = _lift_ocp(N=4) if task == "stance" else _drop_ocp(N=4, dt=0.02, land=2)
    nlp = GeneralizedNLP(ocp)
    rng = np.random.default_rng(3)
    path = np.array(
        [integrate(_robot().model, ocp.q0, 0.1 * rng.standard_normal(18)) for _ in range(5)]
    )
    z = nlp.initial_guess(path) + 0.05 * rng.standard_normal(nlp.n)
    check_generalized_derivatives(nlp, z, rng.standard_normal(nlp.m))


def test_the_generalized_contact_jacobian_is_pinocchio_s() -> None:
    from mbplan.formulations.generalized_contacts import frame_functions

    robot, rng = _robot(), np.random.default_rng(0)
    q = integrate(robot.model, _standing(), 0.3 * rng.standard_normal(18))
    p_of, R_of, J_of = frame_functions(robot, "HR_FOOT")
    data = robot.model.createData()
    fid = robot.frame_id("HR_FOOT")
    J = pin.computeFrameJacobian(robot.model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(np.asarray(J_of(q)), J, atol=1e-12)
    np.testing.assert_allclose(np.asarray(p_of(q)).ravel(), data.oMf[fid].translation, atol=1e-12)
    np.testing.assert_allclose(np.asarray(R_of(q)), data.oMf[fid].rotation, atol=1e-12)


def test_the_pyramid_is_inscribed_in_the_cone_and_touches_it_on_its_diagonals() -> None:
    mu, A = 0.5, pyramid(0.5)
    f = np.random.default_rng(0).uniform(-1.0, 1.0, (2000, 3)) + np.array([0.0, 0.0, 1.0])
    inside = np.all(f @ A.T <= 0.0, axis=1)
    assert inside.sum() > 100
    assert np.all(np.linalg.norm(f[inside, :2], axis=1) <= mu * f[inside, 2] + 1e-12)
    for edge in pyramid_edges(mu):  # on two facets each, on the cone
        assert np.isclose(np.max(A @ edge), 0.0) and np.sum(np.isclose(A @ edge, 0.0)) == 2
        assert np.isclose(np.linalg.norm(edge[:2]), mu * edge[2])


# --------------------------------------------------------------------------- plans


@cache
def _lift_plans() -> dict[str, mb.PlanResult]:
    return {m: mb.plan(_lift_ocp(), m, warm_start="linear") for m in ("ripm", "ipopt")}


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_a_standing_robot_raises_its_base_on_its_feet(method: str) -> None:
    result = _lift_plans()[method]
    assert result.success, result.message
    assert result.contact_forces.shape == (20, 4, 3)
    assert result.contact_frames == FEET
    # the feet carry the robot: their vertical impulse is gravity's plus the momentum gained
    model = _robot().model
    mass = sum(inertia.mass for inertia in model.inertias)
    data = model.createData()
    pin.centerOfMass(model, data, result.q[-1], result.v[-1])
    impulse = result.contact_forces[:, :, 2].sum() * result.dt
    expected = _weight(_robot()) * 20 * result.dt + mass * data.vcom[0][2]
    assert abs(impulse - expected) < 0.05 * _weight(_robot()) * 20 * result.dt, (impulse, expected)
    assert np.all(result.tau[:, :6] == 0.0)
    base = _base(result.q[-1]) - _base(result.q[0])
    np.testing.assert_allclose(base, [0.02, 0.0, 0.04], atol=5e-3)


def test_the_replay_with_the_lgvi_s_contact_forces_verifies_the_plan() -> None:
    result = _lift_plans()["ripm"]
    check = mb.verify(result)
    assert check.passed, check.reasons
    assert check.violations["FL_FOOT.position"] < 1e-7  # at the planned knots
    # along the replay: between the LGVI's impulses at the knots the robot sags by g Δt²/8
    assert check.violations["FL_FOOT.slip"] < 1.2 * 9.81 * result.dt**2 / 8
    assert check.violations["FL_FOOT.cone"] < 1e-6


def test_the_replay_measures_the_slip_against_the_discretisation_error() -> None:
    """Eq. (61) is first order: at Δt = 20 ms its forces, replayed, move the feet by about
    1.5 mm within an interval, within its explicit-Euler error (the LGVI's replay sags by
    g Δt²/8 between its impulses, 0.5 mm); forces 20 % short let the feet sink by centimetres:
    the slip is reported and the velocity deviation fails the plan (the Euler step, with the
    same forces, sinks alike)."""
    import dataclasses

    ripm, ipopt = (_lift_plans()[m] for m in ("ripm", "ipopt"))
    lgvi, euler = mb.verify(ripm), mb.verify(ipopt)
    assert euler.violations["HL_FOOT.slip"] > 2 * lgvi.violations["HL_FOOT.slip"]
    assert euler.violations["HL_FOOT.slip"] > 1e-3 and euler.violations["HL_FOOT.slip_ratio"] < 1
    assert euler.passed, euler.reasons
    short = dataclasses.replace(ipopt, contact_forces=0.8 * ipopt.contact_forces)
    check = mb.verify(short)
    assert check.violations["HL_FOOT.slip"] > 5e-3
    assert not check.passed
    assert any(r.startswith("velocity deviation") for r in check.reasons)


def test_forces_outside_the_cone_fail_the_verification() -> None:
    import dataclasses

    result = _lift_plans()["ripm"]
    knots = result.contact_forces_knots.copy()
    knots[:, 0, 0] += 50.0  # a sideways push far beyond mu f_z
    broken = dataclasses.replace(
        result, contact_forces_knots=knots, contact_forces=0.5 * (knots[:-1] + knots[1:])
    )
    check = mb.verify(broken)
    assert not check.passed
    assert any("friction cone" in r for r in check.reasons)


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_touchdown_stops_the_landing_feet(method: str) -> None:
    """Falling onto the ground at knot 6: no force in the air, the force of knot (interval) 5
    stops the landing feet (plastic impact), which are still from knot 6 on."""
    ocp = _drop_ocp()
    result = mb.plan(ocp, method, warm_start="linear")
    assert result.success, result.message
    model, data = _robot().model, _robot().model.createData()
    speeds = []
    for k in range(ocp.N + 1):
        pin.forwardKinematics(model, data, result.q[k], result.v[k])
        pin.updateFramePlacements(model, data)
        v = pin.getFrameVelocity(model, data, _robot().frame_id("FL_FOOT"), pin.LOCAL_WORLD_ALIGNED)
        speeds.append(np.linalg.norm(v.linear))
    speeds = np.array(speeds)
    assert speeds[4] > 0.2  # falling: ~g t
    assert np.all(speeds[7:] < 0.15 * speeds[4]), speeds  # still (to O(Δt) in eq. 61's tangent)
    assert np.all(result.contact_forces[:4] == 0.0)  # in the air
    assert np.all(result.contact_forces[5, :, 2] > 0.0)  # the landing impulse pushes up


# --------------------------------------------------------------------------- inputs


def test_a_plan_with_contacts_round_trips_through_npz(tmp_path) -> None:
    result = _lift_plans()["ripm"]
    loaded = mb.load_npz(result.save(tmp_path / "lift.npz"))
    np.testing.assert_array_equal(loaded.contact_forces, result.contact_forces)
    assert loaded.contact_frames == FEET
    assert loaded.ocp.contact_names == list(FEET)
    np.testing.assert_array_equal(loaded.ocp.contacts[0].position, result.ocp.contacts[0].position)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"frame": "no_such_foot"}, "no frame 'no_such_foot'"),
        ({"knots": []}, "a phase with no knots"),
        ({"knots": [2, 3, 5]}, "contiguous"),
        ({"knots": [0, 1]}, "end before knot 2"),
        ({"knots": range(3, 30)}, "outside 0..10"),
        ({"friction": 0.0}, "friction"),
        ({"position": [0.0, 0.0, -0.1]}, "0.284 m from its contact position .* at knot 0"),
    ],
)
def test_bad_contacts_are_refused_by_name(kwargs: dict, message: str) -> None:
    ocp = mb.OCP(_robot(), N=10, dt=0.02, q0=_standing())
    args = {"name": "stance", "frame": "FL_FOOT", "knots": range(11)} | kwargs
    with pytest.raises(InputError, match=message):
        ocp.add_contact(**args)


def test_a_frame_held_twice_at_once_is_refused() -> None:
    ocp = mb.OCP(_robot(), N=10, dt=0.02, q0=_standing())
    ocp.add_contact("first", "FL_FOOT", range(6))
    with pytest.raises(InputError, match="already held by contact 'first' at knots \\[4, 5\\]"):
        ocp.add_contact("second", "FL_FOOT", range(4, 11))
    with pytest.raises(InputError, match="already has a cost, constraint or contact"):
        ocp.add_contact("first", "FR_FOOT", range(6))


@pytest.mark.parametrize("method", ["fddp", "csqp"])
def test_shooting_methods_refuse_contacts_before_any_solve(method: str) -> None:
    pytest.importorskip("crocoddyl")
    arm = mb.OCP("iiwa", N=10, dt=0.05)
    arm.add_contact("tool", "iiwa_link_ee", range(11))
    with pytest.raises(InputError, match="does not plan contacts"):
        mb.plan(arm, method)


def test_the_replay_draws_the_ground_and_the_contact_forces(tmp_path) -> None:
    """One slab under the feet and one arrow per contact (a cylinder scaled to the force at
    every knot) for each plan; the longest arrow is the largest force's."""
    from mbplan.viz import replay
    from mbplan.viz.contacts import ARROW_LENGTH, force_layer

    plans = [_lift_plans()[m] for m in ("ripm", "ipopt")]
    page = replay(plans, html=tmp_path / "lift.html", open_browser=False)
    paths = {str(c.get("path", "")) for c in page_commands(Path(page))}
    for i in (0, 1):
        assert any(f"mbplan/ground{i}/visuals/ground" in p for p in paths)
        assert any(f"mbplan/forces{i}/visuals/force_FL_FOOT" in p for p in paths)
    arrows = force_layer("forces", plans[0].ocp, plans[0])
    assert arrows.scales.shape == (21, 4, 3)
    assert np.isclose(arrows.scales[..., 2].max(), ARROW_LENGTH)
    knots = plans[0].contact_forces_knots
    k, i = np.unravel_index(np.argmax(np.linalg.norm(knots, axis=-1)), knots.shape[:2])
    direction = arrows.placements[k, i, :3, 2]
    np.testing.assert_allclose(direction, knots[k, i] / np.linalg.norm(knots[k, i]), atol=1e-12)
