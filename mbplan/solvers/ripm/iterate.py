"""The RIPM's iterate: primal point, slacks, multipliers, their trial points and residuals.

``_Trial`` is a candidate primal point with its values, ``_Step`` a Newton direction and
``_IterateState`` the methods that evaluate the problem and the optimality residuals of eq. (50)
(of the restoration problem in that phase; see :mod:`mbplan.solvers.ripm.restoration`) and the scaled
KKT error ``E_μ`` (eq. 55-56, WB eq. 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.finite import finite_vector
from mbplan.solvers.nlp import NLPEvaluation, Point
from mbplan.solvers.ripm.kernels import (
    abs_max,
    abs_sum,
    complementarity_error,
    constraint_values,
    csr_transpose_times,
    frac_to_boundary,
    measures,
    pairwise_sum,
    safeguarded_duals,
)

EPS = float(np.finfo(float).eps)


@dataclass
class Trial:
    """A candidate primal point with its values (``h``, ``g`` at ``x``; slacks ``s``).

    ``c`` are the constraints of the phase (``(h, g + s)``, minus ``p`` plus ``n`` in the
    restoration phase, whose trials also carry the elastic variables and the displacement ``ξ``).
    """

    x: Point
    s: np.ndarray
    f: float
    h: np.ndarray
    g: np.ndarray
    c: np.ndarray
    theta: float
    phi: float
    log_s: float  # Σ log s (φ_μ's barrier term without μ)
    p: np.ndarray | None = None
    n: np.ndarray | None = None
    xi: np.ndarray | None = None
    ev: NLPEvaluation | None = None  # with the Hessian at ``multipliers`` (see _trial_at)
    multipliers: tuple[np.ndarray, np.ndarray, float] | None = None  # y, z, α_z


@dataclass
class Step:
    """A Newton direction (the elastic parts only in the restoration phase)."""

    dx: np.ndarray
    ds: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    dp: np.ndarray | None = None
    dn: np.ndarray | None = None
    dzp: np.ndarray | None = None
    dzn: np.ndarray | None = None


def finite(*arrays: Any) -> bool:
    """No NaN or infinity in any of the arrays (or floats)."""
    for a in arrays:
        if type(a) is np.ndarray and a.ndim == 1 and a.dtype == np.float64:
            if not finite_vector(a):
                return False
        elif isinstance(a, float):  # np.float64 too
            if not math.isfinite(a):
                return False
        elif not np.isfinite(a).all():
            return False
    return True


amax = abs_max
"""``‖v‖∞`` of a 1-D array (0 if empty)."""

__all__ = [
    "EPS",
    "IterateState",
    "Step",
    "Trial",
    "amax",
    "finite",
    "frac_to_boundary",
    "transpose_times",
]


def transpose_times(a: sp.csr_matrix | sp.csr_array, x: np.ndarray) -> np.ndarray:
    """``aᵀ x`` for a CSR ``a`` without building the transpose (the sums of scipy's
    ``a.T @ x``, in its order)."""
    if not (
        sp.issparse(a) and a.format == "csr" and x.dtype == np.float64 and a.dtype == x.dtype
    ) or x.shape != (a.shape[0],):
        if x.shape == (a.shape[0],) and sp.issparse(a) and a.nnz == 0:
            return np.zeros(a.shape[1])  # an empty block of any dtype
        return a.T @ x  # scipy's product (and its error for a wrong length)
    return csr_transpose_times(a.indptr, a.indices, a.data, x, a.shape[1])


def _shape(a: Any) -> tuple[int, ...]:
    return a.shape if type(a) is np.ndarray else np.shape(a)


def _csr_arrays(a: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``indptr, indices, data`` of a Jacobian (converted to CSR if given otherwise)."""
    if type(a) is not sp.csr_matrix and not (sp.issparse(a) and a.format == "csr"):
        a = sp.csr_matrix(a)
    return a.indptr, a.indices, a.data


class IterateState:
    """Evaluation, trial points and residuals of one phase (main or restoration).

    Attributes set by the driver: ``p`` (problem), ``o`` (options), sizes ``n, me, mi, m``,
    ``resto`` (restoration phase: elastic variables ``ep, en`` with multipliers ``zp, zn``,
    displacement ``xi``, penalty ``rho``, proximity weight ``zeta``, ``sigma = 0`` on ``f``),
    the iterate ``x, s, y, z`` with its evaluation ``ev``, and ``mu``.
    """

    def _evaluate(self, x: Point, y: np.ndarray, z: np.ndarray) -> NLPEvaluation | None:
        """The problem at ``x`` with the Lagrangian's Hessian for ``σ, y, z``, or ``None`` if
        something is not finite."""
        self.sh.n_eval += 1
        ev: NLPEvaluation = self.p.evaluate(x, self.sigma, y, z)
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

    def _values(self, x: Point) -> tuple[float, np.ndarray, np.ndarray] | None:
        """``f, h, g`` at a trial point, or ``None`` if they are not finite."""
        self.sh.n_values += 1
        f, h, g = self.p.values(x)
        h, g = np.asarray(h), np.asarray(g)
        if h.shape != (self.me,) or g.shape != (self.mi,):
            raise InputError(
                f"problem.values returned eq/ineq of shapes {h.shape}, {g.shape}, expected "
                f"({self.me},), ({self.mi},)"
            )
        return (float(f), h, g) if finite(f, h, g) else None

    def _constraints(self, h, g, s, p=None, n=None) -> np.ndarray:
        c = np.concatenate([h, g + s])
        if p is not None:
            c += n - p
        return c

    def _lam(self) -> np.ndarray:
        """Multipliers of all rows ``(y, z)`` (the elastic rows of the restoration phase)."""
        return np.concatenate([self.y, self.z])

    def _make_trial(self, x: Point, s: np.ndarray, f: float, h, g, p=None, n=None, xi=None):
        c = np.empty(self.m)
        theta = constraint_values(h, g, s, c)
        if p is not None:
            c += n - p
            theta = abs_sum(c)
        log_s = pairwise_sum(np.log(s)) if len(s) else 0.0
        phi = self.sigma * f - self.mu * log_s
        if p is not None:
            phi += self.rho * float(np.sum(p) + np.sum(n))
            phi -= self.mu * float(np.sum(np.log(p)) + np.sum(np.log(n)))
            if xi is not None:
                phi += 0.5 * self.zeta * float(xi @ xi)
        return Trial(x, s, f, h, g, c, theta, phi, log_s, p, n, xi)

    def _current_trial(self) -> Trial:
        ev = self.ev
        return self._make_trial(
            self.x, self.s, ev.objective, ev.eq, ev.ineq, self.ep, self.en, self.xi
        )

    def _trial_at(self, step: Step, alpha: float, evaluate: bool = False) -> Trial | None:
        """The point ``R_x(α dx)``, ``s + α ds`` (and elastics), or ``None`` if not finite.
        ``evaluate`` (main phase): the evaluation with the Hessian at the multipliers the step
        would be accepted with, its values those of the trial (:attr:`Trial.ev`); the values
        alone if that evaluation is not finite."""
        x = self.p.retract(self.x, alpha * step.dx)
        if evaluate:
            s = self.s + alpha * step.ds
            multipliers = self._multipliers_at(step, alpha, s)
            ev = self._evaluate(x, *multipliers[:2])
            if ev is not None:
                trial = self._make_trial(x, s, ev.objective, ev.eq, ev.ineq)
                trial.ev, trial.multipliers = ev, multipliers
                return trial
        vals = self._values(x)
        if vals is None:
            return None
        p = n = xi = None
        if self.resto:
            p, n = self.ep + alpha * step.dp, self.en + alpha * step.dn
            xi = self.xi + alpha * step.dx
        return self._make_trial(x, self.s + alpha * step.ds, *vals, p, n, xi)

    def _multipliers_at(
        self, step: Step, alpha: float, s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """``y + α dy``, ``z`` after its own step ``α_z`` (WB eq. 15) within
        ``[μ/(κ_Σ s), κ_Σ μ/s]`` (WB eq. 16) for the slacks ``s``, and ``α_z``.

        In the main phase, when the slacks' fraction-to-the-boundary step ``α_s`` is below
        ``dual_step_cap``, ``α_z ≤ α_s``: ``dz`` is the complementarity row's answer to the whole
        ``ds``, of which the primal point takes only ``α_s``."""
        alpha_z = self._alpha_z_max(step)
        if not self.resto and self.o.dual_step_cap > 0:
            alpha_s = frac_to_boundary(self.s, step.ds, self.tau)
            if alpha_s < self.o.dual_step_cap:
                alpha_z = min(alpha_z, alpha_s)
        z = safeguarded_duals(self.z, step.dz, alpha_z, s, self.mu, self.o.kappa_sigma)
        return self.y + alpha * step.dy, z, alpha_z

    def _alpha_z_max(self, step: Step) -> float:
        """The multipliers' fraction-to-boundary step (WB eq. 15)."""
        alpha_z = frac_to_boundary(self.z, step.dz, self.tau)
        if self.resto:
            alpha_z = min(
                alpha_z,
                frac_to_boundary(self.zp, step.dzp, self.tau),
                frac_to_boundary(self.zn, step.dzn, self.tau),
            )
        return alpha_z

    def _primal_dual_error(self, ev: NLPEvaluation, y, z, s, mu: float) -> float:
        """IPOPT's primal-dual system error of the main phase at ``(ev, y, z, s)``: the mean
        absolute entry of ``(r_d, r_c, s∘z - μ)`` (its soft restoration's measure)."""
        r_d, r_c = np.empty(self.n), np.empty(self.m)
        measures(
            ev.gradient, self.sigma, *_csr_arrays(ev.eq_jacobian), y,
            *_csr_arrays(ev.ineq_jacobian), z, ev.eq, ev.ineq, s, r_d, r_c,
        )  # fmt: skip
        total = abs_sum(r_d) + abs_sum(r_c) + (abs_sum(s * z - mu) if self.mi else 0.0)
        return total / (self.n + self.m + self.mi)

    def _scalings(self, y_sum: float, z_sum: float) -> tuple[float, float]:
        """``s_d``, ``s_c`` of WB eq. 5 (multipliers averaged per component, as in IPOPT) from
        ``Σ|y|`` and ``Σ|z|``."""
        smax = self.o.s_max
        s_d = s_c = 1.0
        n_bounds = self.mi + (2 * len(self.ep) if self.resto else 0)
        bound_sum = z_sum
        if self.resto:
            bound_sum += float(np.sum(self.zp) + np.sum(self.zn))
        if self.m:
            avg = (y_sum + bound_sum) / (self.me + n_bounds)
            s_d = max(smax, avg) / smax
        if n_bounds:
            s_c = max(smax, bound_sum / n_bounds) / smax
        return s_d, s_c

    def _measures(self) -> None:
        """Residuals of (50) (of the restoration problem in that phase) at the current iterate,
        the scalings and the KKT error ``E_0``."""
        ev = self.ev
        self.r_d, self.r_c = np.empty(self.n), np.empty(self.m)
        self.inf_du, self.inf_pr, y_sum, z_sum, compl = measures(
            ev.gradient, self.sigma, *_csr_arrays(ev.eq_jacobian), self.y,
            *_csr_arrays(ev.ineq_jacobian), self.z, ev.eq, ev.ineq, self.s, self.r_d, self.r_c,
        )  # fmt: skip
        if self.resto:
            if self.zeta:
                self.r_d += self.zeta * self.xi
            self.r_c += self.en - self.ep
            lam = self._lam()
            self.r_pn = (self.rho - lam - self.zp, self.rho + lam - self.zn)
            self.inf_du = max(amax(self.r_d), amax(self.r_pn[0]), amax(self.r_pn[1]))
            self.inf_pr = amax(self.r_c)
        self.s_d, self.s_c = self._scalings(y_sum, z_sum)
        self.kkt_error = self._error(0.0, compl)
        self.measured = (ev, self.y, self.z, self.s)

    def _error(self, mu: float, compl: float | None = None) -> float:
        """``E_μ`` (eq. 55-56): scaled dual infeasibility, infeasibility, complementarity
        (``‖s∘z - μ‖∞`` of the main rows given as ``compl``, or computed)."""
        if compl is None:
            compl = complementarity_error(self.s, self.z, mu)
        if self.resto:
            compl = max(
                compl,
                complementarity_error(self.ep, self.zp, mu),
                complementarity_error(self.en, self.zn, mu),
            )
        return max(self.inf_du / self.s_d, self.inf_pr, compl / self.s_c)
