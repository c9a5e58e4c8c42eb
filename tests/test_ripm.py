"""The generic RIPM solver (mbplan.solvers): optimality against IPOPT and independent references,
failure statuses with finite iterates, options, and the sparse LDLᵀ with inertia."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest
import scipy.sparse as sp
from reference_problems import (
    HS071_X0,
    INFEASIBLE_X0,
    BandedControlNLP,
    hs071,
    infeasible_equality,
    infeasible_inequalities,
)
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from mbplan.errors import InputError
from mbplan.solvers import (
    EuclideanNLP,
    ManifoldNLP,
    RIPMOptions,
    RIPMProblem,
    RIPMStatus,
    solve_ripm,
)
from mbplan.solvers.kkt.system import KKTSystem
from mbplan.solvers.ripm.barrier import MU_MIN


def _ipopt(x, f, g, x0, lbg, ubg):
    opts = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.tol": 1e-12,
        "ipopt.bound_relax_factor": 0.0,
    }
    solver = ca.nlpsol("s", "ipopt", {"x": x, "f": f, "g": g}, opts)
    sol = solver(x0=x0, lbg=lbg, ubg=ubg)
    assert solver.stats()["success"]
    return np.array(sol["x"]).ravel(), float(sol["f"]), np.array(sol["lam_g"]).ravel()


def _independent_kkt_error(problem: EuclideanNLP, res) -> float:
    """E_0 of eq. 55-56 / WB eq. 5 recomputed from the problem's own callables."""
    x = res.x
    r_d = (
        problem.gradient(x) + problem.eq_jacobian(x).T @ res.y + problem.ineq_jacobian(x).T @ res.z
    )
    primal = max(np.abs(problem.eq(x)).max(initial=0), np.abs(problem.ineq(x) + res.s).max())
    s_max = 100.0
    s_d = max(s_max, (np.abs(res.y).sum() + np.abs(res.z).sum()) / (len(res.y) + len(res.z)))
    s_c = max(s_max, np.abs(res.z).sum() / len(res.z))
    return max(
        np.abs(r_d).max() / (s_d / s_max), primal, np.abs(res.s * res.z).max() / (s_c / s_max)
    )


# ---------------------------------------------------------------------------- HS071
def test_hs071_matches_ipopt():
    res = solve_ripm(hs071(), HS071_X0)
    assert res.status is RIPMStatus.CONVERGED and res.success
    x = ca.SX.sym("x", 4)
    f = x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2]
    g = ca.vertcat(x[0] * x[1] * x[2] * x[3], ca.sumsqr(x), x)
    lbg = [25, 40, 1, 1, 1, 1]
    ubg = [ca.inf, 40, 5, 5, 5, 5]
    x_ip, f_ip, lam = _ipopt(x, f, g, HS071_X0, lbg, ubg)
    assert np.max(np.abs(res.x - x_ip)) < 1e-8
    assert abs(res.objective - f_ip) < 1e-8
    assert abs(res.objective - 17.0140172891) < 1e-9  # the published optimum
    # multipliers: y of Σx² - 40 = 0 is IPOPT's λ; z of 25 - Πx ≤ 0 is -λ; z of 1 - x₁ ≤ 0 too
    assert abs(res.y[0] - lam[1]) < 1e-7
    assert abs(res.z[0] + lam[0]) < 1e-7
    assert abs(res.z[1] + lam[2]) < 1e-7
    assert res.iterations <= 15


def test_a_problem_s_accept_sees_every_accepted_iterate_in_order():
    problem = hs071()
    seen = []
    problem.accept = lambda x: seen.append(np.array(x, dtype=float))
    res = solve_ripm(problem, HS071_X0)
    assert res.status is RIPMStatus.CONVERGED
    assert len(seen) == res.iterations
    np.testing.assert_array_equal(seen[-1], res.x)


def test_kkt_error_at_solution_is_below_tol():
    problem = hs071()
    res = solve_ripm(problem, HS071_X0, tol=1e-10)
    assert res.success
    assert res.kkt_error <= 1e-10
    assert _independent_kkt_error(problem, res) <= 1e-10
    assert np.all(res.z > 0) and np.all(res.s > 0)
    assert np.all(problem.ineq(res.x) <= 1e-10)  # g(x) ≤ 0 up to the tolerance
    hist = res.history.arrays()
    assert len(hist["kkt_error"]) == res.iterations + 1
    assert hist["kkt_error"][-1] == pytest.approx(res.kkt_error)
    assert np.all(np.diff(hist["time_s"]) >= 0)
    assert np.all(hist["mu"][1:] <= hist["mu"][:-1])  # monotone barrier update


# ---------------------------------------------------------------------------- SO(3)
def _skew_part(b: np.ndarray) -> np.ndarray:
    """``a`` with ``tr(B ξ^) = a·ξ``."""
    return np.array([b[1, 2] - b[2, 1], b[2, 0] - b[0, 2], b[0, 1] - b[1, 0]])


def _sym_part(b: np.ndarray) -> np.ndarray:
    """Hessian at 0 of ``ξ ↦ tr(B exp(ξ^))``: ``sym(B) - tr(B) I`` (from ``ξ^² = ξξᵀ - |ξ|²I``)."""
    return 0.5 * (b + b.T) - np.trace(b) * np.eye(3)


class NearestRotation(ManifoldNLP):
    """``min ‖R - M‖²_F`` s.t. ``(R e₃)_z ≥ c`` on SO(3), retraction ``R exp(ξ^)``.

    Pullbacks: ``f(R exp ξ^) = const - 2 tr(MᵀR exp ξ^)`` and ``g = c - tr(e₃e₃ᵀR exp ξ^)``, so
    gradients and Hessians at ξ = 0 follow from :func:`_skew_part` and :func:`_sym_part`."""

    n, n_eq, n_ineq = 3, 0, 1

    def __init__(self, target: np.ndarray, c: float) -> None:
        self.target, self.c = target, c

    def retract(self, rot: np.ndarray, xi: np.ndarray) -> np.ndarray:
        return rot @ pin.exp3(xi)

    def objective(self, rot: np.ndarray) -> float:
        return float(np.sum((rot - self.target) ** 2))

    def gradient(self, rot: np.ndarray) -> np.ndarray:
        return -2 * _skew_part(self.target.T @ rot)

    def ineq(self, rot: np.ndarray) -> np.ndarray:
        return np.array([self.c - rot[2, 2]])

    def ineq_jacobian(self, rot: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix(-_skew_part(np.outer([0, 0, 1], rot[2]))[None, :])

    def lagrangian_hessian(self, rot, obj_factor, y, z) -> sp.csr_matrix:
        b_f, b_g = self.target.T @ rot, np.outer([0, 0, 1], rot[2])
        return sp.csr_matrix(-2 * obj_factor * _sym_part(b_f) - z[0] * _sym_part(b_g))


def test_so3_derivatives_are_those_of_the_pullback():
    rng = np.random.default_rng(1)
    prob = NearestRotation(rng.normal(size=(3, 3)), 0.3)
    rot = pin.exp3(rng.normal(size=3))
    z = np.array([0.7])

    def lagrangian(xi):
        r = prob.retract(rot, xi)
        return prob.objective(r) + z @ prob.ineq(r)

    h = 1e-4
    eye = np.eye(3)
    grad_fd = np.array([(lagrangian(h * e) - lagrangian(-h * e)) / (2 * h) for e in eye])
    hess_fd = np.array(
        [
            [
                (
                    lagrangian(h * (a + b))
                    - lagrangian(h * (a - b))
                    - lagrangian(h * (b - a))
                    + lagrangian(-h * (a + b))
                )
                / (4 * h * h)
                for b in eye
            ]
            for a in eye
        ]
    )
    grad = prob.gradient(rot) + prob.ineq_jacobian(rot).T @ z
    assert np.allclose(grad, grad_fd, atol=1e-7)
    assert np.allclose(prob.lagrangian_hessian(rot, 1.0, None, z).toarray(), hess_fd, atol=1e-6)


def test_so3_nearest_rotation_with_active_constraint():
    rng = np.random.default_rng(3)
    target = pin.exp3(np.array([1.0, 0.0, 0.0])) + 0.1 * rng.normal(size=(3, 3))
    c = 0.8
    prob = NearestRotation(target, c)
    assert isinstance(prob, RIPMProblem)
    res = solve_ripm(prob, np.eye(3))
    assert res.status is RIPMStatus.CONVERGED
    rot = res.x
    assert np.allclose(rot.T @ rot, np.eye(3), atol=1e-12) and np.linalg.det(rot) > 0
    assert abs(rot[2, 2] - c) < 1e-9 and res.z[0] > 0.1  # the constraint is active

    # the unconstrained optimum (polar factor) violates the constraint ...
    u, _, vt = np.linalg.svd(target)
    polar = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    assert polar[2, 2] < c - 0.1

    # ... and an independent solver over rotation vectors (SLSQP) finds the same optimum
    def objective(v):
        return np.sum((Rotation.from_rotvec(v).as_matrix() - target) ** 2)

    def constraint(v):
        return Rotation.from_rotvec(v).as_matrix()[2, 2] - c

    ref = minimize(
        objective,
        Rotation.from_matrix(polar).as_rotvec(),
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": constraint}],
        options={"ftol": 1e-15, "maxiter": 500},
    )
    rot_ref = Rotation.from_rotvec(ref.x).as_matrix()
    assert np.max(np.abs(rot - rot_ref)) < 1e-6
    assert res.objective <= ref.fun + 1e-10


# ---------------------------------------------------------------------------- failures
def _assert_finite(res):
    assert np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.y))
    assert np.all(np.isfinite(res.z)) and np.all(np.isfinite(res.s)) and np.all(res.s > 0)
    assert not res.success


def test_infeasible_equality_is_detected():
    res = solve_ripm(infeasible_equality(), INFEASIBLE_X0)
    assert res.status is RIPMStatus.LOCALLY_INFEASIBLE
    _assert_finite(res)
    assert abs(res.x[0]) < 1e-6  # the minimizer of the infeasibility x₁² + 1
    assert res.inf_pr == pytest.approx(1.0, abs=1e-9)


def test_infeasible_inequalities_are_detected():
    res = solve_ripm(infeasible_inequalities(), INFEASIBLE_X0)
    assert res.status is RIPMStatus.LOCALLY_INFEASIBLE
    _assert_finite(res)
    assert any(res.history.restoration)


def _wachter_biegler() -> EuclideanNLP:
    """min x₁ s.t. x₁² - x₂ - 1 = 0, x₁ - x₃ - ½ = 0, x₂, x₃ ≥ 0; x* = (1, 0, ½)."""
    return EuclideanNLP(
        3,
        lambda x: x[0],
        lambda x: np.array([1.0, 0.0, 0.0]),
        lambda x, s, y, z: np.diag([2 * y[0], 0.0, 0.0]),
        eq=lambda x: np.array([x[0] ** 2 - x[1] - 1, x[0] - x[2] - 0.5]),
        eq_jacobian=lambda x: np.array([[2 * x[0], -1.0, 0.0], [1.0, 0.0, -1.0]]),
        n_eq=2,
        ineq=lambda x: -x[1:],
        ineq_jacobian=lambda x: np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]),
        n_ineq=2,
    )


def test_wachter_biegler_example():
    """Infeasible-start Newton steps with fraction-to-boundary stall at a non-stationary point
    from (-2, 1, 1) (Wächter & Biegler 2000). The RIPM does not: from there it proves local
    infeasibility at x₁ = -1, x₂ = 0, a local minimizer of the ℓ1 infeasibility (1.5 there,
    larger on both sides), where IPOPT ends too (MUMPS; every μ strategy); from (-0.4, 1, 1),
    past the infeasibility's ridge at x₁ = -½, it converges to x* (IPOPT: infeasible)."""
    x = ca.SX.sym("x", 3)
    g = ca.vertcat(x[0] ** 2 - x[1] - 1, x[0] - x[2] - 0.5, x[1], x[2])
    ipopt = ca.nlpsol(
        "s", "ipopt", {"x": x, "f": x[0], "g": g}, {"print_time": False, "ipopt.print_level": 0}
    )
    ref = ipopt(x0=[-2, 1, 1], lbg=[0, 0, 0, 0], ubg=[0, 0, ca.inf, ca.inf])
    assert ipopt.stats()["return_status"] == "Infeasible_Problem_Detected"
    assert np.allclose(np.array(ref["x"]).ravel()[:2], [-1.0, 0.0], atol=1e-6)
    for options in ({}, {"max_ls_trials": 3}, {"mu_strategy": "monotone", "corrector": False}):
        res = solve_ripm(_wachter_biegler(), np.array([-2.0, 1.0, 1.0]), **options)
        assert res.status is RIPMStatus.LOCALLY_INFEASIBLE, options
        assert np.allclose(res.x[:2], [-1.0, 0.0], atol=1e-6)
        res = solve_ripm(_wachter_biegler(), np.array([-0.4, 1.0, 1.0]), **options)
        assert res.success and np.allclose(res.x, [1.0, 0.0, 0.5], atol=1e-8), options


def _rank_deficient() -> EuclideanNLP:
    """min (x₁ - 2)² + x₂² s.t. x₁ - 1 = 0, (x₁ - 1)² = 0; x* = (1, 0)."""
    return EuclideanNLP(
        2,
        lambda x: (x[0] - 2) ** 2 + x[1] ** 2,
        lambda x: np.array([2 * (x[0] - 2), 2 * x[1]]),
        lambda x, s, y, z: np.diag([2 * s + 2 * y[1], 2 * s]),
        eq=lambda x: np.array([x[0] - 1, (x[0] - 1) ** 2]),
        eq_jacobian=lambda x: np.array([[1.0, 0.0], [2 * (x[0] - 1), 0.0]]),
        n_eq=2,
    )


def test_rank_deficient_equality_jacobian_keeps_multipliers_bounded():
    """The Jacobian has rank 1 everywhere (LICQ fails, constant rank) and the linearized
    constraints are inconsistent off x*: ``K`` is singular. With the ±ε static regularization as
    the only dual regularization ``y₂`` grew like ``1/ε`` (2e9 from (1.5, 0), 15-20 iterations);
    the stalled refinement now gives ``δ_c`` of the residual's size (``NewtonStep._delta_c``)."""
    for x0 in ([3.0, 1.0], [0.0, 0.5], [1.5, 0.0]):
        res = solve_ripm(_rank_deficient(), np.array(x0))
        assert res.status is RIPMStatus.CONVERGED and np.allclose(res.x, [1.0, 0.0], atol=1e-8)
        assert res.y[0] == pytest.approx(2.0, abs=1e-8)
        assert np.max(np.abs(res.y)) <= 100 and res.iterations <= 10


def test_least_squares_multipliers_without_inequalities_and_after_restoration():
    """The start's ``y₀`` of an equality-only problem is the least-squares solution of
    ``A_Eᵀy = -∇f``; with ``resto_ls_multipliers`` the Wächter–Biegler example leaves its
    restoration phase with least-squares ``y`` (the Newton system reused) and converges."""
    problem = EuclideanNLP(
        3,
        lambda x: x[0] ** 2 + 2 * x[1] ** 2 + x[2],
        lambda x: np.array([2 * x[0], 4 * x[1], 1.0]),
        lambda x, s, y, z: np.diag([2 * s, 4 * s, 0.0]),
        eq=lambda x: np.array([x.sum() - 1, x[0] - x[2]]),
        eq_jacobian=lambda x: np.array([[1.0, 1.0, 1.0], [1.0, 0.0, -1.0]]),
        n_eq=2,
    )
    x0 = np.array([0.3, -0.2, 0.1])
    y0 = solve_ripm(problem, x0, max_iter=0, constr_mult_init_max=1e3).y
    a = problem.evaluate(x0).eq_jacobian.toarray()
    expected = np.linalg.lstsq(a.T, -problem.evaluate(x0).gradient, rcond=None)[0]
    np.testing.assert_allclose(y0, expected, rtol=1e-10, atol=1e-12)
    from mbplan.solvers.ripm.newton import NewtonStep

    calls = []
    least_squares = NewtonStep.least_squares_y

    def counted(self, ev, z, limit):
        calls.append(ev)
        return least_squares(self, ev, z, limit)

    for flag in (True, False):  # at the start (and on leaving each restoration phase)
        calls.clear()
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(NewtonStep, "least_squares_y", counted)
            res = solve_ripm(
                _wachter_biegler(), np.array([-0.4, 1.0, 1.0]), resto_ls_multipliers=flag
            )
        assert any(res.history.restoration) and (len(calls) > 1) == flag, calls
        assert res.success and np.allclose(res.x, [1.0, 0.0, 0.5], atol=1e-8)


def _outside_disc() -> EuclideanNLP:
    """min (x₁ - 2)² + x₂² s.t. x₁² + x₂² ≥ 1 (a concave g): x* = (2, 0)."""
    return EuclideanNLP(
        2,
        lambda x: (x[0] - 2) ** 2 + x[1] ** 2,
        lambda x: np.array([2 * (x[0] - 2), 2 * x[1]]),
        lambda x, s, y, z: (2 * s - 2 * z[0]) * np.eye(2),
        ineq=lambda x: np.array([1.0 - x[0] ** 2 - x[1] ** 2]),
        ineq_jacobian=lambda x: np.array([[-2 * x[0], -2 * x[1]]]),
        n_ineq=1,
    )


def test_elastic_restoration_escapes_jamming():
    """Started near the centre of the disc, the slack of the violated concave constraint is
    driven to zero and z blows up (jamming): the main loop's line search fails. The elastic ℓ1
    restoration phase (WB §3.3) moves x out."""
    x0 = np.array([0.0, 1e-3])
    res = solve_ripm(_outside_disc(), x0)
    assert res.status is RIPMStatus.CONVERGED
    assert np.allclose(res.x, [2.0, 0.0], atol=1e-8)
    resto = np.flatnonzero(res.history.restoration)
    assert resto.size and resto[-1] < res.iterations - 2
    off = solve_ripm(_outside_disc(), x0, restoration=False)
    assert off.status is RIPMStatus.LINE_SEARCH_FAILED and not any(off.history.restoration)


def test_multipliers_of_a_blocked_step_follow_the_primal_step(monkeypatch):
    """From near the disc's centre the slack's fraction-to-the-boundary step is ``α_s ≈ 5e-6``:
    with ``dual_step_cap`` (default 1e-2) ``z`` steps ``α_z = α_s`` there, with 0 its own full
    ``α_z`` (WB eq. 15); steps with ``α_s`` at or above the cap keep their own ``α_z``. Both
    solve the test problems; a cap outside [0, 1] is rejected by name."""
    from mbplan.solvers.ripm.iterate import frac_to_boundary
    from mbplan.solvers.ripm.phase import Phase

    multipliers_at = Phase.multipliers_at
    steps = []

    def recorded(self, it, step, alpha, s, mu, tau):
        y, z, alpha_z = multipliers_at(self, it, step, alpha, s, mu, tau)
        if not self.resto:
            alpha_s = frac_to_boundary(it.s, step.ds, tau)
            steps.append((alpha_s, alpha_z, self.alpha_z_max(it, step, tau)))
        return y, z, alpha_z

    monkeypatch.setattr(Phase, "multipliers_at", recorded)
    for cap in (RIPMOptions().dual_step_cap, 0.0):
        steps.clear()
        res = solve_ripm(_outside_disc(), np.array([0.0, 1e-3]), dual_step_cap=cap)
        assert res.status is RIPMStatus.CONVERGED and np.allclose(res.x, [2.0, 0.0], atol=1e-8)
        blocked = [(a_s, a_z, own) for a_s, a_z, own in steps if a_s < 1e-2]
        assert blocked and all(own > 0.5 for _, _, own in blocked)
        if cap:
            assert all(a_z == min(own, a_s) for a_s, a_z, own in blocked)
        else:
            assert all(a_z == own for _, a_z, own in steps)
        assert all(a_z == own for a_s, a_z, own in steps if a_s >= 1e-2)
    _assert_solves_the_test_problems({"dual_step_cap": 0.0})
    _assert_solves_the_test_problems({"dual_step_cap": 1.0})
    for bad in (-1e-3, 2.0):
        with pytest.raises(InputError, match="dual_step_cap"):
            RIPMOptions(dual_step_cap=bad)


def _assert_solves_the_test_problems(options: dict) -> None:
    """HS071, the banded control problem and the jamming disc solved to their reference
    points with ``options``."""
    banded = BandedControlNLP(nx=4, nu=2, horizon=20)
    reference = solve_ripm(banded, banded.initial_guess())
    res = solve_ripm(hs071(), HS071_X0, **options)
    assert res.status is RIPMStatus.CONVERGED, options
    assert abs(res.objective - 17.0140172891) < 1e-8
    res = solve_ripm(banded, banded.initial_guess(), **options)
    assert res.status is RIPMStatus.CONVERGED, options
    assert abs(res.objective - reference.objective) < 1e-7 * abs(reference.objective)
    res = solve_ripm(_outside_disc(), np.array([0.0, 1e-3]), **options)
    assert res.success and np.allclose(res.x, [2.0, 0.0], atol=1e-6), options


def test_adaptive_mu_option():
    """Adaptive μ (LOQO's or Mehrotra's probing oracle) still solves HS071, the banded control
    problem and the jamming example, and is not monotone; removed options are rejected by
    name."""
    uncapped = {"mu_strategy": "adaptive", "mu_max_fact": 1e3, "corrector": False}
    variants = (uncapped | {"mu_oracle": "loqo"}, uncapped | {"mu_oracle": "probing"})
    for options in variants:
        _assert_solves_the_test_problems(options)
    mu = np.array(solve_ripm(hs071(), HS071_X0, **variants[0]).history.mu)
    assert np.any(np.diff(mu) > 0)
    with pytest.raises(InputError, match="mu_strategy"):
        RIPMOptions(mu_strategy="mehrotra")
    for removed in ("restoration_method", "watchdog_shortened_iter_trigger", "regularize_slacks"):
        with pytest.raises(InputError, match=removed):
            RIPMOptions().replace(**{removed: 1})


def test_adaptive_mu_stays_above_its_floor_at_unreachable_tolerance():
    """With ``tol = 1e-20`` the probing oracle would choose μ = 1e-21, where ``τ = 1 - μ``
    rounds to 1 and a slack reaches 0 (non-finite derivatives); μ stops at ``MU_MIN`` and the
    solve ends at the tiny-step rule, with the adaptive and with the monotone strategy."""
    adaptive = {"mu_strategy": "adaptive", "mu_oracle": "probing", "mu_max_fact": 0.0}
    for options in (adaptive | {"corrector": True}, {"mu_strategy": "monotone"}):
        res = solve_ripm(hs071(), HS071_X0, tol=1e-20, **options)
        assert res.status is RIPMStatus.ACCEPTABLE and res.success, options
        assert min(res.history.mu) >= MU_MIN, options
        assert abs(res.objective - 17.0140172891) < 1e-8


def test_mehrotra_corrector_and_mu_cap_options():
    """``corrector`` (Mehrotra's second-order term, monotone or with the probing oracle) and
    ``mu_max_fact = 0`` (adaptive μ capped at μ_init) solve HS071, the banded control problem and
    the jamming example to the reference points; the corrector changes the iterates; bad values
    are rejected by name."""
    banded = BandedControlNLP(nx=4, nu=2, horizon=20)
    probing = {"mu_strategy": "adaptive", "mu_oracle": "probing", "mu_max_fact": 1e3}
    variants = (
        {"mu_strategy": "monotone", "corrector": True},
        {**probing, "corrector": True},
        {**probing, "mu_max_fact": 0.0, "corrector": False},
        {**probing, "mu_max_fact": 0.0, "corrector": True},
    )
    for options in variants:
        _assert_solves_the_test_problems(options)
    plain = solve_ripm(hs071(), HS071_X0, corrector=False).history.objective
    corrected = solve_ripm(hs071(), HS071_X0, corrector=True).history.objective
    assert len(plain) != len(corrected) or not np.allclose(plain, corrected)
    capped = solve_ripm(banded, banded.initial_guess(), **(probing | {"mu_max_fact": 0.0}))
    assert max(capped.history.mu) <= RIPMOptions().mu_init
    with pytest.raises(InputError, match="mu_max_fact"):
        RIPMOptions(mu_max_fact=-1.0)
    with pytest.raises(InputError, match="corrector"):
        RIPMOptions(corrector=1)


def test_degenerate_mode_retries_zero_once_the_perturbation_is_small():
    """Drone case 0: δ_w > 0 on consecutive iterations puts the inertia correction in the
    ``degenerate_iters`` mode (first trial ``κ_w⁻ δ_w,last``). Without
    ``degenerate_zero_below`` δ_w only shrinks 3× per iteration to the end; with it, once the
    first trial would fall below the bound the zero trial runs again, succeeds on this positive
    definite tail and the solve needs fewer iterations and factorizations."""
    from mbplan.tasks.speed import TASKS

    problem, x0, options = TASKS["drone"](0)
    options = options.replace(kappa_curvature=0.0)  # the inertia alone decides, as in WB
    runs = {
        z: solve_ripm(problem, x0, options.replace(degenerate_zero_below=z)) for z in (0.0, 1e-2)
    }
    never, default = (np.array(runs[z].history.delta_w[1:]) for z in (0.0, 1e-2))
    assert all(r.status is RIPMStatus.CONVERGED for r in runs.values())
    start = int(np.argmax(never > 0))  # the first perturbed iteration; the mode follows
    assert np.all(never[start:] > 0) and never[-1] < 1e-2
    tail = default[start + options.degenerate_iters :]
    assert tail[-1] == 0.0 and np.all(tail[tail > 0] >= 1e-2 * options.kappa_w_minus)
    assert runs[1e-2].iterations < runs[0.0].iterations
    assert runs[1e-2].n_factorizations < runs[0.0].n_factorizations
    with pytest.raises(InputError, match="degenerate_zero_below"):
        RIPMOptions(degenerate_zero_below=-1.0)


def _sqrt_problem(objective) -> EuclideanNLP:
    return EuclideanNLP(
        1,
        objective,
        lambda x: np.array([1.0 - 1.0 / np.sqrt(x[0])]),
        lambda x, s, y, z: np.array([[s * 0.5 * x[0] ** -1.5]]),
    )


def test_nan_objective_trial_is_backtracked():
    """f = x - 2√x: the Newton step from 4 lands at -4 where f is NaN."""

    def objective(x):
        with np.errstate(invalid="ignore"):
            return x[0] - 2 * np.sqrt(x[0])

    res = solve_ripm(_sqrt_problem(objective), np.array([4.0]))
    assert res.status is RIPMStatus.CONVERGED
    assert res.x[0] == pytest.approx(1.0, abs=1e-9)
    assert res.history.ls_trials[1] >= 2


def test_nan_everywhere_ends_with_numerical_error():
    x0 = np.array([4.0])

    def objective(x):
        return x[0] - 2 * np.sqrt(x[0]) if np.array_equal(x, x0) else np.nan

    res = solve_ripm(_sqrt_problem(objective), x0)
    assert res.status is RIPMStatus.NUMERICAL_ERROR
    _assert_finite(res)
    assert np.isfinite(res.objective) and np.array_equal(res.x, x0)

    res0 = solve_ripm(_sqrt_problem(lambda x: np.nan), x0)
    assert res0.status is RIPMStatus.NUMERICAL_ERROR and res0.iterations == 0
    _assert_finite(res0)


# ---------------------------------------------------------------------------- options, log
def test_defaults_are_table_iv_and_overrides_apply(capsys):
    o = RIPMOptions()
    table_iv = {
        "max_iter": 200,
        "max_ls_trials": 30,
        "tol": 1e-11,
        "kappa_mu": 0.99,
        "theta_mu": 1.99,
        "tau_min": 0.995,
        "gamma_phi": 1e-6,
        "theta_min_fact": 1e-4,
        "eta_phi": 1e-4,
        "gamma_theta": 1e-4,
        "beta": 0.5,
    }
    assert {k: getattr(o, k) for k in table_iv} == table_iv

    res = solve_ripm(hs071(), HS071_X0, max_iter=3, verbose=True)
    assert res.status is RIPMStatus.MAX_ITER and not res.success
    assert res.iterations == 3 and len(res.history) == 4
    out = capsys.readouterr().out
    assert "iter    objective    inf_pr   inf_du lg(mu)" in out and "MAX_ITER" in out
    assert len([ln for ln in out.splitlines() if ln[:4].strip().isdigit()]) == 4

    res = solve_ripm(hs071(), HS071_X0, RIPMOptions(tol=1e-6, mu_init=1.0))
    assert res.success and res.history.mu[0] == 1.0 and res.kkt_error <= 1e-6
    assert capsys.readouterr().out == ""  # print_level 0 by default
    res = solve_ripm(hs071(), HS071_X0, tol=1e-20)  # unreachable: stops at the tiny-step rule
    assert res.status is RIPMStatus.ACCEPTABLE and res.success and res.kkt_error < 1e-12
    assert dataclasses.replace(o, beta=0.25).beta == 0.25
    with pytest.raises(InputError, match="unknown"):
        solve_ripm(hs071(), HS071_X0, not_an_option=1)
    with pytest.raises(InputError, match="kappa_mu"):
        RIPMOptions(kappa_mu=1.5)


# ---------------------------------------------------------------------------- structure
def test_block_banded_control_problem_matches_ipopt():
    prob = BandedControlNLP(nx=4, nu=2, horizon=20)
    res = solve_ripm(prob, prob.initial_guess())
    assert res.status is RIPMStatus.CONVERGED
    assert res.n_factorizations <= 2 * res.iterations
    assert res.n_evaluations <= res.iterations + 3  # one per iterate (+ initialization)

    nx, nu, n_k = prob.nx, prob.nu, prob.N
    x = ca.SX.sym("x", prob.n)
    knots = ca.reshape(x[: n_k * (nx + nu)], nx + nu, n_k)
    xs, us, x_end = knots[:nx, :], knots[nx:, :], x[n_k * (nx + nu) :]
    f = prob.w * ca.sumsqr(xs) + prob.r * ca.sumsqr(us) + prob.w_final * ca.sumsqr(x_end)
    drift = ca.mtimes(ca.DM(prob.A), xs) + ca.mtimes(ca.DM(prob.B), us) + prob.c * ca.sin(xs)
    dyn = ca.horzcat(xs[:, 1:], x_end) - (xs + prob.dt * drift)
    g = ca.vertcat(xs[:, 0] - prob.x_init, ca.vec(dyn), ca.vec(us))
    lbg = np.r_[np.zeros(prob.n_eq), -prob.u_max * np.ones(n_k * nu)]
    ubg = np.r_[np.zeros(prob.n_eq), prob.u_max * np.ones(n_k * nu)]
    x_ip, f_ip, _ = _ipopt(x, f, g, prob.initial_guess(), lbg, ubg)
    assert abs(res.objective - f_ip) < 1e-7 * abs(f_ip)
    assert np.max(np.abs(res.x - x_ip)) < 1e-6


def test_kkt_system_inertia_pattern_cache_and_refinement():
    rng = np.random.default_rng(0)
    n, me, mi = 30, 10, 8
    dense_h = rng.normal(size=(n, n))
    hess = sp.csr_matrix(np.tril(dense_h + dense_h.T) * (rng.random((n, n)) < 0.2))
    jac_e = sp.random(me, n, density=0.3, random_state=1, format="csr")
    jac_i = sp.random(mi, n, density=0.3, random_state=2, format="csr")
    kkt = KKTSystem(n, me, mi)
    kkt.set_matrices(hess, jac_e, jac_i)
    diag = np.concatenate([np.full(n, 0.5), np.zeros(me), -rng.random(mi)])
    inertia = kkt.factorize(diag, static_reg=1e-9)
    full = (hess + sp.tril(hess, -1).T).toarray() + 0.5 * np.eye(n)
    k_dense = np.block(
        [
            [full, jac_e.T.toarray(), jac_i.T.toarray()],
            [jac_e.toarray(), np.zeros((me, me)), np.zeros((me, mi))],
            [jac_i.toarray(), np.zeros((mi, me)), np.diag(diag[n + me :])],
        ]
    )
    eig = np.linalg.eigvalsh(k_dense)
    assert (inertia.positive, inertia.negative) == (np.sum(eig > 0), np.sum(eig < 0))
    assert inertia.zero == 0
    rhs = rng.normal(size=n + me + mi)
    sol, ratio = kkt.solve(rhs)
    assert ratio < 1e-10
    assert np.allclose(sol, np.linalg.solve(k_dense, rhs), atol=1e-8)

    kkt.set_matrices(2 * hess, jac_e, jac_i)  # same pattern: no new analysis
    kkt.factorize(diag)
    assert kkt.n_analyses == 1
    kkt.set_matrices(hess + sp.eye(n, format="csr"), jac_e, jac_i)  # new pattern
    kkt.factorize(diag)
    assert kkt.n_analyses == 2


def test_initial_equality_multipliers_option():
    """``constr_mult_init_max``: the least-squares ``y₀`` is kept only up to it in max norm
    (default 1; IPOPT's 1e3; 0: always ``y₀ = 0``); every choice solves HS071 and the
    Wächter–Biegler example (from (0, 1, 1)) to the same point; a negative bound is
    rejected."""
    wb_x0 = np.array([0.0, 1.0, 1.0])
    for bound in (0.0, 1.0, 1e3):
        res = solve_ripm(hs071(), HS071_X0, constr_mult_init_max=bound)
        assert res.success and res.objective == pytest.approx(17.0140173, abs=1e-6)
        wb = solve_ripm(_wachter_biegler(), wb_x0, constr_mult_init_max=bound)
        assert wb.success and np.allclose(wb.x, [1.0, 0.0, 0.5], atol=1e-8)
    ls = solve_ripm(hs071(), HS071_X0, max_iter=0, constr_mult_init_max=1e3).y
    assert np.any(ls != 0.0)
    big = float(np.max(np.abs(ls)))
    kept = solve_ripm(hs071(), HS071_X0, max_iter=0, constr_mult_init_max=big).y
    dropped = solve_ripm(hs071(), HS071_X0, max_iter=0, constr_mult_init_max=0.5 * big).y
    np.testing.assert_array_equal(kept, ls)
    assert np.all(dropped == 0.0)
    assert np.all(solve_ripm(hs071(), HS071_X0, max_iter=0, constr_mult_init_max=0.0).y == 0.0)
    assert RIPMOptions().constr_mult_init_max == 1.0
    with pytest.raises(InputError, match="constr_mult_init_max"):
        RIPMOptions(constr_mult_init_max=-1.0)


def test_the_start_evaluates_again_only_for_a_kept_least_squares_y0():
    """The start evaluates once, with the Hessian, and takes the slacks and the least-squares
    ``y₀`` from it; it evaluates again only when that ``y₀`` is kept (the Hessian of the
    Lagrangian depends on it). A non-finite start is a numerical error either way."""
    cold = solve_ripm(hs071(), HS071_X0, max_iter=3)  # y₀ = 0.596 kept
    assert cold.n_evaluations == cold.iterations + 2
    dropped = solve_ripm(hs071(), HS071_X0, max_iter=3, constr_mult_init_max=0.5)
    assert dropped.n_evaluations == dropped.iterations + 1
    warm = {"y0": cold.y, "z0": cold.z, "s0": cold.s}
    once = solve_ripm(hs071(), cold.x, max_iter=3, **warm)
    slacks = solve_ripm(hs071(), cold.x, max_iter=3, **{**warm, "s0": None})
    assert once.n_evaluations == once.iterations + 1
    assert slacks.n_evaluations == slacks.iterations + 1
    parabola = EuclideanNLP(
        1, lambda x: (x[0] - 1) ** 2, lambda x: 2 * (x - 1), lambda x, s, y, z: np.array([[2 * s]])
    )
    no_ls = solve_ripm(parabola, np.array([4.0]))
    assert no_ls.success and no_ls.n_evaluations == no_ls.iterations + 1
    res = solve_ripm(_sqrt_problem(lambda x: np.nan), np.array([4.0]), y0=np.zeros(0))
    assert res.status is RIPMStatus.NUMERICAL_ERROR and "derivatives" in res.message


def test_wrong_constraint_lengths_are_input_errors():
    """A problem whose constraint values do not match its declared sizes is rejected by name
    before the compiled iteration kernels index them."""
    prob = EuclideanNLP(
        2,
        lambda x: float(x @ x),
        lambda x: 2 * x,
        lambda x, s, y, z: 2 * s * np.eye(2),
        ineq=lambda x: np.array([x[0] - 1.0, x[1] - 1.0]),  # two rows, one declared
        ineq_jacobian=lambda x: np.array([[1.0, 0.0]]),
        n_ineq=1,
    )
    with pytest.raises(InputError, match="shapes"):
        solve_ripm(prob, np.zeros(2))


@pytest.mark.parametrize(
    ("make", "x0"),
    [
        (lambda: BandedControlNLP(nx=4, nu=2, horizon=20), None),
        (_outside_disc, np.array([0.0, 1e-3])),  # rejected first trials, second-order corrections
        (_wachter_biegler, np.array([-0.4, 1.0, 1.0])),  # restoration phase
    ],
)
def test_first_trials_evaluated_with_their_multipliers_take_the_same_steps(make, x0, monkeypatch):
    """The line search evaluates its first trial with the Hessian at the multipliers the step
    would be accepted with, and the accepted point reuses that evaluation: the iterates are
    those of the values-then-evaluate order, one ``values`` call fewer per accepted first trial
    and one evaluation more per rejected one."""
    from mbplan.solvers.ripm.phase import Phase

    problem = make()
    x0 = problem.initial_guess() if x0 is None else x0
    fast = solve_ripm(problem, x0)
    trial_at = Phase.trial_at
    monkeypatch.setattr(
        Phase,
        "trial_at",
        lambda self, it, step, alpha, mu, tau, evaluate=False: trial_at(
            self, it, step, alpha, mu, tau
        ),
    )
    plain = solve_ripm(problem, x0)
    assert fast.iterations == plain.iterations and fast.status == plain.status
    np.testing.assert_array_equal(fast.history.kkt_error, plain.history.kkt_error)
    np.testing.assert_array_equal(fast.history.objective, plain.history.objective)
    np.testing.assert_array_equal(
        np.concatenate([fast.y, fast.z]), np.concatenate([plain.y, plain.z])
    )
    assert fast.n_trial_evaluations < plain.n_trial_evaluations
    assert (
        fast.n_evaluations + fast.n_trial_evaluations
        <= plain.n_evaluations + plain.n_trial_evaluations
    )


def test_soft_restoration_steps_where_the_line_search_fails(monkeypatch):
    """IPOPT's soft restoration phase: where the filter line search fails (here: always), steps
    to the boundary are taken while the original filter accepts them (HS071: every one, and the
    solve ends at the optimum) or they reduce the primal-dual error (Wächter-Biegler from
    (-0.4, 1, 1): one or two steps, the path is sensitive to rounding); the first that does neither starts the restoration phase (which
    fails here: its line search too), as does every failure with ``max_soft_resto_iters=0``."""
    from mbplan.solvers.ripm.line_search import FilterLineSearch, Search
    from mbplan.solvers.ripm.phase import Phase

    reference = solve_ripm(hs071(), HS071_X0)
    monkeypatch.setattr(FilterLineSearch, "search", lambda self, *args: Search(None))
    errors = []
    pd_error = Phase.primal_dual_error

    def recorded(self, ev, y, z, s, mu):
        errors.append(pd_error(self, ev, y, z, s, mu))
        return errors[-1]

    monkeypatch.setattr(Phase, "primal_dual_error", recorded)
    soft = solve_ripm(hs071(), HS071_X0)
    assert soft.status is RIPMStatus.CONVERGED and not any(soft.history.restoration)
    np.testing.assert_allclose(soft.x, reference.x, atol=1e-8)
    assert not errors  # every step acceptable to the filter
    wb = solve_ripm(_wachter_biegler(), np.array([-0.4, 1.0, 1.0]))
    assert wb.status is RIPMStatus.LINE_SEARCH_FAILED and "restoration" in wb.message
    trials, currents = np.array(errors[::2]), np.array(errors[1::2])
    assert len(trials) in (2, 3)  # one or two soft steps, then the one that starts restoration
    assert np.all(trials[:-1] <= 0.9999 * currents[:-1]) and trials[-1] > 0.9999 * currents[-1]
    none = solve_ripm(hs071(), HS071_X0, max_soft_resto_iters=0)
    assert none.status is RIPMStatus.LINE_SEARCH_FAILED and "restoration" in none.message
    assert none.iterations == 0


def test_no_restoration_phase_at_an_almost_feasible_point(monkeypatch):
    """IPOPT's rule: where the line search fails at ‖c‖∞ ≤ min(tol/100, constr_viol_tol/10) the
    restoration phase cannot help; the solve stops there (LINE_SEARCH_FAILED, no restoration
    iteration). From an infeasible start the same failure starts the restoration phase."""
    from mbplan.solvers.ripm.line_search import FilterLineSearch, Search

    opt = solve_ripm(hs071(), HS071_X0)
    monkeypatch.setattr(FilterLineSearch, "search", lambda self, *args: Search(None))
    near = solve_ripm(hs071(), opt.x, tol=1e-6, max_soft_resto_iters=0, s0=opt.s, z0=opt.z + 1)
    assert near.status is RIPMStatus.LINE_SEARCH_FAILED and "almost feasible" in near.message
    assert near.iterations == 0 and not any(near.history.restoration)
    assert near.inf_pr <= 1e-8
    far = solve_ripm(hs071(), HS071_X0, tol=1e-6, max_soft_resto_iters=0)
    assert far.status is RIPMStatus.LINE_SEARCH_FAILED and "restoration" in far.message
    assert "almost feasible" not in far.message


def test_a_non_finite_predictor_step_leaves_mu_finite(monkeypatch):
    """A predictor solve that breaks down (NaN, e.g. a failed fallback factorization) gives
    LOQO's μ and no corrector instead of μ = NaN: HS071 still converges to its optimum."""
    from mbplan.solvers.ripm.iterate import Step
    from mbplan.solvers.ripm.newton import NewtonStep

    affine = NewtonStep._affine_step
    broken = []

    def once_nan(self):
        step = affine(self)
        if not broken:
            broken.append(self._mu)
            return Step(*(np.full_like(a, np.nan) for a in (step.dx, step.ds, step.dy, step.dz)))
        return step

    monkeypatch.setattr(NewtonStep, "_affine_step", once_nan)
    res = solve_ripm(hs071(), HS071_X0)
    assert broken and res.status is RIPMStatus.CONVERGED
    assert abs(res.objective - 17.0140172891) < 1e-8 and np.isfinite(res.history.mu).all()


def test_curvature_test_keeps_a_step_whose_inertia_only_the_regularization_spoils():
    """``min ½x₀² + ½x₁² - ½x₂²`` s.t. ``x₀ + x₁ = 1``, ``x₀ + x₁ + 10⁻⁶ x₂ = 1``: the reduced
    Hessian is positive definite and the exact KKT matrix has the right inertia, but ``A_E``'s
    smallest singular value (~7e-7) is below ``√ε`` of the static regularization ε = 1e-9, so
    the factorized matrix shows ``-x₂²`` as one negative eigenvalue too many. The step has
    positive curvature: the curvature test keeps it (one Newton step, no δ_w); the inertia
    alone regularizes along x₂, which the nearly dependent rows barely hold, and diverges."""
    e = 1e-6
    nlp = EuclideanNLP(
        3,
        lambda x: 0.5 * x[0] ** 2 + 0.5 * x[1] ** 2 - 0.5 * x[2] ** 2,
        lambda x: np.array([x[0], x[1], -x[2]]),
        lambda x, s, y, z: s * np.diag([1.0, 1.0, -1.0]),
        eq=lambda x: np.array([x[0] + x[1] - 1.0, x[0] + x[1] + e * x[2] - 1.0]),
        eq_jacobian=lambda x: np.array([[1.0, 1.0, 0.0], [1.0, 1.0, e]]),
        n_eq=2,
    )
    x0 = np.array([0.3, 0.7, 0.0])  # feasible: the test runs at nearly feasible iterates
    kept = solve_ripm(nlp, x0, tol=1e-9)
    assert kept.status is RIPMStatus.CONVERGED and kept.iterations <= 2
    assert max(kept.history.delta_w) == 0.0
    np.testing.assert_allclose(kept.x, [0.5, 0.5, 0.0], atol=1e-6)
    inertia_only = solve_ripm(nlp, x0, tol=1e-9, kappa_curvature=0.0)
    assert inertia_only.status is not RIPMStatus.CONVERGED
    assert max(inertia_only.history.delta_w) > 1.0
    with pytest.raises(InputError, match="kappa_curvature"):
        RIPMOptions(kappa_curvature=-1.0)


def test_curvature_test_still_regularizes_genuine_negative_curvature():
    """``min -½x₀² + ¼x₀⁴ + ½x₁²`` s.t. ``x₁ = 0.1`` from near the maximum at ``x₀ = 0``: the
    reduced Hessian is negative there, the Newton step has negative curvature, δ_w > 0 is used
    and the solve reaches a minimum ``x₀ = ±1``, not the stationary point at 0."""
    nlp = EuclideanNLP(
        2,
        lambda x: -0.5 * x[0] ** 2 + 0.25 * x[0] ** 4 + 0.5 * x[1] ** 2,
        lambda x: np.array([-x[0] + x[0] ** 3, x[1]]),
        lambda x, s, y, z: s * np.diag([-1.0 + 3.0 * x[0] ** 2, 1.0]),
        eq=lambda x: np.array([x[1] - 0.1]),
        eq_jacobian=lambda x: np.array([[0.0, 1.0]]),
        n_eq=1,
    )
    r = solve_ripm(nlp, np.array([1e-3, 0.0]), tol=1e-9)
    assert r.status is RIPMStatus.CONVERGED
    assert max(r.history.delta_w) > 0.0
    np.testing.assert_allclose(np.abs(r.x), [1.0, 0.1], atol=1e-6)
