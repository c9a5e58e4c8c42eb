"""The speed benchmark's building blocks: the chain robot and the per-iteration profile."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from reference_problems import BandedControlNLP

from mbplan.benchmarks.kkt_profile import PROFILE_KEYS, profile_solve
from mbplan.solvers import RIPMOptions
from mbplan.tasks.speed import chain_start, chain_target, chain_task


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


def test_median_ratio_interval_is_a_paired_bootstrap_of_the_medians():
    import pytest

    from mbplan.benchmarks.common import median_ratio_interval
    from mbplan.errors import InputError

    rng = np.random.default_rng(3)
    den = {c: float(t) for c, t in enumerate(rng.lognormal(0.0, 0.5, 60))}
    # twice as slow on every case: every paired draw has the ratio 2 exactly (unpaired draws
    # would not)
    assert median_ratio_interval({c: 2.0 * t for c, t in den.items()}, den) == (2.0, 2.0)
    noisy = {c: t * float(rng.uniform(0.8, 1.2)) for c, t in den.items()}
    lo, hi = median_ratio_interval(noisy, den)
    point = np.median(list(noisy.values())) / np.median(list(den.values()))
    assert lo < point < hi and hi - lo < 0.3
    assert median_ratio_interval(noisy, den) == (lo, hi)  # seeded: the same interval
    # the percentiles of the level, over draws of the cases in their sorted order
    cases = sorted(den, key=str)
    pick = np.random.default_rng(0).integers(0, len(cases), size=(2000, len(cases)))
    a, b = (np.array([d[c] for c in cases]) for d in (noisy, den))
    ref = np.median(a[pick], axis=1) / np.median(b[pick], axis=1)
    for level in (0.95, 0.5):
        want = np.percentile(ref, [50 * (1 - level), 50 * (1 + level)])
        np.testing.assert_allclose(median_ratio_interval(noisy, den, level=level), want)
    # a case that did not converge leaves only that method's median: here the slow cases 0-9
    # stay in the denominator's, so some draws' ratios fall well below 1
    slow = {c: 10.0 if c < 10 else 1.0 for c in range(21)}
    ones = {c: None if c < 10 else 1.0 for c in range(21)}
    lo2, hi2 = median_ratio_interval(ones, slow)
    assert hi2 == 1.0 and lo2 < 0.5
    assert median_ratio_interval({c: 1.0 for c in range(9)}) is None  # too few cases
    assert median_ratio_interval({0: None}, {0: 1.0}) is None
    for bad in ({"level": 1.5}, {"level": 0.0}, {"draws": 0}, {"draws": 2.5}):
        with pytest.raises(InputError):
            median_ratio_interval(noisy, den, **bad)


def test_speed_tables_show_each_ratio_with_its_interval():
    from mbplan.benchmarks.speed import _method_stats, ratio_intervals
    from mbplan.benchmarks.speed_report import INTERVALS
    from mbplan.benchmarks.speed_report import markdown as _markdown

    rng = np.random.default_rng(0)
    rows = []
    for case in range(40):
        base = float(rng.lognormal(0.0, 0.3))
        for method, scale, solve, its in (("ipopt", 1.0, 0.9, 10), ("ripm", 0.25, 0.5, 5)):
            t = scale * base * float(rng.uniform(0.9, 1.1))
            rows.append(
                {"case": case, "method": method, "success": case != 5 or method == "ipopt",
                 "verified": True, "iterations": its, "time_per_iter_s": t / its,
                 "total_time_s": t, "solve_time_s": solve * t, "status": "ok"}
            )  # fmt: skip
    ci = ratio_intervals(rows, "ipopt")
    assert set(ci) == {"ipopt", "ripm"} and set(ci["ipopt"]) == {"time_per_iter_s"}
    r = ci["ripm"]
    # total 0.25, solve 0.25 * 0.5 / 0.9, per iteration 0.25 * 10 / 5: one interval each
    for key, want in (("total_ratio", 0.25), ("solve_ratio", 0.25 * 0.5 / 0.9), ("time_per_iter_ratio", 0.5)):  # fmt: skip
        assert r[key][0] < want < r[key][1] and r[key][1] - r[key][0] < 0.25 * want
    tasks = {m: _method_stats([x for x in rows if x["method"] == m]) for m in ("ipopt", "ripm")}
    summary = {
        "command": "mbplan bench speed …",
        "tasks": {"iiwa-com": tasks},
        "intervals": {"iiwa-com": ci},
        "interval_method": INTERVALS,
        "profile": {},
        "orderings": {},
    }
    text = _markdown(summary)
    assert "95 % interval, a paired percentile bootstrap over the cases (2000 draws" in text
    cells = {
        line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
        for line in text.splitlines()
        if line.startswith(("| ripm |", "| ipopt |"))
    }
    ripm, ipopt = cells["ripm"], cells["ipopt"]
    assert ripm[1] == "39/40" and [ipopt[i] for i in (5, 7, 8)] == ["1.00"] * 3
    lo, hi = (1e3 * v for v in ci["ripm"]["time_per_iter_s"])
    value = 1e3 * tasks["ripm"]["median_time_per_iter_s"]
    d = max(0, 2 - int(np.floor(np.log10(value))))
    shown = (
        f"{value:.{d}f} ({np.floor(lo * 10**d) / 10**d:.{d}f}–{np.ceil(hi * 10**d) / 10**d:.{d}f})"
    )
    assert ripm[3] == shown  # in ms, the interval rounded outwards
    for column, key in ((5, "total_ratio"), (7, "solve_ratio"), (8, "time_per_iter_ratio")):
        lo, hi = ci["ripm"][key]
        low, high = (float(x) for x in ripm[column].split("(")[1].rstrip(")").split("–"))
        assert low <= lo and hi <= high and high - low < hi - lo + 0.0021
