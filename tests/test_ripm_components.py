"""The RIPM's components driven alone, without a solve: the filter line search on a constructed
filter, the barrier update, and the inertia correction's ``δ_w`` sequence on a small indefinite
KKT matrix (WB Algorithm IC)."""

from __future__ import annotations

import numpy as np
import pytest

from mbplan.solvers import EuclideanNLP
from mbplan.solvers.kkt.reduced.system import kkt_system
from mbplan.solvers.ripm.barrier import BarrierStrategy
from mbplan.solvers.ripm.iterate import Iterate, Step, Trial
from mbplan.solvers.ripm.line_search import FilterLineSearch
from mbplan.solvers.ripm.newton import NewtonStep
from mbplan.solvers.ripm.options import (
    BarrierOptions,
    InertiaOptions,
    LinearSolverOptions,
    LineSearchOptions,
)
from mbplan.solvers.ripm.phase import Counters, Phase


def _trial(theta: float, phi: float, c: np.ndarray | None = None) -> Trial:
    """A trial point that only its ``θ``, ``φ`` (and constraint values ``c``) describe."""
    x, s = np.zeros(1), np.ones(1)
    c = np.zeros(1) if c is None else c
    return Trial(x, s, phi, np.zeros(0), np.zeros(1), c, theta, phi, 0.0)


# ---------------------------------------------------------------- filter line search
def test_filter_rejects_dominated_points_and_theta_max():
    """WB eq. 22: the corner ``((1-γ_θ)θ, φ - γ_φ θ)`` is added, dominated entries dropped;
    a point is rejected if an entry dominates it or ``θ ≥ θ_max``."""
    o = LineSearchOptions()
    f = FilterLineSearch(o, theta0=2.0)
    assert f.theta_max == o.theta_max_fact * 2.0 and f.theta_min == o.theta_min_fact * 2.0
    f.augment(1.0, 5.0)
    corner = ((1 - o.gamma_theta) * 1.0, 5.0 - o.gamma_phi * 1.0)
    assert f.entries == [corner]
    assert not f.accepts(1.0, 5.0)  # dominated by the corner
    assert f.accepts(0.5, 6.0) and f.accepts(2.0, 4.0)  # better in θ or in φ
    assert not f.accepts(f.theta_max, -1e9)
    f.augment(0.5, 4.0)  # dominates the first corner: it is dropped
    assert f.entries == [((1 - o.gamma_theta) * 0.5, 4.0 - o.gamma_phi * 0.5)]
    f.reset()
    assert f.entries == [] and f.accepts(1.0, 5.0)


def test_acceptance_by_sufficient_progress_and_by_armijo():
    """Above ``θ_min``: sufficient decrease of ``θ`` or ``φ`` (WB eq. 18, tag ``h``). Below
    ``θ_min`` with the switching condition (WB eq. 19): the Armijo condition (WB eq. 20,
    tag ``f``), or rejection."""
    o = LineSearchOptions()
    f = FilterLineSearch(o, theta0=1.0)
    cur = _trial(1.0, 0.0)
    assert f.acceptable(cur, _trial(0.5, 1.0), 1.0, -1.0) == "h"  # θ decreased
    assert f.acceptable(cur, _trial(1.0, -1.0), 1.0, -1.0) == "h"  # φ decreased
    assert f.acceptable(cur, _trial(1.0, 0.0), 1.0, -1.0) is None  # neither
    f.augment(0.2, -5.0)
    assert f.acceptable(cur, _trial(0.5, 1.0), 1.0, -1.0) is None  # the filter rejects it
    feasible = _trial(0.0, 0.0)  # θ = 0 ≤ θ_min: the switching condition holds for gφ < 0
    g = FilterLineSearch(o, theta0=1.0)
    assert g.acceptable(feasible, _trial(0.0, -1.0), 1.0, -1.0) == "f"
    assert g.acceptable(feasible, _trial(0.0, -0.5 * o.eta_phi), 1.0, -1.0) is None


def test_search_backtracks_to_the_first_acceptable_step():
    """``β``-backtracking from ``α_max``: the trials at 1 and 1/2 increase ``φ``, the one at
    1/4 is accepted; no second-order correction (``θ`` did not grow)."""
    o = LineSearchOptions()
    f = FilterLineSearch(o, theta0=1.0)
    cur, seen = _trial(1.0, 0.0), []

    def trial_at(step: Step, alpha: float, evaluate: bool) -> Trial:
        seen.append((alpha, evaluate))
        return _trial(0.99995, -1.0 if alpha < 0.3 else 1.0)  # θ barely smaller

    def correction(c: np.ndarray) -> Step:
        raise AssertionError("no second-order correction expected")

    step = Step(np.ones(1), np.zeros(1), np.zeros(0), np.zeros(1))
    search = f.search(cur, step, -1.0, lambda d: 1.0, trial_at, correction, np.zeros(1))
    assert search.trial is not None and search.tag == "h" and search.trials == 3
    assert search.alpha == o.beta**2
    assert seen == [(1.0, True), (0.5, False), (0.25, False)]  # the first one evaluated


def test_second_order_correction_after_a_first_trial_that_increases_theta():
    """WB: the first trial increases ``θ`` and is rejected; the correction solved for
    ``c_soc = α r_c + c(x_trial)`` gives an acceptable point (tag ``hS``), counted as a trial."""
    f = FilterLineSearch(LineSearchOptions(), theta0=1.0)
    cur = _trial(1.0, 0.0)
    soc_step = Step(np.full(1, 7.0), np.zeros(1), np.zeros(0), np.zeros(1))
    rhs = []

    def trial_at(step: Step, alpha: float, evaluate: bool) -> Trial:
        if step is soc_step:
            return _trial(0.1, 0.0)
        return _trial(2.0, 0.0, c=np.array([3.0]))

    def correction(c: np.ndarray) -> Step:
        rhs.append(c)
        return soc_step

    step = Step(np.ones(1), np.zeros(1), np.zeros(0), np.zeros(1))
    r_c = np.array([0.5])
    search = f.search(cur, step, -1.0, lambda d: 1.0, trial_at, correction, r_c)
    assert search.step is soc_step and search.tag == "hS" and search.trials == 2
    np.testing.assert_array_equal(rhs[0], 1.0 * r_c + np.array([3.0]))


# ---------------------------------------------------------------- barrier update
def test_monotone_barrier_update():
    """WB eq. 7: ``μ ← max(tol/10, min(κ_μ μ, μ^θ_μ))`` while ``E_μ ≤ κ_ε μ``, ``τ`` with it,
    the filter emptied; nothing while ``E_μ`` is larger; down to ``tol/10`` at most."""
    o = BarrierOptions(mu_strategy="monotone")
    s = z = np.ones(2)
    b = BarrierStrategy(o, tol=1e-8, mu=0.1, adaptive=False)
    assert b.update(1e3, lambda mu: 1.0 + mu, False, s, z) is False
    assert b.mu == 0.1 and not b.filter_reset
    assert b.update(0.5, lambda mu: 0.5, False, s, z) is False  # 0.5 ≤ κ_ε μ once
    assert b.mu == 0.1**o.theta_mu and b.tau == max(o.tau_min, 1 - b.mu) and b.filter_reset
    b.update(0.0, lambda mu: 0.0, False, s, z)
    assert b.mu == 1e-9


def test_adaptive_barrier_free_mode_and_fallback():
    """LOQO's μ in free mode while ``E_0`` decreases; without progress the monotone mode with
    ``μ = 0.8 sᵀz/m`` (IPOPT) until ``E_μ ≤ κ_ε μ``. The probing oracle defers μ to the Newton step's affine step:
    ``μ = (μ_aff/μ_avg)³ μ_avg``."""
    s, z = np.array([1.0, 2.0]), np.array([0.5, 0.1])
    loqo = BarrierStrategy(BarrierOptions(mu_oracle="loqo", mu_max_fact=1e3), 1e-8, 0.1, True)
    loqo.start(s, z)
    avg, xi = float(np.mean(s * z)), float(np.min(s * z) / np.mean(s * z))
    assert loqo.mu_max == max(0.1, 1e3 * avg)
    loqo.update(1.0, lambda mu: 1.0, False, s, z)
    sigma = 0.1 * min(0.05 * (1 - xi) / xi, 2.0) ** 3
    assert loqo.free_mode and loqo.mu == pytest.approx(sigma * avg, rel=1e-15)
    loqo.filter_reset = False
    loqo.update(2.0, lambda mu: 100.0, False, s, z)  # E_0 grew: monotone mode
    assert not loqo.free_mode and loqo.mu == pytest.approx(0.8 * avg) and loqo.filter_reset
    probing = BarrierStrategy(BarrierOptions(), 1e-8, 0.1, True)
    probing.start(s, z)
    probing.update(1.0, lambda mu: 1.0, False, s, z)
    assert probing.probe_pending and probing.mu == 0.1
    aff = Step(np.zeros(1), -0.5 * s, np.zeros(0), -0.5 * z)  # halves s and z: μ_aff = μ_avg/4
    mu, tau = probing.probe(s, z, aff)
    assert mu == pytest.approx(avg / 4**3) and tau == max(0.995, 1 - mu)


# ---------------------------------------------------------------- inertia correction
def _indefinite_newton(
    options: InertiaOptions | None = None,
) -> tuple[NewtonStep, Phase, Iterate, list[float]]:
    """``min -x₁²/4 + x₂²/2`` s.t. ``x₂ = 0``: ``K`` has one negative eigenvalue too many until
    ``δ_w > 1/2``. Returns the Newton step, the phase, an iterate and the ``δ_w`` of every
    factorization (recorded)."""
    problem = EuclideanNLP(
        2,
        lambda x: -0.25 * x[0] ** 2 + 0.5 * x[1] ** 2,
        lambda x: np.array([-0.5 * x[0], x[1]]),
        lambda x, s, y, z: s * np.diag([-0.5, 1.0]),
        eq=lambda x: x[1:],
        eq_jacobian=lambda x: np.array([[0.0, 1.0]]),
        n_eq=1,
    )
    phase = Phase(problem, Counters(), LineSearchOptions(), s_max=100.0)
    kkt = kkt_system(problem, "full", "amd", 0.0)
    newton = NewtonStep(kkt, phase, options or InertiaOptions(), LinearSolverOptions())
    x, y = np.array([1.0, 0.5]), np.zeros(1)
    it = Iterate(x, np.zeros(0), y, np.zeros(0), phase.evaluate(x, y, np.zeros(0)))
    deltas: list[float] = []
    factorize = kkt.factorize

    def recorded(diagonal: np.ndarray, *args):
        deltas.append(float(diagonal[0]))
        return factorize(diagonal, *args)

    kkt.factorize = recorded
    return newton, phase, it, deltas


def test_inertia_correction_delta_w_sequence():
    """WB Algorithm IC: 0, then ``δ_w,0`` and ``κ_w⁺``-fold (first perturbation: ``κ̄_w⁺``)
    increases until the inertia is right; the next step starts at ``κ_w⁻ δ_w,last``; after
    ``degenerate_iters`` perturbed steps the zero trial is skipped."""
    o = InertiaOptions()
    newton, phase, it, deltas = _indefinite_newton()
    res = phase.measures(it, 0.1)
    step, dw = newton.compute(it, res, 0.1, 0.995)
    first = [0.0, o.delta_w_init, o.delta_w_init * 100, o.delta_w_init * 100**2]
    assert deltas == pytest.approx(first, rel=1e-15) and dw == deltas[-1] == 1.0
    assert newton.delta_w_last == 1.0 and newton.n_perturbed == 1
    assert step.dx[0] == pytest.approx(-((-0.5 * 1.0) / (-0.5 + 1.0)))  # (H + δ_w I) dx = -g
    deltas.clear()
    _, dw = newton.compute(it, res, 0.1, 0.995)
    assert deltas == pytest.approx([0.0, 1 / 3, 8 / 3], rel=1e-15) and dw == deltas[-1]
    assert newton.n_perturbed == 2 == o.degenerate_iters
    deltas.clear()
    _, dw = newton.compute(it, res, 0.1, 0.995)
    assert deltas == pytest.approx([8 / 9], rel=1e-15) and dw == deltas[0]


def test_inertia_correction_gives_up_above_delta_w_max():
    """IC-6: ``δ_w > δ_w,max`` ends the correction (``None``) and forgets ``δ_w,last``."""
    newton, phase, it, deltas = _indefinite_newton(InertiaOptions(delta_w_max=0.1))
    assert newton.compute(it, phase.measures(it, 0.1), 0.1, 0.995) is None
    assert deltas == pytest.approx([0.0, 1e-4, 1e-2], rel=1e-15)
    assert newton.delta_w_last == 0.0 and newton.n_perturbed == 0
