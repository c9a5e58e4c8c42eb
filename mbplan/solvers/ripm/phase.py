"""The barrier problem of a phase of the RIPM: eq. (49) in the main phase, the ℓ1 restoration
problem of :mod:`mbplan.solvers.ripm.restoration` in a restoration phase. :class:`Phase`
evaluates the problem, trial points along a step and the residuals of (50) at an
:class:`~mbplan.solvers.ripm.iterate.Iterate`; ``μ`` and ``τ`` are arguments (the barrier
strategy owns them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.solvers.nlp import NLPEvaluation, Point, RIPMProblem
from mbplan.solvers.ripm.iterate import Iterate, Residuals, Step, Trial, amax, finite
from mbplan.solvers.ripm.kernels import (
    abs_sum,
    complementarity_error,
    constraint_values,
    frac_to_boundary,
    measures,
    pairwise_sum,
    ratio_sum,
    safeguarded_duals,
)
from mbplan.solvers.ripm.options import LineSearchOptions


@dataclass
class Counters:
    """Problem calls of a solve (the main and the restoration phases together)."""

    n_eval: int = 0
    n_values: int = 0


def _shape(a: Any) -> tuple[int, ...]:
    return a.shape if type(a) is np.ndarray else np.shape(a)


def _csr_arrays(a: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``indptr, indices, data`` of a Jacobian (converted to CSR if given otherwise)."""
    if type(a) is not sp.csr_matrix and not (sp.issparse(a) and a.format == "csr"):
        a = sp.csr_matrix(a)
    return a.indptr, a.indices, a.data


class Phase:
    """The barrier problem of one phase: eq. (49) with ``σ = 1`` (``rho=None``), or the ℓ1
    restoration problem with penalty ``ρ = rho``, proximity weight ``ζ = proximity · √μ`` and
    ``σ = 0`` on ``f``. Evaluates the problem, trial points and the residuals of (50)."""

    def __init__(
        self,
        problem: RIPMProblem,
        counters: Counters,
        line_search: LineSearchOptions,
        s_max: float,
        rho: float | None = None,
        proximity: float = 0.0,
    ) -> None:
        self.problem, self.counters, self.o, self.s_max = problem, counters, line_search, s_max
        self.n, self.me, self.mi = int(problem.n), int(problem.n_eq), int(problem.n_ineq)
        self.m = self.me + self.mi
        self.resto = rho is not None
        self.sigma = 0.0 if self.resto else 1.0
        self.rho = 0.0 if rho is None else rho
        self.proximity = proximity

    def zeta(self, mu: float) -> float:
        """Weight ``ζ`` of ``½‖ξ‖²`` (0 in the main phase)."""
        return self.proximity * math.sqrt(mu) if self.resto else 0.0

    def evaluate(self, x: Point, y: np.ndarray, z: np.ndarray) -> NLPEvaluation | None:
        """The problem at ``x`` with the Lagrangian's Hessian for ``σ, y, z``, or ``None`` if
        something is not finite."""
        self.counters.n_eval += 1
        ev: NLPEvaluation = self.problem.evaluate(x, self.sigma, y, z)
        h = ev.hessian_lower
        if not finite(
            ev.objective, ev.gradient, ev.eq, ev.ineq, ev.eq_jacobian.data, ev.ineq_jacobian.data,
            h.data,
        ):  # fmt: skip
            return None
        shapes = (_shape(ev.gradient), _shape(ev.eq), _shape(ev.ineq))
        shapes += (ev.eq_jacobian.shape, ev.ineq_jacobian.shape, h.shape)
        expected = ((self.n,), (self.me,), (self.mi,), (self.me, self.n), (self.mi, self.n))
        expected += ((self.n, self.n),)
        if shapes != expected:  # the compiled kernels index by these shapes unchecked
            raise InputError(
                "problem returned gradient, eq, ineq, their Jacobians and the Hessian of "
                f"shapes {shapes}, expected {expected}"
            )
        return ev

    def values(self, x: Point) -> tuple[float, np.ndarray, np.ndarray] | None:
        """``f, h, g`` at a trial point, or ``None`` if they are not finite."""
        self.counters.n_values += 1
        f, h, g = self.problem.values(x)
        h, g = np.asarray(h), np.asarray(g)
        if h.shape != (self.me,) or g.shape != (self.mi,):
            raise InputError(
                f"problem.values returned eq/ineq of shapes {h.shape}, {g.shape}, expected "
                f"({self.me},), ({self.mi},)"
            )
        return (float(f), h, g) if finite(f, h, g) else None

    def trial(self, x: Point, s, f: float, h, g, mu: float, p=None, n=None, xi=None) -> Trial:
        """The point with ``θ`` and ``φ_μ`` of this phase."""
        c = np.empty(self.m)
        theta = constraint_values(h, g, s, c)
        if p is not None:
            c += n - p
            theta = abs_sum(c)
        log_s = pairwise_sum(np.log(s)) if len(s) else 0.0
        phi = self.sigma * f - mu * log_s
        if p is not None:
            phi += self.rho * float(np.sum(p) + np.sum(n))
            phi -= mu * float(np.sum(np.log(p)) + np.sum(np.log(n)))
            if xi is not None:
                phi += 0.5 * self.zeta(mu) * float(xi @ xi)
        return Trial(x, s, f, h, g, c, theta, phi, log_s, p, n, xi)

    def current(self, it: Iterate, mu: float) -> Trial:
        """The iterate as a trial point."""
        ev = it.ev
        return self.trial(it.x, it.s, ev.objective, ev.eq, ev.ineq, mu, it.ep, it.en, it.xi)

    def trial_at(
        self, it: Iterate, step: Step, alpha: float, mu: float, tau: float, evaluate: bool = False
    ) -> Trial | None:
        """The point ``R_x(α dx)``, ``s + α ds`` (and elastics), or ``None`` if not finite.
        ``evaluate`` (main phase only): the evaluation with the Hessian at the multipliers the
        step would be accepted with, its values those of the trial (:attr:`Trial.ev`); the
        values alone if that evaluation is not finite."""
        x = self.problem.retract(it.x, alpha * step.dx)
        if evaluate and not self.resto:
            s = it.s + alpha * step.ds
            multipliers = self.multipliers_at(it, step, alpha, s, mu, tau)
            ev = self.evaluate(x, *multipliers[:2])
            if ev is not None:
                trial = self.trial(x, s, ev.objective, ev.eq, ev.ineq, mu)
                trial.ev, trial.multipliers = ev, multipliers
                return trial
        vals = self.values(x)
        if vals is None:
            return None
        p = n = xi = None
        if self.resto:
            p, n = it.ep + alpha * step.dp, it.en + alpha * step.dn
            xi = it.xi + alpha * step.dx
        return self.trial(x, it.s + alpha * step.ds, *vals, mu, p, n, xi)

    def multipliers_at(
        self, it: Iterate, step: Step, alpha: float, s: np.ndarray, mu: float, tau: float
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """``y + α dy``, ``z`` after its own step ``α_z`` (WB eq. 15) within
        ``[μ/(κ_Σ s), κ_Σ μ/s]`` (WB eq. 16) for the slacks ``s``, and ``α_z``.

        In the main phase, when the slacks' fraction-to-the-boundary step ``α_s`` is below
        ``dual_step_cap``, ``α_z ≤ α_s``: ``dz`` is the complementarity row's answer to the whole
        ``ds``, of which the primal point takes only ``α_s``."""
        alpha_z = self.alpha_z_max(it, step, tau)
        if not self.resto and self.o.dual_step_cap > 0:
            alpha_s = frac_to_boundary(it.s, step.ds, tau)
            if alpha_s < self.o.dual_step_cap:
                alpha_z = min(alpha_z, alpha_s)
        z = safeguarded_duals(it.z, step.dz, alpha_z, s, mu, self.o.kappa_sigma)
        return it.y + alpha * step.dy, z, alpha_z

    def alpha_max(self, it: Iterate, step: Step, tau: float) -> float:
        """The primal fraction-to-boundary step (WB eq. 15)."""
        a = frac_to_boundary(it.s, step.ds, tau)
        if self.resto:
            a = min(a, frac_to_boundary(it.ep, step.dp, tau))
            a = min(a, frac_to_boundary(it.en, step.dn, tau))
        return a

    def alpha_z_max(self, it: Iterate, step: Step, tau: float) -> float:
        """The multipliers' fraction-to-boundary step (WB eq. 15)."""
        alpha_z = frac_to_boundary(it.z, step.dz, tau)
        if self.resto:
            alpha_z = min(
                alpha_z,
                frac_to_boundary(it.zp, step.dzp, tau),
                frac_to_boundary(it.zn, step.dzn, tau),
            )
        return alpha_z

    def slope(self, it: Iterate, step: Step, mu: float) -> float:
        """Directional derivative of ``φ_μ`` along the step."""
        gphi = self.sigma * float(np.dot(it.ev.gradient, step.dx))
        gphi -= mu * ratio_sum(step.ds, it.s)
        if self.resto:
            gphi += self.rho * float(np.sum(step.dp) + np.sum(step.dn))
            gphi -= mu * float(np.sum(step.dp / it.ep) + np.sum(step.dn / it.en))
            gphi += self.zeta(mu) * float(it.xi @ step.dx)
        return gphi

    def primal_dual_error(self, ev: NLPEvaluation, y, z, s, mu: float) -> float:
        """IPOPT's primal-dual system error of the main phase at ``(ev, y, z, s)``: the mean
        absolute entry of ``(r_d, r_c, s∘z - μ)`` (its soft restoration's measure)."""
        r_d, r_c = np.empty(self.n), np.empty(self.m)
        measures(
            ev.gradient, self.sigma, *_csr_arrays(ev.eq_jacobian), y,
            *_csr_arrays(ev.ineq_jacobian), z, ev.eq, ev.ineq, s, r_d, r_c,
        )  # fmt: skip
        total = abs_sum(r_d) + abs_sum(r_c) + (abs_sum(s * z - mu) if self.mi else 0.0)
        return total / (self.n + self.m + self.mi)

    def measures(self, it: Iterate, mu: float) -> Residuals:
        """Residuals of (50) (of the restoration problem in that phase) at ``it``, the scalings
        and the KKT error ``E_0``."""
        ev = it.ev
        r_d, r_c = np.empty(self.n), np.empty(self.m)
        inf_du, inf_pr, y_sum, z_sum, compl = measures(
            ev.gradient, self.sigma, *_csr_arrays(ev.eq_jacobian), it.y,
            *_csr_arrays(ev.ineq_jacobian), it.z, ev.eq, ev.ineq, it.s, r_d, r_c,
        )  # fmt: skip
        r_pn = None
        if self.resto:
            zeta = self.zeta(mu)
            if zeta:
                r_d += zeta * it.xi
            r_c += it.en - it.ep
            lam = it.lam
            r_pn = (self.rho - lam - it.zp, self.rho + lam - it.zn)
            inf_du = max(amax(r_d), amax(r_pn[0]), amax(r_pn[1]))
            inf_pr = amax(r_c)
        s_d, s_c = self._scalings(it, y_sum, z_sum)
        res = Residuals(r_d, r_c, inf_du, inf_pr, s_d, s_c, 0.0, (ev, it.y, it.z, it.s), r_pn)
        res.kkt_error = self.error(it, res, 0.0, compl)
        return res

    def _scalings(self, it: Iterate, y_sum: float, z_sum: float) -> tuple[float, float]:
        """``s_d``, ``s_c`` of WB eq. 5 (multipliers averaged per component, as in IPOPT) from
        ``Σ|y|`` and ``Σ|z|``."""
        smax = self.s_max
        s_d = s_c = 1.0
        n_bounds = self.mi + (2 * len(it.ep) if self.resto else 0)
        bound_sum = z_sum
        if self.resto:
            bound_sum += float(np.sum(it.zp) + np.sum(it.zn))
        if self.m:
            avg = (y_sum + bound_sum) / (self.me + n_bounds)
            s_d = max(smax, avg) / smax
        if n_bounds:
            s_c = max(smax, bound_sum / n_bounds) / smax
        return s_d, s_c

    def error(self, it: Iterate, res: Residuals, mu: float, compl: float | None = None) -> float:
        """``E_μ`` (eq. 55-56): scaled dual infeasibility, infeasibility, complementarity
        (``‖s∘z - μ‖∞`` of the main rows given as ``compl``, or computed)."""
        if compl is None:
            compl = complementarity_error(it.s, it.z, mu)
        if self.resto:
            compl = max(
                compl,
                complementarity_error(it.ep, it.zp, mu),
                complementarity_error(it.en, it.zn, mu),
            )
        return max(res.inf_du / res.s_d, res.inf_pr, compl / res.s_c)
