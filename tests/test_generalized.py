"""The generalized formulation (eq. 61 with Pinocchio) and its IPOPT adapter, on OCPs."""

from __future__ import annotations

import numpy as np
import pytest

import mbplan as mb
import mbplan.planning.methods as methods
from mbplan.formulations.casadi_nlp import callbacks
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.joint_space import evaluate
from mbplan.multibody.collision import chain_kinematics, joint_space_contacts, point_jacobians
from mbplan.planning.initial_guess import initial_path
from mbplan.residuals import JointPosition
from mbplan.residuals.distance import distance_values
from mbplan.tasks.paper import IIWA_TARGET, add_obstacle_constraint, tracking_ocp


def small_cases(
    n: int = 3, constraint: str = "com", radius: float = 0.08, between_knots: bool = False
) -> list[mb.OCP]:
    """N = 10 tasks whose straight path brushes a cylinder in the way of the wrist (links 6, 7
    pass at 0.60-0.62 m from the base axis; the cylinder's near side is at 0.60 m)."""
    rng = np.random.default_rng(0)
    c = (0.68 * np.cos(0.6), 0.68 * np.sin(0.6))
    target = np.array(IIWA_TARGET)
    out = []
    for _ in range(n):
        q0 = target + np.concatenate([[-0.8], 0.1 * rng.uniform(-1.0, 1.0, 6)])
        scene = mb.Scene().add_cylinder("cylinder", radius, 1.5, (*c, 0.75))
        ocp = tracking_ocp("iiwa", q0, target, scene, N=10, dt=0.1)
        out.append(add_obstacle_constraint(ocp, constraint, between_knots=between_knots))
    return out


def test_callbacks_agree_with_the_numpy_functions() -> None:
    nlp = GeneralizedNLP(small_cases(1)[0])
    g, jac_g, hess_lag = callbacks(nlp, "generalized")
    z = nlp.initial_guess(initial_path(nlp.ocp, "linear"))
    z = z + 0.1 * np.random.default_rng(3).standard_normal(nlp.n)
    lam = np.random.default_rng(4).standard_normal(nlp.m)
    np.testing.assert_allclose(np.asarray(g(z)).ravel(), nlp.constraints(z))
    g_out, J = jac_g(z, np.zeros(0))
    np.testing.assert_allclose(np.asarray(g_out).ravel(), nlp.constraints(z))
    np.testing.assert_allclose(np.asarray(J), nlp.jacobian(z).toarray())
    np.testing.assert_allclose(
        np.asarray(hess_lag(z, np.zeros(0), 0.5, lam)),
        nlp.lagrangian_hessian(z, 0.5, lam).toarray(),
    )


def test_residuals_of_new_ocps_reuse_the_robots_symbolic_kinematics(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The joint placements' SX graph is built once per robot and a residual's rows once per
    robot and structure: a new OCP (new residuals, another scene) passes its numbers as
    parameters. Its COM clearances are those of Pinocchio's link COMs."""
    import pinocchio as pin

    import mbplan.formulations.joint_space as js

    built = []
    original = js.symbolic_placements
    monkeypatch.setattr(js, "symbolic_placements", lambda *a: built.append(1) or original(*a))
    js._state_symbols.cache_clear()
    rows = []
    original_rows = js._rows
    monkeypatch.setattr(js, "_rows", lambda *a: rows.append(a[1].key) or original_rows(*a))
    js._parametric.cache_clear()
    for ocp in small_cases(3):
        item = ocp.constraints[-1]
        q = ocp.q0 + 0.3
        value = evaluate(ocp.robot, ocp.scene, item.residual, q[None], ocp.v0[None], None)[0]
        model = ocp.robot.model
        data = model.createData()
        pin.forwardKinematics(model, data, q)
        cx, cy, r = item.residual.circle(ocp.scene)  # r: radius + margin
        com = [data.oMi[j].act(model.inertias[j].lever) for j in range(1, model.njoints)]
        clearance = [r**2 - (c[0] - cx) ** 2 - (c[1] - cy) ** 2 for c in com]  # eq. 62
        np.testing.assert_allclose(value, clearance, atol=1e-12)
    assert len(built) == 1
    ocp = small_cases(1)[0]
    q = ocp.q0 + 0.2
    goals = [JointPosition(target=t).resolve(ocp.robot, ocp.scene) for t in (q - 0.1, q + 0.3)]
    values = [evaluate(ocp.robot, ocp.scene, g, q[None], ocp.v0[None], None)[0] for g in goals]
    np.testing.assert_allclose(values, [np.full(7, 0.1), np.full(7, -0.3)], atol=1e-15)
    assert rows == [(type(item.residual),), (JointPosition, tuple(range(7)))]


def test_initial_guess_satisfies_eq61() -> None:
    ocp = small_cases(1)[0]
    nlp = GeneralizedNLP(ocp)
    q = initial_path(ocp, "linear")
    z = nlp.initial_guess(q)
    np.testing.assert_array_equal(nlp.unpack(z)[0], q)
    g = nlp.constraints(z)
    assert np.max(np.abs(g[: 2 * ocp.N * 7])) < 1e-9
    assert np.max(g[2 * ocp.N * 7 :]) > 0.0  # the straight path crosses the obstacle


def test_small_runs_converge_and_pass_verification() -> None:
    for ocp in small_cases(3):
        result = mb.plan(ocp, "ipopt", warm_start="linear")
        assert result.success, result.message
        assert result.status == "Solve_Succeeded" and result.method == "ipopt"
        assert result.formulation == "generalized" and result.ocp is ocp
        assert 0 < result.iterations < 100 and result.entered_restoration is False
        assert result.kkt_history.shape == (result.iterations + 1, 2)
        assert 0.0 < result.solve_time_s <= result.total_time_s
        np.testing.assert_array_equal(result.q[0], ocp.q0)
        com = ocp["com_outside_cylinder"].residual
        r = evaluate(ocp.robot, ocp.scene, com, result.q[1:], result.v[1:], None)
        assert r.max() == pytest.approx(0.0, abs=1e-6)  # eq. 62 is active at some knot
        lim = ocp.robot.model.effortLimit
        assert np.all(np.abs(result.tau) <= lim)
        check = mb.verify(ocp, result)
        assert check.passed, check.reasons
        assert set(check.violations) == set(n for n in ocp.names if ocp[n].role == "constraint")


def test_restoration_is_detected_and_can_be_disabled() -> None:
    ocp = small_cases(1)[0]
    forced = mb.plan(ocp, "ipopt", warm_start="linear", options={"start_with_resto": "yes"})
    assert forced.entered_restoration is True and forced.extra["restoration_iterations"] > 0
    stopped = mb.plan(
        ocp, "ipopt-no-restoration", warm_start="linear", options={"start_with_resto": "yes"}
    )
    assert stopped.entered_restoration is True and not stopped.success
    assert stopped.status == "Maximum_Iterations_Exceeded"
    assert "restoration" in stopped.message and stopped.iterations <= 2
    log = (
        "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls\n"
        "   0  2.0000000e-02 2.38e+00 2.00e-01  -1.0 0.00e+00    -  0.00e+00 0.00e+00   0\n"
        "  12r 1.0040046e+00 4.64e-02 9.99e+02  -1.3 0.00e+00    -  0.00e+00 3.73e-09R 29\n"
        "  13r 1.0028337e+00 7.97e-02 9.75e+02  -1.3 2.03e+00    -  5.48e-01 2.46e-02f  1\n"
        "  14  1.0028337e+00 7.97e-02 9.75e+02  -1.3 2.03e+00    -  5.48e-01 2.46e-02f  1\n"
    )
    assert methods._restoration_iterations(log) == 2


def test_input_errors_before_solving(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_solver(*args: object, **kwargs: object) -> None:
        raise AssertionError("nlpsol must not be reached")

    monkeypatch.setattr(methods.cs, "nlpsol", no_solver)
    ocp = small_cases(1)[0]
    guess = initial_path(ocp, "linear")
    guess[3, 2] = np.nan
    with pytest.raises(mb.InputError, match=r"warm_start: contains NaN"):
        mb.plan(ocp, "ipopt", warm_start=guess)
    with pytest.raises(mb.InputError, match=r"warm_start: expected shape"):
        mb.plan(ocp, "ipopt", warm_start=guess[:-1])
    with pytest.raises(mb.InputError, match="max_iter"):
        mb.plan(ocp, "ipopt", max_iter=-1)
    with pytest.raises(mb.InputError, match="restoration"):
        mb.plan(ocp, "ipopt", options={"output_file": "x.log"})
    with pytest.raises(mb.InputError, match="tol"):
        mb.plan(ocp, "ipopt", tol=float("nan"))
    com = ocp.robot.model  # the COM of link 5 at q0 inside a cylinder: named before solving
    data = com.createData()
    import pinocchio as pin

    pin.forwardKinematics(com, data, ocp.q0)
    c = data.oMi[5].act(com.inertias[5].lever)
    blocked = tracking_ocp(
        "iiwa", ocp.q0, IIWA_TARGET, mb.Scene().add_cylinder("c", 0.1, 1.5, (c[0], c[1], 0.75))
    )
    add_obstacle_constraint(blocked, "com")
    with pytest.raises(mb.InfeasibleRequestError, match=r"q0 violates.*'iiwa_joint_5'"):
        mb.plan(blocked, "ipopt")


def _distance_ocp() -> mb.OCP:
    scene = mb.Scene().add_sphere("sphere", 0.1, (0.35, 0.25, 0.6))
    import pinocchio as pin

    scene.add_box("box", (0.2, 0.15, 0.3), (-0.35, 0.2, 0.5), pin.rpy.rpyToMatrix(0.2, -0.5, 0.3))
    ocp = tracking_ocp("iiwa", small_cases(1)[0].q0, IIWA_TARGET, scene, N=4)
    return add_obstacle_constraint(ocp, "distance")


def test_distance_rows_hessian_is_the_fixed_witness_point_model() -> None:
    """``∇²(μ d)`` with coal's witness point fixed in its link and the normal fixed
    (mbplan.multibody.collision), against central differences of that model's gradient."""
    ocp = _distance_ocp()
    nlp = GeneralizedNLP(ocp)
    (block,) = nlp.own
    item, row0 = block.item, block.row0
    z = nlp.initial_guess(initial_path(ocp, "linear"))
    z = z + 0.1 * np.random.default_rng(6).standard_normal(nlp.n)
    _, _, kin, contacts, _ = distance_values(
        ocp.robot, ocp.scene, item.residual, nlp.unpack(z)[0][1:], 1
    )
    pairs_n = contacts.distance.shape[1]
    assert pairs_n == 14 and nlp.m == 2 * 4 * 7 + 4 * pairs_n
    mu = np.random.default_rng(7).uniform(0.5, 2.0, (ocp.N, pairs_n))
    lam = np.zeros(nlp.m)
    lam[row0:] = mu.ravel()
    U = nlp.lagrangian_hessian(z, 0.0, lam).toarray()
    H = U + U.T - np.diag(np.diag(U))
    from mbplan.residuals.distance import distance_pairs

    pairs = distance_pairs(ocp.robot, ocp.scene, item.residual.objects)
    q = nlp.unpack(z)[0]
    model, data = ocp.robot.model, ocp.robot.model.createData()
    joints = pairs.joint
    for k in range(1, ocp.N + 1):
        R, t = kin.rotation[k - 1, joints], kin.translation[k - 1, joints]
        local = np.einsum("pji,pj->pi", R, contacts.robot_point[k - 1] - t)

        def model_gradient(qk: np.ndarray, k: int = k, local: np.ndarray = local) -> np.ndarray:
            chain = chain_kinematics(model, data, qk[None])
            points = chain.translation[0, joints] + np.einsum(
                "pij,pj->pi", chain.rotation[0, joints], local
            )
            J = point_jacobians(chain, joints, points[None])[0]
            return np.einsum("p,pa,pja->j", mu[k - 1], contacts.normal[k - 1], J)

        fd = np.column_stack(
            [
                (model_gradient(q[k] + 1e-6 * e) - model_gradient(q[k] - 1e-6 * e)) / 2e-6
                for e in np.eye(7)
            ]
        )
        np.testing.assert_allclose(H[np.ix_(nlp.iq(k), nlp.iq(k))], fd, atol=1e-7)
    assert joint_space_contacts  # the one coal path of the planner and the verifier


def test_small_distance_runs_converge_and_pass_verification() -> None:
    """N = 10 with coal distances: the straight path crosses a thinner cylinder with the links'
    geometry; IPOPT converges onto the margin and the replay keeps clear of the solid."""
    for ocp in small_cases(2, "distance", radius=0.05):
        item = ocp["clearance"]
        path = initial_path(ocp, "linear")
        assert (
            evaluate(ocp.robot, ocp.scene, item.residual, path, path, None).max()
            > item.residual.margin
        )
        result = mb.plan(ocp, "ipopt", warm_start="linear")
        assert result.success, result.message
        check = mb.verify(result)
        assert check.passed, check.reasons
        r = evaluate(ocp.robot, ocp.scene, item.residual, result.q[1:], result.v[1:], None)
        assert r.max() == pytest.approx(0.0, abs=1e-6)  # active constraint
