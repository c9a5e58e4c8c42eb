"""Input bounds ``lb ≤ u_k ≤ ub`` by an augmented-Lagrangian outer loop around iLQR (Alg. 3).

Inner problem: the shooting cost plus the PHR term
``(1/2ρ) Σ_k (‖max(0, λ_k + ρ g(u_k))‖² - ‖λ_k‖²)`` with ``g(u) = [u - ub; lb - u] ≤ 0``
(Gauss–Newton: ``ρ`` on the active rows), solved by SS-/MS-iLQR warm-started from the previous
outer iterate; then ``λ⁺ = max(0, λ + ρ g)`` and ``ρ ← βρ`` while the violation does not shrink
by ``shrink``; stop when ``‖max(g, 0)‖∞ ≤ constraint_tol`` and the inner solve converged.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mbplan.errors import InputError
from mbplan.shooting.problem import ShootingBase
from mbplan.solvers.ilqr.options import ILQROptions
from mbplan.solvers.ilqr.result import ILQRHistory, ILQRResult, ILQRStatus
from mbplan.solvers.ilqr.solver import solve_ilqr


@dataclass(frozen=True)
class ALOptions:
    rho_init: float = 10.0
    rho_factor: float = 10.0
    rho_max: float = 1e10
    shrink: float = 0.25
    constraint_tol: float = 1e-6
    max_outer: int = 20


class _Penalized:
    """A :class:`ShootingProblem` whose cost carries the AL term of the input bounds."""

    def __init__(self, problem: ShootingBase, lb, ub, lam, rho) -> None:
        self._p, self.lb, self.ub, self.lam, self.rho = problem, lb, ub, lam, rho

    def __getattr__(self, name):
        return getattr(self._p, name)

    def _shifted(self, U):
        g = constraint(U, self.lb, self.ub)
        return np.maximum(0.0, self.lam + self.rho * g)

    def _extra(self, U) -> float:
        s = self._shifted(U)
        return float(np.sum(s * s - self.lam * self.lam) / (2 * self.rho))

    def cost_value(self, X, U) -> float:
        return self._p.cost_value(X, U) + self._extra(U)

    def cost_derivatives(self, X, U):
        J, lx, lxx, lu, luu = self._p.cost_derivatives(X, U)
        s = self._shifted(U)
        nu = U.shape[1]
        lu = lu + s[:, :nu] - s[:, nu:]
        active = (s > 0).astype(float)
        diag = self.rho * (active[:, :nu] + active[:, nu:])
        luu = luu + diag[:, :, None] * np.eye(nu)
        return J + self._extra(U), lx, lxx, lu, luu


def constraint(U: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """``g(u) = [u - ub; lb - u]`` per knot, ``(N, 2 nu)`` (``±inf`` bounds give ``-inf``)."""
    return np.hstack([U - ub, lb - U])


def solve_ilqr_bounded(
    problem: ShootingBase,
    lower: np.ndarray,
    upper: np.ndarray,
    options: ILQROptions | None = None,
    al: ALOptions | None = None,
    *,
    x_init: np.ndarray | None = None,
    u_init: np.ndarray | None = None,
) -> ILQRResult:
    """SS-/MS-iLQR with input bounds by the AL outer loop; ``iterations`` counts inner ones.
    ``lower``/``upper`` are ``(nu,)`` or per interval ``(N, nu)`` (``±inf``: unbounded); ``x_init``/``u_init`` start
    the first inner solve."""
    opts, al = options or ILQROptions(), al or ALOptions()
    shape = (problem.N, problem.nu)
    try:
        lb = np.broadcast_to(np.asarray(lower, dtype=float), shape).copy()
        ub = np.broadcast_to(np.asarray(upper, dtype=float), shape).copy()
    except ValueError:
        raise InputError(f"input bounds: expected shape ({shape[1]},) or {shape}") from None
    if np.any(np.isnan(lb)) or np.any(np.isnan(ub)) or np.any(lb > ub):
        raise InputError("input bounds: need lower <= upper and no NaN")
    lb_f, ub_f = np.where(np.isfinite(lb), lb, -1e300), np.where(np.isfinite(ub), ub, 1e300)
    start = time.perf_counter()
    lam = np.zeros((problem.N, 2 * problem.nu))
    rho = al.rho_init
    history = ILQRHistory()
    iterations, violation_prev = 0, np.inf
    timings = {"derivatives": 0.0, "backward": 0.0, "rollout": 0.0}
    res = None
    for _ in range(al.max_outer):
        inner = _Penalized(problem, lb_f, ub_f, lam, rho)
        res = solve_ilqr(inner, opts, x_init=x_init, u_init=u_init)
        iterations += res.iterations
        for k, v in res.timings.items():
            timings[k] += v
        for name in history.__dict__:
            getattr(history, name).extend(getattr(res.history, name))
        if res.status is ILQRStatus.NUMERICAL_ERROR:
            break
        g = constraint(res.u, lb_f, ub_f)
        violation = float(np.max(np.maximum(g, 0.0), initial=0.0))
        if violation <= al.constraint_tol and res.success:
            break
        lam = np.maximum(0.0, lam + rho * g)
        if violation > al.shrink * violation_prev:
            rho = min(rho * al.rho_factor, al.rho_max)
        violation_prev = violation
        u_init = res.u
        x_init = res.x if opts.multiple_shooting else None
    g = constraint(res.u, lb_f, ub_f)
    violation = float(np.max(np.maximum(g, 0.0), initial=0.0))
    status, message = res.status, res.message
    if res.success and violation > al.constraint_tol:
        status = ILQRStatus.MAX_ITER
        message = f"AL outer loop: input bounds violated by {violation:.2e} after {al.max_outer}"
    return ILQRResult(
        status=status,
        message=message,
        method=res.method + "-al",
        iterations=iterations,
        wall_time_s=time.perf_counter() - start,
        x=res.x,
        u=res.u,
        K=res.K,
        k=res.k,
        objective=problem.cost_value(res.x, res.u),
        grad_norm=res.grad_norm,
        defect_norm=res.defect_norm,
        max_defect=res.max_defect,
        group_violation=float(max(history.group_violation, default=0.0)),
        history=history,
        timings=timings,
    )
