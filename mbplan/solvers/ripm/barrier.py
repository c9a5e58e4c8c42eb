"""Barrier parameter strategies of the RIPM.

``"monotone"``: Fiacco-McCormick (RIPM Algorithm 1, WB eq. 7): ``μ ← max(ε_tol/10,
min(κ_μ μ, μ^θ_μ))`` while ``E_μ ≤ κ_ε μ``. ``"adaptive"``: LOQO's oracle every iteration
(free mode) while ``E_0`` decreases, with IPOPT's fall-back to the monotone rule
(``adaptive_mu_globalization=kkt-error``).
"""

from __future__ import annotations

import math

import numpy as np

from mbplan.solvers.ripm.iterate import EPS, Step, finite
from mbplan.solvers.ripm.kernels import affine_complementarity, mean_product

MU_MIN = 1e-14
"""The smallest μ the barrier strategies choose (the role of IPOPT's ``mu_min``): the
fraction to the boundary ``τ = 1 - μ`` stays below 1 in floating point, so slacks stay
positive (with ``tol = 1e-20`` the probing oracle chose μ = 1e-21, τ rounded to 1 and a slack
reached 0)."""


class BarrierStrategy:
    """``mu``, ``tau`` (fraction to the boundary, WB eq. 8) and their updates."""

    def _update_barrier(self, tiny_step: bool) -> bool:
        """Decrease μ while the barrier problem is solved to κ_ε μ (WB eq. 7).

        Returns ``True`` when a tiny step was taken at the smallest μ (no progress possible)."""
        o = self.o
        mu_min = self._mu_floor()
        if self.free_mode:
            if tiny_step or not self._free_mode_progress():
                self._enter_monotone_mode()
                tiny_step = False
            else:
                self._free_mode_mu()
                return False
        while (tiny_step or self._error(self.mu) <= o.kappa_eps * self.mu) and self.mu > mu_min:
            if o.mu_strategy == "adaptive" and not self.resto and not tiny_step:
                self.free_mode, self.kkt_refs = True, []  # monotone phase done: free mode again
                self._free_mode_mu()
                return False
            self.mu = max(mu_min, min(o.kappa_mu * self.mu, self.mu**o.theta_mu))
            self.tau = max(o.tau_min, 1 - self.mu)
            if self.resto:
                self.zeta = o.resto_proximity_weight * math.sqrt(self.mu)
            self.filter = []
            tiny_step = False
        return tiny_step

    def _free_mode_mu(self) -> None:
        """μ of the free mode: LOQO's now, or Mehrotra's probing once the step's matrix is
        factorized (:meth:`_probe_mu`, called by the Newton step)."""
        if self.o.mu_oracle == "probing" and self.mi:
            self.probe_pending = True
        else:
            self._set_mu(self._loqo_mu())

    def _probe_mu(self) -> Step:
        """Mehrotra's predictor (IPOPT's probing oracle): the affine-scaling step (μ = 0) with
        the current factorization, ``μ_aff`` the average complementarity after its
        fraction-to-boundary steps, ``μ = σ μ_avg`` with ``σ = (μ_aff / μ_avg)³``; returns the
        affine step. LOQO's μ if the affine step is not finite (a broken-down solve)."""
        self.probe_pending = False
        mu_avg = self._avg_compl()
        aff = self._affine_step()
        if not finite(aff.ds, aff.dz):
            self._set_mu(self._loqo_mu())
            return aff
        mu_aff = affine_complementarity(self.s, aff.ds, self.z, aff.dz, self.tau)
        sigma = min((mu_aff / mu_avg) ** 3, 1.0) if mu_avg > 0 else 0.0
        self._set_mu(min(max(sigma * mu_avg, self._mu_floor()), self.mu_max))
        return aff

    def _mu_floor(self) -> float:
        """Lower bound of μ: ``tol/10`` (WB eq. 7), at least :data:`MU_MIN`."""
        return max(self.o.tol / 10, MU_MIN)

    def _set_mu(self, mu: float) -> None:
        if mu != self.mu:
            self.mu = mu
            self.tau = max(self.o.tau_min, 1 - mu)
            self.filter = []

    def _avg_compl(self) -> float:
        return mean_product(self.s, self.z) if self.mi else 0.0

    def _loqo_mu(self) -> float:
        """LOQO's oracle (Vanderbei & Shanno 1999; IPOPT's ``mu_oracle=loqo``):
        ``μ = σ sᵀz/m`` with ``σ = 0.1 min(0.05 (1-ξ)/ξ, 2)³``, ``ξ = min(s z)/avg(s z)``."""
        if not self.mi:
            return max(self._mu_floor(), self.mu * self.o.kappa_mu)
        sz = self.s * self.z
        avg = float(np.mean(sz))
        xi = float(np.min(sz)) / avg if avg > 0 else 1.0
        sigma = 0.1 * min(0.05 * (1 - xi) / max(xi, EPS), 2.0) ** 3
        return float(np.clip(sigma * avg, self._mu_floor(), self.mu_max))

    def _free_mode_progress(self) -> bool:
        """IPOPT's ``adaptive_mu_globalization=kkt-error``: stay in free mode while ``E_0``
        decreases by ``1 - 10⁻⁴`` against the worst of the last 4 reference values."""
        refs = self.kkt_refs
        ok = not refs or self.kkt_error <= (1 - 1e-4) * max(refs)
        if ok:
            refs.append(self.kkt_error)
            del refs[:-4]
        return ok

    def _enter_monotone_mode(self) -> None:
        """Fixed-μ fallback (IPOPT): μ = 0.8 · average complementarity, the filter reset."""
        self.free_mode = False
        self._count("monotone_switches")
        self._set_mu(float(np.clip(0.8 * self._avg_compl(), self._mu_floor(), self.mu_max)))
        self.filter = []
