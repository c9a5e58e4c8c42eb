"""Revolute position limits beyond what a rotation shows, in maximal coordinates: ranges of a
turn or more (UR elbows: ±π, the UR5's other joints: ±2π) count the turns from a reference per
knot (:meth:`mbplan.residuals.JointPositionLimits.maximal_terms`)."""

from __future__ import annotations

import numpy as np
import pytest

import mbplan as mb
from mbplan import residuals as res
from mbplan.engine import check_derivatives
from mbplan.formulations.maximal import MaximalNLP
from mbplan.formulations.maximal_joints import joint_function
from mbplan.formulations.maximal_turns import center_turns, follow_turns
from mbplan.lie import SO3

N, DT = 3, 0.075


def _limits_ocp() -> mb.OCP:
    robot = mb.load_robot("ur5")
    ocp = mb.OCP(robot, N=N, dt=DT, q0=np.zeros(robot.nq))
    ocp.add_cost("v", res.JointVelocity(), 1.0)
    ocp.add_constraint("position_limits", res.JointPositionLimits())
    return ocp


def test_ranges_of_a_turn_or_more_count_turns_to_their_exact_limits():
    """The UR5's elbow (±π) and its other joints (±2π) have two rows per knot each, exact at
    the limit: ``lo + 0.01`` inside, ``lo - 0.01`` outside, both ends of the range."""
    ocp = _limits_ocp()
    model = ocp.robot.model
    ranges = model.upperPositionLimit - model.lowerPositionLimit
    elbow = int(np.flatnonzero(np.isclose(ranges, 2 * np.pi))[0])
    nlp = MaximalNLP(ocp, jit=False)
    assert nlp.problem.n_ineq == N * 2 * model.nq
    for limit, sign in (
        (model.lowerPositionLimit[elbow], 1.0),
        (model.upperPositionLimit[elbow], -1.0),
    ):
        for offset, inside in ((0.01, True), (-0.01, False)):
            q = np.zeros((N + 1, model.nq))
            q[1:, elbow] = np.linspace(0.0, limit + sign * offset, N)
            center_turns(nlp, q)
            _, _, g = nlp.problem.values(nlp.initial_point(q))
            assert (np.max(g) <= 0.0) == inside, (limit, offset, np.max(g))


def _turn_rows(nlp: MaximalNLP, q: np.ndarray) -> np.ndarray:
    """The turn-counting rows at the path ``q``, ``(sites, 2)``: the shoulder's (a child of
    the world) at knots 1..N first, then the other joints'."""
    _, _, g = nlp.problem.values(nlp.initial_point(q))
    rows = nlp.problem.term_rows("ineq")
    return np.concatenate(
        [g[rows[n]] for n in ("position_limits_world/turns", "position_limits/turns")]
    )


def test_wider_ranges_count_the_turns_from_their_references():
    """``(lo - θ, θ - hi)`` with ``θ`` the angle counted from the reference: the same rows for
    any reference within π of the path (the chart), a joint wound past ``hi`` caught although
    its rotation is inside the range again, and the references moved only where the path
    left them by more than ``beyond``."""
    ocp = _limits_ocp()
    model = ocp.robot.model
    nlp = MaximalNLP(ocp, jit=False)
    wide = np.flatnonzero(model.upperPositionLimit - model.lowerPositionLimit > 2 * np.pi + 1.0)
    rng = np.random.default_rng(3)
    q = np.zeros((N + 1, model.nq))
    q[1:, wide] = rng.uniform(-5.0, 5.0, (N, wide.size))
    q[N, wide[0]] = model.upperPositionLimit[wide[0]] + 0.4  # wound past the limit
    assert center_turns(nlp, q)
    rows = _turn_rows(nlp, q)
    first = rows[:N]
    expect = np.stack([model.lowerPositionLimit[wide[0]] - q[1:, 0], q[1:, 0] - 2 * np.pi], 1)
    np.testing.assert_allclose(first, expect, atol=1e-9)
    assert first[-1, 1] == pytest.approx(0.4)
    # any reference within π gives the same rows
    assert not center_turns(nlp, q + 0.1, beyond=0.5)
    assert center_turns(nlp, q + 2.0, beyond=0.5)
    np.testing.assert_allclose(_turn_rows(nlp, q), rows, atol=1e-9)
    # past π the chart wraps: the same rotation 2π lower
    center_turns(nlp, q - 4.0)
    moved = _turn_rows(nlp, q)[:N]
    np.testing.assert_allclose(moved[-1, 1], 0.4 - 2 * np.pi, atol=1e-9)


@pytest.mark.parametrize("world", [False, True])
def test_turn_rows_match_finite_differences(world):
    f = joint_function("revolute", "position_winding", False, world)
    rng = np.random.default_rng(5)
    axis = rng.standard_normal(3)
    params = {
        "R_ref": SO3.exp(rng.standard_normal(3)),
        "theta_ref": 4.0,
        "a": axis / np.linalg.norm(axis),
        "lo": -6.0,
        "hi": 6.0,
    }
    for _ in range(3):
        x = {s.name: SO3.exp(rng.standard_normal(3)) for s in f.variables}
        assert check_derivatives(f, x, params, rng=rng).ok(1e-6)


def test_the_references_follow_the_iterates_so_the_rows_count_their_turns():
    """Iterates turning the shoulder by 2 rad twice: each accepted iterate moves the references
    (farther than π/2) without changing the rows, so the second counts +4 rad, not 4 - 2π."""
    ocp = _limits_ocp()
    nlp = MaximalNLP(ocp, jit=False)
    q = np.zeros((N + 1, ocp.robot.nq))
    center_turns(nlp, q)
    turned = q.copy()
    for k in range(1, 3):
        turned[1:, 0] = 2.0 * k
        before = _turn_rows(nlp, turned)
        follow_turns(nlp, nlp.initial_point(turned))
        np.testing.assert_allclose(_turn_rows(nlp, turned), before, atol=1e-9)
    upper = ocp.robot.model.upperPositionLimit[0]
    np.testing.assert_allclose(_turn_rows(nlp, turned)[:N, 1], 4.0 - upper, atol=1e-9)
