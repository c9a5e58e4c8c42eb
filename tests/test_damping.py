"""URDF viscous joint damping (generalized force ``-D q̇``): the ``load_robot`` flag, the damped
generalized dynamics (derivatives against finite differences), the Crocoddyl actuation and the
verifier's replay."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from fd import central, check_generalized_derivatives

import mbplan as mb
from mbplan import residuals as res
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.robots import load_robot
from mbplan.robots.robot import robot_from_source
from mbplan.simulation.reference import (
    damped_aba,
    damped_euler_velocity,
    integrate_aba,
    mass_matrix,
)
from mbplan.tasks.paper import IIWA_START, tracking_ocp
from mbplan.verification import verify
from mbplan.verification.multibody import SUBSTEPS, substeps

DAMPING = np.linspace(0.5, 3.5, 7)  # N m s/rad, distinct per joint (the iiwa URDF's is 0.5)


def damped_iiwa(damping: np.ndarray = DAMPING) -> mb.Robot:
    base = load_robot("iiwa")
    model = pin.Model(base.model)
    model.damping[:] = damping
    return load_robot(model, collision_model=base.collision_model)


def test_load_robot_reads_and_zeroes_damping() -> None:
    damped, plain = load_robot("iiwa"), load_robot("iiwa", damping=False)
    np.testing.assert_array_equal(damped.model.damping, np.full(7, 0.5))  # the URDF's value
    assert not np.any(plain.model.damping)
    assert plain.source["damping"] is False and damped.source["damping"] is True
    old = {k: v for k, v in damped.source.items() if k != "damping"}  # saved before damping
    assert not np.any(robot_from_source(old).model.damping)
    assert not np.any(robot_from_source(plain.source).model.damping)
    np.testing.assert_array_equal(robot_from_source(damped.source).model.damping, 0.5)
    model = damped_iiwa().model
    undamped = load_robot(model, damping=False)
    assert not np.any(undamped.model.damping)
    np.testing.assert_array_equal(model.damping, DAMPING)  # the caller's model is untouched
    saved = mb.OCP(plain, N=3).to_dict()
    assert not np.any(mb.OCP.from_dict(saved).robot.model.damping)


def test_damped_generalized_dynamics_derivatives_match_finite_differences() -> None:
    ocp = mb.OCP(damped_iiwa(), N=3, dt=0.05, q0=IIWA_START)
    ocp.add_cost("q", res.JointPosition(np.zeros(7)), 1.0)
    ocp.add_constraint("v_limits", res.JointVelocityLimits())
    nlp = GeneralizedNLP(ocp)
    rng = np.random.default_rng(0)
    z = nlp.initial_guess(np.linspace(ocp.q0, np.zeros(7), ocp.N + 1))
    z = z + 0.05 * rng.standard_normal(nlp.n)
    # the dynamics rows of knots 1..N-1 vanish at the initial guess (knot 0 has the OCP's v0)
    guess = nlp.constraints(nlp.initial_guess(np.linspace(ocp.q0, np.zeros(7), ocp.N + 1)))
    np.testing.assert_allclose(guess[(ocp.N + 1) * 7 : 2 * ocp.N * 7], 0.0, atol=1e-9)
    q, v, tau = nlp.unpack(z)
    data = ocp.robot.model.createData()
    v2 = damped_euler_velocity(ocp.robot.model, data, q[1], v[1], tau[1], ocp.dt)
    M = mass_matrix(ocp.robot.model, data, q[1])  # M (v₂ - v₁)/Δt = τ₁ - h - D v₂
    h = pin.rnea(ocp.robot.model, data, q[1], v[1], np.zeros(7))
    np.testing.assert_allclose(M @ (v2 - v[1]) / ocp.dt, tau[1] - h - DAMPING * v2, atol=1e-8)
    dyn = nlp.constraints(nlp.pack(q, np.vstack([v[:2], v2, v[3:]]), tau))
    np.testing.assert_allclose(dyn[(ocp.N + 1) * 7 : (ocp.N + 2) * 7], 0.0, atol=1e-9)
    check_generalized_derivatives(nlp, z, rng.standard_normal(nlp.m))


def test_crocoddyl_damped_actuation_matches_damped_aba() -> None:
    crocoddyl = pytest.importorskip("crocoddyl")
    from mbplan.formulations.crocoddyl import ShootingBuilder

    proximal = DAMPING * [1, 1, 1, 1, 0.01, 0.01, 0.01]  # λ(M⁻¹D) Δt < 1 at Δt = 0.02
    ocp = mb.OCP(damped_iiwa(proximal), N=2, dt=0.02, q0=IIWA_START)
    ocp.add_cost("tau", res.JointTorque(), 1e-3)
    builder = ShootingBuilder(ocp, hard=False, method="fddp")
    dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(
        builder.state, builder.actuation, crocoddyl.CostModelSum(builder.state, 7)
    )
    data = dam.createData()
    rng = np.random.default_rng(2)
    x = np.concatenate([np.asarray(IIWA_START), rng.standard_normal(7)])
    u = 10 * rng.standard_normal(7)
    dam.calc(data, x, u)
    model = ocp.robot.model
    expected = damped_aba(model, model.createData(), x[:7], x[7:], u)
    np.testing.assert_allclose(data.xout, expected, rtol=1e-10, atol=1e-10)
    assert np.abs(expected - pin.aba(model, model.createData(), x[:7], x[7:], u)).max() > 1.0
    dam.calcDiff(data, x, u)
    stiff = mb.OCP(damped_iiwa(), N=2, dt=0.075, q0=IIWA_START)
    with pytest.raises(mb.InputError, match="too stiff for Crocoddyl"):
        ShootingBuilder(stiff, hard=False, method="fddp")

    def xout(xx: np.ndarray) -> np.ndarray:
        dam.calc(data, xx, u)
        return data.xout.copy()

    Fx = data.Fx.copy()
    np.testing.assert_allclose(Fx, central(xout, x, 1e-6), atol=1e-5 * np.abs(Fx).max())


def test_damped_replay_integrates_the_damped_dynamics() -> None:
    model = damped_iiwa().model
    q0, v0, tau = np.asarray(IIWA_START), np.full(7, 0.3), np.zeros(7)
    _, v_fine = integrate_aba(model, q0, v0, tau, 0.05, 400, damping=True)
    _, v_free = integrate_aba(model, q0, v0, tau, 0.05, 400)
    _, v_h = integrate_aba(model, q0, v0, tau, 0.05, 100, damping=True)
    assert np.abs(v_h - v_fine).max() < 1e-6 < np.abs(v_free - v_fine).max()
    # the wrist's damping is stiff (λ(M⁻¹D) ~ 1e3/s): the verifier refines its substeps
    plan = mb.PlanResult(
        "x", "x", False, "", 0, 0.0, 0.0, 0.0, [q0] * 3, [v0] * 3, [tau] * 2, 0.075
    )
    ocp = mb.OCP(load_robot(model), N=2, dt=0.075, q0=q0)
    plain = mb.OCP(load_robot("iiwa", damping=False), N=2, dt=0.075, q0=q0)
    assert substeps(ocp, plan) > SUBSTEPS == substeps(plain, plan)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("damping", "N", "dt"),
    [(np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]), 40, 0.02), (DAMPING, 12, 0.1)],
    ids=["proximal", "stiff"],  # λ(M⁻¹D) Δt < 1; up to ~300 on the wrist
)
def test_verifier_replays_damped_plans_and_flags_undamped_ones(damping, N: int, dt: float) -> None:
    robot = damped_iiwa(damping)
    target = np.asarray(IIWA_START) + np.array([0.5, -0.3, 0.4, 0.3, 0.0, -0.3, 0.0])
    damped = tracking_ocp(robot, IIWA_START, target, N=N, dt=dt, goal_tolerance=None)
    plain = tracking_ocp(
        load_robot("iiwa", damping=False), IIWA_START, target, N=N, dt=dt, goal_tolerance=None
    )
    with_damping = mb.plan(damped, "ipopt", warm_start="linear")
    without = mb.plan(plain, "ipopt", warm_start="linear")
    assert with_damping.success and without.success
    assert verify(damped, with_damping).passed
    assert verify(plain, without).passed
    check = verify(damped, without)
    assert not check.passed and check.velocity_deviation_ratio > 1.0, check.reasons
    # the plans differ by the damping torques D v (the torque-cost optimum is close to gravity)
    assert np.abs(with_damping.tau - without.tau).max() > 0.5
