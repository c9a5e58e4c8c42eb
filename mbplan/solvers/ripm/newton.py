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
are eliminated row by row as well (:mod:`mbplan.solvers.ripm.restoration`): the matrix keeps the
main loop's pattern, and its symbolic factorization. With ``corrector`` the complementarity row's
``μe`` becomes Mehrotra's ``μe - ΔS_aff Δz_aff`` (solves with the same factorization).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from mbplan.solvers.kkt.reduced.system import ReducedKKTSystem
from mbplan.solvers.kkt.system import KKTSystem
from mbplan.solvers.nlp import NLPEvaluation
from mbplan.solvers.ripm.iterate import (
    Iterate,
    Residuals,
    Step,
    amax,
    finite,
    frac_to_boundary,
    transpose_times,
)
from mbplan.solvers.ripm.kernels import corrector_shift, newton_diagonal, newton_rhs, slack_step
from mbplan.solvers.ripm.options import InertiaOptions, LinearSolverOptions
from mbplan.solvers.ripm.phase import Phase

_NO_SHIFT = np.zeros(0)

CURVATURE_TEST_INF_PR = 1e-4
"""The curvature test runs only at iterates this close to feasibility (``inf_pr``), where the
crawls it ends happen: applied everywhere it accepted poor steps far from feasibility (the
drone benchmark's iterations went from 10.3 to 29.9 on average, one case to 458)."""

AFFINE_RATIO_MAX = 1e-8
"""Residual ratio the predictor step is solved to (or ``residual_ratio_max`` if looser): it only
sets μ (probing) and the corrector's shift ``Δs_aff Δz_aff``, which it moves by ~1e-5 relative
against a solve to 1e-14 (one triangular solve and residual fewer per iteration)."""


class NewtonStep:
    """The KKT system of one phase with the inertia correction's state: ``delta_w_last`` (the
    last ``δ_w > 0``) and ``n_perturbed`` (consecutive steps that needed one). After
    :meth:`compute`, :meth:`correction` solves with the same factorization, iterate, μ and
    corrector shift (WB's second-order correction)."""

    def __init__(
        self,
        kkt: KKTSystem | ReducedKKTSystem,
        phase: Phase,
        inertia: InertiaOptions,
        linear: LinearSolverOptions,
    ) -> None:
        self.kkt, self.phase, self.o, self.lin = kkt, phase, inertia, linear
        self.delta_w_last = 0.0
        self.n_perturbed = 0
        # the last step's context: iterate, residuals, μ, τ, corrector shift, rows' constraints
        self._it: Iterate | None = None
        self._res: Residuals | None = None
        self._mu = self._tau = 0.0
        self._shift: np.ndarray | None = None
        self._rhs_c = _NO_SHIFT

    def _rhs(self, c: np.ndarray) -> np.ndarray:
        """Right-hand side for the constraint values ``c`` (``r_c``, or a second-order
        correction's)."""
        ph, it, mu = self.phase, self._it, self._mu
        self._rhs_c = c  # the rows' linearization the solution satisfies (see _split)
        rhs = np.empty(ph.n + ph.m)
        shift = _NO_SHIFT if self._shift is None else self._shift
        newton_rhs(self._res.r_d, c, ph.me, it.s, it.z, mu, shift, rhs)
        if ph.resto:
            lam, lower = it.lam, rhs[ph.n :]
            lower += (mu - it.ep * (ph.rho - lam)) / it.zp
            lower -= (mu - it.en * (ph.rho + lam)) / it.zn
        return rhs

    def _diagonal(self, dw: float, dc: float) -> np.ndarray:
        """Diagonal added to ``K``: ``δ_w (+ζ)`` on the primal, the eliminated blocks and
        ``-δ_c`` on the dual rows."""
        ph, it = self.phase, self._it
        diagonal = np.empty(ph.n + ph.m)
        newton_diagonal(ph.n, ph.me, dw + ph.zeta(self._mu), dc, it.s, it.z, diagonal)
        if ph.resto:
            diagonal[ph.n :] -= it.ep / it.zp + it.en / it.zn
        return diagonal

    def _affine_step(self) -> Step:
        """The affine-scaling (predictor) step: the Newton step for μ = 0 with the current
        factorization, solved to :data:`AFFINE_RATIO_MAX` (no refinement step unless the first
        solve misses it)."""
        saved, self._mu, self._shift = self._mu, 0.0, None
        try:
            ratio_max = max(AFFINE_RATIO_MAX, self.lin.residual_ratio_max)
            return self._split(self._solve(self._rhs(self._res.r_c), ratio_max, min_refinement=0))
        finally:
            self._mu = saved

    def _safeguarded_corrector(self, corrected: np.ndarray, aff_reach: float) -> Step:
        """The corrected step if its fraction-to-boundary step ``min(α_s, α_z)`` (WB eq. 15) is
        at least the affine step's (``aff_reach``); otherwise the uncorrected step (one more
        solve) if that one reaches farther."""
        step = self._split(corrected)
        reach = self._boundary_step(step)
        if reach >= aff_reach:
            return step
        shift, self._shift = self._shift, None
        plain = self._split(self._solve(self._rhs(self._res.r_c)))
        if finite(plain.dx, plain.dz) and self._boundary_step(plain) > reach:
            return plain
        self._shift = shift
        return step

    def _boundary_step(self, step: Step) -> float:
        it, tau = self._it, self._tau
        return min(frac_to_boundary(it.s, step.ds, tau), frac_to_boundary(it.z, step.dz, tau))

    def _solve(
        self, rhs: np.ndarray, ratio_max: float | None = None, min_refinement: int = 1
    ) -> np.ndarray:
        """Solve with the current factorization (iterative refinement to ``ratio_max``, default
        ``residual_ratio_max``)."""
        lin = self.lin
        ratio = lin.residual_ratio_max if ratio_max is None else ratio_max
        return self.kkt.solve(rhs, lin.max_refinement_steps, ratio, min_refinement)[0]

    def _split(self, sol: np.ndarray) -> Step:
        ph, it = self.phase, self._it
        n, me = ph.n, ph.me
        dlam = sol[n:]
        dz = dlam[me:]
        shift = _NO_SHIFT if self._shift is None else self._shift
        ds = slack_step(it.s, it.z, dz, self._mu, shift)
        step = Step(sol[:n], ds, dlam[:me], dz)
        if ph.resto:
            self._elastic_steps(step, dlam)
        return step

    def _elastic_steps(self, step: Step, dlam: np.ndarray) -> None:
        """``dp, dn`` and their multipliers' steps of the restoration phase. Each row's elastic
        with the larger ``p/z_p`` (``n/z_n``) comes from the row's linearization
        ``c + A dx + ds - dp + dn = 0`` instead of its own equations: where ``z → 0`` its formula
        ``(n/z_n)(-dλ + μ/n - ρ - λ)`` multiplies the cancellation in ``ρ + λ`` by ``n/z_n``."""
        it, rho, mu, me = self._it, self.phase.rho, self._mu, self.phase.me
        lam = it.lam
        p, nn, zp, zn = it.ep, it.en, it.zp, it.zn
        dp = (p / zp) * (dlam + mu / p - rho + lam)
        dn = (nn / zn) * (-dlam + mu / nn - rho - lam)
        lin = np.array(self._rhs_c, dtype=float)
        lin[:me] += it.ev.eq_jacobian @ step.dx
        lin[me:] += it.ev.ineq_jacobian @ step.dx + step.ds
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
        stabilized SQP (Wright 1998)."""
        return max(self.o.delta_c_bar * self._mu**self.o.kappa_c, residual)

    def next_delta_w(self, dw: float) -> float:
        """The next trial ``δ_w`` after ``dw`` gave the wrong inertia (WB IC-3, IC-5)."""
        o = self.o
        if dw == 0.0:  # IC-3
            return (
                o.delta_w_init
                if self.delta_w_last == 0
                else max(o.delta_w_min, o.kappa_w_minus * self.delta_w_last)
            )
        first = self.delta_w_last == 0 or 1e5 * self.delta_w_last < dw  # IC-5
        return dw * (o.kappa_w_plus_first if first else o.kappa_w_plus)

    def first_delta_w(self) -> float:
        """The first trial ``δ_w``: 0 (IC-1), or ``κ_w⁻ δ_w,last`` after ``degenerate_iters``
        perturbed steps while that is at least ``degenerate_zero_below``."""
        o = self.o
        if o.degenerate_iters and self.n_perturbed >= o.degenerate_iters and self.delta_w_last:
            dw = max(o.delta_w_min, o.kappa_w_minus * self.delta_w_last)
            return 0.0 if dw < o.degenerate_zero_below else dw
        return 0.0

    def compute(
        self,
        it: Iterate,
        res: Residuals,
        mu: float,
        tau: float,
        probe: Callable[[Step], tuple[float, float]] | None = None,
        corrector: bool = False,
    ) -> tuple[Step, float] | None:
        """The Newton step (53) at ``it`` for ``μ`` with inertia correction (WB Algorithm IC)
        and its ``δ_w``; ``None`` if ``δ_w`` exceeds ``δ_w,max`` (IC-6). ``probe`` maps the
        affine-scaling step of each factorization with the right inertia to the step's μ and τ
        (Mehrotra's probing); ``corrector``: Mehrotra's corrector (with inequalities)."""
        lin, m = self.lin, self.phase.m
        self._it, self._res, self._mu, self._tau, self._shift = it, res, mu, tau, None
        self.kkt.set_matrices(it.ev.hessian_lower, it.ev.eq_jacobian, it.ev.ineq_jacobian)
        dw, dc = self.first_delta_w(), 0.0
        pretend_singular = False
        while True:
            inertia = self.kkt.factorize(self._diagonal(dw, dc), lin.static_regularization)
            correct = inertia is not None and inertia.zero == 0 and inertia.negative == m
            singular = not correct and (inertia is None or inertia.zero > 0 or inertia.negative < m)
            if not (correct or singular) and self._curvature_test(res):
                correct = self._positive_curvature(dw)
            if correct:
                aff = None
                if probe is not None:  # μ from an affine step with this factorization
                    aff = self._affine_step()
                    self._mu, self._tau = probe(aff)
                if corrector and self.phase.mi:
                    aff = aff or self._affine_step()
                    if finite(aff.ds, aff.dz):  # else no corrector (a broken-down solve)
                        self._shift, aff_reach = corrector_shift(
                            it.s, aff.ds, it.z, aff.dz, self._tau
                        )
                rhs = self._rhs(res.r_c)
                sol, ratio = self.kkt.solve(rhs, lin.max_refinement_steps, lin.residual_ratio_max)
                if dc == 0.0 and m > 0 and ratio > lin.residual_ratio_max and finite(sol):
                    # refinement stalled: K is singular, the right-hand side not in its range
                    # (e.g. a rank-deficient A_E with inconsistent linearized constraints)
                    pretend_singular = ratio > lin.residual_ratio_singular
                    dc = self._delta_c(_residual(ratio, sol, rhs))
                    continue
                if finite(sol) and (ratio <= lin.residual_ratio_singular or pretend_singular):
                    if dw > 0:
                        self.delta_w_last = dw
                        self.n_perturbed += 1
                    else:
                        self.n_perturbed = 0
                    if self._shift is not None:
                        return self._safeguarded_corrector(sol, aff_reach), dw
                    return self._split(sol), dw
                pretend_singular = singular = True  # IPOPT: refinement failed
            if singular and dc == 0.0 and m > 0:
                dc = self._delta_c()  # IC-2
                continue
            dw = self.next_delta_w(dw)
            if dw > self.o.delta_w_max:  # IC-6
                self.delta_w_last = 0.0
                self.n_perturbed = 0
                return None

    def _curvature_test(self, res: Residuals) -> bool:
        """Whether a wrong inertia may be overruled by :meth:`_positive_curvature`: main phase,
        ``kappa_curvature > 0``, a nearly feasible iterate (:data:`CURVATURE_TEST_INF_PR`)."""
        return (
            self.o.kappa_curvature > 0
            and not self.phase.resto
            and res.inf_pr <= CURVATURE_TEST_INF_PR
        )

    def _positive_curvature(self, dw: float) -> bool:
        """Chiang & Zavala's inertia-free test on the Newton step ``dx`` of the current
        factorization (for the iteration's μ, without corrector): ``dxᵀ(W + δ_w I + A_Iᵀ Σ A_I)
        dx ≥ κ dxᵀdx``, ``Σ = S⁻¹Z``, the curvature of the condensed primal system along
        ``dx``."""
        lin, it = self.lin, self._it
        sol, _ = self.kkt.solve(
            self._rhs(self._res.r_c), lin.max_refinement_steps, lin.residual_ratio_max
        )
        if not finite(sol):
            return False
        dx = sol[: self.phase.n]
        lower = sp.tril(it.ev.hessian_lower, format="csr")  # it may hold the full matrix
        lower_dx = lower @ dx
        curvature = 2.0 * float(dx @ lower_dx) - float(dx @ (lower.diagonal() * dx))
        curvature += dw * float(dx @ dx)
        if it.ev.ineq_jacobian.shape[0]:
            a = it.ev.ineq_jacobian @ dx
            curvature += float(np.sum(it.z / it.s * a * a))
        return curvature >= self.o.kappa_curvature * float(dx @ dx)

    def correction(self, c: np.ndarray) -> Step | None:
        """The last step's system solved for the constraint values ``c`` (a second-order
        correction, WB); ``None`` if not finite."""
        sol = self._solve(self._rhs(c))
        return self._split(sol) if finite(sol) else None

    def least_squares_y(self, ev: NLPEvaluation, z: np.ndarray, limit: float) -> np.ndarray | None:
        """``y`` minimizing ``‖grad f + A_Eᵀy + A_Iᵀz‖`` (WB); ``None`` if it is larger than
        ``limit`` (``constr_mult_init_max``) or not computable. Solved with this system and pattern (its
        symbolic phase and reduction serve both): ``H`` and ``A_I`` with zero values, ``I`` on
        the primal diagonal, ``-I`` on the inequality rows (it overwrites the system's matrices
        and factorization: every Newton step sets its own first)."""
        kkt, n, me, m = self.kkt, self.phase.n, self.phase.me, self.phase.m
        kkt.set_matrices(
            _zero_values(ev.hessian_lower), ev.eq_jacobian, _zero_values(ev.ineq_jacobian)
        )
        diag = np.zeros(n + m)
        diag[:n] = 1.0
        diag[n + me :] = -1.0
        inertia = kkt.factorize(diag, self.lin.static_regularization)
        if inertia is None or inertia.zero or inertia.negative != m:
            return None
        rhs = np.zeros(n + m)
        np.negative(ev.gradient + transpose_times(ev.ineq_jacobian, z), out=rhs[:n])
        sol, _ = kkt.solve(rhs, self.lin.max_refinement_steps, self.lin.residual_ratio_max)
        y = sol[n : n + me]
        return y if finite(y) and amax(y) <= limit else None


def _residual(ratio: float, x: np.ndarray, b: np.ndarray) -> float:
    """``‖b - K x‖∞`` from IPOPT's ratio ``‖r‖∞ / (min(‖x‖∞, 1e6‖b‖∞) + ‖b‖∞)``."""
    nb = amax(b)
    return ratio * (min(amax(x), 1e6 * nb) + nb)


def _zero_values(matrix: sp.spmatrix) -> sp.csr_matrix:
    """``matrix``'s pattern with zero values."""
    m = sp.csr_matrix(matrix)
    return sp.csr_matrix((np.zeros_like(m.data), m.indices, m.indptr), shape=m.shape)
