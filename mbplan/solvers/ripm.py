"""Line-search Riemannian interior point method: Algorithm 1 of the RIPM paper (§VII) with the
globalization of IPOPT (Wächter & Biegler 2006, "WB"): filter line search with switching
condition and second-order correction, inertia correction, multiplier safeguards and an
ℓ1 feasibility restoration phase (WB §3.3) — what the paper's own implementation lacked (§IX).

**Barrier problem** (eq. 49): slacks ``g(x) + s = 0``, ``s > 0``, barrier objective
``φ_μ = f - μ Σ log s``. One multiplier ``z`` serves both ``g + s = 0`` and ``s ≥ 0`` (eq. 50).

**Newton step** (eq. 53). With ``Σ = S⁻¹Z`` the last row ``Z ds + S dz = -(Sz - μe)`` gives
``ds = -Z⁻¹(Sz - μe + S dz)``; substituted into ``A_I dx + ds = -(g + s)`` it leaves the
symmetric system solved by :class:`~mbplan.solvers.linear_solver.KKTSystem`::

    [[W + δ_w I,  A_Eᵀ,    A_Iᵀ           ]   [dx]     [grad f + A_Eᵀy + A_Iᵀz]
     [A_E,       -δ_c I,   0              ] · [dy] = - [h                     ]
     [A_I,        0,      -(Σ⁻¹ + δ_c I)  ]]  [dz]     [g + μ/z               ]

``W`` is the Riemannian Hessian of the Lagrangian (eq. 54). The step is a descent direction of
the barrier problem iff the inertia is ``(n, n_eq + n_ineq, 0)`` (the eliminated block ``Σ`` is
positive definite); otherwise ``δ_w``, ``δ_c`` follow WB Algorithm IC. By default ``δ_w`` is not
added to ``Σ`` (``ds`` then satisfies the linearized complementarity exactly); option
``regularize_slacks`` adds it as IPOPT does (``(Σ + δ_w)⁻¹`` in the last block).

**Step acceptance** (WB filter line search, in place of Algorithm 1's simpler test): trial points
``x(α) = R_x(α dx)`` (the retraction replaces ``x + α dx``), ``s(α) = s + α ds`` with
``α ≤ α_max`` from the fraction-to-boundary rule (WB eq. 15), accepted by the filter,
the switching condition (WB eq. 19) with the Armijo condition on ``φ_μ`` (WB eq. 20), or
sufficient progress in ``θ = ‖h‖₁ + ‖g + s‖₁`` or ``φ_μ`` (WB eq. 18); second-order
corrections (WB) when the first trial increases ``θ``; ``α < α_min`` (WB eq. 23) calls the
restoration phase. ``z`` takes its own fraction-to-boundary step ``α_z`` (WB eq. 15) and is
kept within ``[μ/(κ_Σ s), κ_Σ μ/s]`` (WB eq. 16).

**Barrier update and termination** (eq. 55-56, WB eq. 5 and 7): ``μ ← max(ε_tol/10,
min(κ_μ μ, μ^θ_μ))`` while ``E_μ ≤ κ_ε μ``; stop when ``E_0 ≤ ε_tol``.

**Restoration** (``restoration_method="elastic"``, WB §3.3, IPOPT's ``RestoMinC_1Nrm``): from
the iterate ``x_R`` where the line search failed, the same algorithm (a second instance of this
class) solves ::

    min  ρ Σ (p + n) + ζ/2 ‖ξ‖²   s.t.  (h(x), g(x) + s) - p + n = 0,   s, p, n ≥ 0,

with ``ξ`` the tangent displacement from ``x_R`` accumulated over the restoration steps (the
manifold version of IPOPT's ``x - x_R``), ``ζ = resto_proximity_weight · √μ`` and ``σ = 0`` on
``f``. The elastic variables ``p, n`` and their bound multipliers are eliminated row by row, which
adds ``-(P Z_p⁻¹ + N Z_n⁻¹)`` to the dual diagonal: the restoration's KKT matrix has the main
loop's sparsity pattern and reuses its symbolic factorization. It returns as soon as a point
reduces the original ``θ`` by ``kappa_resto`` and is acceptable to the original filter; a
converged restoration problem with ``‖h, g + s‖∞ > constr_viol_tol`` proves local
infeasibility. ``restoration_method="simple"`` keeps the earlier damped Gauss-Newton on
``½‖h, g + s‖²`` (see :meth:`_RIPM._restoration_simple`).

Every linear-algebra object is sparse with a fixed pattern; one iteration costs one
``problem.evaluate``, one ``problem.values`` per trial and a few sparse LDLᵀ factorizations
(the same AMD ordering throughout), i.e. time linear in the size of block-banded problems.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mbplan.errors import InputError
from mbplan.solvers.linear_solver import KKTSystem
from mbplan.solvers.options import RIPMOptions
from mbplan.solvers.problem import NLPEvaluation, Point, RIPMProblem
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus

_EPS = float(np.finfo(float).eps)
_HEADER = "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls"


def solve_ripm(
    problem: RIPMProblem,
    x0: Point,
    options: RIPMOptions | None = None,
    *,
    y0: np.ndarray | None = None,
    z0: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    verbose: bool = False,
    **overrides: Any,
) -> RIPMResult:
    """Solve Problem 2 (eq. 46) from ``x0`` with the RIPM.

    ``options`` defaults to :class:`RIPMOptions` (Table IV); keyword ``overrides`` replace single
    parameters (``solve_ripm(p, x0, tol=1e-8)``). ``y0``, ``z0`` (> 0) and ``s0`` (> 0) warm-start
    the multipliers and slacks. ``verbose=True`` is ``print_level=1``.
    """
    opts = (options or RIPMOptions()).replace(**overrides)
    if verbose and opts.print_level == 0:
        opts = opts.replace(print_level=1)
    return _RIPM(problem, opts).run(x0, y0, z0, s0)


@dataclass
class _Trial:
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
    p: np.ndarray | None = None
    n: np.ndarray | None = None
    xi: np.ndarray | None = None


@dataclass
class _Step:
    dx: np.ndarray
    ds: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    dp: np.ndarray | None = None
    dn: np.ndarray | None = None
    dzp: np.ndarray | None = None
    dzn: np.ndarray | None = None


@dataclass
class _Search:
    """Outcome of a line search: the accepted trial (``None`` if it failed) and the step taken.

    ``tag`` is ``f`` (Armijo), ``h`` (filter progress), ``T`` (tiny step, no search), ``w``
    (watchdog trial step), with ``S`` appended for a second-order correction."""

    trial: _Trial | None
    step: _Step | None = None
    alpha: float = 0.0
    trials: int = 0
    tag: str = ""
    all_nan: bool = False


@dataclass
class _Shared:
    """What the main phase and a restoration phase share: counters, log, KKT system."""

    kkt: KKTSystem
    history: IterationHistory
    out: Callable[[str], None] | None
    t0: float = 0.0
    iter: int = 0
    n_eval: int = 0
    n_values: int = 0
    counts: dict[str, int] = field(default_factory=dict)


class _Stop(Exception):
    """Ends the main loop with a status (raised from the phases of an iteration)."""

    def __init__(self, status: RIPMStatus, message: str = "") -> None:
        super().__init__(message)
        self.status, self.message = status, message or status.value


def _finite(*arrays: Any) -> bool:
    return all(np.all(np.isfinite(a)) for a in arrays)


def _frac_to_boundary(v: np.ndarray, dv: np.ndarray, tau: float) -> float:
    """Largest ``α ∈ (0, 1]`` with ``v + α dv ≥ (1 - τ) v`` (WB eq. 15)."""
    neg = dv < 0
    if not np.any(neg):
        return 1.0
    return float(min(1.0, np.min(-tau * v[neg] / dv[neg])))


def _amax(v: np.ndarray) -> float:
    return float(np.max(np.abs(v), initial=0.0))


def _elastic_start(c: np.ndarray, mu: float, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """``p, n > 0`` with ``c - p + n = 0`` and ``μ/p + μ/n = 2ρ`` (WB eq. 33)."""
    a = (mu - rho * c) / (2 * rho)
    n = np.maximum(a + np.sqrt(a * a + mu * c / (2 * rho)), _EPS * mu)
    return np.maximum(c + n, _EPS * mu), n


class _RIPM:
    """State of one solve (or of one restoration phase, ``parent`` given); see the module
    docstring for the algorithm."""

    def __init__(
        self, problem: RIPMProblem, options: RIPMOptions, parent: _RIPM | None = None
    ) -> None:
        self.p, self.o = problem, options
        self.n, self.me, self.mi = int(problem.n), int(problem.n_eq), int(problem.n_ineq)
        self.m = self.me + self.mi
        self.parent = parent
        self.resto = parent is not None
        if parent is None:
            out = (lambda line: print(line, file=sys.stdout)) if options.print_level > 0 else None
            self.sh = _Shared(KKTSystem(self.n, self.me, self.mi), IterationHistory(), out)
        else:
            self.sh = parent.sh
        # the phase: σ f + ρ Σ(p + n) + ζ/2 ‖ξ‖² (σ = 1, no elastics in the main phase)
        self.sigma = 0.0 if self.resto else 1.0
        self.elastic = self.resto
        self.er = slice(0, self.m)  # the rows with elastic variables (all in restoration)
        self.rho = options.resto_penalty
        self.zeta = 0.0
        self.delta_w_last = 0.0
        self.filter: list[tuple[float, float]] = []
        self.ep = self.en = self.zp = self.zn = self.xi = None
        # describes the step that produced the current iterate (for the log and history)
        self.last = {"d": 0.0, "dw": 0.0, "a_du": 0.0, "a_pr": 0.0, "ls": 0, "tag": " "}
        self.free_mode = options.mu_strategy == "adaptive" and parent is None
        self.kkt_refs: list[float] = []
        self.mu_max = math.inf
        self.wd: dict[str, Any] | None = None  # watchdog reference state
        self.n_short = 0
        self._soc_ok = True

    @property
    def kkt(self) -> KKTSystem:
        return self.sh.kkt

    @property
    def iter(self) -> int:
        return self.sh.iter

    def _count(self, key: str) -> None:
        self.sh.counts[key] = self.sh.counts.get(key, 0) + 1

    # ================================================================== evaluation
    def _evaluate(
        self, x: Point, y: np.ndarray, z: np.ndarray, hessian: bool = True
    ) -> NLPEvaluation | None:
        self.sh.n_eval += 1
        ev: NLPEvaluation = self.p.evaluate(x, self.sigma, y, z, hessian)
        parts = [ev.objective, ev.gradient, ev.eq, ev.ineq, ev.eq_jacobian.data]
        parts.append(ev.ineq_jacobian.data)
        if hessian:
            parts.append(ev.hessian_lower.data)
        if not _finite(*parts):
            return None
        shapes = (np.shape(ev.gradient), np.shape(ev.eq), np.shape(ev.ineq))
        if shapes != ((self.n,), (self.me,), (self.mi,)):
            raise InputError(
                f"problem returned gradient/eq/ineq of shapes {shapes}, expected "
                f"({self.n},), ({self.me},), ({self.mi},)"
            )
        return ev

    def _values(self, x: Point) -> tuple[float, np.ndarray, np.ndarray] | None:
        """``f, h, g`` at a trial point, or ``None`` if they are not finite."""
        self.sh.n_values += 1
        f, h, g = self.p.values(x)
        return (float(f), np.asarray(h), np.asarray(g)) if _finite(f, h, g) else None

    def _constraints(self, h, g, s, p=None, n=None) -> np.ndarray:
        c = np.concatenate([h, g + s])
        if p is not None:
            c[self.er] += n - p
        return c

    def _lam(self) -> np.ndarray:
        """Multipliers of the elastic rows."""
        return np.concatenate([self.y, self.z])[self.er]

    def _make_trial(
        self,
        x: Point,
        s: np.ndarray,
        f: float,
        h: np.ndarray,
        g: np.ndarray,
        p=None,
        n=None,
        xi=None,
    ) -> _Trial:
        c = self._constraints(h, g, s, p, n)
        theta = float(np.sum(np.abs(c)))
        phi = self.sigma * f - self.mu * float(np.sum(np.log(s)))
        if p is not None:
            phi += self.rho * float(np.sum(p) + np.sum(n))
            phi -= self.mu * float(np.sum(np.log(p)) + np.sum(np.log(n)))
            if xi is not None:
                phi += 0.5 * self.zeta * float(xi @ xi)
        return _Trial(x, s, f, h, g, c, theta, phi, p, n, xi)

    def _current_trial(self) -> _Trial:
        ev = self.ev
        return self._make_trial(
            self.x, self.s, ev.objective, ev.eq, ev.ineq, self.ep, self.en, self.xi
        )

    def _trial_at(self, step: _Step, alpha: float) -> _Trial | None:
        """The point ``R_x(α dx)``, ``s + α ds`` (and elastics), or ``None`` if not finite."""
        x = self.p.retract(self.x, alpha * step.dx)
        vals = self._values(x)
        if vals is None:
            return None
        p = n = xi = None
        if self.elastic:
            p, n = self.ep + alpha * step.dp, self.en + alpha * step.dn
            xi = None if self.xi is None else self.xi + alpha * step.dx
        return self._make_trial(x, self.s + alpha * step.ds, *vals, p, n, xi)

    # ================================================================== errors (eq. 55-56)
    def _scalings(self) -> tuple[float, float]:
        """``s_d``, ``s_c`` of WB eq. 5 (multipliers averaged per component, as in IPOPT)."""
        smax = self.o.s_max
        s_d = s_c = 1.0
        n_bounds = self.mi + (2 * len(self.ep) if self.elastic else 0)
        bound_sum = float(np.sum(np.abs(self.z)))
        if self.elastic:
            bound_sum += float(np.sum(self.zp) + np.sum(self.zn))
        if self.m:
            avg = (float(np.sum(np.abs(self.y))) + bound_sum) / (self.me + n_bounds)
            s_d = max(smax, avg) / smax
        if n_bounds:
            s_c = max(smax, bound_sum / n_bounds) / smax
        return s_d, s_c

    def _measures(self) -> None:
        """Residuals of (50) (of the restoration problem in that phase) at the current iterate."""
        ev = self.ev
        self.r_d = (
            self.sigma * ev.gradient + ev.eq_jacobian.T @ self.y + ev.ineq_jacobian.T @ self.z
        )
        if self.zeta:
            self.r_d += self.zeta * self.xi
        self.r_c = self._constraints(ev.eq, ev.ineq, self.s, self.ep, self.en)
        self.inf_du = _amax(self.r_d)
        if self.elastic:
            lam = self._lam()
            self.r_pn = (self.rho - lam - self.zp, self.rho + lam - self.zn)
            self.inf_du = max(self.inf_du, _amax(self.r_pn[0]), _amax(self.r_pn[1]))
        self.inf_pr_phase = _amax(self.r_c)
        self.inf_pr = self.inf_pr_phase
        self.s_d, self.s_c = self._scalings()
        self.kkt_error = self._error(0.0)
        if self.elastic and not self.resto:  # elastic mode: converge to an original solution
            self.inf_pr = max(_amax(ev.eq), _amax(ev.ineq + self.s))
            self.kkt_error = max(self.kkt_error, self.inf_pr)

    def _error(self, mu: float) -> float:
        """``E_μ`` (eq. 55-56): scaled dual infeasibility, infeasibility, complementarity."""
        compl = _amax(self.s * self.z - mu)
        if self.elastic:
            compl = max(compl, _amax(self.ep * self.zp - mu), _amax(self.en * self.zn - mu))
        return max(self.inf_du / self.s_d, self.inf_pr_phase, compl / self.s_c)

    # ================================================================== Newton step (53)
    def _rhs(self, c: np.ndarray, dw: float = 0.0) -> np.ndarray:
        """Right-hand side for the constraint values ``c`` (``r_c``, or a second-order
        correction's) and the regularization ``δ_w`` (only with ``regularize_slacks``)."""
        lower = -c
        if self.o.regularize_slacks and dw:
            lower[self.me :] -= (self.mu / self.s - self.z) / (self.z / self.s + dw)
        else:
            lower[self.me :] += self.s - self.mu / self.z
        if self.elastic:
            lam = self._lam()
            lower[self.er] += (self.mu - self.ep * (self.rho - lam)) / self.zp
            lower[self.er] -= (self.mu - self.en * (self.rho + lam)) / self.zn
        return np.concatenate([-self.r_d, lower])

    def _diagonal(self, dw: float, dc: float) -> np.ndarray:
        """Diagonal added to ``K``: ``δ_w (+ζ)`` on the primal, the eliminated blocks and
        ``-δ_c`` on the dual rows."""
        dual = np.full(self.m, -dc)
        sigma_inv = self.s / self.z
        if self.o.regularize_slacks and dw:
            sigma_inv = 1.0 / (self.z / self.s + dw)
        dual[self.me :] -= sigma_inv
        if self.elastic:
            dual[self.er] -= self.ep / self.zp + self.en / self.zn
        return np.concatenate([np.full(self.n, dw + self.zeta), dual])

    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the current factorization (iterative refinement as configured)."""
        return self.kkt.solve(rhs, self.o.max_refinement_steps, self.o.residual_ratio_max)[0]

    def _split(self, sol: np.ndarray, dw: float = 0.0) -> _Step:
        n, me = self.n, self.me
        dlam = sol[n:]
        dz = dlam[me:]
        if self.o.regularize_slacks and dw:
            # (Σ + δ_w) ds = -(μ/s - z) - dz... i.e. the s-row of IPOPT's system with δ_w
            ds = -(self.z - self.mu / self.s + dz) / (self.z / self.s + dw)
        else:
            ds = -self.s + self.mu / self.z - self.s * dz / self.z
        step = _Step(sol[:n], ds, dlam[:me], dz)
        if self.elastic:
            lam, dl = self._lam(), dlam[self.er]
            p, nn, zp, zn, mu = self.ep, self.en, self.zp, self.zn, self.mu
            step.dp = (p / zp) * (dl + mu / p - self.rho + lam)
            step.dn = (nn / zn) * (-dl + mu / nn - self.rho - lam)
            step.dzp = mu / p - zp - (zp / p) * step.dp
            step.dzn = mu / nn - zn - (zn / nn) * step.dn
        return step

    def _newton_step(self) -> tuple[_Step, float] | None:
        """Factorize with inertia correction (WB Algorithm IC) and solve; ``None`` on failure."""
        o, m = self.o, self.m
        self.kkt.set_matrices(self.ev.hessian_lower, self.ev.eq_jacobian, self.ev.ineq_jacobian)
        dw = dc = 0.0
        pretend_singular = False
        while True:
            inertia = self.kkt.factorize(self._diagonal(dw, dc), o.static_regularization)
            correct = inertia is not None and inertia.zero == 0 and inertia.negative == m
            singular = not correct and (inertia is None or inertia.zero > 0 or inertia.negative < m)
            if correct:
                rhs = self._rhs(self.r_c, dw)
                sol, ratio = self.kkt.solve(rhs, o.max_refinement_steps, o.residual_ratio_max)
                if _finite(sol) and (ratio <= o.residual_ratio_singular or pretend_singular):
                    if dw > 0:
                        self.delta_w_last = dw
                    return self._split(sol, dw), dw
                pretend_singular = singular = True  # IPOPT: refinement failed
            if singular and dc == 0.0 and m > 0:
                dc = o.delta_c_bar * self.mu**o.kappa_c  # IC-2
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
                return None

    # ================================================================== filter (WB)
    def _filter_accepts(self, theta: float, phi: float) -> bool:
        if theta >= self.theta_max:
            return False
        return all(theta < t or phi < f for t, f in self.filter)

    def _augment_filter(self, theta: float, phi: float) -> None:
        """Add the corner ``((1-γ_θ)θ, φ - γ_φ θ)`` (WB eq. 22), dropping dominated entries."""
        t, f = (1 - self.o.gamma_theta) * theta, phi - self.o.gamma_phi * theta
        self.filter = [(ti, fi) for ti, fi in self.filter if ti < t or fi < f]
        self.filter.append((t, f))

    def _acceptable(self, cur: _Trial, trial: _Trial, alpha: float, gphi: float) -> str | None:
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

    # ================================================================== line search
    def _alpha_max(self, step: _Step) -> float:
        a = _frac_to_boundary(self.s, step.ds, self.tau)
        if self.elastic:
            a = min(a, _frac_to_boundary(self.ep, step.dp, self.tau))
            a = min(a, _frac_to_boundary(self.en, step.dn, self.tau))
        return a

    def _slope(self, step: _Step) -> float:
        """Directional derivative of ``φ_μ`` along the step."""
        gphi = self.sigma * float(self.ev.gradient @ step.dx)
        gphi -= self.mu * float(np.sum(step.ds / self.s))
        if self.elastic:
            gphi += self.rho * float(np.sum(step.dp) + np.sum(step.dn))
            gphi -= self.mu * float(np.sum(step.dp / self.ep) + np.sum(step.dn / self.en))
            if self.xi is not None:
                gphi += self.zeta * float(self.xi @ step.dx)
        return gphi

    def _line_search(self, step: _Step, cur: _Trial) -> _Search:
        """Backtracking filter line search with second-order correction (WB)."""
        o = self.o
        alpha_max = self._alpha_max(step)
        gphi = self._slope(step)
        alpha_min = self._alpha_min(cur.theta, gphi)
        alpha, n_trials, n_nan = alpha_max, 0, 0
        while n_trials < o.max_ls_trials and (n_trials == 0 or alpha >= alpha_min):
            n_trials += 1
            trial = self._trial_at(step, alpha)
            if trial is None:
                n_nan += 1
            else:
                tag = self._acceptable(cur, trial, alpha, gphi)
                if tag:
                    return _Search(trial, step, alpha, n_trials, tag)
                if (
                    n_trials == 1
                    and trial.theta >= cur.theta
                    and o.second_order_correction
                    and self._soc_ok
                ):
                    soc = self._second_order_correction(cur, trial, alpha, gphi)
                    n_trials += soc.trials
                    if soc.trial is not None:
                        soc.trials = n_trials
                        return soc
            alpha *= o.beta
        return _Search(None, trials=n_trials, all_nan=n_nan == n_trials)

    def _second_order_correction(
        self, cur: _Trial, trial: _Trial, alpha: float, gphi: float
    ) -> _Search:
        """WB second-order correction: re-solve with ``c_soc = α c_k + c(x_trial)`` using the
        same factorization; the step was rejected at ``alpha`` with ``trial``."""
        o = self.o
        c_soc = alpha * self.r_c + trial.c
        theta_old, count = cur.theta, 0
        for _ in range(o.max_soc):
            sol = self._solve(self._rhs(c_soc, self._dw))
            if not _finite(sol):
                break
            soc = self._split(sol, self._dw)
            a_soc = self._alpha_max(soc)
            count += 1
            t = self._trial_at(soc, a_soc)
            if t is None:
                break
            tag = self._acceptable(cur, t, alpha, gphi)
            if tag:
                return _Search(t, soc, a_soc, count, tag + "S")
            if t.theta > o.kappa_soc * theta_old:
                break
            theta_old = t.theta
            c_soc = a_soc * c_soc + t.c
        return _Search(None, trials=count)

    # ================================================================== restoration (WB §3.3)
    def _restoration(self) -> None:
        if self.o.restoration_method == "simple":
            self._restoration_simple()
        else:
            self._restoration_elastic()

    def _restoration_elastic(self) -> None:
        """Run the ℓ1 restoration phase (module docstring) and continue from its result.

        On return, ``y = 0`` (IPOPT's default ``constr_mult_reset_threshold = 0``; a least-squares
        estimate with ``resto_ls_multipliers``) and ``z = μ/s``, or all ``z = 1`` if that exceeds
        ``bound_mult_reset_threshold`` (IPOPT's rule)."""
        o = self.o
        self._count("restorations")
        self._augment_filter(self.cur.theta, self.cur.phi)
        phase = _RIPM(self.p, o, parent=self)
        try:
            phase._start_restoration(self)
            phase._iterate()
        except _Stop:
            self._adopt(phase, keep_multipliers=True)
            raise
        self._adopt(phase, keep_multipliers=False)
        self.last = phase.last
        self.kkt_refs = []
        self.n_short, self.wd = 0, None

    def _adopt(self, phase: _RIPM, keep_multipliers: bool) -> None:
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
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
        self.x, self.s, self.y, self.z, self.ev = x, s, y, z, ev
        if self.elastic and not keep_multipliers:  # elastic mode: restart p, n; a new filter
            self._start_elastic(ev.ineq + s)
            self.filter = []
        if not keep_multipliers and o.resto_ls_multipliers and self.me:
            y_ls = self._least_squares_y(ev)
            if np.any(y_ls):
                self.y = y_ls
                ev = self._evaluate(x, self.y, self.z)
                if ev is None:
                    raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
                self.ev = ev

    def _start_restoration(self, main: _RIPM) -> None:
        """Initial point of the restoration problem at the main phase's iterate (WB eq. 33)."""
        o = self.o
        self.x = main.x
        c = np.concatenate([main.ev.eq, main.ev.ineq + main.s])
        self.mu = max(main.mu, _amax(c))
        self.tau = max(o.tau_min, 1 - self.mu)
        self.zeta = o.resto_proximity_weight * math.sqrt(self.mu)
        rho, mu = self.rho, self.mu
        # slacks: satisfied rows exactly, none below μ/ρ (their value at a solution of the
        # restoration problem where the row stays violated: z = ρ, s z = μ)
        self.s = np.maximum(main.s, np.maximum(-main.ev.ineq, mu / rho))
        c = np.concatenate([main.ev.eq, main.ev.ineq + self.s])
        self.ep, self.en = _elastic_start(c, mu, rho)
        self.zp, self.zn = mu / self.ep, mu / self.en
        self.xi = np.zeros(self.n)
        self.y = np.zeros(self.me)
        self.z = np.minimum(mu / self.s, rho)
        ev = self._evaluate(self.x, self.y, self.z)
        if ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
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
        return theta, phi, _amax(c)

    def _restoration_simple(self) -> None:
        """Restoration phase: damped Newton steps on ``½‖c‖²``, ``c = (h, g + s)``.

        The slacks are not free variables here: after every step they are reset to
        ``s⁺ = max(-g(x⁺), (1-τ)s)`` (satisfied rows get ``c = 0``; the slacks of violated rows
        shrink geometrically, down to ``ε_mach min(1, μ)``, as IPOPT's safe slacks). The step ``dx``
        minimizes ``½‖c_A + J_A dx‖² + ½dxᵀ(W_c + ρI)dx`` over the rows ``A`` with ``c ≠ 0``,
        ``W_c = Σ cᵢ Hess cᵢ`` (the problem's Lagrangian Hessian with ``σ = 0``, ``y = c_h``,
        ``z = c_g``), i.e. it solves the main loop's KKT pattern::

            [[W_c + ρI, A_Eᵀ, A_Iᵀ], [A_E, -I, 0], [A_I, 0, -D]] (dx, λ_h, λ_g) = (0, -c_h, -c_g)

        with ``D = 1`` on ``A`` and ``D = 10⁸`` (decoupled) elsewhere, ``ρ`` increased until the
        inertia is ``(n, m, 0)`` (a descent direction), then Armijo backtracking on ``½‖c‖²``.
        Each restoration iterate becomes the current one. Returns with an iterate acceptable to
        the filter (``y = 0``, ``z = μ/s``, or ``z = 1`` if that exceeds
        ``bound_mult_reset_threshold``) or raises :class:`_Stop`; a stationary point of
        ``½‖c‖²`` with ``‖c‖∞ > constr_viol_tol`` proves local infeasibility."""
        o = self.o
        n, me, m = self.n, self.me, self.m
        self._count("restorations")
        theta_start = self.cur.theta
        self._augment_filter(self.cur.theta, self.cur.phi)
        self.s = np.maximum(self.s, -self.ev.ineq)

        def evaluate_c(x, c_h, c_g):
            self.sigma = 0.0
            try:
                return self._evaluate(x, c_h, c_g)
            finally:
                self.sigma = 1.0

        ev = evaluate_c(self.x, self.ev.eq, self.ev.ineq + self.s)
        if ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
        while True:
            x, s = self.x, self.s
            c = np.concatenate([ev.eq, ev.ineq + s])
            c_inf = _amax(c)
            grad = ev.eq_jacobian.T @ c[:me] + ev.ineq_jacobian.T @ c[me:]
            stat = _amax(grad)
            if stat <= o.resto_stationarity_tol * max(1.0, c_inf):
                if c_inf <= o.constr_viol_tol:
                    raise _Stop(RIPMStatus.LINE_SEARCH_FAILED, "restoration: already feasible")
                raise _Stop(RIPMStatus.LOCALLY_INFEASIBLE)
            if self.iter >= o.max_iter:
                raise _Stop(RIPMStatus.MAX_ITER)
            self.kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
            d_in = np.where(c[me:] != 0.0, -1.0, -1e8)
            rho, sol = max(1e-8, 1e-2 * min(1.0, float(np.linalg.norm(c)))), None
            while sol is None and rho <= o.delta_w_max:
                inertia = self.kkt.factorize(np.concatenate([np.full(n, rho), -np.ones(me), d_in]))
                if inertia is not None and inertia.zero == 0 and inertia.negative == m:
                    sol = self._solve(np.concatenate([np.zeros(n), -c]))
                else:
                    rho *= o.kappa_w_plus
            if sol is None or not _finite(sol):
                raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: unsolvable linear system")
            dx = sol[:n]
            slope = float(grad @ dx)
            half = 0.5 * float(c @ c)
            s_floor = np.maximum((1 - self.tau) * s, _EPS * min(1.0, self.mu))
            alpha, trials = 1.0, 0
            while trials < o.max_ls_trials:
                trials += 1
                x_t = self.p.retract(x, alpha * dx)
                vals = self._values(x_t)
                if vals is not None:
                    trial = self._make_trial(x_t, np.maximum(-vals[2], s_floor), *vals)
                    if 0.5 * float(trial.c @ trial.c) <= half + o.eta_phi * alpha * slope:
                        break
                alpha *= o.beta
            else:
                if stat <= math.sqrt(o.resto_stationarity_tol) * max(1.0, c_inf):
                    raise _Stop(RIPMStatus.LOCALLY_INFEASIBLE)
                raise _Stop(RIPMStatus.LINE_SEARCH_FAILED, "restoration: line search failed")
            done = trial.theta <= o.kappa_resto * theta_start and self._filter_accepts(
                trial.theta, trial.phi
            )
            if done:
                self.y, self.z = np.zeros(me), self.mu / trial.s
                if np.max(self.z, initial=0.0) > o.bound_mult_reset_threshold:
                    self.z = np.ones(self.mi)
                ev = self._evaluate(trial.x, self.y, self.z)
            else:
                ev = evaluate_c(trial.x, trial.h, trial.g + trial.s)
            if ev is None:
                raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
            self.x, self.s, self.ev = trial.x, trial.s, ev
            self.sh.iter += 1
            d = _amax(alpha * dx)
            self.last = {"d": d, "dw": rho, "a_du": 0.0, "a_pr": alpha, "ls": trials, "tag": "r"}
            if done:
                return
            self._measures()
            self._record(ev.objective)

    # ================================================================== main loop
    def _initialize(self, x0: Point, y0, z0, s0) -> None:
        o = self.o
        self.mu = o.mu_init
        self.tau = max(o.tau_min, 1 - self.mu)
        self.x = x0
        self.y = np.zeros(self.me)
        self.z = np.full(self.mi, o.bound_mult_init_val)
        ev = self._evaluate(x0, self.y, self.z, hessian=False)
        if ev is None:
            self.s = np.ones(self.mi)
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite evaluation at the initial point")
        self.s = np.maximum(-ev.ineq, o.bound_push) if s0 is None else np.asarray(s0, float)
        if z0 is not None:
            self.z = np.asarray(z0, dtype=float)
        if y0 is not None:
            self.y = np.asarray(y0, dtype=float)
        elif self.me:
            self.y = self._least_squares_y(ev)
        shapes = (self.y.shape, self.z.shape, self.s.shape)
        if shapes != ((self.me,), (self.mi,), (self.mi,)):
            raise InputError(
                f"y0, z0, s0 have shapes {shapes}; expected ({self.me},), ({self.mi},) x2"
            )
        if np.any(self.s <= 0) or np.any(self.z <= 0) or not _finite(self.y, self.z, self.s):
            raise InputError("s0 and z0 must be finite and positive, y0 finite")
        if o.elastic_inequalities and self.mi:
            self._start_elastic(np.asarray(ev.ineq) + self.s)
        self.ev = self._evaluate(x0, self.y, self.z)
        if self.ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the initial point")
        theta0 = float(np.sum(np.abs(self._current_trial().c)))
        self.mu_max = max(o.mu_init, 1e3 * self._avg_compl())
        self.theta_max = o.theta_max_fact * max(1.0, theta0)
        self.theta_min = o.theta_min_fact * max(1.0, theta0)

    def _start_elastic(self, c: np.ndarray) -> None:
        """Elastic mode of the main phase: ``g + s - p + n = 0`` with ``ρ Σ(p + n)`` in the
        objective (an exact ℓ1 penalty of the inequalities, Benson, Shanno & Vanderbei 2004's
        remedy for jamming); ``p, n`` start at their central values (WB eq. 33)."""
        self.elastic = True
        self.er = slice(self.me, self.m)
        if self.ep is None:
            self.rho = self.o.elastic_penalty
        self.ep, self.en = _elastic_start(c, self.mu, self.rho)
        self.zp, self.zn = self.mu / self.ep, self.mu / self.en

    def _least_squares_y(self, ev: NLPEvaluation) -> np.ndarray:
        """``y`` minimizing ``‖grad f + A_Eᵀy + A_Iᵀz‖`` (WB), or 0 if it is large."""
        kkt = KKTSystem(self.n, self.me, 0)
        kkt.set_matrices(None, ev.eq_jacobian, None)
        diag = np.concatenate([np.ones(self.n), np.zeros(self.me)])
        inertia = kkt.factorize(diag, self.o.static_regularization)
        if inertia is None or inertia.zero or inertia.negative != self.me:
            return np.zeros(self.me)
        rhs = np.concatenate([-(ev.gradient + ev.ineq_jacobian.T @ self.z), np.zeros(self.me)])
        sol, _ = kkt.solve(rhs, self.o.max_refinement_steps, self.o.residual_ratio_max)
        y = sol[self.n :]
        return y if _finite(y) and np.max(np.abs(y)) <= self.o.constr_mult_init_max else 0 * y

    def _update_barrier(self, tiny_step: bool) -> bool:
        """WB eq. 7 (Algorithm 1): decrease μ while the barrier problem is solved to κ_ε μ.

        Returns ``True`` when a tiny step was taken at the smallest μ (no progress possible)."""
        o = self.o
        mu_min = o.tol / 10
        if self.free_mode:
            if tiny_step or not self._free_mode_progress():
                self._enter_monotone_mode()
                tiny_step = False
            else:
                self._set_mu(self._loqo_mu())
                return False
        while (tiny_step or self._error(self.mu) <= o.kappa_eps * self.mu) and self.mu > mu_min:
            if o.mu_strategy == "adaptive" and not self.resto and not tiny_step:
                self.free_mode, self.kkt_refs = True, []  # monotone phase done: free mode again
                self._set_mu(self._loqo_mu())
                return False
            if self.elastic and not self.resto and self._increase_penalty():
                break
            self.mu = max(mu_min, min(o.kappa_mu * self.mu, self.mu**o.theta_mu))
            self.tau = max(o.tau_min, 1 - self.mu)
            if self.resto:
                self.zeta = o.resto_proximity_weight * math.sqrt(self.mu)
            self.filter = []
            tiny_step = False
        return tiny_step

    # ------------------------------------------------------------------ adaptive μ
    def _set_mu(self, mu: float) -> None:
        if mu != self.mu:
            self.mu = mu
            self.tau = max(self.o.tau_min, 1 - mu)
            self.filter = []

    def _avg_compl(self) -> float:
        return float(np.mean(self.s * self.z)) if self.mi else 0.0

    def _loqo_mu(self) -> float:
        """LOQO's oracle (Vanderbei & Shanno 1999; IPOPT's ``mu_oracle=loqo``):
        ``μ = σ sᵀz/m`` with ``σ = 0.1 min(0.05 (1-ξ)/ξ, 2)³``, ``ξ = min(s z)/avg(s z)``."""
        if not self.mi:
            return max(self.o.tol / 10, self.mu * self.o.kappa_mu)
        sz = self.s * self.z
        avg = float(np.mean(sz))
        xi = float(np.min(sz)) / avg if avg > 0 else 1.0
        sigma = 0.1 * min(0.05 * (1 - xi) / max(xi, _EPS), 2.0) ** 3
        return float(np.clip(sigma * avg, self.o.tol / 10, self.mu_max))

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
        self._set_mu(float(np.clip(0.8 * self._avg_compl(), self.o.tol / 10, self.mu_max)))
        self.filter = []

    def _increase_penalty(self) -> bool:
        """Elastic mode at a solved barrier problem: if a multiplier is close to ρ, the ℓ1
        penalty is not exact (yet); multiply ρ by 10 (and keep μ)."""
        lam = self._lam()
        if lam.size and np.max(lam) > 0.5 * self.rho and _amax(self.ep - self.en) > self.mu:
            self.zp, self.zn = self.zp + 9.0 * self.rho, self.zn + 9.0 * self.rho
            self.rho *= 10.0
            self.filter = []
            self._count("penalty_increases")
            return True
        return False

    def run(self, x0: Point, y0, z0, s0) -> RIPMResult:
        self.sh.t0 = time.perf_counter()
        if self.sh.out:
            self.sh.out(f"RIPM: n = {self.n}, n_eq = {self.me}, n_ineq = {self.mi}")
            self.sh.out(_HEADER)
        try:
            self._initialize(x0, y0, z0, s0)
            self._iterate()
        except _Stop as stop:
            return self._result(stop.status, stop.message)
        raise AssertionError("unreachable")  # pragma: no cover

    def _check_main(self, n_acceptable: int) -> int:
        """Termination tests of the main phase; returns the count of acceptable iterates."""
        o = self.o
        if self.kkt_error <= o.tol:
            raise _Stop(RIPMStatus.CONVERGED)
        n_acceptable = n_acceptable + 1 if self.kkt_error <= o.acceptable_tol else 0
        if n_acceptable >= o.acceptable_iter:
            raise _Stop(
                RIPMStatus.ACCEPTABLE, f"E_0 ≤ acceptable_tol for {n_acceptable} iterations"
            )
        if self.iter >= o.max_iter:
            raise _Stop(RIPMStatus.MAX_ITER)
        return n_acceptable

    def _resto_converged(self) -> None:
        """The restoration problem is solved: locally infeasible, unless the point is feasible."""
        c_inf = self._original_measures()[2]
        if c_inf > self.o.constr_viol_tol:
            raise _Stop(RIPMStatus.LOCALLY_INFEASIBLE)
        raise _Stop(
            RIPMStatus.LINE_SEARCH_FAILED,
            "restoration converged to a feasible point the filter does not accept",
        )

    def _check_resto(self, first: bool) -> bool:
        """Termination tests of the restoration phase; ``True``: return to the main phase."""
        o = self.o
        if not first:
            theta, phi, _ = self._original_measures()
            main = self.parent
            if theta <= o.kappa_resto * self.theta_start and (
                main.elastic or main._filter_accepts(theta, phi)
            ):
                return True
        if self.kkt_error <= o.tol:
            self._resto_converged()
        if self.iter >= o.max_iter:
            raise _Stop(RIPMStatus.MAX_ITER)
        return False

    def _iterate(self) -> None:
        """The iterations of a phase: returns only when a restoration phase is done."""
        o = self.o
        n_acceptable, tiny_step, first = 0, False, True
        while True:
            self._measures()
            if self.resto:
                if self._check_resto(first):
                    return  # the main phase records this iterate
                if not first:
                    self._record(self.ev.objective, self._original_measures()[2])
            else:
                self._record(self.ev.objective)
                n_acceptable = self._check_main(n_acceptable)
            first = False
            if self._update_barrier(tiny_step):
                if self.resto and self.kkt_error <= o.acceptable_tol:
                    self._resto_converged()
                ok = self.kkt_error <= o.acceptable_tol
                raise _Stop(
                    RIPMStatus.ACCEPTABLE if ok else RIPMStatus.NUMERICAL_ERROR,
                    "search direction became too small to make progress",
                )
            self.cur = self._current_trial()
            computed = self._newton_step()
            if computed is None:
                self._fail_or_restore("inertia correction failed (δ_w > δ_w,max)")
                continue
            step, dw = computed
            self._dw = dw
            tiny_step = (
                self.inf_pr < 1e-4
                and max(_amax(step.dx), _amax(step.ds / (1 + self.s))) < o.tiny_step_tol
            )
            if tiny_step:  # IPOPT's tiny-step rule: accept the full step without line search
                alpha = self._alpha_max(step)
                trial = self._trial_at(step, alpha)
                search = _Search(trial, step, alpha, 1, "T", all_nan=trial is None)
            elif o.watchdog_shortened_iter_trigger > 0 and not self.resto:
                search = self._watchdog_search(step, dw)
            else:
                search = self._line_search(step, self.cur)
            if search.trial is None:
                if search.all_nan:
                    raise _Stop(
                        RIPMStatus.NUMERICAL_ERROR, "non-finite values at every trial point"
                    )
                self._fail_or_restore("line search failed")
                continue
            self._accept(search, dw)

    # ------------------------------------------------------------------ watchdog
    _STATE = ("x", "s", "y", "z", "ev", "mu", "tau", "cur", "ep", "en", "zp", "zn")

    def _watchdog_search(self, step: _Step, dw: float) -> _Search:
        """IPOPT's watchdog: after ``watchdog_shortened_iter_trigger`` consecutive shortened
        steps, take full steps (α_max) for up to ``watchdog_trial_iter_max`` iterations without
        the filter test; if none is acceptable to the filter and the reference iterate, return
        to the reference iterate and backtrack along its step."""
        o = self.o
        if self.wd is not None and self.wd["mu"] != self.mu:
            self.wd = None  # μ changed: the reference is meaningless
        if self.wd is None and self.n_short >= o.watchdog_shortened_iter_trigger:
            alpha = self._alpha_max(step)
            trial = self._trial_at(step, alpha)
            if trial is not None:
                self._count("watchdog")
                self.wd = {k: getattr(self, k) for k in self._STATE}
                self.wd |= {
                    "filter": list(self.filter),
                    "step": step,
                    "dw": dw,
                    "left": o.watchdog_trial_iter_max,
                    "gphi": self._slope(step),
                    "alpha": alpha,
                }
                self.n_short = 0
                return _Search(trial, step, alpha, 1, "w")
        if self.wd is not None:
            wd = self.wd
            alpha = self._alpha_max(step)
            trial = self._trial_at(step, alpha)
            if trial is not None:
                saved_filter, self.filter = self.filter, wd["filter"]
                ok = self._acceptable(wd["cur"], trial, wd["alpha"], wd["gphi"])
                self.filter = saved_filter
                if ok:
                    self.wd = None
                    return _Search(trial, step, alpha, 1, "w")
                if wd["left"] > 0:
                    wd["left"] -= 1
                    return _Search(trial, step, alpha, 1, "w")
            # back to the reference iterate, backtracking along its step (no second-order
            # correction: the current factorization belongs to another matrix)
            self._count("watchdog_reverts")
            for k in self._STATE:
                setattr(self, k, wd[k])
            self.filter = wd["filter"]
            self._measures()
            self.wd = None
            self._soc_ok = False
            try:
                search = self._line_search(wd["step"], self.cur)
            finally:
                self._soc_ok = True
            self._dw = wd["dw"]
            return search
        search = self._line_search(step, self.cur)
        if search.trial is not None:
            shortened = search.alpha < self._alpha_max(step)
            self.n_short = self.n_short + 1 if shortened else 0
        return search

    def _fail_or_restore(self, why: str) -> None:
        if self.resto:
            if self.kkt_error <= self.o.acceptable_tol:  # solved to the acceptable level
                self._resto_converged()
            raise _Stop(RIPMStatus.LINE_SEARCH_FAILED, f"restoration phase: {why}")
        if self.m == 0 or not self.o.restoration:
            status = (
                RIPMStatus.NUMERICAL_ERROR if "inertia" in why else RIPMStatus.LINE_SEARCH_FAILED
            )
            raise _Stop(status, why)
        self._restoration()

    def _accept(self, search: _Search, dw: float) -> None:
        """Take the step: primal with α, ``y`` with α, ``z`` with its own α_z (WB eq. 15-16)."""
        o = self.o
        trial, step, alpha = search.trial, search.step, search.alpha
        alpha_z = _frac_to_boundary(self.z, step.dz, self.tau)
        if self.elastic:
            alpha_z = min(
                alpha_z,
                _frac_to_boundary(self.zp, step.dzp, self.tau),
                _frac_to_boundary(self.zn, step.dzn, self.tau),
            )
        if search.tag[0] == "h":
            self._augment_filter(self.cur.theta, self.cur.phi)
        y = self.y + alpha * step.dy
        z = self.z + alpha_z * step.dz
        s = trial.s
        z = np.clip(z, self.mu / (o.kappa_sigma * s), o.kappa_sigma * self.mu / s)  # WB eq. 16
        if self.elastic:
            zp = self.zp + alpha_z * step.dzp
            zn = self.zn + alpha_z * step.dzn
            p, n = trial.p, trial.n
            self.zp = np.clip(zp, self.mu / (o.kappa_sigma * p), o.kappa_sigma * self.mu / p)
            self.zn = np.clip(zn, self.mu / (o.kappa_sigma * n), o.kappa_sigma * self.mu / n)
            self.ep, self.en, self.xi = p, n, trial.xi
        ev = self._evaluate(trial.x, y, z)
        if ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the accepted point")
        self.x, self.s, self.y, self.z, self.ev = trial.x, s, y, z, ev
        self.sh.iter += 1
        self.last = {
            "d": _amax(alpha * step.dx),
            "dw": dw,
            "a_du": alpha_z,
            "a_pr": alpha,
            "ls": search.trials,
            "tag": "r" if self.resto else search.tag[0],
        }

    # ================================================================== output
    def _record(self, objective: float, inf_pr: float | None = None) -> None:
        h, last = self.sh.history, self.last
        restoration = last["tag"] == "r"
        inf_pr = self.inf_pr if inf_pr is None else inf_pr
        h.objective.append(float(objective))
        h.inf_pr.append(inf_pr)
        h.inf_du.append(self.inf_du)
        h.kkt_error.append(self.kkt_error)
        h.mu.append(self.mu)
        h.step_norm.append(last["d"])
        h.delta_w.append(last["dw"])
        h.alpha_du.append(last["a_du"])
        h.alpha_pr.append(last["a_pr"])
        h.ls_trials.append(last["ls"])
        h.time_s.append(time.perf_counter() - self.sh.t0)
        h.restoration.append(restoration)
        if self.sh.out:
            rg = f"{math.log10(last['dw']):5.1f}" if last["dw"] > 0 else "    -"
            self.sh.out(
                f"{self.iter:4d}{'r' if restoration else ' '}{objective:14.7e} {inf_pr:7.2e} "
                f"{self.inf_du:7.2e} {math.log10(self.mu):5.1f} {last['d']:7.2e} {rg} "
                f"{last['a_du']:7.2e} {last['a_pr']:7.2e}{last['tag']}{last['ls']:3d}"
            )

    def _result(self, status: RIPMStatus, message: str) -> RIPMResult:
        wall = time.perf_counter() - self.sh.t0
        ok = getattr(self, "ev", None) is not None
        if ok:
            self._measures()
        result = RIPMResult(
            status=status,
            message=message,
            iterations=self.iter,
            wall_time_s=wall,
            x=self.x,
            y=self.y,
            z=self.z,
            s=self.s,
            objective=float(self.ev.objective) if ok else math.nan,
            kkt_error=self.kkt_error if ok else math.inf,
            inf_pr=self.inf_pr if ok else math.inf,
            inf_du=self.inf_du if ok else math.inf,
            mu=self.mu,
            history=self.sh.history,
            n_evaluations=self.sh.n_eval,
            n_trial_evaluations=self.sh.n_values,
            n_factorizations=self.kkt.n_factorizations,
        )
        if self.sh.out:
            self.sh.out(
                f"\nRIPM {status.name}: {message}\n  iterations {self.iter}, objective "
                f"{result.objective:.12e}, E_0 {result.kkt_error:.2e}, time {wall:.3f} s "
                f"({self.sh.n_eval} evaluations, {self.sh.n_values} trial evaluations, "
                f"{self.kkt.n_factorizations} factorizations)"
            )
        return result
