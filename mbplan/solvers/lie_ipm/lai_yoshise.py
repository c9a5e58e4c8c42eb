"""Lai & Yoshise's globally convergent Riemannian IPM (JOTA 201, 2024, Algorithm 2), the
baseline of the MLG-IPM paper, from its published description and its code's documented defaults.

Each iteration solves the perturbed Newton equation ``∇F(w)Δw = -F(w) + σ_k ρ_k ê`` with
``ρ_k = sᵀz/m``, ``σ_k = min(0.5, ‖F(w)‖^{1/2})`` and ``ê`` the unit vector of the
complementarity block (so ``μ = σ_k ρ_k`` in the field of :mod:`mbplan.solvers.lie_ipm.kkt_field`),
then backtracks ``α = θʲ`` (``θ = 0.5``, at most 50 trials) from ``α = 1`` until ``s, z > 0``, the
centrality condition ``min(z∘s) ≥ γ_k τ₁ zᵀs/m`` (``τ₁ = min(z₀∘s₀)/(z₀ᵀs₀/m)``) and the Armijo
condition on the merit ``φ = ‖F‖²``: ``φ(w(α)) ≤ φ(w) + αβ⟨grad φ, Δw⟩`` with ``β = 1e-4`` and
``⟨grad φ, Δw⟩ = -2φ + 2σ_kρ_k zᵀs``; ``γ_{k+1} = (γ_k + ½)/2`` from ``γ₀ = 0.9``. Stops when
``‖F(w)‖₂ < 1e-6`` or after 500 iterations; the initial ``z, s`` are uniform on (0, 1) (seeded),
``y = 0``. The Riemannian Hessian is the symmetric one of the problem (Lai & Yoshise work with a
Riemannian metric; exp curves are geodesics of the bi-invariant metric of SO(n)).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mbplan.errors import InputError
from mbplan.solvers.lie_ipm.kkt_field import (
    FieldValue,
    PrimalDual,
    check_start,
    evaluate_field,
    newton_matrix,
    point_is_finite,
    solve_newton,
    split_step,
)
from mbplan.solvers.lie_ipm.mlgipm import make_result
from mbplan.solvers.nlp import Point, RIPMProblem
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus


@dataclass(frozen=True)
class LaiYoshiseOptions:
    """Defaults of Lai & Yoshise's ``RIPM.m`` (maxiter, tolKKTres, gamma, ls_beta, ls_theta,
    ls_max_steps); ``rho`` is the MLG-IPM paper's perturbation ``‖ρ_k‖ = rho‖F_k‖``."""

    max_iter: int = 500
    tol: float = 1e-6
    gamma: float = 0.9
    ls_beta: float = 1e-4
    ls_theta: float = 0.5
    ls_max_steps: int = 50
    rho: float = 0.0
    seed: int = 0
    """Seed of the random initial ``z, s`` and of the perturbation direction."""

    def __post_init__(self) -> None:
        if not (
            self.max_iter >= 0
            and self.tol > 0
            and 0.5 < self.gamma < 1
            and 0 < self.ls_beta < 1
            and 0 < self.ls_theta < 1
            and self.ls_max_steps >= 1
            and 0 <= self.rho < 1
        ):
            raise InputError(f"Lai-Yoshise options out of range: {self}")


def solve_lai_yoshise(
    problem: RIPMProblem, x0: Point, options: LaiYoshiseOptions | None = None
) -> RIPMResult:
    """Solve problem (2) from ``x0`` with Lai & Yoshise's RIPM; ``success``: ``‖F‖₂ < tol``."""
    o = options or LaiYoshiseOptions()
    x0 = check_start(problem, x0)
    if problem.n_ineq == 0:
        raise InputError("Lai-Yoshise's RIPM needs inequality constraints")
    rng = np.random.default_rng(o.seed)
    m = problem.n_ineq
    it = PrimalDual(x0, rng.uniform(size=m), np.zeros(problem.n_eq), rng.uniform(size=m))
    hist = IterationHistory()
    counts = [0, 0, 0]
    t0 = time.perf_counter()

    def evaluate(w: PrimalDual, hessian: bool) -> FieldValue | None:
        try:
            with np.errstate(all="ignore"):
                fv = evaluate_field(problem, w, hessian=hessian)
        except (FloatingPointError, np.linalg.LinAlgError, InputError, ValueError):
            return None
        counts[0 if hessian else 1] += 1
        ok = np.isfinite(fv.ev.objective) and np.all(np.isfinite(fv.vector(0.0)))
        return fv if ok else None

    def record(fv: FieldValue, mu: float, step: float, alpha: float, trials: int) -> None:
        for name, v in (
            ("objective", float(fv.ev.objective)),
            ("inf_pr", fv.inf_pr()),
            ("inf_du", fv.inf_du()),
            ("kkt_error", fv.norm()),
            ("mu", mu),
            ("step_norm", step),
            ("delta_w", 0.0),
            ("alpha_du", alpha),
            ("alpha_pr", alpha),
            ("ls_trials", trials),
            ("time_s", time.perf_counter() - t0),
            ("restoration", False),
        ):
            getattr(hist, name).append(v)

    def done(w: PrimalDual, fv: FieldValue | None, mu: float, status: RIPMStatus, msg: str = ""):
        res = make_result(status, msg, w, fv, mu, hist, time.perf_counter() - t0, tuple(counts))
        if fv is not None:
            res.kkt_error = fv.norm()  # Lai-Yoshise's KKT residual ‖F‖₂
        return res

    fv = evaluate(it, True)
    if fv is None:
        return done(it, None, 0.0, RIPMStatus.NUMERICAL_ERROR, "x0: not finite")
    tau1 = float(np.min(it.nu * it.s) / (it.nu @ it.s / m))
    gamma = o.gamma
    record(fv, 0.0, 0.0, 0.0, 0)
    while True:
        phi = fv.norm() ** 2
        if np.sqrt(phi) < o.tol:
            return done(it, fv, 0.0, RIPMStatus.CONVERGED)
        if len(hist) - 1 >= o.max_iter:
            return done(it, fv, 0.0, RIPMStatus.MAX_ITER)
        rho_k = float(it.nu @ it.s) / m
        sigma = min(0.5, np.sqrt(phi) ** 0.5)
        mu = sigma * rho_k
        rhs = -fv.vector(mu)
        if o.rho > 0:
            u = rng.standard_normal(rhs.size)
            rhs = rhs + o.rho * np.sqrt(phi) * u / np.linalg.norm(u)
        try:
            sol, _ = solve_newton(newton_matrix(problem, it, fv, "symmetric"), rhs)
        except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
            return done(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, f"Newton: {exc}")
        counts[2] += 1
        if not np.all(np.isfinite(sol)):
            return done(it, fv, mu, RIPMStatus.NUMERICAL_ERROR, "Newton: not finite")
        dx, dnu, dlam, ds = split_step(problem, sol)
        slope = -2.0 * phi + 2.0 * mu * float(it.nu @ it.s)
        alpha, accepted, trials = 1.0, None, 0
        while trials < o.ls_max_steps:
            trials += 1
            nu, s = it.nu + alpha * dnu, it.s + alpha * ds
            if np.all(nu > 0) and np.all(s > 0):
                central = np.min(nu * s) >= gamma * tau1 * float(nu @ s) / m
                if central:
                    with np.errstate(all="ignore"):
                        try:
                            x = problem.retract(it.x, alpha * dx)
                        except (np.linalg.LinAlgError, InputError, ValueError):
                            x = None
                    if x is not None and point_is_finite(x):
                        w = PrimalDual(x, nu, it.lam + alpha * dlam, s)
                        new = evaluate(w, False)
                        if new is not None and new.norm() ** 2 <= phi + alpha * o.ls_beta * slope:
                            accepted = (w, new)
                            break
            alpha *= o.ls_theta
        if accepted is None:
            # the backtracking ran out (ls_max_steps_break): take the last trial if admissible
            nu, s = it.nu + alpha * dnu, it.s + alpha * ds
            with np.errstate(all="ignore"):
                x = problem.retract(it.x, alpha * dx)
            w = PrimalDual(x, nu, it.lam + alpha * dlam, s)
            ok = point_is_finite(x) and np.all(nu > 0) and np.all(s > 0)
            accepted = (w, None) if ok else None
            if accepted is None:
                return done(it, fv, mu, RIPMStatus.LINE_SEARCH_FAILED)
        it, fv = accepted[0], evaluate(accepted[0], True)
        if fv is None:
            return done(it, None, mu, RIPMStatus.NUMERICAL_ERROR, "not finite")
        gamma = 0.5 * (gamma + 0.5)
        record(fv, mu, float(np.max(np.abs(alpha * dx), initial=0.0)), alpha, trials)
