"""SS-iLQR (thesis Alg. 1) and MS-iLQR (Alg. 2, after Crocoddyl's FDDP) on Lie-group states.

One loop serves both: the nominal ``(X̄, Ū)`` is linearised (defects ``d_k``, ``A_k``, ``B_k``),
the Riccati recursion (3-61) gives ``K_k, k_k``, and the gap-closing rollout (3-73) produces the
trial. Single shooting keeps ``d = 0`` (its nominal is always a rollout from ``x₀``) and accepts
on cost decrease; multiple shooting starts from a state guess (default: the reference) and
accepts on the merit ``J + γ‖d‖₂`` with an Armijo test against the model (3-74…3-78).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from mbplan.errors import InputError
from mbplan.shooting.problem import ShootingBase
from mbplan.solvers.ilqr.options import ILQROptions
from mbplan.solvers.ilqr.result import ILQRHistory, ILQRResult, ILQRStatus
from mbplan.solvers.ilqr.riccati import (
    adjoint_gradient,
    backward_pass,
    expected_change,
    row_norms,
)

_HEADER = "iter        objective    ‖g‖    ‖d‖        μ        α  ls  group"


class _Nominal:
    """A trajectory with its cost, derivatives, linearisation and stationarity measures."""

    def __init__(
        self, problem: ShootingBase, X, U, single_shooting: bool, clock: dict, second_order
    ):
        t = time.perf_counter()
        self.X, self.U = X, U
        self.J, self.lx, self.lxx, self.lu, self.luu = problem.cost_derivatives(X, U)
        self.defects, self.A, self.B = problem.dynamics.linearize(X, U)
        self.H = (
            problem.dynamics.second_derivatives(X, U) if second_order else np.zeros((1, 1, 1, 1))
        )
        t1 = time.perf_counter()
        clock["derivatives"] += t1 - t
        self.d = np.zeros_like(self.defects) if single_shooting else self.defects
        self.grad = adjoint_gradient(self.A, self.B, self.lx, self.lu)
        self.grad_norm = row_norms(self.grad)[0]
        self.defect_norm = 0.0 if single_shooting else row_norms(self.d)[2]
        self.max_defect = row_norms(self.defects)[1]
        clock["backward"] += time.perf_counter() - t1

    def lq(self) -> tuple:
        """The linear–quadratic model ``(A, B, l_x, l_xx, l_u, l_uu, d)``."""
        return self.A, self.B, self.lx, self.lxx, self.lu, self.luu, self.d

    def finite(self) -> bool:
        # A sum is finite only if every entry is (barring overflow of the sum itself).
        arrays = (self.lx, self.lxx, self.lu, self.luu, self.A, self.B, self.d, self.grad)
        scalars = (self.J, self.grad_norm, self.defect_norm, *(a.sum() for a in arrays))
        return all(math.isfinite(v) for v in scalars)


def _initial_guess(problem, opts, x_init, u_init):
    N, nu, space = problem.N, problem.nu, problem.space
    if u_init is None:
        U = np.zeros((N, nu))
    else:
        U = np.asarray(u_init, dtype=float)
        if U.shape != (N, nu) or not np.all(np.isfinite(U)):
            raise InputError(f"u_init: expected a finite ({N}, {nu}) array, got {U.shape}")
    if not opts.multiple_shooting:
        if x_init is not None:
            raise InputError("x_init is only used by multiple shooting")
        return problem.dynamics.simulate(problem.x0, U), U
    if x_init is None:
        X = problem.x_ref.copy()
    else:
        X = space.check(x_init, "x_init")
        if X.shape != (N + 1, space.nq):
            raise InputError(f"x_init: expected shape ({N + 1}, {space.nq}), got {X.shape}")
        X = X.copy()
    X[0] = problem.x0
    return X, U


def solve_ilqr(
    problem: ShootingBase,
    options: ILQROptions | None = None,
    *,
    x_init: np.ndarray | None = None,
    u_init: np.ndarray | None = None,
    callback: Callable[[int, ILQRHistory], None] | None = None,
    verbose: bool = False,
) -> ILQRResult:
    """Solve a :class:`~mbplan.shooting.problem.ShootingBase` by SS- or MS-iLQR (or DDP).

    ``verbose`` prints one line per iterate (IPOPT-style, like ``solve_ripm``); ``callback``
    is called with the iteration number and the history after each iterate.
    """
    opts = options or ILQROptions()
    ss = not opts.multiple_shooting
    method = ("ss-" if ss else "ms-") + ("ddp" if opts.second_order else "ilqr")
    space = problem.space
    N, nu, nx = problem.N, problem.nu, space.nx
    clock = {"derivatives": 0.0, "backward": 0.0, "rollout": 0.0}
    start = time.perf_counter()
    X, U = _initial_guess(problem, opts, x_init, u_init)
    history = ILQRHistory()
    K = np.zeros((N, nu, nx))
    k = np.zeros((N, nu))
    nominal = _Nominal(problem, X, U, ss, clock, opts.second_order)
    mu, delta = opts.mu_init, 1.0

    def record(alpha: float, trials: int) -> None:
        history.objective.append(nominal.J)
        history.grad_norm.append(nominal.grad_norm)
        history.defect_norm.append(nominal.defect_norm)
        history.alpha.append(alpha)
        history.mu.append(mu)
        history.ls_trials.append(trials)
        history.group_violation.append(space.violation(nominal.X))
        history.time_s.append(time.perf_counter() - start)
        if verbose:
            it = len(history) - 1
            if it % 10 == 0:
                print(_HEADER)
            print(
                f"{it:4d} {nominal.J:16.10e} {nominal.grad_norm:8.2e} {nominal.defect_norm:8.2e}"
                f" {mu:8.1e} {alpha:8.2e} {trials:3d} {history.group_violation[-1]:8.1e}"
            )
        if callback is not None:
            callback(len(history) - 1, history)

    if not (np.all(np.isfinite(X)) and nominal.finite()):
        status, message = (
            ILQRStatus.NUMERICAL_ERROR,
            "initial guess: non-finite cost or derivatives",
        )
        record(0.0, 0)
        return _result(status, message, method, 0, start, nominal, K, k, history, clock)
    record(0.0, 0)
    alphas = (
        [opts.alpha_base ** (-(j * j)) for j in range(opts.ls_max_trials)]
        if opts.line_search
        else [1.0]
    )
    iteration = 0
    while True:
        if nominal.grad_norm < opts.tol and nominal.defect_norm < opts.defect_tol:
            status, message = ILQRStatus.CONVERGED, ILQRStatus.CONVERGED.value
            break
        if iteration >= opts.max_iter:
            status, message = ILQRStatus.MAX_ITER, ILQRStatus.MAX_ITER.value
            break
        trial = None
        while trial is None:
            t = time.perf_counter()
            failed = backward_pass(*nominal.lq(), mu, K, k, nominal.H, opts.second_order)
            clock["backward"] += time.perf_counter() - t
            if failed < 0:
                trial = _forward(problem, opts, nominal, K, k, alphas, ss, clock)
                if trial is not None:
                    break
            mu, delta = _increase(mu, delta, opts)
            if mu > opts.mu_max:
                break
        if trial is None:
            if failed >= 0:
                status = ILQRStatus.NUMERICAL_ERROR
                message = f"Q_uu not positive definite at knot {failed} with μ at μ_max"
            elif opts.line_search:
                status, message = ILQRStatus.LINE_SEARCH_FAILED, ILQRStatus.LINE_SEARCH_FAILED.value
            else:
                status = ILQRStatus.NUMERICAL_ERROR
                message = "full-step rollout diverged (non-finite or unbounded) up to μ_max"
            break
        Xn, Un, alpha, trials = trial
        delta = min(1.0 / opts.mu_factor, delta / opts.mu_factor)
        mu = mu * delta if mu * delta >= opts.mu_min else 0.0
        candidate = _Nominal(problem, Xn, Un, ss, clock, opts.second_order)
        if not candidate.finite():
            status, message = (
                ILQRStatus.NUMERICAL_ERROR,
                "non-finite derivatives at the new iterate",
            )
            break
        nominal = candidate
        iteration += 1
        record(alpha, trials)
    return _result(status, message, method, iteration, start, nominal, K, k, history, clock)


def _increase(mu: float, delta: float, opts: ILQROptions) -> tuple[float, float]:
    delta = max(opts.mu_factor, delta * opts.mu_factor)
    return max(opts.mu_min, mu * delta), delta


def _forward(problem, opts, nominal, K, k, alphas, ss, clock):
    """First acceptable trial ``(X, U, α, trials)`` or None."""
    t = time.perf_counter()
    dyn = problem.dynamics
    d1 = d2 = 0.0
    dbar = nominal.defect_norm
    gamma = opts.merit_gamma_min
    if opts.line_search:
        d1, d2 = expected_change(*nominal.lq(), K, k)
        if not ss and dbar > 1e-14:
            gamma = max(
                opts.merit_gamma_min,
                (d1 + 0.5 * d2) / ((1 - opts.merit_sigma) * dbar) + opts.merit_gamma_min,
            )
    merit0 = nominal.J + gamma * dbar
    out = None
    for j, alpha in enumerate(alphas):
        Xn, Un, gaps = dyn.rollout(nominal.X, nominal.U, K, k, nominal.d, alpha)
        bound = opts.divergence_bound
        if not (np.all(np.abs(Xn) < bound) and np.all(np.abs(Un) < bound)):
            continue  # also rejects NaN
        if not opts.line_search:
            out = (Xn, Un, alpha, j + 1)  # full step: the cost is evaluated with the derivatives
            break
        Jn = problem.cost_value(Xn, Un)
        if not np.isfinite(Jn):
            continue
        if ss:
            ok = Jn < nominal.J
        else:
            model = alpha * d1 + 0.5 * alpha**2 * d2
            merit = Jn + gamma * row_norms(gaps)[2]
            ok = merit < merit0 + opts.armijo_kappa * (model - alpha * gamma * dbar)
        if ok:
            out = (Xn, Un, alpha, j + 1)
            break
    clock["rollout"] += time.perf_counter() - t
    return out


def _result(status, message, method, iterations, start, nominal, K, k, history, clock):
    return ILQRResult(
        status=status,
        message=message,
        method=method,
        iterations=iterations,
        wall_time_s=time.perf_counter() - start,
        x=nominal.X,
        u=nominal.U,
        K=K,
        k=k,
        objective=float(nominal.J),
        grad_norm=nominal.grad_norm,
        defect_norm=nominal.defect_norm,
        max_defect=nominal.max_defect,
        group_violation=float(max(history.group_violation, default=0.0)),
        history=history,
        timings=dict(clock),
    )
