"""Every serial arm of ``mbplan robots`` plans a sampled joint-goal task and a frame-goal task in both
formulations (small N), and the results replay to a static HTML page."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import mbplan as mb
from mbplan.engine.jit import jit_available
from mbplan.formulations import maximal
from mbplan.robots import available_arms
from mbplan.solvers import RIPMStatus, solve_ripm
from mbplan.tasks.arm_sweep import sweep_robot, sweep_tasks
from mbplan.viz import static_html

# Known failures, asserted so that a fix shows up: IPOPT's restoration fails on the 3-dof
# finger's frame goal, whose 3 equations have rank 2 (the frame's origin is on the last joint's
# axis; test_rank_deficient_frame_goal), where the RIPM converges.
KNOWN_FAILURES = {("finger_edu", "frame", "ipopt")}


@pytest.mark.slow
@pytest.mark.parametrize("name", available_arms())  # continuous joints: one angle each
def test_every_arm_plans_joint_and_frame_goals_in_both_formulations(name: str, tmp_path: Path):
    robot = sweep_robot(name)
    for kind, ocp in sweep_tasks(robot, seed=len(name)).items():
        results = []
        for method in ("ripm", "ipopt"):
            rest = np.repeat(ocp.q0[None], ocp.N + 1, axis=0)  # the solver has to move the arm
            result = mb.plan(ocp, method, warm_start=rest, max_iter=200)
            if (name, kind, method) in KNOWN_FAILURES:
                assert not result.success, f"{name} {kind} {method} now succeeds: update the list"
                continue
            assert result.success, f"{name} {kind} {method}: {result.message}"
            assert result.violations["goal"] <= 1e-5
            results.append(result)
        if (
            kind == "joint"
            and len(results) == 2
            and robot.visual_model is not None
            and robot.visual_model.ngeoms
        ):
            page = static_html(results, tmp_path / f"{name}.html")
            assert page.stat().st_size > 10_000


def test_rank_deficient_frame_goal():
    """The sweep's frame goal of the 3-dof finger is the origin of ``finger_lower_link``, on the
    last joint's axis: its 3 equations have rank 2 at every configuration (LICQ fails, the
    linearized goal is inconsistent off the solution), so the KKT matrix is singular. The
    stalled refinement gives ``δ_c`` of the residual's size (``NewtonStep._delta_c``): the full
    and the joint-eliminated step reach the same point in a few iterations (how few depends on
    round-off: the static regularization decides the sign of K's ~1e-14 eigenvalue), a KKT point
    without the multiplier scaling ``s_d`` (the static regularization alone: 75 / > 200
    iterations, ``y`` ~ 6e5 ~ 1/ε, and with ε = 1e-11 "converged" at ``inf_du`` 2e-2)."""
    robot = sweep_robot("finger_edu")
    model, data = robot.model, robot.model.createData()
    ocp = sweep_tasks(robot, seed=len("finger_edu"))["frame"]
    frame = model.getFrameId(ocp["goal"].residual.frame)
    for q in (ocp.q0, np.zeros(model.nq)):
        jac = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED)[:3]
        sv = np.linalg.svd(jac, compute_uv=False)
        assert sv[2] < 1e-12 * sv[0] and sv[1] > 1e-2 * sv[0]
    nlp, _ = maximal.build(ocp, jit_available())
    x0 = nlp.initial_point(np.repeat(ocp.q0[None], ocp.N + 1, axis=0))
    runs = [
        solve_ripm(nlp.problem, x0, tol=1e-6, max_iter=50, kkt_method=method)
        for method in ("full", "reduced")
    ]
    for res in runs:  # the path depends on round-off in the null direction: 6 / 14 iterations
        assert res.status is RIPMStatus.CONVERGED and res.iterations <= 20
        # unscaled: the stop is on E_0 with s_d (the reduced path ends at 1.7e-6 here); the
        # static regularization alone stopped at 2e-2
        assert res.inf_du <= 1e-5 and res.inf_pr <= 1e-6
        assert np.max(np.abs(res.y)) < 1e5
    assert runs[0].objective == pytest.approx(runs[1].objective, rel=1e-8)
