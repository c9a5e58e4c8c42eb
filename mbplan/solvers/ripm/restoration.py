"""IPOPT's soft and ℓ1 feasibility restoration phases (WB §3.3, ``RestoMinC_1Nrm``) on the
manifold.

From the iterate ``x_R`` where the line search failed, the same interior point iteration (the
driver on the restoration :class:`~mbplan.solvers.ripm.iterate.Phase`) solves ::

    min  ρ Σ (p + n) + ζ/2 ‖ξ‖²   s.t.  (h(x), g(x) + s) - p + n = 0,   s, p, n ≥ 0,

with ``ξ`` the tangent displacement from ``x_R`` accumulated over the restoration steps (the
manifold version of IPOPT's ``x - x_R``), ``ζ = resto_proximity_weight · √μ`` and ``σ = 0`` on
``f``. The elastic variables ``p, n`` and their bound multipliers are eliminated row by row,
which adds ``-(P Z_p⁻¹ + N Z_n⁻¹)`` to the dual diagonal: the restoration's KKT matrix has the
main loop's sparsity pattern. The phase returns as soon as a point reduces the original ``θ``
by ``kappa_resto`` and is acceptable to the original filter; a converged restoration problem
with ``‖h, g + s‖∞ > constr_viol_tol`` proves local infeasibility.
"""

from __future__ import annotations

import numpy as np

from mbplan.solvers.result import RIPMStatus
from mbplan.solvers.ripm.iterate import EPS, Iterate, Step, Stop, Trial, amax
from mbplan.solvers.ripm.kernels import safeguarded_duals
from mbplan.solvers.ripm.line_search import FilterLineSearch, Search
from mbplan.solvers.ripm.options import RestorationOptions
from mbplan.solvers.ripm.phase import Phase


def elastic_start(c: np.ndarray, mu: float, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """``p, n > 0`` with ``c - p + n = 0`` and ``μ/p + μ/n = 2ρ`` (WB eq. 33)."""
    a = (mu - rho * c) / (2 * rho)
    n = np.maximum(a + np.sqrt(a * a + mu * c / (2 * rho)), EPS * mu)
    return np.maximum(c + n, EPS * mu), n


class SoftRestoration:
    """IPOPT's soft restoration phase (``TrySoftRestoStep``) of the main phase; ``steps``
    counts its steps in a row (0: not in one)."""

    def __init__(self, options: RestorationOptions, phase: Phase, kappa_sigma: float) -> None:
        self.o, self.phase, self.kappa_sigma = options, phase, kappa_sigma
        self.steps = 0

    def step(
        self,
        it: Iterate,
        cur: Trial,
        step: Step,
        filter_: FilterLineSearch,
        mu: float,
        tau: float,
        free_mode: bool,
    ) -> Search:
        """Tried where the line search fails and then instead of it: the step to the boundary
        ``α = min(α_max, α_z,max)`` of primal and dual variables, accepted if the original
        filter and sufficient-decrease tests accept it (the phase ends) or if it reduces the
        primal-dual error (at μ = 0 in free mode) by ``soft_resto_pderror_reduction_factor``;
        at most ``max_soft_resto_iters`` steps in a row. A failed search (``trial=None``) leads
        to the restoration phase."""
        o, ph = self.o, self.phase
        if ph.resto or ph.m == 0 or self.steps >= o.max_soft_resto_iters:
            return Search(None)
        if self.steps == 0:  # the filter as at the start of a restoration phase
            filter_.augment(cur.theta, cur.phi)
        self.steps += 1
        alpha = min(ph.alpha_max(it, step, tau), ph.alpha_z_max(it, step, tau))
        trial = ph.trial_at(it, step, alpha, mu, tau)
        if trial is None:
            return Search(None)
        y = it.y + alpha * step.dy
        z = safeguarded_duals(it.z, step.dz, alpha, trial.s, mu, self.kappa_sigma)
        trial.ev, trial.multipliers = ph.evaluate(trial.x, y, z), (y, z, alpha)
        if trial.ev is None:
            return Search(None)
        if filter_.acceptable(cur, trial, 0.0, 0.0):
            self.steps = 0
            return Search(trial, step, alpha, 1, "s")
        mu_pd = 0.0 if free_mode else mu
        error = ph.primal_dual_error(trial.ev, y, z, trial.s, mu_pd)
        current = ph.primal_dual_error(it.ev, it.y, it.z, it.s, mu_pd)
        if error <= o.soft_resto_pderror_reduction_factor * current:
            return Search(trial, step, alpha, 1, "s")
        return Search(None)


class Restoration:
    """Entering and leaving the ℓ1 restoration phase of the ``main`` phase, and its
    termination tests against the main phase's filter."""

    def __init__(
        self, options: RestorationOptions, main: Phase, tau_min: float, tol: float,
        constr_viol_tol: float,
    ) -> None:  # fmt: skip
        self.o, self.main, self.tau_min = options, main, tau_min
        self.tol, self.constr_viol_tol = tol, constr_viol_tol
        self.theta_start = 0.0

    def phase(self) -> Phase:
        """The restoration problem of the main phase's problem."""
        m = self.main
        return Phase(
            m.problem, m.counters, m.o, m.s_max, self.o.resto_penalty,
            self.o.resto_proximity_weight,
        )  # fmt: skip

    def start(self, resto: Phase, it: Iterate, mu: float) -> tuple[Iterate, float, float]:
        """The restoration problem's initial point, μ and ``θ_0`` at the main iterate ``it``
        (WB eq. 33); its evaluation ``ev`` is ``None`` (and ``θ_0`` NaN) if not finite."""
        c = np.concatenate([it.ev.eq, it.ev.ineq + it.s])
        mu = max(mu, amax(c))
        rho = resto.rho
        # slacks: satisfied rows exactly, none below μ/ρ (their value at a solution of the
        # restoration problem where the row stays violated: z = ρ, s z = μ)
        s = np.maximum(it.s, np.maximum(-it.ev.ineq, mu / rho))
        ep, en = elastic_start(np.concatenate([it.ev.eq, it.ev.ineq + s]), mu, rho)
        y, z = np.zeros(resto.me), np.minimum(mu / s, rho)
        start = Iterate(it.x, s, y, z, None, ep, en, mu / ep, mu / en, np.zeros(resto.n))
        start.ev = resto.evaluate(start.x, y, z)
        self.theta_start = float(np.sum(np.abs(c)))
        theta0 = np.nan
        if start.ev is not None:
            c0 = np.concatenate([start.ev.eq, start.ev.ineq + s])
            c0 += en - ep
            theta0 = float(np.sum(np.abs(c0)))
        return start, mu, theta0

    def original_measures(self, it: Iterate, main_mu: float) -> tuple[float, float, float]:
        """``θ``, ``φ_μ`` of the main phase (its μ) and ``‖h, g + s‖∞`` at ``it``."""
        ev = it.ev
        c = np.concatenate([ev.eq, ev.ineq + it.s])
        theta = float(np.sum(np.abs(c)))
        phi = ev.objective - main_mu * float(np.sum(np.log(it.s)))
        return theta, phi, amax(c)

    def converged(self, it: Iterate) -> None:
        """The restoration problem is solved: locally infeasible, unless the point is feasible."""
        if amax(np.concatenate([it.ev.eq, it.ev.ineq + it.s])) > self.constr_viol_tol:
            raise Stop(RIPMStatus.LOCALLY_INFEASIBLE)
        raise Stop(
            RIPMStatus.LINE_SEARCH_FAILED,
            "restoration converged to a feasible point the filter does not accept",
        )

    def done(
        self, it: Iterate, kkt_error: float, first: bool, main_mu: float,
        main_filter: FilterLineSearch,
    ) -> bool:  # fmt: skip
        """Termination tests of the restoration phase; ``True``: return to the main phase."""
        if not first:
            theta, phi, _ = self.original_measures(it, main_mu)
            if theta <= self.o.kappa_resto * self.theta_start and main_filter.accepts(theta, phi):
                return True
        if kkt_error <= self.tol:
            self.converged(it)
        return False

    def leave(self, it: Iterate, mu: float, keep_multipliers: bool) -> Iterate | None:
        """The main phase's iterate at the restoration's ``it`` (the original objective again):
        ``y = 0`` (IPOPT's default ``constr_mult_reset_threshold = 0``) and ``z = μ/s``, or all
        ``z = 1`` if that exceeds ``bound_mult_reset_threshold`` (IPOPT's rule).
        ``keep_multipliers`` (the solve ends: they certify infeasibility): the restoration's
        ``y, z``, and ``None`` if the evaluation is not finite."""
        main, o = self.main, self.o
        if keep_multipliers:
            y, z = it.y.copy(), it.z.copy()
        else:
            y = np.zeros(main.me)
            z = mu / it.s
            if np.max(z, initial=0.0) > o.bound_mult_reset_threshold:
                z = np.ones(main.mi)
        ev = main.evaluate(it.x, y, z)
        if ev is None:
            if keep_multipliers:
                return None
            raise Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
        return Iterate(it.x, it.s, y, z, ev)
