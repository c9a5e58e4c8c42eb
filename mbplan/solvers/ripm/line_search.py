"""IPOPT's filter line search (Wächter & Biegler 2006, "WB") along the retraction.

Trial points ``x(α) = R_x(α dx)`` (the retraction replaces ``x + α dx``), ``s(α) = s + α ds``
with ``α ≤ α_max`` from the fraction-to-boundary rule (WB eq. 15) are accepted by the filter,
the switching condition (WB eq. 19) with the Armijo condition on ``φ_μ`` (WB eq. 20), or
sufficient progress in ``θ = ‖h‖₁ + ‖g + s‖₁`` or ``φ_μ`` (WB eq. 18); second-order corrections
reuse the step's factorization when the first trial increases ``θ``; ``α < α_min`` (WB eq. 23)
ends the search (the driver then calls the restoration phase).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbplan.solvers.ripm.iterate import Step, Trial, finite, frac_to_boundary
from mbplan.solvers.ripm.kernels import ratio_sum


@dataclass
class Search:
    """Outcome of a line search: the accepted trial (``None`` if it failed) and the step taken.

    ``tag`` is ``f`` (Armijo), ``h`` (filter progress), ``T`` (tiny step, no search) or ``s``
    (soft restoration step), with ``S`` appended for a second-order correction."""

    trial: Trial | None
    step: Step | None = None
    alpha: float = 0.0
    trials: int = 0
    tag: str = ""
    all_nan: bool = False


class FilterLineSearch:
    """The filter (``self.filter``, bounds ``theta_max``, ``theta_min``) and the search."""

    def _filter_accepts(self, theta: float, phi: float) -> bool:
        if theta >= self.theta_max:
            return False
        return all(theta < t or phi < f for t, f in self.filter)

    def _augment_filter(self, theta: float, phi: float) -> None:
        """Add the corner ``((1-γ_θ)θ, φ - γ_φ θ)`` (WB eq. 22), dropping dominated entries."""
        t, f = (1 - self.o.gamma_theta) * theta, phi - self.o.gamma_phi * theta
        self.filter = [(ti, fi) for ti, fi in self.filter if ti < t or fi < f]
        self.filter.append((t, f))

    def _acceptable(self, cur: Trial, trial: Trial, alpha: float, gphi: float) -> str | None:
        """``"f"`` (Armijo step), ``"h"`` (feasibility/cost progress) or ``None`` (rejected)."""
        o = self.o
        if not self._filter_accepts(trial.theta, trial.phi):
            return None
        switching = gphi < 0 and alpha * (-gphi) ** o.s_phi > o.delta * cur.theta**o.s_theta
        if cur.theta <= self.theta_min and switching:
            return "f" if trial.phi <= cur.phi + o.eta_phi * alpha * gphi else None
        if (
            trial.theta <= (1 - o.gamma_theta) * cur.theta
            or trial.phi <= cur.phi - o.gamma_phi * cur.theta
        ):
            return "h"
        return None

    def _alpha_min(self, theta: float, gphi: float) -> float:
        """WB eq. 23."""
        o = self.o
        if gphi < 0:
            a = min(o.gamma_theta, o.gamma_phi * theta / -gphi)
            if theta <= self.theta_min:
                a = min(a, o.delta * theta**o.s_theta / (-gphi) ** o.s_phi)
            return o.gamma_alpha * a
        return o.gamma_alpha * o.gamma_theta

    def _alpha_max(self, step: Step) -> float:
        a = frac_to_boundary(self.s, step.ds, self.tau)
        if self.resto:
            a = min(a, frac_to_boundary(self.ep, step.dp, self.tau))
            a = min(a, frac_to_boundary(self.en, step.dn, self.tau))
        return a

    def _slope(self, step: Step) -> float:
        """Directional derivative of ``φ_μ`` along the step."""
        gphi = self.sigma * float(np.dot(self.ev.gradient, step.dx))
        gphi -= self.mu * ratio_sum(step.ds, self.s)
        if self.resto:
            gphi += self.rho * float(np.sum(step.dp) + np.sum(step.dn))
            gphi -= self.mu * float(np.sum(step.dp / self.ep) + np.sum(step.dn / self.en))
            gphi += self.zeta * float(self.xi @ step.dx)
        return gphi

    def _line_search(self, step: Step, cur: Trial) -> Search:
        """Backtracking filter line search with second-order correction (WB)."""
        o = self.o
        alpha_max = self._alpha_max(step)
        gphi = self._slope(step)
        alpha_min = self._alpha_min(cur.theta, gphi)
        alpha, n_trials, n_nan = alpha_max, 0, 0
        while n_trials < o.max_ls_trials and (n_trials == 0 or alpha >= alpha_min):
            n_trials += 1
            # the first trial is usually accepted: evaluated with its multipliers at once
            trial = self._trial_at(step, alpha, evaluate=n_trials == 1 and not self.resto)
            if trial is None:
                n_nan += 1
            else:
                tag = self._acceptable(cur, trial, alpha, gphi)
                if tag:
                    return Search(trial, step, alpha, n_trials, tag)
                if n_trials == 1 and trial.theta >= cur.theta and o.second_order_correction:
                    soc = self._second_order_correction(cur, trial, alpha, gphi)
                    n_trials += soc.trials
                    if soc.trial is not None:
                        soc.trials = n_trials
                        return soc
            alpha *= o.beta
        return Search(None, trials=n_trials, all_nan=n_nan == n_trials)

    def _second_order_correction(
        self, cur: Trial, trial: Trial, alpha: float, gphi: float
    ) -> Search:
        """WB second-order correction: re-solve with ``c_soc = α c_k + c(x_trial)`` using the
        same factorization; the step was rejected at ``alpha`` with ``trial``."""
        o = self.o
        c_soc = alpha * self.r_c + trial.c
        theta_old, count = cur.theta, 0
        for _ in range(o.max_soc):
            sol = self._solve(self._rhs(c_soc))
            if not finite(sol):
                break
            soc = self._split(sol)
            a_soc = self._alpha_max(soc)
            count += 1
            t = self._trial_at(soc, a_soc)
            if t is None:
                break
            tag = self._acceptable(cur, t, alpha, gphi)
            if tag:
                return Search(t, soc, a_soc, count, tag + "S")
            if t.theta > o.kappa_soc * theta_old:
                break
            theta_old = t.theta
            c_soc = a_soc * c_soc + t.c
        return Search(None, trials=count)
