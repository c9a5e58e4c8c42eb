"""Line-search Riemannian interior point method: Algorithm 1 of the RIPM paper (§VII) with the
globalization of IPOPT (Wächter & Biegler 2006, "WB"): filter line search with switching
condition and second-order correction, inertia correction, multiplier safeguards and a
(simplified) feasibility restoration phase.

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
positive definite); otherwise ``δ_w``, ``δ_c`` follow WB Algorithm IC. Unlike IPOPT, which
treats ``s`` as a primal variable, ``δ_w`` is not added to ``Σ``: ``ds`` then satisfies the
linearized complementarity exactly.

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

**Restoration** (a simplified WB restoration phase, entered when the line search or the inertia
correction fails): damped Newton steps in ``x`` on ``½‖h, g + s‖²`` with the slacks reset to their
best interior values after each step, solved with the same sparse KKT pattern; it returns when
``θ`` is reduced by ``κ_resto`` and the filter accepts the point, and proves local infeasibility
at a stationary point of the infeasibility with ``θ > 0``.

Every linear-algebra object is sparse with a fixed pattern; one iteration costs one
``problem.evaluate``, one ``problem.values`` per trial and a few sparse LDLᵀ factorizations
(the same AMD ordering throughout), i.e. time linear in the size of block-banded problems.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
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
    """A candidate primal point with its values (``h``, ``g`` at ``x``; slacks ``s``)."""

    x: Point
    s: np.ndarray
    f: float
    h: np.ndarray
    g: np.ndarray
    theta: float
    phi: float


@dataclass
class _Step:
    dx: np.ndarray
    ds: np.ndarray
    dy: np.ndarray
    dz: np.ndarray


@dataclass
class _Search:
    """Outcome of a line search: the accepted trial (``None`` if it failed) and the step taken.

    ``tag`` is ``f`` (Armijo), ``h`` (filter progress), ``T`` (tiny step, no search), with ``S``
    appended for a second-order correction."""

    trial: _Trial | None
    step: _Step | None = None
    alpha: float = 0.0
    trials: int = 0
    tag: str = ""
    all_nan: bool = False


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


class _RIPM:
    """State of one solve; see the module docstring for the algorithm."""

    def __init__(self, problem: RIPMProblem, options: RIPMOptions) -> None:
        self.p, self.o = problem, options
        self.n, self.me, self.mi = int(problem.n), int(problem.n_eq), int(problem.n_ineq)
        self.m = self.me + self.mi
        self.kkt = KKTSystem(self.n, self.me, self.mi)
        self.history = IterationHistory()
        self.out: Callable[[str], None] | None = (
            (lambda line: print(line, file=sys.stdout)) if options.print_level > 0 else None
        )
        self.n_eval = self.n_values = 0
        self.iter = 0
        self.delta_w_last = 0.0
        self.filter: list[tuple[float, float]] = []
        # describes the step that produced the current iterate (for the log and history)
        self.last = {"d": 0.0, "dw": 0.0, "a_du": 0.0, "a_pr": 0.0, "ls": 0, "tag": " "}

    # ================================================================== evaluation
    def _evaluate(
        self, x: Point, y: np.ndarray, z: np.ndarray, hessian: bool = True, obj_factor: float = 1.0
    ) -> NLPEvaluation | None:
        self.n_eval += 1
        ev: NLPEvaluation = self.p.evaluate(x, obj_factor, y, z, hessian)
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
        self.n_values += 1
        f, h, g = self.p.values(x)
        return (float(f), np.asarray(h), np.asarray(g)) if _finite(f, h, g) else None

    def _trial(self, x: Point, s: np.ndarray) -> _Trial | None:
        vals = self._values(x)
        return None if vals is None else self._make_trial(x, s, *vals)

    def _make_trial(
        self, x: Point, s: np.ndarray, f: float, h: np.ndarray, g: np.ndarray
    ) -> _Trial:
        theta = float(np.sum(np.abs(h)) + np.sum(np.abs(g + s)))
        return _Trial(x, s, f, h, g, theta, f - self.mu * float(np.sum(np.log(s))))

    # ================================================================== errors (eq. 55-56)
    def _scalings(self) -> tuple[float, float]:
        """``s_d``, ``s_c`` of WB eq. 5 (multipliers averaged per component, as in IPOPT)."""
        smax = self.o.s_max
        s_d = s_c = 1.0
        if self.m:
            avg = (np.sum(np.abs(self.y)) + np.sum(np.abs(self.z))) / self.m
            s_d = max(smax, avg) / smax
        if self.mi:
            s_c = max(smax, np.sum(np.abs(self.z)) / self.mi) / smax
        return s_d, s_c

    def _measures(self) -> None:
        """Residuals of (50) at the current iterate."""
        ev = self.ev
        self.r_d = ev.gradient + ev.eq_jacobian.T @ self.y + ev.ineq_jacobian.T @ self.z
        self.r_p = ev.ineq + self.s
        self.inf_du = float(np.max(np.abs(self.r_d), initial=0.0))
        self.inf_pr = float(
            max(np.max(np.abs(ev.eq), initial=0.0), np.max(np.abs(self.r_p), initial=0.0))
        )
        self.s_d, self.s_c = self._scalings()
        self.kkt_error = self._error(0.0)

    def _error(self, mu: float) -> float:
        """``E_μ`` (eq. 55-56): scaled dual infeasibility, infeasibility, complementarity."""
        compl = float(np.max(np.abs(self.s * self.z - mu), initial=0.0))
        return max(self.inf_du / self.s_d, self.inf_pr, compl / self.s_c)

    # ================================================================== Newton step (53)
    def _rhs(self, eq_res: np.ndarray, in_res: np.ndarray) -> np.ndarray:
        return np.concatenate([-self.r_d, -eq_res, -in_res + self.s - self.mu / self.z])

    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the current factorization (iterative refinement as configured)."""
        return self.kkt.solve(rhs, self.o.max_refinement_steps, self.o.residual_ratio_max)[0]

    def _split(self, sol: np.ndarray) -> _Step:
        n, me = self.n, self.me
        dz = sol[n + me :]
        ds = -self.s + self.mu / self.z - self.s * dz / self.z
        return _Step(sol[:n], ds, sol[n : n + me], dz)

    def _newton_step(self) -> tuple[_Step, float] | None:
        """Factorize with inertia correction (WB Algorithm IC) and solve; ``None`` on failure."""
        o, n, m = self.o, self.n, self.m
        self.kkt.set_matrices(self.ev.hessian_lower, self.ev.eq_jacobian, self.ev.ineq_jacobian)
        rhs = self._rhs(self.ev.eq, self.r_p)
        sigma_inv = self.s / self.z
        dw = dc = 0.0
        pretend_singular = False
        while True:
            diag = np.concatenate([np.full(n, dw), np.full(self.me, -dc), -sigma_inv - dc])
            inertia = self.kkt.factorize(diag, o.static_regularization)
            correct = inertia is not None and inertia.zero == 0 and inertia.negative == m
            singular = not correct and (inertia is None or inertia.zero > 0 or inertia.negative < m)
            if correct:
                sol, ratio = self.kkt.solve(rhs, o.max_refinement_steps, o.residual_ratio_max)
                if _finite(sol) and (ratio <= o.residual_ratio_singular or pretend_singular):
                    if dw > 0:
                        self.delta_w_last = dw
                    return self._split(sol), dw
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
    def _line_search(self, step: _Step, cur: _Trial) -> _Search:
        """Backtracking filter line search with second-order correction (WB)."""
        o = self.o
        alpha_max = _frac_to_boundary(self.s, step.ds, self.tau)
        gphi = float(self.ev.gradient @ step.dx - self.mu * np.sum(step.ds / self.s))
        alpha_min = self._alpha_min(cur.theta, gphi)
        alpha, n_trials, n_nan = alpha_max, 0, 0
        while n_trials < o.max_ls_trials and (n_trials == 0 or alpha >= alpha_min):
            n_trials += 1
            trial = self._trial(self.p.retract(self.x, alpha * step.dx), self.s + alpha * step.ds)
            if trial is None:
                n_nan += 1
            else:
                tag = self._acceptable(cur, trial, alpha, gphi)
                if tag:
                    return _Search(trial, step, alpha, n_trials, tag)
                if n_trials == 1 and trial.theta >= cur.theta and o.second_order_correction:
                    soc = self._second_order_correction(step, cur, trial, alpha, gphi)
                    n_trials += soc.trials
                    if soc.trial is not None:
                        soc.trials = n_trials
                        return soc
            alpha *= o.beta
        return _Search(None, trials=n_trials, all_nan=n_nan == n_trials)

    def _second_order_correction(
        self, step: _Step, cur: _Trial, trial: _Trial, alpha: float, gphi: float
    ) -> _Search:
        """WB second-order correction: re-solve with ``c_soc = α c_k + c(x_trial)`` using the same factorization;
        ``step`` was rejected at ``alpha`` with ``trial``."""
        o = self.o
        c_h = alpha * self.ev.eq + trial.h
        c_p = alpha * self.r_p + (trial.g + trial.s)
        theta_old, count = cur.theta, 0
        for _ in range(o.max_soc):
            sol = self._solve(self._rhs(c_h, c_p))
            if not _finite(sol):
                break
            soc = self._split(sol)
            a_soc = _frac_to_boundary(self.s, soc.ds, self.tau)
            count += 1
            t = self._trial(self.p.retract(self.x, a_soc * soc.dx), self.s + a_soc * soc.ds)
            if t is None:
                break
            tag = self._acceptable(cur, t, alpha, gphi)
            if tag:
                return _Search(t, soc, a_soc, count, tag + "S")
            if t.theta > o.kappa_soc * theta_old:
                break
            theta_old = t.theta
            c_h = a_soc * c_h + t.h
            c_p = a_soc * c_p + (t.g + t.s)
        return _Search(None, trials=count)

    # ================================================================== restoration
    def _restoration(self) -> None:
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
        theta_start = self.cur.theta
        self._augment_filter(self.cur.theta, self.cur.phi)
        self.s = np.maximum(self.s, -self.ev.ineq)
        ev = self._evaluate(self.x, self.ev.eq, self.ev.ineq + self.s, obj_factor=0.0)
        if ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
        while True:
            x, s = self.x, self.s
            c = np.concatenate([ev.eq, ev.ineq + s])
            c_inf = float(np.max(np.abs(c), initial=0.0))
            grad = ev.eq_jacobian.T @ c[:me] + ev.ineq_jacobian.T @ c[me:]
            stat = float(np.max(np.abs(grad), initial=0.0))
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
                    c_t = np.concatenate([trial.h, trial.g + trial.s])
                    if 0.5 * float(c_t @ c_t) <= half + o.eta_phi * alpha * slope:
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
                ev = self._evaluate(trial.x, trial.h, trial.g + trial.s, obj_factor=0.0)
            if ev is None:
                raise _Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
            self.x, self.s, self.ev = trial.x, trial.s, ev
            self.iter += 1
            d = float(np.max(np.abs(alpha * dx), initial=0.0))
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
        self.ev = self._evaluate(x0, self.y, self.z)
        if self.ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the initial point")
        theta0 = float(np.sum(np.abs(self.ev.eq)) + np.sum(np.abs(self.ev.ineq + self.s)))
        self.theta_max = o.theta_max_fact * max(1.0, theta0)
        self.theta_min = o.theta_min_fact * max(1.0, theta0)

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

    def _update_barrier(self, tiny_step: bool) -> None:
        """WB eq. 7 (Algorithm 1): decrease μ while the barrier problem is solved to κ_ε μ."""
        o = self.o
        mu_min = o.tol / 10
        while (tiny_step or self._error(self.mu) <= o.kappa_eps * self.mu) and self.mu > mu_min:
            self.mu = max(mu_min, min(o.kappa_mu * self.mu, self.mu**o.theta_mu))
            self.tau = max(o.tau_min, 1 - self.mu)
            self.filter = []
            tiny_step = False
        if tiny_step:
            ok = self.kkt_error <= o.acceptable_tol
            raise _Stop(
                RIPMStatus.ACCEPTABLE if ok else RIPMStatus.NUMERICAL_ERROR,
                "search direction became too small to make progress",
            )

    def run(self, x0: Point, y0, z0, s0) -> RIPMResult:
        self.t0 = time.perf_counter()
        if self.out:
            self.out(f"RIPM: n = {self.n}, n_eq = {self.me}, n_ineq = {self.mi}")
            self.out(_HEADER)
        try:
            self._initialize(x0, y0, z0, s0)
            self._iterate()
        except _Stop as stop:
            return self._result(stop.status, stop.message)
        raise AssertionError("unreachable")  # pragma: no cover

    def _iterate(self) -> None:
        o = self.o
        n_acceptable, tiny_step = 0, False
        while True:
            self._measures()
            self._record(self.ev.objective)
            if self.kkt_error <= o.tol:
                raise _Stop(RIPMStatus.CONVERGED)
            n_acceptable = n_acceptable + 1 if self.kkt_error <= o.acceptable_tol else 0
            if n_acceptable >= o.acceptable_iter:
                raise _Stop(
                    RIPMStatus.ACCEPTABLE, f"E_0 ≤ acceptable_tol for {n_acceptable} iterations"
                )
            if self.iter >= o.max_iter:
                raise _Stop(RIPMStatus.MAX_ITER)
            self._update_barrier(tiny_step)
            self.cur = self._make_trial(self.x, self.s, self.ev.objective, self.ev.eq, self.ev.ineq)
            computed = self._newton_step()
            if computed is None:
                self._fail_or_restore("inertia correction failed (δ_w > δ_w,max)")
                continue
            step, dw = computed
            tiny_step = (
                self.inf_pr < 1e-4
                and max(
                    np.max(np.abs(step.dx), initial=0.0),
                    np.max(np.abs(step.ds) / (1 + self.s), initial=0.0),
                )
                < o.tiny_step_tol
            )
            if tiny_step:  # IPOPT's tiny-step rule: accept the full step without line search
                alpha = _frac_to_boundary(self.s, step.ds, self.tau)
                trial = self._trial(
                    self.p.retract(self.x, alpha * step.dx), self.s + alpha * step.ds
                )
                search = _Search(trial, step, alpha, 1, "T", all_nan=trial is None)
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

    def _fail_or_restore(self, why: str) -> None:
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
        if search.tag[0] == "h":
            self._augment_filter(self.cur.theta, self.cur.phi)
        y = self.y + alpha * step.dy
        z = self.z + alpha_z * step.dz
        s = trial.s
        z = np.clip(z, self.mu / (o.kappa_sigma * s), o.kappa_sigma * self.mu / s)  # WB eq. 16
        ev = self._evaluate(trial.x, y, z)
        if ev is None:
            raise _Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the accepted point")
        self.x, self.s, self.y, self.z, self.ev = trial.x, s, y, z, ev
        self.iter += 1
        self.last = {
            "d": float(np.max(np.abs(alpha * step.dx), initial=0.0)),
            "dw": dw,
            "a_du": alpha_z,
            "a_pr": alpha,
            "ls": search.trials,
            "tag": search.tag[0],
        }

    # ================================================================== output
    def _record(self, objective: float) -> None:
        h, last = self.history, self.last
        restoration = last["tag"] == "r"
        h.objective.append(float(objective))
        h.inf_pr.append(self.inf_pr)
        h.inf_du.append(self.inf_du)
        h.kkt_error.append(self.kkt_error)
        h.mu.append(self.mu)
        h.step_norm.append(last["d"])
        h.delta_w.append(last["dw"])
        h.alpha_du.append(last["a_du"])
        h.alpha_pr.append(last["a_pr"])
        h.ls_trials.append(last["ls"])
        h.time_s.append(time.perf_counter() - self.t0)
        h.restoration.append(restoration)
        if self.out:
            rg = f"{math.log10(last['dw']):5.1f}" if last["dw"] > 0 else "    -"
            self.out(
                f"{self.iter:4d}{'r' if restoration else ' '}{objective:14.7e} {self.inf_pr:7.2e} "
                f"{self.inf_du:7.2e} {math.log10(self.mu):5.1f} {last['d']:7.2e} {rg} "
                f"{last['a_du']:7.2e} {last['a_pr']:7.2e}{last['tag']}{last['ls']:3d}"
            )

    def _result(self, status: RIPMStatus, message: str) -> RIPMResult:
        wall = time.perf_counter() - self.t0
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
            history=self.history,
            n_evaluations=self.n_eval,
            n_trial_evaluations=self.n_values,
            n_factorizations=self.kkt.n_factorizations,
        )
        if self.out:
            self.out(
                f"\nRIPM {status.name}: {message}\n  iterations {self.iter}, objective "
                f"{result.objective:.12e}, E_0 {result.kkt_error:.2e}, time {wall:.3f} s "
                f"({self.n_eval} evaluations, {self.n_values} trial evaluations, "
                f"{self.kkt.n_factorizations} factorizations)"
            )
        return result
