"""The Lie-group iLQR as a planning method: ``mbplan.plan(ocp, "ms-ilqr" | "ss-ilqr")`` on a
free body (the drone docking OCP), its results verified, saved, loaded and replayed."""

import numpy as np
import pytest

import mbplan
from mbplan.cli.main import main
from mbplan.errors import InputError
from mbplan.formulations.free_body import input_bounds
from mbplan.results import load_npz
from mbplan.tasks.drone import sample_docking_cases
from mbplan.tasks.paper import drone_docking


def _docking(seed: int = 0, with_input_limits: bool = False) -> mbplan.OCP:
    return drone_docking(sample_docking_cases(1, seed, with_input_limits=with_input_limits)[0])


def test_ms_ilqr_plans_the_drone_docking_and_the_plan_verifies(tmp_path):
    ocp = _docking()
    result = mbplan.plan(ocp, "ms-ilqr")
    assert result.success, result.message
    assert result.method == "ms-ilqr" and result.formulation == "shooting"
    assert result.q.shape == (ocp.N + 1, 7) and result.tau.shape == (ocp.N, ocp.robot.nu)
    assert result.extra["defect_norm"] < 1e-6
    assert mbplan.verify(result).passed
    loaded = load_npz(result.save(tmp_path / "plan.npz"))
    assert loaded.method == "ms-ilqr" and mbplan.verify(loaded).passed
    assert main(["replay", str(tmp_path / "plan.npz"), "--html", str(tmp_path / "p.html")]) == 0


def test_ms_ilqr_keeps_the_input_limits_by_the_augmented_lagrangian():
    ocp = _docking(with_input_limits=True)
    result = mbplan.plan(ocp, "ms-ilqr")
    assert result.success, result.message
    lower, upper = input_bounds(ocp)
    assert np.all(result.tau >= lower - 1e-6) and np.all(result.tau <= upper + 1e-6)
    assert mbplan.verify(result).passed


def test_ss_ilqr_plans_a_docking_without_a_flip():
    result = mbplan.plan(_docking(seed=2), "ss-ilqr")
    assert result.success, result.message
    assert result.extra["defect_norm"] == 0.0  # single shooting: a rollout at every iterate
    assert mbplan.verify(result).passed


def test_ilqr_refuses_unknown_options_before_building():
    with pytest.raises(InputError, match=r"ms-ilqr options: unknown \['mu'\]"):
        mbplan.plan(_docking(), "ms-ilqr", options={"mu": 1.0})


def test_results_share_scipys_optimize_result_names():
    from mbplan.solvers.ilqr import ILQRResult
    from mbplan.solvers.result import RIPMResult, SolverResult

    assert issubclass(ILQRResult, SolverResult) and issubclass(RIPMResult, SolverResult)
    result = mbplan.plan(_docking(seed=2), "ms-ilqr")
    assert isinstance(result, SolverResult)
    assert result.nit == result.iterations and result.fun == result.extra["objective"]
    assert result.success and result.status == "CONVERGED" and result.message
