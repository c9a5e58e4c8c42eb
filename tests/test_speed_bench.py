"""The speed benchmark's building blocks: the chain robot and the per-iteration profile."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mbplan.benchmarks.kkt_profile import PROFILE_KEYS, profile_solve
from mbplan.benchmarks.speed_tasks import chain_start, chain_target, chain_task
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

    for n in (4, 8, 64):
        ocp = chain_task(n, N=10, obstacle=True)
        assert [o.name for o in ocp.scene] == ["cylinder"]
        assert "com_outside_cylinder" in [c.name for c in ocp.constraints]
        path = initial_path(ocp, "linear")
        assert path_clearance(ocp, path) > 0.0  # the straight reach crosses the cylinder
        assert path_clearance(ocp, path[[0, -1]]) < 0.0  # start and goal are clear
        np.testing.assert_allclose(path[0], chain_start(n, obstacle=True))
        np.testing.assert_allclose(path[-1], ocp["joint_position_terminal"].residual.target)


def _growth_rate(model: pin.Model, q: np.ndarray) -> float:
    """Largest real part (1/s) of the eigenvalues of the dynamics linearised at rest at ``q``
    under the torques that hold it (``pinocchio.rnea``)."""
    data, n = model.createData(), model.nv
    tau = pin.rnea(model, data, q, np.zeros(n), np.zeros(n))
    pin.computeABADerivatives(model, data, q, np.zeros(n), tau)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [data.ddq_dq, data.ddq_dv]])
    return float(np.max(np.linalg.eigvals(a).real))


def test_chain_obstacle_start_and_goal_are_stable_at_every_size():
    # a plan that holds an open-loop unstable goal cannot be replayed (growth e^{λΔt} per interval)
    for n in (4, 64):
        model = chain_task(n, N=2, obstacle=True).robot.model
        for q in (chain_start(n, obstacle=True), chain_target(n, obstacle=True)):
            assert _growth_rate(model, q) < 1e-6
        bent = np.zeros(n)
        bent[0], bent[n // 2 + 1] = 1.0, 1.5  # the old goal's kind: x bend above, y bend below
        assert _growth_rate(model, bent) > 1.0


def test_alternating_runs_run_each_tree_in_abba_order(tmp_path):
    """Every round runs the code once in each tree (its working directory), the trees' order
    reversed every other round; each tree's outputs come back in round order."""
    from mbplan.benchmarks.common import alternating_runs

    log = tmp_path / "order.txt"
    trees = {name: tmp_path / name for name in ("a", "b")}
    for path in trees.values():
        path.mkdir()
    code = (
        "import json, os, sys; arg = json.loads(sys.argv[1]); name = os.path.basename(os.getcwd())\n"
        "n = sum(1 for _ in open(arg)) if os.path.exists(arg) else 0\n"
        "open(arg, 'a').write(name + '\\n'); print(json.dumps([name, n]))"
    )
    runs = alternating_runs(trees, code, str(log), rounds=3)
    assert log.read_text().split() == ["a", "b", "b", "a", "a", "b"]
    assert runs == {"a": [["a", 0], ["a", 3], ["a", 4]], "b": [["b", 1], ["b", 2], ["b", 5]]}
