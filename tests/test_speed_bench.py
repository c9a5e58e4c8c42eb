"""The speed benchmark's building blocks: the chain robot and the per-iteration profile."""

from __future__ import annotations

import numpy as np

from mbplan.benchmarks.kkt_profile import PROFILE_KEYS, profile_solve
from mbplan.benchmarks.speed_tasks import chain_task
from mbplan.solvers import RIPMOptions
from mbplan.solvers.examples import BandedControlNLP


def test_chain_task_is_a_hanging_chain_of_n_revolute_links():
    ocp = chain_task(3, N=5)
    model = ocp.robot.model
    assert model.nq == 3 and [model.joints[j].shortname() for j in (1, 2, 3)] == [
        "JointModelRX",
        "JointModelRY",
        "JointModelRX",
    ]
    np.testing.assert_allclose(ocp["joint_position_terminal"].residual.target, np.full(3, 0.4))
    assert len(ocp.scene) == 0


def test_profile_splits_the_iteration_into_parts_that_add_up():
    prob = BandedControlNLP(nx=4, nu=2, horizon=20)
    row = profile_solve(prob, prob.initial_guess(), RIPMOptions())
    assert row["status"] == "CONVERGED" and row["iterations"] > 0
    parts = sum(row[k + "_ms"] for k in PROFILE_KEYS)
    assert 0 < parts <= row["per_iter_ms"] and row["python_ms"] >= 0
    assert row["factorize_per_iter"] >= 1 and row["evaluate_per_iter"] >= 1
    assert row["kkt_dim"] == prob.n + prob.n_eq + prob.n_ineq


def test_chain_obstacle_task_blocks_the_linear_path_but_not_its_ends():
    from mbplan.planning.initial_guess import initial_path, path_clearance

    for n in (4, 8):
        ocp = chain_task(n, N=10, obstacle=True)
        assert [o.name for o in ocp.scene] == ["cylinder"]
        assert "com_outside_cylinder" in [c.name for c in ocp.constraints]
        path = initial_path(ocp, "linear")
        assert path_clearance(ocp, path) > 0.0  # the straight reach crosses the cylinder
        assert path_clearance(ocp, path[[0, -1]]) < 0.0  # start and goal are clear
        np.testing.assert_allclose(path[-1], ocp["joint_position_terminal"].residual.target)
