"""The RIPM's Newton step (eq. 53) with IPOPT's inertia correction (WB Algorithm IC).

With ``Σ = S⁻¹Z`` the last row of (53), ``Z ds + S dz = -(Sz - μe)``, gives
``ds = -Z⁻¹(Sz - μe + S dz)``; substituted into ``A_I dx + ds = -(g + s)`` it leaves the
symmetric system solved by :class:`~mbplan.solvers.kkt.system.KKTSystem`::

    [[W + δ_w I,  A_Eᵀ,    A_Iᵀ           ]   [dx]     [grad f + A_Eᵀy + A_Iᵀz]
     [A_E,       -δ_c I,   0              ] · [dy] = - [h                     ]
     [A_I,        0,      -(Σ⁻¹ + δ_c I)  ]]  [dz]     [g + μ/z               ]

``W`` is the Riemannian Hessian of the Lagrangian (eq. 54). The step is a descent direction of
the barrier problem iff the inertia is ``(n, n_eq + n_ineq, 0)``; otherwise ``δ_w``, ``δ_c``
follow WB Algorithm IC. ``K`` is also treated as singular (IC-2) when iterative refinement cannot
bring the residual ratio below ``residual_ratio_max``: the static regularization hides a zero
pivot from the inertia, and only a right-hand side outside the range of ``K`` leaves a residual
that refinement cannot remove. In the restoration phase the elastic variables and their multipliers
are eliminated row by row as well (:mod:`mbplan.solvers.ripm.restoration`): the matrix keeps the main
loop's pattern, and its symbolic factorization. With ``corrector`` the complementarity row's
``μe`` becomes Mehrotra's ``μe - ΔS_aff Δz_aff`` (solves with the same factorization).
"""

from __future__ import annotations

import numpy as np

from mbplan.solvers.ripm.iterate import Step, amax, finite, frac_to_boundary
from mbplan.solvers.ripm.kernels import corrector_shift, newton_diagonal, newton_rhs, slack_step

_NO_SHIFT = np.zeros(0)

AFFINE_RATIO_MAX = 1e-8
"""Residual ratio the predictor step is solved to (or ``residual_ratio_max`` if looser): it only
sets μ (probing) and the corrector's shift ``Δs_aff Δz_aff``, which it moves by ~1e-5 relative
against a solve to 1e-14 (one triangular solve and residual fewer per iteration; the iterates
change in their last digits, and a rounding-sensitive path with them)."""


class NewtonStep:
    """Right-hand side, diagonal, factorization with inertia correction and step recovery."""

    def _rhs(self, c: np.ndarray) -> np.ndarray:
        """Right-hand side for the constraint values ``c`` (``r_c``, or a second-order
        correction's)."""
        self.rhs_c = c  # the rows' linearization the solution satisfies (see _split)
        rhs = np.empty(self.n + self.m)
        shift = _NO_SHIFT if self.compl_shift is None else self.compl_shift
        newton_rhs(self.r_d, c, self.me, self.s, self.z, self.mu, shift, rhs)
        if self.resto:
            lam, lower = self._lam(), rhs[self.n :]
            lower += (self.mu - self.ep * (self.rho - lam)) / self.zp
            lower -= (self.mu - self.en * (self.rho + lam)) / self.zn
        return rhs

    def _diagonal(self, dw: float, dc: float) -> np.ndarray:
        """Diagonal added to ``K``: ``δ_w (+ζ)`` on the primal, the eliminated blocks and
        ``-δ_c`` on the dual rows."""
        diagonal = np.empty(self.n + self.m)
        newton_diagonal(self.n, self.me, dw + self.zeta, dc, self.s, self.z, diagonal)
        if self.resto:
            diagonal[self.n :] -= self.ep / self.zp + self.en / self.zn
        return diagonal

    def _affine_step(self) -> Step:
        """The affine-scaling (predictor) step: the Newton step for μ = 0 with the current
        factorization, solved to :data:`AFFINE_RATIO_MAX` (no refinement step unless the first
        solve misses it)."""
        saved, self.mu, self.compl_shift = self.mu, 0.0, None
        try:
            ratio_max = max(AFFINE_RATIO_MAX, self.o.residual_ratio_max)
            return self._split(self._solve(self._rhs(self.r_c), ratio_max, min_refinement=0))
        finally:
            self.mu = saved

    def _safeguarded_corrector(self, corrected: np.ndarray, aff_reach: float) -> Step:
        """The corrected step if its fraction-to-boundary step ``min(α_s, α_z)`` (WB eq. 15) is
        at least the affine step's (``aff_reach``); otherwise the uncorrected step (one more
        solve) if that one reaches farther."""
        step = self._split(corrected)
        reach = self._boundary_step(step)
        if reach >= aff_reach:
            return step
        shift, self.compl_shift = self.compl_shift, None
        plain = self._split(self._solve(self._rhs(self.r_c)))
        if finite(plain.dx, plain.dz) and self._boundary_step(plain) > reach:
            return plain
        self.compl_shift = shift
        return step

    def _boundary_step(self, step: Step) -> float:
        return min(
            frac_to_boundary(self.s, step.ds, self.tau), frac_to_boundary(self.z, step.dz, self.tau)
        )

    def _solve(
        self, rhs: np.ndarray, ratio_max: float | None = None, min_refinement: int = 1
    ) -> np.ndarray:
        """Solve with the current factorization (iterative refinement to ``ratio_max``, default
        ``residual_ratio_max``)."""
        o = self.o
        ratio = o.residual_ratio_max if ratio_max is None else ratio_max
        return self.kkt.solve(rhs, o.max_refinement_steps, ratio, min_refinement)[0]

    def _split(self, sol: np.ndarray) -> Step:
        n, me = self.n, self.me
        dlam = sol[n:]
        dz = dlam[me:]
        ds = slack_step(
            self.s, self.z, dz, self.mu, _NO_SHIFT if self.compl_shift is None else self.compl_shift
        )
        step = Step(sol[:n], ds, dlam[:me], dz)
        if self.resto:
            self._elastic_steps(step, dlam)
        return step

    def _elastic_steps(self, step: Step, dlam: np.ndarray) -> None:
        """``dp, dn`` and their multipliers' steps of the restoration phase. Each row's elastic
        with the larger ``p/z_p`` (``n/z_n``) comes from the row's linearization
        ``c + A dx + ds - dp + dn = 0`` instead of its own equations: where ``z → 0`` its formula
        ``(n/z_n)(-dλ + μ/n - ρ - λ)`` multiplies the cancellation in ``ρ + λ`` by ``n/z_n``
        (10¹⁰ on the Wächter–Biegler example: rows off by 5e-5, the line search failed)."""
        lam, me = self._lam(), self.me
        p, nn, zp, zn, mu = self.ep, self.en, self.zp, self.zn, self.mu
        dp = (p / zp) * (dlam + mu / p - self.rho + lam)
        dn = (nn / zn) * (-dlam + mu / nn - self.rho - lam)
        lin = np.array(self.rhs_c, dtype=float)
        lin[:me] += self.ev.eq_jacobian @ step.dx
        lin[me:] += self.ev.ineq_jacobian @ step.dx + step.ds
        from_row = nn / zn >= p / zp
        step.dn = np.where(from_row, dp - lin, dn)
        step.dp = np.where(from_row, dp, lin + dn)
        step.dzp = mu / p - zp - (zp / p) * step.dp
        step.dzn = mu / nn - zn - (zn / nn) * step.dn

    def _delta_c(self, residual: float = 0.0) -> float:
        """``δ_c`` of a singular ``K`` (IC-2): IPOPT's ``δ̄_c μ^κ_c``, at least the residual
        ``‖b - K x‖∞`` that refinement could not remove (the right-hand side's part outside the
        range of ``K``). Along a left null vector ``v`` of the Jacobian the step is
        ``dλ_v = -vᵀc / δ_c``: with ``δ_c`` of the residual's size it stays bounded, as in
        stabilized SQP (Wright 1998); a small fixed ``δ_c`` or the static regularization alone
        let the multipliers, and with them the Hessian of the Lagrangian, grow like ``1/δ_c``."""
        o = self.o
        return max(o.delta_c_bar * self.mu**o.kappa_c, residual)

    def _newton_step(self) -> tuple[Step, float] | None:
        """Factorize with inertia correction (WB Algorithm IC) and solve; ``None`` on failure."""
        o, m = self.o, self.m
        self.kkt.set_matrices(self.ev.hessian_lower, self.ev.eq_jacobian, self.ev.ineq_jacobian)
        self.compl_shift = None
        dw = dc = 0.0
        if o.degenerate_iters and self.n_perturbed >= o.degenerate_iters and self.delta_w_last:
            # the zero trial has failed every time lately: start from the last iteration's δ_w
            # while that is large
            dw = max(o.delta_w_min, o.kappa_w_minus * self.delta_w_last)
            if dw < o.degenerate_zero_below:
                dw = 0.0
        pretend_singular = False
        while True:
            inertia = self.kkt.factorize(self._diagonal(dw, dc), o.static_regularization)
            correct = inertia is not None and inertia.zero == 0 and inertia.negative == m
            singular = not correct and (inertia is None or inertia.zero > 0 or inertia.negative < m)
            if correct:
                aff, probing = None, self.probe_pending
                if probing:  # μ from an affine step with this factorization
                    aff = self._probe_mu()
                if o.corrector and self.mi and not self.resto:
                    aff = aff or self._affine_step()
                    if finite(aff.ds, aff.dz):  # else no corrector (a broken-down solve)
                        self.compl_shift, aff_reach = corrector_shift(
                            self.s, aff.ds, self.z, aff.dz, self.tau
                        )
                rhs = self._rhs(self.r_c)
                sol, ratio = self.kkt.solve(rhs, o.max_refinement_steps, o.residual_ratio_max)
                if dc == 0.0 and m > 0 and ratio > o.residual_ratio_max and finite(sol):
                    # refinement stalled: K is singular, the right-hand side not in its range
                    # (e.g. a rank-deficient A_E with inconsistent linearized constraints)
                    pretend_singular = ratio > o.residual_ratio_singular
                    self.probe_pending = probing
                    dc = self._delta_c(_residual(ratio, sol, rhs))
                    continue
                if finite(sol) and (ratio <= o.residual_ratio_singular or pretend_singular):
                    if dw > 0:
                        self.delta_w_last = dw
                        self.n_perturbed += 1
                    else:
                        self.n_perturbed = 0
                    if self.compl_shift is not None:
                        return self._safeguarded_corrector(sol, aff_reach), dw
                    return self._split(sol), dw
                pretend_singular = singular = True  # IPOPT: refinement failed
                self.probe_pending = probing  # μ from the next factorization
            if singular and dc == 0.0 and m > 0:
                dc = self._delta_c()  # IC-2
                continue
            if dw == 0.0:  # IC-3
                dw = (
                    o.delta_w_init
                    if self.delta_w_last == 0
                    else max(o.delta_w_min, o.kappa_w_minus * self.delta_w_last)
                )
            else:  # IC-5
                first = self.delta_w_last == 0 or 1e5 * self.delta_w_last < dw
                dw *= o.kappa_w_plus_first if first else o.kappa_w_plus
            if dw > o.delta_w_max:  # IC-6
                self.delta_w_last = 0.0
                self.n_perturbed = 0
                return None


def _residual(ratio: float, x: np.ndarray, b: np.ndarray) -> float:
    """``‖b - K x‖∞`` from IPOPT's ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``."""
    nb = amax(b)
    return ratio * (min(amax(x), 1e6 * nb) + nb)
