"""Matrix Lie group interior point method (MLG-IPM; Santos, Pereira & Raffo 2026, Alg. 1).

Newton's system (3) on the KKT field of :mod:`mbplan.solvers.lie_ipm.kkt_field`, one step size
``α = τ_k min(1, α_pri, α_dual)`` for every block, the exponential update (4) through
``problem.retract`` (``G ← G exp(αΔζ^)``; the duals, in the translation group T(d), move
additively), then the barrier rule ``μ = σ_k sᵀν / n₁`` (the paper's "m" read as n₁). The inexact
variant (5) solves ``𝕵_F Δ = -F + ρ_k`` with ``‖ρ_k‖ = ρ‖F_k‖`` in a seeded random direction.

Our additions, each switchable back to the paper's literal rule (``MLGIPMOptions.paper()``):
``σ_k = min(σ, ‖F₀‖)`` and ``τ_k = max(τ, 1 - ‖F₀‖)`` (fast local convergence; the paper's fixed
σ and τ make the rate linear, Theorem 2 with α < 1) and a backtracking line search on the merit
``‖F_μ‖²``, nonmonotone (on by default: without it 8-15 % of the SL(7) instances diverge, see
``benchmarks/results/lie-ipm``). The curvature defaults to the paper's 𝕳_ℒ when the problem
offers it (fewer iterations than the symmetric Hessian on SO(7), the same on SL(7)).
Termination: ``‖F₀‖∞ ≤ tol`` (μ = 0), the measure of every solver here.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbplan.engine.compile_clock import CompileClock
from mbplan.errors import InputError
from mbplan.solvers.lie_ipm.kkt_field import (
    CurvatureProblem,
    FieldValue,
    NewtonSolver,
    PrimalDual,
    check_curvature,
    check_start,
    evaluate_field,
    initial_duals,
    max_step,
    point_is_finite,
    split_step,
)
from mbplan.solvers.nlp import Point, RIPMProblem
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus


@dataclass(frozen=True)
class MLGIPMOptions:
    """Parameters of :func:`solve_mlgipm` (the paper gives only σ ∈ [0.1, 0.5], τ ∈ (0, 1))."""

    max_iter: int = 500
    tol: float = 1e-8
    """Stop when ``‖F₀‖∞ ≤ tol``."""
    sigma: float = 0.1
    superlinear_mu: bool = True
    """``σ_k = min(σ, ‖F₀‖₂)`` instead of the paper's fixed σ."""
    tau: float = 0.995
    adaptive_tau: bool = True
    """``τ_k = max(τ, 1 - ‖F₀‖₂)`` instead of the paper's fixed τ."""
    curvature: str = "auto"
    """``"exact"``: the paper's 𝕳_ℒ (needs ``problem.lagrangian_curvature``); ``"symmetric"``:
    the Riemannian Hessian of the Lagrangian; ``"auto"``: exact when the problem offers it."""
    rho: float = 0.0
    """Inexact term (5): ``‖ρ_k‖ = rho·‖F_μ‖₂``."""
    rho_seed: int = 0
    line_search: bool = True
    """Backtrack α until ``‖F_μ(α)‖² ≤ (1 - 2βα)‖F_μ‖²`` (our globalisation)."""
    ls_beta: float = 1e-4
    ls_theta: float = 0.5
    ls_max_steps: int = 30
    ls_memory: int = 10
    """Nonmonotone reference (Grippo et al. 1986): the Armijo test compares with the largest
    merit of the last ``ls_memory`` iterates (1: monotone; 10 escapes the slack jamming that
    stalls the monotone search on ~0.5 % of the SO(7) instances)."""
    slack_reset: float = 1e-2
    """After a step shorter than this, reset ``s ← max(s, -g(x))`` (primal infeasibility only
    decreases): the escape from slack jamming at the boundary; 0 disables it."""
    slack_min: float = 1e-2
    """Initial slacks ``s0 = max(-g(x0), slack_min)``."""
    mult_init: float = 1.0
    """Initial multipliers ``ν0``."""
    divergence_bound: float = 1e12
    """An iterate with ‖F₀‖ above this stops with NUMERICAL_ERROR."""
    print_level: int = 0

    def __post_init__(self) -> None:
        checks = {
            "max_iter": self.max_iter >= 0,
            "tol": self.tol > 0,
            "sigma": 0 < self.sigma < 1,
            "tau": 0 < self.tau < 1,
            "rho": 0 <= self.rho < 1,
            "ls_beta": 0 < self.ls_beta < 0.5,
            "ls_theta": 0 < self.ls_theta < 1,
            "ls_max_steps": self.ls_max_steps >= 1,
            "ls_memory": self.ls_memory >= 1,
            "slack_min": self.slack_min > 0,
            "slack_reset": 0 <= self.slack_reset < 1,
            "mult_init": self.mult_init > 0,
            "curvature": self.curvature in ("auto", "symmetric", "exact"),
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise InputError(
                "MLG-IPM option(s) out of range: "
                + ", ".join(f"{k}={getattr(self, k)!r}" for k in bad)
            )

    def replace(self, **overrides: Any) -> MLGIPMOptions:
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise InputError(f"unknown MLG-IPM option(s): {unknown}")
        return dataclasses.replace(self, **overrides)

    @classmethod
    def paper(cls, **overrides: Any) -> MLGIPMOptions:
        """Algorithm 1 literally: fixed σ and τ, exact curvature matrix, no line search."""
        base = cls(
            superlinear_mu=False,
            adaptive_tau=False,
            curvature="exact",
            line_search=False,
            slack_reset=0.0,
        )
        return base.replace(**overrides)


def solve_mlgipm(
    problem: RIPMProblem,
    x0: Point,
    options: MLGIPMOptions | None = None,
    *,
    nu0: np.ndarray | None = None,
    lam0: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    **overrides: Any,
) -> RIPMResult:
    """Solve ``min f s.t. g ≤ 0, h = 0`` (problem (2)) from ``x0`` with MLG-IPM.

    ``problem`` follows :class:`~mbplan.solvers.nlp.RIPMProblem`; ``curvature="exact"``
    also needs ``problem.lagrangian_curvature``. Returns a :class:`RIPMResult` (``z`` holds ν,
    ``y`` holds λ); ``success`` means ``‖F₀‖∞ ≤ tol``.
    """
    opts = (options or MLGIPMOptions()).replace(**overrides)
    if opts.curvature == "auto":
        exact = isinstance(problem, CurvatureProblem)
        opts = opts.replace(curvature="exact" if exact else "symmetric")
    check_curvature(problem, opts.curvature)
    x0 = check_start(problem, x0)
    it = initial_duals(problem, x0, nu0, lam0, s0, opts.slack_min, opts.mult_init)
    return _MLGIPM(problem, opts).run(it)


class _MLGIPM:
    def __init__(self, problem: RIPMProblem, opts: MLGIPMOptions) -> None:
        self.p, self.o = problem, opts
        self.m1 = problem.n_ineq
        self.rng = np.random.default_rng(opts.rho_seed)
        self.hist = IterationHistory()
        self.newton = NewtonSolver(problem, opts.curvature)
        self.n_eval = self.n_trial = self.n_fact = 0
        self.clock = CompileClock()  # the solve's time, its kernels' compilation left out

    def _mu(self, it: PrimalDual, kkt2: float) -> float:
        if not self.m1:
            return 0.0
        sigma = min(self.o.sigma, kkt2) if self.o.superlinear_mu else self.o.sigma
        return sigma * float(it.s @ it.nu) / self.m1

    def _evaluate(self, it: PrimalDual, hessian: bool) -> FieldValue | None:
        try:
            with np.errstate(all="ignore"):
                fv = evaluate_field(self.p, it, hessian=hessian)
        except (FloatingPointError, np.linalg.LinAlgError, InputError, ValueError):
            return None
        if hessian:
            self.n_eval += 1
        else:
            self.n_trial += 1
        vec = fv.vector(0.0)
        if not (np.isfinite(fv.ev.objective) and np.all(np.isfinite(vec))):
            return None
        return fv

    def _record(self, fv: FieldValue, mu: float, step: float, alpha: float, trials: int) -> None:
        h = self.hist
        h.objective.append(float(fv.ev.objective))
        h.inf_pr.append(fv.inf_pr())
        h.inf_du.append(fv.inf_du())
        h.kkt_error.append(fv.kkt_error())
        h.mu.append(mu)
        h.step_norm.append(step)
        h.delta_w.append(0.0)
        h.alpha_du.append(alpha)
        h.alpha_pr.append(alpha)
        h.ls_trials.append(trials)
        h.time_s.append(self.clock.elapsed())
        h.restoration.append(False)
        if self.o.print_level:
            k = len(h) - 1
            print(
                f"{k:4d} {fv.ev.objective:+.8e} {h.inf_pr[-1]:.2e} {h.inf_du[-1]:.2e} "
                f"{h.kkt_error[-1]:.2e} mu={mu:.1e} a={alpha:.3f} ls={trials}"
            )

    def run(self, it: PrimalDual) -> RIPMResult:
        self.clock.start()
        try:
            return self._run(it)
        finally:
            self.clock.stop()

    def _run(self, it: PrimalDual) -> RIPMResult:
        o = self.o
        fv = self._evaluate(it, hessian=True)
        if fv is None:
            return self._result(it, None, math.nan, RIPMStatus.NUMERICAL_ERROR, "x0: not finite")
        mu = self._mu(it, fv.norm())
        self._record(fv, mu, 0.0, 0.0, 0)
        merits: list[float] = []
        while True:
            if fv.kkt_error() <= o.tol:
                return self._result(it, fv, mu, RIPMStatus.CONVERGED, "")
            if len(self.hist) - 1 >= o.max_iter:
                return self._result(it, fv, mu, RIPMStatus.MAX_ITER, "")
            if fv.norm() > o.divergence_bound:
                return self._result(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, "diverged")
            F = fv.vector(mu)
            rhs = -F
            if o.rho > 0:
                u = self.rng.standard_normal(F.size)
                rhs = rhs + o.rho * np.linalg.norm(F) * u / np.linalg.norm(u)
            try:
                sol = self.newton.solve(it, fv, rhs)
            except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
                return self._result(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, f"Newton: {exc}")
            self.n_fact += 1
            if not np.all(np.isfinite(sol)):
                return self._result(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, "Newton: not finite")
            dx, dnu, dlam, ds = split_step(self.p, sol)
            tau = max(o.tau, 1.0 - fv.norm()) if o.adaptive_tau else o.tau
            alpha = tau * min(1.0, max_step(it.s, ds), max_step(it.nu, dnu))
            merits.append(float(F @ F))
            merit = max(merits[-o.ls_memory :])
            trials = 0
            while True:
                trial = self._trial(it, alpha, dx, dnu, dlam, ds)
                new = None if trial is None else self._evaluate(trial, hessian=not o.line_search)
                trials += 1
                ok = new is not None
                if ok and o.line_search:
                    ok = new.norm(mu) ** 2 <= (1.0 - 2.0 * o.ls_beta * alpha) * merit
                if ok or trials >= (o.ls_max_steps if o.line_search else 1):
                    break
                alpha *= o.ls_theta
            if new is None:
                return self._result(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, "step not finite")
            if o.line_search:
                new = self._evaluate(trial, hessian=True)
                if new is None:
                    return self._result(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, "not finite")
            if alpha < o.slack_reset and self.m1:
                reset = np.maximum(trial.s, -np.asarray(new.ev.ineq, dtype=float))
                if np.any(reset > trial.s):
                    trial = PrimalDual(trial.x, trial.nu, trial.lam, reset)
                    new = self._evaluate(trial, hessian=True)
                    if new is None:
                        return self._result(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, "not finite")
            it, fv = trial, new
            mu = self._mu(it, fv.norm())
            self._record(fv, mu, float(np.max(np.abs(alpha * dx), initial=0.0)), alpha, trials)

    def _trial(self, it, alpha, dx, dnu, dlam, ds) -> PrimalDual | None:
        try:
            with np.errstate(all="ignore"):
                x = self.p.retract(it.x, alpha * dx)
            if not point_is_finite(x):
                return None
        except (FloatingPointError, np.linalg.LinAlgError, InputError, ValueError):
            return None
        return PrimalDual(x, it.nu + alpha * dnu, it.lam + alpha * dlam, it.s + alpha * ds)

    def _result(
        self, it: PrimalDual, fv: FieldValue | None, mu: float, status: RIPMStatus, msg: str
    ) -> RIPMResult:
        return make_result(
            status,
            msg,
            it,
            fv,
            mu,
            self.hist,
            self.clock.elapsed(),
            (self.n_eval, self.n_trial, self.n_fact),
            self.clock.compile_s,
        )


def make_result(
    status: RIPMStatus,
    msg: str,
    it: PrimalDual,
    fv: FieldValue | None,
    mu: float,
    hist: IterationHistory,
    wall: float,
    counts: tuple[int, int, int],
    compile_s: float = 0.0,
) -> RIPMResult:
    """A :class:`RIPMResult` of a primal-dual Newton solver (MLG-IPM, Lai-Yoshise); ``wall``
    without the ``compile_s`` seconds of kernel compilation."""
    return RIPMResult(
        status=status,
        message=msg or status.value,
        iterations=max(len(hist) - 1, 0),
        wall_time_s=wall,
        x=it.x,
        y=it.lam,
        z=it.nu,
        s=it.s,
        objective=math.nan if fv is None else float(fv.ev.objective),
        kkt_error=math.inf if fv is None else fv.kkt_error(),
        inf_pr=math.inf if fv is None else fv.inf_pr(),
        inf_du=math.inf if fv is None else fv.inf_du(),
        mu=mu if math.isfinite(mu) else 0.0,
        history=hist,
        n_evaluations=counts[0],
        n_trial_evaluations=counts[1],
        n_factorizations=counts[2],
        compile_time_s=compile_s,
    )
