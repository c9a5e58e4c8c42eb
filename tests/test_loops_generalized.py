"""Closed loops in the generalized formulation: closure rows, loop forces, their derivatives, an
IPOPT plan of a four-bar, and the methods that refuse loops."""

from __future__ import annotations

import numpy as np
import pytest
from fd import check_generalized_derivatives
from loop_problems import fourbar, fourbar_ocp, fourbar_plan, rocker_goal, welded_arm

import mbplan as mb
from mbplan.errors import InputError
from mbplan.formulations.casadi_nlp import callbacks
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.generalized_loops import loop_functions
from mbplan.residuals import JointTorque
from mbplan.robots.loops import closure_jacobian, closure_residual


@pytest.mark.parametrize("kind", ["point", "revolute", "weld"])
def test_symbolic_closure_matches_pinocchio(kind: str) -> None:
    """The CasADi rows, Jacobian and force term against Pinocchio's forward kinematics."""
    robot = welded_arm(kind)
    fns = loop_functions(robot)
    rng = np.random.default_rng(0)
    for _ in range(3):
        q = rng.uniform(-1.5, 1.5, robot.nv)
        lam = rng.standard_normal(fns.size)
        r = closure_residual(robot.model, robot.loops, q)
        J = closure_jacobian(robot.model, robot.loops, q)
        assert np.abs(r).max() > 1e-2  # away from the closure
        np.testing.assert_allclose(np.asarray(fns.closure(q)).ravel(), r, atol=1e-12)
        np.testing.assert_allclose(np.asarray(fns.jacobian(q)), J, atol=1e-7)
        force = np.asarray(fns.force(np.concatenate([q, lam]))).ravel()
        np.testing.assert_allclose(force, -J.T @ lam, atol=1e-6)


@pytest.mark.parametrize("case", ["fourbar", "point", "revolute"])
def test_loop_rows_derivatives_match_finite_differences(case: str) -> None:
    """Jacobian and Lagrangian Hessian of the NLP with closure rows and loop forces (and the
    callbacks IPOPT calls) against central differences, at a random point."""
    if case == "fourbar":
        ocp = fourbar_ocp(N=4)
    else:
        ocp = mb.OCP(welded_arm(case), N=3, dt=0.05)
        ocp.add_cost("effort", JointTorque(), 1e-2)
    nlp = GeneralizedNLP(ocp)
    assert nlp.nc == sum(loop.dim for loop in ocp.robot.loops) > 0
    rng = np.random.default_rng(1)
    q = ocp.q0 + 0.2 * rng.standard_normal((ocp.N + 1, ocp.robot.nq))
    q[0] = ocp.q0
    z = nlp.initial_guess(q) + 0.1 * rng.standard_normal(nlp.n)
    lam = rng.standard_normal(nlp.m)
    check_generalized_derivatives(nlp, z, lam)
    _, jac_g, hess_lag = callbacks(nlp, "generalized")
    np.testing.assert_allclose(np.asarray(jac_g(z, np.zeros(0))[1]), nlp.jacobian(z).toarray())
    np.testing.assert_allclose(
        np.asarray(hess_lag(z, np.zeros(0), 0.3, lam)),
        nlp.lagrangian_hessian(z, 0.3, lam).toarray(),
    )


def test_initial_guess_closes_the_knots_and_meets_the_dynamics() -> None:
    """The warm start's knots are closed and its torques and loop forces satisfy eq. (61) with
    zero torque at the passive joints (least squares, exact for the four-bar)."""
    ocp = fourbar_ocp()
    nlp = GeneralizedNLP(ocp)
    q = np.linspace(ocp.q0, ocp.q0 + np.array([0.5, 0.0, 0.3]), ocp.N + 1)
    q[1] = ocp.q0  # at rest: q_1 = q_0
    z = nlp.initial_guess(q)
    q_z, _, tau = nlp.unpack(z)
    assert (
        max(np.abs(closure_residual(ocp.robot.model, ocp.robot.loops, qk)).max() for qk in q_z)
        < 1e-9
    )
    g = nlp.constraints(z)
    assert np.abs(g[: 2 * ocp.N * ocp.robot.nv]).max() < 1e-9  # kinematics and dynamics
    passive = ocp.robot.joint_indices(ocp.robot.passive)
    assert np.abs(tau[:, passive]).max() < 1e-9
    assert np.abs(nlp.loop_forces(z)).max() > 0.1  # the loop carries gravity


def test_given_torques_make_a_square_system() -> None:
    """With every torque given, the NLP is a simulation: one equation per unknown (closure of
    knots 2..N and of the step after N for the N loop forces)."""
    ocp = mb.OCP(fourbar(), N=6, dt=0.02)
    ocp.add_constraint("drive", JointTorque(joints=["crank_joint"], target=[0.01]))
    nlp = GeneralizedNLP(ocp)
    assert np.all(nlp.lbg == nlp.ubg) and np.all(np.isinf(nlp.lbz))
    assert nlp.m == nlp.n


def test_fourbar_plan_solves_closes_the_loops_and_verifies() -> None:
    ocp, result = fourbar_ocp(), fourbar_plan()
    assert result.success, result.message
    assert result.iterations < 50
    robot = ocp.robot
    closure = max(np.abs(closure_residual(robot.model, robot.loops, q)).max() for q in result.q)
    assert closure <= 1e-9
    assert result.extra["closure_residual"] == pytest.approx(closure, abs=1e-15)
    assert np.array(result.extra["loop_forces"]).shape == (ocp.N, 2)
    assert np.abs(result.tau[:, robot.joint_indices(robot.passive)]).max() < 1e-9
    assert result.q[-1, 2] == pytest.approx(rocker_goal(robot), abs=1e-8)
    check = mb.verify(ocp, result)
    assert check.passed, check.reasons
    assert check.closure_residual <= 1e-9 and check.passive_torque_nm < 1e-9
    assert check.joint_deviation_ratio <= 1.0 and check.velocity_deviation_ratio <= 1.0


def test_a_start_velocity_whose_first_step_opens_the_loops_is_refused() -> None:
    """``q0 + Δt v0`` is knot 1 of the explicit-Euler transcription: it must close."""
    robot = fourbar()
    q0 = robot.configuration("neutral")
    J = closure_jacobian(robot.model, robot.loops, q0)
    v0 = np.linalg.svd(J)[2][-1]  # tangent to the closure at q0: the step still opens it
    ocp = mb.OCP(robot, N=5, dt=0.05, q0=q0, v0=v0)
    ocp.add_cost("effort", JointTorque(joints=["crank_joint"]), 1e-2)
    with pytest.raises(InputError, match=r"first step q0 \+ dt v0 does not close the loops"):
        mb.plan(ocp, "ipopt", warm_start="linear")


@pytest.mark.parametrize("method", ["fddp", "csqp"])
def test_crocoddyl_methods_refuse_loops(method: str) -> None:
    with pytest.raises(InputError, match=rf"{method} cannot plan 'fourbar'.*close: point closure"):
        mb.plan(fourbar_ocp(N=5), method)


def test_the_shooting_builder_refuses_loops() -> None:
    pytest.importorskip("crocoddyl")
    from mbplan.formulations.crocoddyl import ShootingBuilder

    with pytest.raises(InputError, match="closed kinematic loops"):
        ShootingBuilder(fourbar_ocp(N=5), hard=True, method="csqp")
