"""IPOPT's filter line search (Wächter & Biegler 2006, "WB") along the retraction.

Trial points ``x(α) = R_x(α dx)`` (the retraction replaces ``x + α dx``), ``s(α) = s + α ds``
with ``α ≤ α_max`` from the fraction-to-boundary rule (WB eq. 15) are accepted by the filter,
the switching condition (WB eq. 19) with the Armijo condition on ``φ_μ`` (WB eq. 20), or
sufficient progress in ``θ = ‖h‖₁ + ‖g + s‖₁`` or ``φ_μ`` (WB eq. 18); second-order corrections
reuse the step's factorization when the first trial increases ``θ``; ``α < α_min`` (WB eq. 23)
ends the search (the driver then calls the restoration phase).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mbplan.solvers.ripm.iterate import Step, Trial
from mbplan.solvers.ripm.options import LineSearchOptions

TrialAt = Callable[[Step, float, bool], "Trial | None"]
"""``(step, α, evaluate) ↦`` the trial point (``None`` if not finite); ``evaluate``: with its
evaluation at the multipliers it would be accepted with (the first trial)."""


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
    """The filter (``entries`` of ``(θ, φ)``, with the bounds ``theta_max``, ``theta_min`` from
    the phase's initial ``θ_0``) and the backtracking search."""

    def __init__(self, options: LineSearchOptions, theta0: float) -> None:
        self.o = options
        self.theta_max = options.theta_max_fact * max(1.0, theta0)
        self.theta_min = options.theta_min_fact * max(1.0, theta0)
        self.entries: list[tuple[float, float]] = []

    def reset(self) -> None:
        """An empty filter (a new barrier problem)."""
        self.entries = []

    def accepts(self, theta: float, phi: float) -> bool:
        """``(θ, φ)`` is not dominated by the filter and ``θ < θ_max``."""
        if theta >= self.theta_max:
            return False
        return all(theta < t or phi < f for t, f in self.entries)

    def augment(self, theta: float, phi: float) -> None:
        """Add the corner ``((1-γ_θ)θ, φ - γ_φ θ)`` (WB eq. 22), dropping dominated entries."""
        t, f = (1 - self.o.gamma_theta) * theta, phi - self.o.gamma_phi * theta
        self.entries = [(ti, fi) for ti, fi in self.entries if ti < t or fi < f]
        self.entries.append((t, f))

    def acceptable(self, cur: Trial, trial: Trial, alpha: float, gphi: float) -> str | None:
        """``"f"`` (Armijo step, WB eq. 19-20), ``"h"`` (sufficient progress, WB eq. 18) or
        ``None`` (rejected) for ``trial`` at step ``alpha`` from ``cur`` with slope ``gphi``."""
        o = self.o
        if not self.accepts(trial.theta, trial.phi):
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

    def alpha_min(self, theta: float, gphi: float) -> float:
        """The smallest step tried (WB eq. 23)."""
        o = self.o
        if gphi < 0:
            a = min(o.gamma_theta, o.gamma_phi * theta / -gphi)
            if theta <= self.theta_min:
                a = min(a, o.delta * theta**o.s_theta / (-gphi) ** o.s_phi)
            return o.gamma_alpha * a
        return o.gamma_alpha * o.gamma_theta

    def search(
        self,
        cur: Trial,
        step: Step,
        gphi: float,
        alpha_max: Callable[[Step], float],
        trial_at: TrialAt,
        correction: Callable[[np.ndarray], Step | None],
        r_c: np.ndarray,
    ) -> Search:
        """Backtracking from ``alpha_max(step)`` along ``step`` (slope ``gphi`` of ``φ_μ``) with
        second-order corrections (WB): ``correction(c)`` is the step's system solved for the
        constraint values ``c``, ``r_c`` the current ones."""
        o = self.o
        alpha = alpha_max(step)
        alpha_min = self.alpha_min(cur.theta, gphi)
        n_trials, n_nan = 0, 0
        while n_trials < o.max_ls_trials and (n_trials == 0 or alpha >= alpha_min):
            n_trials += 1
            # the first trial is usually accepted: evaluated with its multipliers at once
            trial = trial_at(step, alpha, n_trials == 1)
            if trial is None:
                n_nan += 1
            else:
                tag = self.acceptable(cur, trial, alpha, gphi)
                if tag:
                    return Search(trial, step, alpha, n_trials, tag)
                if n_trials == 1 and trial.theta >= cur.theta and o.second_order_correction:
                    c_soc = alpha * r_c + trial.c
                    soc = self._second_order_correction(
                        cur, c_soc, alpha, gphi, alpha_max, trial_at, correction
                    )
                    n_trials += soc.trials
                    if soc.trial is not None:
                        soc.trials = n_trials
                        return soc
            alpha *= o.beta
        return Search(None, trials=n_trials, all_nan=n_nan == n_trials)

    def _second_order_correction(
        self,
        cur: Trial,
        c_soc: np.ndarray,
        alpha: float,
        gphi: float,
        alpha_max: Callable[[Step], float],
        trial_at: TrialAt,
        correction: Callable[[np.ndarray], Step | None],
    ) -> Search:
        """WB's second-order correction of the step rejected at ``alpha``: re-solve with
        ``c_soc = α c_k + c(x_trial)`` using the same factorization, at most ``max_soc`` times."""
        o = self.o
        theta_old, count = cur.theta, 0
        for _ in range(o.max_soc):
            soc = correction(c_soc)
            if soc is None:
                break
            a_soc = alpha_max(soc)
            count += 1
            t = trial_at(soc, a_soc, False)
            if t is None:
                break
            tag = self.acceptable(cur, t, alpha, gphi)
            if tag:
                return Search(t, soc, a_soc, count, tag + "S")
            if t.theta > o.kappa_soc * theta_old:
                break
            theta_old = t.theta
            c_soc = a_soc * c_soc + t.c
        return Search(None, trials=count)
