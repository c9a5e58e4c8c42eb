"""MLG-IPM, its problems and the Lai-Yoshise baseline: derivatives against finite differences
along ``G exp(tζ^)``, local convergence rates, statuses and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg
from reference_problems import HS071_X0, hs071

from mbplan.benchmarks.lie_ipm_stats import SUMMARY_KEYS
from mbplan.errors import InputError
from mbplan.lie import SL
from mbplan.solvers import RIPMStatus, solve_ripm
from mbplan.solvers.lie_ipm.lai_yoshise import LaiYoshiseOptions, solve_lai_yoshise
from mbplan.solvers.lie_ipm.mlgipm import MLGIPMOptions, solve_mlgipm
from mbplan.tasks.lie_ipm import SLTraceProblem, SOLogProblem, make_problem, sample_instance


def _problems():
    so = sample_instance("so", 0, 2)
    sl = sample_instance("sl", 0, 0)
    return [
        (SOLogProblem(so.Gd, "squared"), so.G0),
        (SOLogProblem(so.Gd, "literal"), so.G0),
        (SLTraceProblem(sl.Gd), sl.G0),
    ]


def _move(p, x, zeta):
    return p.retract(x, zeta)


@pytest.mark.parametrize("case", range(3))
def test_derivatives_match_finite_differences_along_exp(case: int) -> None:
    """Gradient, sensitivity (Jacobian), curvature 𝕳 and symmetric Hessian vs central FD."""
    p, x = _problems()[case]
    rng = np.random.default_rng(case)
    z = rng.uniform(0.5, 2.0, p.n_ineq)
    ev = p.evaluate(x, 1.0, None, z)
    Jg = ev.ineq_jacobian.toarray()
    C = p.lagrangian_curvature(x, 1.0, None, z).toarray()
    H = p.lagrangian_hessian(x, 1.0, None, z).toarray()
    h = 1e-6
    eye = np.eye(p.n)

    def lag_grad(y):
        e = p.evaluate(y, 1.0, None, z, hessian=False)
        return e.gradient + e.ineq_jacobian.T @ z

    def lag(y):
        f, _, g = p.values(y)
        return f + z @ g

    grad_fd = np.array(
        [
            (p.objective(_move(p, x, h * e)) - p.objective(_move(p, x, -h * e))) / (2 * h)
            for e in eye
        ]
    )
    jac_fd = np.array(
        [(p.ineq(_move(p, x, h * e)) - p.ineq(_move(p, x, -h * e))) / (2 * h) for e in eye]
    ).T
    curv_fd = np.array(
        [(lag_grad(_move(p, x, h * e)) - lag_grad(_move(p, x, -h * e))) / (2 * h) for e in eye]
    ).T
    scale = max(1.0, np.abs(ev.gradient).max())
    assert np.abs(grad_fd - ev.gradient).max() < 1e-6 * scale
    assert np.abs(jac_fd - Jg).max() < 1e-6 * max(1.0, np.abs(Jg).max())
    assert np.abs(curv_fd - C).max() < 1e-5 * max(1.0, np.abs(C).max())
    # symmetric Hessian = second derivative of ζ ↦ L(G exp ζ) (a few random directions)
    hh = 1e-4
    for _ in range(4):
        u, v = rng.standard_normal(p.n), rng.standard_normal(p.n)
        fd = (
            lag(_move(p, x, hh * (u + v)))
            - lag(_move(p, x, hh * (u - v)))
            - lag(_move(p, x, hh * (v - u)))
            + lag(_move(p, x, -hh * (u + v)))
        ) / (4 * hh * hh)
        assert abs(fd - u @ H @ v) < 1e-4 * max(1.0, np.abs(H).max()) * np.linalg.norm(
            u
        ) * np.linalg.norm(v)
    assert np.allclose(H, 0.5 * (C + C.T))
    assert np.abs(C - C.T).max() > 1e-3  # the paper's 𝕳 is not symmetric away from ∇L = 0


def _tail_ratios(result, power: float) -> np.ndarray:
    e = np.asarray(result.history.kkt_error)
    e = e[e > 1e-13]
    return e[1:] / e[:-1] ** power


def test_quadratic_local_convergence_on_an_active_instance() -> None:
    inst = sample_instance("so", 0, 15)  # G_d(0,0) = 0.71 > 0.5: constraint active, ν* > 0
    p = make_problem(inst)
    r = solve_mlgipm(p, inst.G0, tol=1e-13, line_search=False)
    assert r.status is RIPMStatus.CONVERGED
    assert r.z[0] > 1e-3  # the active constraint has a positive multiplier
    e = np.asarray(r.history.kkt_error)
    tail = np.flatnonzero((e < 1e-2) & (e > 1e-12))
    assert len(tail) >= 2
    q = e[tail[1:]] / e[tail[:-1]] ** 2
    assert np.all(q < 50.0), q  # ‖F_{k+1}‖ ≤ C‖F_k‖²
    assert e[tail[-1] + 1] / e[tail[-1]] < 1e-2


def test_inexact_steps_with_rho_proportional_to_F_converge_linearly() -> None:
    inst = sample_instance("so", 0, 15)
    p = make_problem(inst)
    r = solve_mlgipm(p, inst.G0, tol=1e-10, rho=0.3, rho_seed=1, line_search=False)
    assert r.status is RIPMStatus.CONVERGED
    lin = _tail_ratios(r, 1.0)[-5:]
    assert np.all(lin < 0.9)  # contraction ...
    assert np.median(lin) > 0.02  # ... but not superlinear
    exact = solve_mlgipm(p, inst.G0, tol=1e-10, line_search=False)
    assert exact.iterations < r.iterations


def test_infeasible_instance_ends_without_success_or_nan() -> None:
    inst = sample_instance("so", 0, 3)
    p = SOLogProblem(inst.Gd, bounds=(-1.5, 0.3))  # G[0,0] ≥ -1 on SO(n): infeasible
    for r in (
        solve_mlgipm(p, inst.G0, max_iter=60),
        solve_mlgipm(p, inst.G0, MLGIPMOptions.paper(max_iter=60)),
        solve_lai_yoshise(p, inst.G0, LaiYoshiseOptions(max_iter=60)),
    ):
        assert not r.success
        assert r.status is not RIPMStatus.CONVERGED
        for v in (r.x, r.z, r.s, r.y, r.objective, r.kkt_error):
            assert np.all(np.isfinite(v))


def test_bad_input_raises_mbplan_errors() -> None:
    inst = sample_instance("so", 0, 0)
    p = make_problem(inst)
    off = inst.G0.copy()
    off[0] *= 1.01  # not orthogonal
    with pytest.raises(InputError, match="orthogonal"):
        solve_mlgipm(p, off)
    nan = inst.G0.copy()
    nan[1, 2, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        solve_mlgipm(p, nan)
    with pytest.raises(InputError, match="NaN"):
        solve_lai_yoshise(p, nan)
    with pytest.raises(InputError, match="determinant"):
        SLTraceProblem(2.0 * np.eye(7))
    with pytest.raises(InputError, match="logarithm"):
        SL(7).log(np.diag([-1.0, -1.0, 1, 1, 1, 1, 1]))
    with pytest.raises(InputError, match="lagrangian_curvature"):
        solve_mlgipm(hs071(), HS071_X0, curvature="exact")
    with pytest.raises(InputError, match="unknown"):
        solve_mlgipm(p, inst.G0, sigmaa=0.2)
    with pytest.raises(InputError, match="out of range"):
        MLGIPMOptions(sigma=1.5)
    with pytest.raises(InputError):
        sample_instance("se3", 0, 0)


def test_mlgipm_and_lai_yoshise_solve_hs071() -> None:
    """On a Euclidean NLP (symmetric Hessian only) both reach IPOPT's optimum 17.014017."""
    for r in (solve_mlgipm(hs071(), HS071_X0), solve_lai_yoshise(hs071(), HS071_X0)):
        assert r.success
        assert r.objective == pytest.approx(17.0140173, abs=1e-5)


def test_sl_problem_certificate_and_all_methods_agree() -> None:
    inst = sample_instance("sl", 0, 1)
    p = make_problem(inst)
    for r in (
        solve_mlgipm(p, inst.G0),
        solve_lai_yoshise(p, inst.G0),
        solve_ripm(p, inst.G0, max_iter=200, tol=1e-8),
    ):
        assert r.success, r.status
        assert r.objective == pytest.approx(p.optimum(), abs=1e-6)
        assert np.allclose(np.linalg.det(r.x), 1.0, atol=1e-9)  # the exp update stays on SL(7)


def test_samplers_are_seeded_and_on_the_group() -> None:
    a, b = sample_instance("so", 3, 7), sample_instance("so", 3, 7)
    assert np.array_equal(a.G0, b.G0) and np.array_equal(a.Gd, b.Gd)
    assert np.allclose(a.Gd.T @ a.Gd, np.eye(7)) and np.linalg.det(a.Gd) == pytest.approx(1.0)
    s = sample_instance("sl", 3, 7)
    assert np.allclose(np.linalg.det(s.G0), 1.0)
    retracted = make_problem(s).retract(s.G0, np.ones(96) * 0.01)
    expected = s.G0[0] @ scipy.linalg.expm(SL(7).hat(np.ones(48) * 0.01))
    assert np.allclose(retracted[0], expected)


def test_statistics_reproduce_the_papers_effect_sizes() -> None:
    from mbplan.benchmarks.lie_ipm_stats import cohens_d, lilliefors_p, proportions

    # Tables I, III, IV success rates with n = 1000 per arm: V = 0.628, 0.660, 0.563; Z = 29.6, 25.21
    assert proportions(991, 1000, 416, 1000)["cramers_v"] == pytest.approx(0.628, abs=2e-3)
    t3 = proportions(981, 1000, 359, 1000)
    assert t3["cramers_v"] == pytest.approx(0.660, abs=2e-3) and t3["z"] == pytest.approx(
        29.6, abs=0.05
    )
    assert t3["chi2_p"] < 1e-100  # the paper's "p = 1" is the CDF
    assert proportions(937, 1000, 408, 1000)["z"] == pytest.approx(25.21, abs=0.02)
    rng = np.random.default_rng(0)
    assert lilliefors_p(rng.exponential(size=300), n_mc=199) < 0.05
    assert lilliefors_p(rng.standard_normal(300), n_mc=199) > 0.01
    assert cohens_d([0.0, 1.0, 2.0], [1.0, 2.0, 3.0]) == pytest.approx(-1.0)


def test_bench_lie_ipm_writes_the_issue_schema_and_resumes(tmp_path) -> None:
    from mbplan.benchmarks.lie_ipm import run

    out = tmp_path / "so7"
    run(out, problem="so7", n=3, methods=("mlgipm", "lai-yoshise"))
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) == {"problem", "methods"} and summary["problem"] == "so7"
    keys = set(SUMMARY_KEYS)
    for entry in summary["methods"].values():
        assert set(entry) == keys and entry["n"] == 3
    assert summary["methods"]["mlgipm"]["success"] == 3
    lines = (out / "results.jsonl").read_text().splitlines()
    run(out, problem="so7", n=3, methods=("mlgipm", "lai-yoshise"))
    assert (out / "results.jsonl").read_text().splitlines() == lines
    assert "Success Rate" in (out / "results.md").read_text() and (out / "study.png").exists()
    with pytest.raises(InputError, match="ipopt"):
        run(tmp_path / "x", problem="so7", n=1, methods=("ipopt",))


def test_mlgipm_plans_a_drone_docking_case_through_the_planning_registry() -> None:
    import mbplan as mb
    from mbplan.solvers.dispatch import options_for, solve_with
    from mbplan.tasks import paper

    ocp = paper.drone_docking_cases(1, 0, with_input_limits=True)[0]
    result = mb.plan(ocp, "mlgipm", tol=1e-6, max_iter=100)
    assert result.success, result.message
    assert result.status == "CONVERGED" and result.kkt_history[-1].max() <= 1e-6
    check = mb.verify(result)  # the inputs replay through the LGVI simulator
    assert check.passed, check.reasons
    assert check.max_joint_deviation_rad < 1e-3
    with pytest.raises(InputError, match="MLGIPMOptions"):
        solve_with("mlgipm", hs071(), HS071_X0, options_for("ripm"))
    with pytest.raises(InputError, match="unknown solver"):
        options_for("newton")


def test_reduced_sparse_newton_step_equals_the_full_system() -> None:
    """The LDLᵀ of the reduced symmetric system gives the step of the full 𝕵_F (sparse LU)."""
    from mbplan.formulations.free_body import FreeBodyNLP
    from mbplan.planning.initial_guess import initial_path
    from mbplan.solvers.lie_ipm.kkt_field import (
        NewtonSolver,
        evaluate_field,
        initial_duals,
        newton_matrix,
        solve_newton,
    )
    from mbplan.tasks import paper

    ocp = paper.drone_docking_cases(1, 0, with_input_limits=True)[0]
    nlp = FreeBodyNLP(ocp, jit=False)
    p = nlp.problem
    x0 = nlp.initial_point(initial_path(ocp, "linear"))
    it = initial_duals(p, x0, None, None, None, 1e-2, 1.0)
    it.nu = np.random.default_rng(0).uniform(0.5, 2.0, p.n_ineq)
    fv = evaluate_field(p, it)
    rhs = -fv.vector(0.05)
    K = newton_matrix(p, it, fv, "symmetric")
    assert K.shape[0] > 600  # the sparse path
    full, _ = solve_newton(K, rhs)
    reduced = NewtonSolver(p, "symmetric")._reduced(it, fv, rhs)
    assert reduced is not None
    assert np.abs(reduced - full).max() < 1e-8 * max(1.0, np.abs(full).max())


def test_mlgipm_plans_an_ocp_through_the_planning_registry():
    """``mbplan.plan(ocp, "mlgipm")``: the maximal-coordinate LGVI of an OCP solved by MLG-IPM,
    with the same result type, success rule and independent verification as the RIPM."""
    import mbplan as mb

    q0 = np.zeros(6)
    q0[1] = -1.0
    ocp = mb.OCP(mb.load_robot("ur5"), N=6, dt=0.1, q0=q0)
    ocp.add_cost("velocity", mb.residuals.JointVelocity(), 1e-2)
    ocp.add_cost("effort", mb.residuals.JointTorque(), 1e-4)
    ocp.add_terminal_constraint("goal", mb.residuals.JointPosition(q0 + 0.2))
    result = mb.plan(ocp, "mlgipm", warm_start="linear", max_iter=200)
    assert result.method == "mlgipm" and result.formulation == "maximal"
    assert result.status == "CONVERGED" and result.success
    np.testing.assert_allclose(result.q[-1], q0 + 0.2, atol=1e-6)
    assert mb.verify(result).passed
    with pytest.raises(InputError, match=r"unknown MLG-IPM option\(s\): \[.sigmaa.\]"):
        mb.plan(ocp, "mlgipm", options={"sigmaa": 0.2})
