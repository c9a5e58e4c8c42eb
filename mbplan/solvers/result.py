"""What a RIPM run returns: status, iterate, multipliers and the per-iteration history."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np


class RIPMStatus(enum.Enum):
    """Why the solver stopped. Only CONVERGED and ACCEPTABLE count as success."""

    CONVERGED = "converged: scaled KKT error E_0 below tol"
    ACCEPTABLE = "solved to acceptable level"
    MAX_ITER = "maximum number of iterations reached"
    LINE_SEARCH_FAILED = "line search and restoration failed to make progress"
    LOCALLY_INFEASIBLE = "converged to a stationary point of the infeasibility"
    NUMERICAL_ERROR = "numerical error (non-finite evaluation or unsolvable KKT system)"


class SolverResult:
    """What every result shares, named as in ``scipy.optimize.OptimizeResult``: ``success``,
    ``status`` (an enum member or, for a :class:`~mbplan.results.PlanResult`, its name),
    ``message``, ``nit`` (``iterations``) and ``fun`` (``objective``, the cost at the returned
    point). A solver's ``x`` is its returned point; a plan's is its trajectory ``q, v, tau``."""

    success: bool
    status: Any
    message: str
    iterations: int
    objective: float

    @property
    def nit(self) -> int:
        return self.iterations

    @property
    def fun(self) -> float:
        return self.objective


HISTORY_FIELDS = (
    "objective",
    "inf_pr",
    "inf_du",
    "kkt_error",
    "mu",
    "step_norm",
    "delta_w",
    "alpha_du",
    "alpha_pr",
    "ls_trials",
    "time_s",
)


@dataclass
class IterationHistory:
    """One entry per iteration, iteration 0 (the initial point) included.

    ``step_norm`` (‖α dx‖∞), ``delta_w`` (inertia correction δ_w; the damping ρ for restoration
    iterates), ``alpha_*`` and ``ls_trials`` describe the step that produced the iterate (0 at
    iteration 0); ``time_s`` is wall time since the start of the solve; ``restoration`` marks
    iterates produced by the feasibility restoration phase.
    """

    objective: list[float] = field(default_factory=list)
    inf_pr: list[float] = field(default_factory=list)
    inf_du: list[float] = field(default_factory=list)
    kkt_error: list[float] = field(default_factory=list)
    mu: list[float] = field(default_factory=list)
    step_norm: list[float] = field(default_factory=list)
    delta_w: list[float] = field(default_factory=list)
    alpha_du: list[float] = field(default_factory=list)
    alpha_pr: list[float] = field(default_factory=list)
    ls_trials: list[int] = field(default_factory=list)
    time_s: list[float] = field(default_factory=list)
    restoration: list[bool] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.objective)

    def arrays(self) -> dict[str, np.ndarray]:
        """The history as NumPy arrays."""
        return {name: np.asarray(getattr(self, name)) for name in (*HISTORY_FIELDS, "restoration")}


@dataclass
class RIPMResult(SolverResult):
    """Outcome of :func:`~mbplan.solvers.ripm.driver.solve_ripm` (like ``scipy.optimize.OptimizeResult``).

    ``x`` is a manifold point (the last accepted iterate); ``y``, ``z`` are the multipliers of
    ``h = 0`` and ``g ≤ 0`` (``z > 0``) and ``s > 0`` the slacks (``s = -g(x)`` at convergence).
    All are finite whatever the status; only when ``x0`` itself cannot be evaluated are
    ``objective`` NaN and the errors infinite. ``wall_time_s`` is the solve's wall time without
    the kernels compiled (or loaded from their disk caches) during it, ``compile_time_s``
    (:mod:`mbplan.engine.compile_clock`): a first solve in a fresh environment compiles for tens
    of seconds, which is no property of the solver.
    """

    status: RIPMStatus
    message: str
    iterations: int
    wall_time_s: float
    x: Any
    y: np.ndarray
    z: np.ndarray
    s: np.ndarray
    objective: float
    kkt_error: float
    """Scaled KKT error E_0 (eq. 55-56 with μ = 0) at ``x``."""
    inf_pr: float
    """‖h(x), g(x) + s‖∞."""
    inf_du: float
    """‖grad f + A_E y + A_I z‖∞ (eq. 50, first row)."""
    mu: float
    history: IterationHistory
    n_evaluations: int
    """Calls of ``problem.evaluate`` (derivatives)."""
    n_trial_evaluations: int
    """Calls of ``problem.values`` (line-search trials)."""
    n_factorizations: int
    """Numeric KKT factorizations: every inertia-correction trial, and the least-squares
    multipliers' (at the start, and after restoration with ``resto_ls_multipliers``); a trial
    whose joint reduction falls back to the full factorization counts twice."""
    compile_time_s: float = 0.0
    """Seconds of kernel compilation (and cache loading) during the solve, not in
    ``wall_time_s``."""

    @property
    def success(self) -> bool:
        return self.status in (RIPMStatus.CONVERGED, RIPMStatus.ACCEPTABLE)

    def __repr__(self) -> str:
        return (
            f"RIPMResult(status={self.status.name}, iterations={self.iterations}, "
            f"objective={self.objective:.10g}, kkt_error={self.kkt_error:.3e}, "
            f"wall_time_s={self.wall_time_s:.4f}, compile_time_s={self.compile_time_s:.4f})"
        )
