"""The shooting formulation (Crocoddyl FDDP, mim-solvers CSQP; the ``baselines`` extra) on OCPs."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest

pytest.importorskip("crocoddyl", reason="the baselines extra (crocoddyl) is not installed")
pytest.importorskip("mim_solvers", reason="the baselines extra (mim-solvers) is not installed")

import crocoddyl
import pinocchio as pin

import mbplan as mb
from mbplan import residuals as res
from mbplan.errors import MbplanError
from mbplan.formulations import crocoddyl as sh
from mbplan.formulations.joint_space import evaluate, knot_function
from mbplan.tasks.paper import IIWA_TARGET, add_obstacle_constraint, iiwa_obstacle, tracking_ocp
from mbplan.verification.report import CONSTRAINT_TOLERANCE

MODEL = mb.load_robot("iiwa", damping=False).model  # the paper task: no damping


def small_cases(n: int = 3) -> list[mb.OCP]:
    """N = 10 tasks whose straight path brushes a cylinder in the way of the wrist, with joint 1
    limited to 10 N m so that the torque bound is active."""
    rng = np.random.default_rng(0)
    c = (0.68 * np.cos(0.6), 0.68 * np.sin(0.6))
    limit = MODEL.effortLimit.copy()
    limit[0] = 10.0
    out = []
    for _ in range(n):
        q0 = np.array(IIWA_TARGET) + np.concatenate([[-0.8], 0.1 * rng.uniform(-1.0, 1.0, 6)])
        scene = mb.Scene().add_cylinder("cylinder", 0.08, 1.5, (*c, 0.75))
        robot = mb.load_robot("iiwa", damping=False)
        ocp = tracking_ocp(robot, q0, IIWA_TARGET, scene, N=10, dt=0.1, torque_limit=limit)
        out.append(add_obstacle_constraint(ocp, "com"))
    return out


def test_forward_dynamics_guard() -> None:
    sh.check_forward_dynamics(seed=3)
    reference = np.array([1.0, -200.0, 3.0])
    sh.compare_forward_dynamics(reference * (1.0 + 1e-12), reference)
    with pytest.raises(MbplanError, match=r"forward dynamics different.*pin==4\.0\.0"):
        sh.compare_forward_dynamics(reference + np.array([0.0, 1e-4, 0.0]), reference)
    with pytest.raises(MbplanError, match="forward dynamics different"):
        sh.compare_forward_dynamics(np.array([np.nan, -200.0, 3.0]), reference)


def test_missing_crocoddyl_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "crocoddyl", None)
    monkeypatch.delitem(sys.modules, sh.__name__)
    with pytest.raises(MbplanError, match=r"pip install 'mbplan\[baselines\]'"):
        importlib.import_module(sh.__name__)


def _check_residual(residual, x: np.ndarray, expected: np.ndarray, atol: float) -> None:
    data = residual.createData(crocoddyl.DataCollectorMultibody(MODEL.createData()))

    def r(x: np.ndarray) -> np.ndarray:
        residual.calc(data, x)
        return data.r.copy()

    np.testing.assert_allclose(r(x), expected, atol=1e-12)
    residual.calcDiff(data, x)
    h = 1e-6
    fd = np.column_stack([(r(x + h * e) - r(x - h * e)) / (2.0 * h) for e in np.eye(x.size)])
    np.testing.assert_allclose(data.Rx, fd, atol=atol * max(1.0, np.abs(fd).max()))


def test_python_residuals_match_the_joint_space_residuals_and_finite_differences() -> None:
    """Every residual kind the shooting formulation writes in Python (frames and any CasADi
    residual, eq. 62, coal distances), values against the joint-space definition, Jacobians
    against central differences."""
    scene = mb.Scene().add_cylinder("post", 0.1, 1.5, (0.4, 0.2, 0.75))
    scene.add_sphere("ball", 0.1, (0.35, -0.3, 0.6))
    ocp = mb.OCP("iiwa", scene, N=4)
    goal = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, 0.3), np.array([0.4, 0.1, 0.6]))
    ocp.add_constraint("pose", res.FramePlacement("iiwa_link_ee", goal), "terminal")
    ocp.add_constraint("point", res.FrameTranslation("iiwa_link_4", [0.1, 0.0, 0.7]))
    ocp.add_constraint("com", res.ComOutsideCylinder("post", 0.03, between_knots=False))
    ocp.add_constraint("clearance", res.Distance(0.02, between_knots=False))
    state = crocoddyl.StateMultibody(MODEL)
    rng = np.random.default_rng(0)
    x = np.concatenate([np.array(IIWA_TARGET) + 0.3 * rng.standard_normal(7), np.ones(7)])
    q = x[None, :7]
    for name in ("pose", "point"):
        r = ocp[name].residual
        residual = sh.ResidualModelJointSpace(state, 7, knot_function(ocp.robot, scene, r))
        _check_residual(residual, x, evaluate(ocp.robot, scene, r, q, x[None, 7:], None)[0], 1e-7)
    r = ocp["com"].residual
    cx, cy, radius = r.circle(scene)
    residual = sh.ResidualModelCylinderClearance(state, 7, (cx, cy), radius - r.margin)
    d2 = radius**2 - evaluate(ocp.robot, scene, r, q, q, None)[0]
    _check_residual(residual, x, np.sqrt(d2) - (radius - r.margin), 1e-7)
    r = ocp["clearance"].residual
    residual = sh.ResidualModelCoalDistance(state, 7, ocp, r)
    _check_residual(residual, x, r.margin - evaluate(ocp.robot, scene, r, q, q, None)[0], 1e-6)


@pytest.mark.parametrize("method", ["fddp", "csqp"])
def test_small_cases_converge_within_the_torque_limits(method: str) -> None:
    for ocp in small_cases():
        result = mb.plan(ocp, method, max_iter=200, warm_start="linear")
        assert result.status == "converged", result.message
        assert result.method == method and result.formulation == "shooting"
        assert result.q.shape == (11, 7) and result.tau.shape == (10, 7)
        assert result.kkt_history.shape == (result.iterations + 1, 2)
        check = mb.verify(result)
        assert check.torque_limit_violation <= 1e-6 * 10.0
        assert np.max(np.abs(result.tau[:, 0])) > 0.99 * 10.0  # the bound is active
        if method == "csqp":  # hard constraints (the semi-implicit Euler replay may still fail
            assert result.success, result.message  # the explicit-Euler deviation threshold)
        else:  # penalties: success only if they leave every constraint within tolerance
            assert result.success == (max(result.violations.values()) <= CONSTRAINT_TOLERANCE)


def test_fddp_refuses_equality_constraints() -> None:
    ocp = iiwa_obstacle(N=4)
    ocp.add_constraint("hold", res.JointPosition(np.zeros(7)), "terminal")
    with pytest.raises(mb.InputError, match=r"fddp cannot express the equality constraint 'hold'"):
        mb.plan(ocp, "fddp")
    result = mb.plan(ocp, "csqp", max_iter=3)
    assert result.method == "csqp" and "hold" in result.violations


def test_csqp_keeps_the_coal_distance_margin() -> None:
    """The Crocoddyl row of a Distance constraint is the signed distance, bounded below by the
    margin: a hard-constrained plan past a sphere keeps its clearance at every knot."""
    scene = mb.Scene().add_sphere("ball", 0.08, (0.45, 0.0, 0.75))
    ocp = mb.OCP(mb.load_robot("iiwa", damping=False), scene, N=8, dt=0.1)
    ocp.add_cost("velocity", res.JointVelocity(), 1e-2)
    ocp.add_cost("goal", res.JointPosition(IIWA_TARGET), 1.0, "terminal")
    ocp.add_constraint("clearance", res.Distance(0.03, between_knots=False))
    result = mb.plan(ocp, "csqp", max_iter=100, warm_start="linear")
    assert result.violations["clearance"] <= CONSTRAINT_TOLERANCE, result.violations
