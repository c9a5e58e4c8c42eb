"""IPOPT's ℓ1 feasibility restoration phase (WB §3.3, ``RestoMinC_1Nrm``) on the manifold.

From the iterate ``x_R`` where the line search failed, the same interior point iteration (a
second driver instance with ``resto = True``) solves ::

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

import math

import numpy as np

from mbplan.solvers.result import RIPMStatus
from mbplan.solvers.ripm.iterate import EPS, Step, amax
from mbplan.solvers.ripm.kernels import safeguarded_duals
from mbplan.solvers.ripm.line_search import Search


class Stop(Exception):
    """Ends the main loop with a status (raised from the phases of an iteration)."""

    def __init__(self, status: RIPMStatus, message: str = "") -> None:
        super().__init__(message)
        self.status, self.message = status, message or status.value


def elastic_start(c: np.ndarray, mu: float, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """``p, n > 0`` with ``c - p + n = 0`` and ``μ/p + μ/n = 2ρ`` (WB eq. 33)."""
    a = (mu - rho * c) / (2 * rho)
    n = np.maximum(a + np.sqrt(a * a + mu * c / (2 * rho)), EPS * mu)
    return np.maximum(c + n, EPS * mu), n


class Restoration:
    """Entering, running and leaving the restoration phase (``parent``: the main phase)."""

    def _soft_restoration(self, step: Step) -> Search:
        """IPOPT's soft restoration phase (``TrySoftRestoStep``), tried where the line search
        fails and then instead of it: the step to the boundary ``α = min(α_max, α_z,max)`` of
        primal and dual variables, accepted if the original filter and sufficient-decrease tests
        accept it (the phase ends) or if it reduces the primal-dual error
        (:meth:`_primal_dual_error`, at μ = 0 in free mode) by
        ``soft_resto_pderror_reduction_factor``; at most ``max_soft_resto_iters`` steps in a
        row. A failed search (``trial=None``) leads to the restoration phase."""
        o = self.o
        if self.resto or self.m == 0 or self.soft_steps >= o.max_soft_resto_iters:
            return Search(None)
        if self.soft_steps == 0:  # the filter as at the start of a restoration phase
            self._augment_filter(self.cur.theta, self.cur.phi)
        self.soft_steps += 1
        alpha = min(self._alpha_max(step), self._alpha_z_max(step))
        trial = self._trial_at(step, alpha)
        if trial is None:
            return Search(None)
        y = self.y + alpha * step.dy
        z = safeguarded_duals(self.z, step.dz, alpha, trial.s, self.mu, o.kappa_sigma)
        trial.ev, trial.multipliers = self._evaluate(trial.x, y, z), (y, z, alpha)
        if trial.ev is None:
            return Search(None)
        if self._acceptable(self.cur, trial, 0.0, 0.0):
            self.soft_steps = 0
            return Search(trial, step, alpha, 1, "s")
        mu = 0.0 if self.free_mode else self.mu
        error = self._primal_dual_error(trial.ev, y, z, trial.s, mu)
        current = self._primal_dual_error(self.ev, self.y, self.z, self.s, mu)
        if error <= o.soft_resto_pderror_reduction_factor * current:
            return Search(trial, step, alpha, 1, "s")
        return Search(None)

    def _restoration(self) -> None:
        """Run the ℓ1 restoration phase and continue from its result.

        On return, ``y = 0`` (IPOPT's default ``constr_mult_reset_threshold = 0``; a least-squares
        estimate with ``resto_ls_multipliers``) and ``z = μ/s``, or all ``z = 1`` if that exceeds
        ``bound_mult_reset_threshold`` (IPOPT's rule)."""
        self._count("restorations")
        if not self.soft_steps:  # else augmented when the soft restoration phase started
            self._augment_filter(self.cur.theta, self.cur.phi)
        self.soft_steps = 0
        phase = type(self)(self.p, self.o, parent=self)
        try:
            phase._start_restoration(self)
            phase._iterate()
        except Stop:
            self._adopt(phase, keep_multipliers=True)
            raise
        self._adopt(phase, keep_multipliers=False)
        self.last = phase.last
        self.kkt_refs = []

    def _adopt(self, phase, keep_multipliers: bool) -> None:
        """Continue from the restoration phase's iterate (the original objective again)."""
        o = self.o
        x, s = phase.x, phase.s
        if keep_multipliers:  # the restoration's multipliers certify infeasibility
            y, z = phase.y.copy(), phase.z.copy()
        else:
            y = np.zeros(self.me)
            z = self.mu / s
            if np.max(z, initial=0.0) > o.bound_mult_reset_threshold:
                z = np.ones(self.mi)
        ev = self._evaluate(x, y, z)
        if ev is None:
            if keep_multipliers:
                return
            raise Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
        self.x, self.s, self.y, self.z, self.ev = x, s, y, z, ev
        if not keep_multipliers and o.resto_ls_multipliers and self.me:
            y_ls = self._least_squares_y(ev)
            if y_ls is not None and np.any(y_ls):
                self.y = y_ls
                ev = self._evaluate(x, self.y, self.z)
                if ev is None:
                    raise Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
                self.ev = ev

    def _start_restoration(self, main) -> None:
        """Initial point of the restoration problem at the main phase's iterate (WB eq. 33)."""
        o = self.o
        self.x = main.x
        c = np.concatenate([main.ev.eq, main.ev.ineq + main.s])
        self.mu = max(main.mu, amax(c))
        self.tau = max(o.tau_min, 1 - self.mu)
        self.zeta = o.resto_proximity_weight * math.sqrt(self.mu)
        rho, mu = self.rho, self.mu
        # slacks: satisfied rows exactly, none below μ/ρ (their value at a solution of the
        # restoration problem where the row stays violated: z = ρ, s z = μ)
        self.s = np.maximum(main.s, np.maximum(-main.ev.ineq, mu / rho))
        c = np.concatenate([main.ev.eq, main.ev.ineq + self.s])
        self.ep, self.en = elastic_start(c, mu, rho)
        self.zp, self.zn = mu / self.ep, mu / self.en
        self.xi = np.zeros(self.n)
        self.y = np.zeros(self.me)
        self.z = np.minimum(mu / self.s, rho)
        ev = self._evaluate(self.x, self.y, self.z)
        if ev is None:
            raise Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
        self.ev = ev
        theta0 = float(np.sum(np.abs(self._constraints(ev.eq, ev.ineq, self.s, self.ep, self.en))))
        self.theta_max = o.theta_max_fact * max(1.0, theta0)
        self.theta_min = o.theta_min_fact * max(1.0, theta0)
        self.theta_start = float(
            np.sum(np.abs(np.concatenate([main.ev.eq, main.ev.ineq + main.s])))
        )

    def _original_measures(self) -> tuple[float, float, float]:
        """``θ``, ``φ_μ`` of the main phase (its μ) and ``‖h, g + s‖∞`` at this iterate."""
        main, ev = self.parent, self.ev
        c = np.concatenate([ev.eq, ev.ineq + self.s])
        theta = float(np.sum(np.abs(c)))
        phi = ev.objective - main.mu * float(np.sum(np.log(self.s)))
        return theta, phi, amax(c)

    def _resto_converged(self) -> None:
        """The restoration problem is solved: locally infeasible, unless the point is feasible."""
        c_inf = self._original_measures()[2]
        if c_inf > self.o.constr_viol_tol:
            raise Stop(RIPMStatus.LOCALLY_INFEASIBLE)
        raise Stop(
            RIPMStatus.LINE_SEARCH_FAILED,
            "restoration converged to a feasible point the filter does not accept",
        )

    def _check_resto(self, first: bool) -> bool:
        """Termination tests of the restoration phase; ``True``: return to the main phase."""
        o = self.o
        if not first:
            theta, phi, _ = self._original_measures()
            if theta <= o.kappa_resto * self.theta_start and self.parent._filter_accepts(
                theta, phi
            ):
                return True
        if self.kkt_error <= o.tol:
            self._resto_converged()
        if self.iter >= o.max_iter:
            raise Stop(RIPMStatus.MAX_ITER)
        return False
