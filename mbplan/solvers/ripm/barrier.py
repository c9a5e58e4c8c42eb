"""Barrier parameter strategies of the RIPM.

``"monotone"``: Fiacco-McCormick (RIPM Algorithm 1, WB eq. 7): ``μ ← max(ε_tol/10,
min(κ_μ μ, μ^θ_μ))`` while ``E_μ ≤ κ_ε μ``. ``"adaptive"``: LOQO's oracle or Mehrotra's probing
every iteration (free mode) while ``E_0`` decreases, with IPOPT's fall-back to the monotone rule
(``adaptive_mu_globalization=kkt-error``). The fraction to the boundary is
``τ = max(τ_min, 1 - μ)`` (WB eq. 8).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from mbplan.solvers.ripm.iterate import EPS, Step, finite
from mbplan.solvers.ripm.kernels import affine_complementarity, mean_product
from mbplan.solvers.ripm.options import BarrierOptions

MU_MIN = 1e-14
"""The smallest μ the barrier strategies choose (the role of IPOPT's ``mu_min``): the
fraction to the boundary ``τ = 1 - μ`` stays below 1 in floating point, so slacks stay
positive (with ``tol = 1e-20`` the probing oracle chose μ = 1e-21, τ rounded to 1 and a slack
reached 0)."""


class BarrierStrategy:
    """``mu``, ``tau`` and their updates. ``adaptive``: the free mode may be entered (the main
    phase with ``mu_strategy="adaptive"``). ``probe_pending``: Mehrotra's μ is due with the next
    Newton step's factorization (:meth:`probe`). ``filter_reset``: μ changed or the mode switched
    since the driver last reset the filter (WB: a new barrier problem, an empty filter)."""

    def __init__(self, options: BarrierOptions, tol: float, mu: float, adaptive: bool) -> None:
        self.o, self.adaptive = options, adaptive
        self.mu_floor = max(tol / 10, MU_MIN)
        """Lower bound of μ: ``tol/10`` (WB eq. 7), at least :data:`MU_MIN`."""
        self.mu, self.tau = mu, max(options.tau_min, 1 - mu)
        self.mu_max = math.inf
        self.free_mode = adaptive
        self.kkt_refs: list[float] = []
        self.probe_pending = False
        self.filter_reset = False

    def start(self, s: np.ndarray, z: np.ndarray) -> None:
        """The adaptive μ's upper bound ``max(μ_init, mu_max_fact · sᵀz/m)`` at the start."""
        self.mu_max = max(self.o.mu_init, self.o.mu_max_fact * avg_compl(s, z))

    def update(
        self,
        kkt_error: float,
        error_at: Callable[[float], float],
        tiny_step: bool,
        s: np.ndarray,
        z: np.ndarray,
    ) -> bool:
        """Decrease μ while the barrier problem is solved to κ_ε μ (``error_at(μ) = E_μ``,
        WB eq. 7), or the free mode's μ. Returns ``True`` when a tiny step was taken at the
        smallest μ (no progress possible)."""
        o = self.o
        if self.free_mode:
            if tiny_step or not self._free_mode_progress(kkt_error):
                self._enter_monotone_mode(s, z)
                tiny_step = False
            else:
                self._free_mode_mu(s, z)
                return False
        while (tiny_step or error_at(self.mu) <= o.kappa_eps * self.mu) and self.mu > self.mu_floor:
            if self.adaptive and not tiny_step:
                self.free_mode, self.kkt_refs = True, []  # monotone phase done: free mode again
                self._free_mode_mu(s, z)
                return False
            self.mu = max(self.mu_floor, min(o.kappa_mu * self.mu, self.mu**o.theta_mu))
            self.tau = max(o.tau_min, 1 - self.mu)
            self.filter_reset = True
            tiny_step = False
        return tiny_step

    def probe(self, s: np.ndarray, z: np.ndarray, aff: Step) -> tuple[float, float]:
        """Mehrotra's predictor (IPOPT's probing oracle) from the affine-scaling step ``aff``
        (μ = 0): ``μ_aff`` the average complementarity after its fraction-to-boundary steps,
        ``μ = σ μ_avg`` with ``σ = (μ_aff / μ_avg)³``; LOQO's μ if ``aff`` is not finite (a
        broken-down solve). Returns the new μ and τ."""
        mu_avg = avg_compl(s, z)
        if not finite(aff.ds, aff.dz):
            self._set_mu(self._loqo_mu(s, z))
        else:
            mu_aff = affine_complementarity(s, aff.ds, z, aff.dz, self.tau)
            sigma = min((mu_aff / mu_avg) ** 3, 1.0) if mu_avg > 0 else 0.0
            self._set_mu(min(max(sigma * mu_avg, self.mu_floor), self.mu_max))
        return self.mu, self.tau

    def _free_mode_mu(self, s: np.ndarray, z: np.ndarray) -> None:
        """μ of the free mode: LOQO's now, or Mehrotra's probing with the Newton step."""
        if self.o.mu_oracle == "probing" and len(s):
            self.probe_pending = True
        else:
            self._set_mu(self._loqo_mu(s, z))

    def _set_mu(self, mu: float) -> None:
        if mu != self.mu:
            self.mu = mu
            self.tau = max(self.o.tau_min, 1 - mu)
            self.filter_reset = True

    def _loqo_mu(self, s: np.ndarray, z: np.ndarray) -> float:
        """LOQO's oracle (Vanderbei & Shanno 1999; IPOPT's ``mu_oracle=loqo``):
        ``μ = σ sᵀz/m`` with ``σ = 0.1 min(0.05 (1-ξ)/ξ, 2)³``, ``ξ = min(s z)/avg(s z)``."""
        if not len(s):
            return max(self.mu_floor, self.mu * self.o.kappa_mu)
        sz = s * z
        avg = float(np.mean(sz))
        xi = float(np.min(sz)) / avg if avg > 0 else 1.0
        sigma = 0.1 * min(0.05 * (1 - xi) / max(xi, EPS), 2.0) ** 3
        return float(np.clip(sigma * avg, self.mu_floor, self.mu_max))

    def _free_mode_progress(self, kkt_error: float) -> bool:
        """IPOPT's ``adaptive_mu_globalization=kkt-error``: stay in free mode while ``E_0``
        decreases by ``1 - 10⁻⁴`` against the worst of the last 4 reference values."""
        refs = self.kkt_refs
        ok = not refs or kkt_error <= (1 - 1e-4) * max(refs)
        if ok:
            refs.append(kkt_error)
            del refs[:-4]
        return ok

    def _enter_monotone_mode(self, s: np.ndarray, z: np.ndarray) -> None:
        """Fixed-μ fallback (IPOPT): μ = 0.8 · average complementarity, the filter reset."""
        self.free_mode = False
        self._set_mu(float(np.clip(0.8 * avg_compl(s, z), self.mu_floor, self.mu_max)))
        self.filter_reset = True


def avg_compl(s: np.ndarray, z: np.ndarray) -> float:
    """The average complementarity ``sᵀz/m`` (0 without inequalities)."""
    return mean_product(s, z) if len(s) else 0.0
