"""Revolute position limits whose range is 2π (UR elbows: ±π) in maximal coordinates: a
rotation forgets the turns, so the rows keep the joint off an arc around the angle it must not
pass (:meth:`mbplan.residuals.JointPositionLimits.maximal_terms`); wider ranges have none."""

from __future__ import annotations

import numpy as np

import mbplan as mb
from mbplan import residuals as res
from mbplan.formulations.maximal import MaximalNLP

N, DT = 3, 0.075


def _limits_ocp() -> mb.OCP:
    robot = mb.load_robot("ur5")
    ocp = mb.OCP(robot, N=N, dt=DT, q0=np.zeros(robot.nq))
    ocp.add_cost("v", res.JointVelocity(), 1.0)
    ocp.add_constraint("position_limits", res.JointPositionLimits())
    return ocp


def test_a_two_pi_range_keeps_an_arc_of_half_width_eps_and_wider_ranges_have_no_rows():
    ocp = _limits_ocp()
    model = ocp.robot.model
    ranges = model.upperPositionLimit - model.lowerPositionLimit
    elbow = int(np.flatnonzero(np.isclose(ranges, 2 * np.pi))[0])
    assert np.all(ranges[np.arange(model.nq) != elbow] > 2 * np.pi + 1.0)
    nlp = MaximalNLP(ocp, jit=False)
    assert nlp.problem.n_ineq == N  # the elbow's cosine row per knot, no others
    eps = 0.5 * min(model.velocityLimit[elbow] * DT, 0.5 * np.pi)
    lo = model.lowerPositionLimit[elbow]
    for angle, inside in ((lo + 2.0 * eps, True), (lo + 0.5 * eps, False), (lo - 0.1, False)):
        q = np.zeros((N + 1, model.nq))
        q[1:, elbow] = angle
        _, _, g = nlp.problem.values(nlp.initial_point(q))
        assert (np.max(g) <= 0.0) == inside, (angle, np.max(g))
    # the rows are the cosine form with half = π - ε about the range's middle
    q = np.zeros((N + 1, model.nq))
    q[1:, elbow] = 0.3
    _, _, g = nlp.problem.values(nlp.initial_point(q))
    np.testing.assert_allclose(np.max(g), np.cos(np.pi - eps) - np.cos(0.3), atol=1e-12)
