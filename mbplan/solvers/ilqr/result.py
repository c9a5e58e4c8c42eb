"""What an iLQR run returns: status, trajectory, gains and the per-iteration history."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from mbplan.solvers.result import SolverResult


class ILQRStatus(enum.Enum):
    """Why the solver stopped. Only CONVERGED counts as success."""

    CONVERGED = "converged: mean gradient norm and defect norm below tol"
    MAX_ITER = "maximum number of iterations reached"
    LINE_SEARCH_FAILED = "no step size decreased the merit (failed to find a descent direction)"
    NUMERICAL_ERROR = "numerical error (non-finite rollout or cost, or Q_uu not definite at μ_max)"


@dataclass
class ILQRHistory:
    """One entry per iterate, iteration 0 (the initial guess) included.

    ``grad_norm`` is the mean over knots of ``‖∂J/∂u_k‖₂`` (adjoint recursion), ``defect_norm``
    the 2-norm of all stacked defects, ``alpha``/``mu``/``ls_trials`` describe the step that
    produced the iterate, ``group_violation`` its distance from the group, ``time_s`` wall time
    since the start.
    """

    objective: list[float] = field(default_factory=list)
    grad_norm: list[float] = field(default_factory=list)
    defect_norm: list[float] = field(default_factory=list)
    alpha: list[float] = field(default_factory=list)
    mu: list[float] = field(default_factory=list)
    ls_trials: list[int] = field(default_factory=list)
    group_violation: list[float] = field(default_factory=list)
    time_s: list[float] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.objective)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.asarray(v) for name, v in self.__dict__.items()}


@dataclass
class ILQRResult(SolverResult):
    """Outcome of :func:`~mbplan.solvers.ilqr.solve_ilqr` (fields as in ``RIPMResult``).

    ``x``/``u`` are the last accepted iterate (finite whatever the status); ``K``/``k`` the gains
    of the last backward pass (the feedback policy ``u = ū + k + K(x ⊖ x̄)`` around the
    previous iterate).
    """

    status: ILQRStatus
    message: str
    method: str
    iterations: int
    wall_time_s: float
    x: np.ndarray
    u: np.ndarray
    K: np.ndarray
    k: np.ndarray
    objective: float
    grad_norm: float
    defect_norm: float
    max_defect: float
    """Largest ``‖d_k‖₂`` at the final iterate."""
    group_violation: float
    """Largest group-membership error over all iterates."""
    history: ILQRHistory
    timings: dict[str, float]
    """Seconds spent in derivatives, backward passes, rollouts and cost evaluations."""

    @property
    def success(self) -> bool:
        return self.status is ILQRStatus.CONVERGED

    @property
    def time_per_iteration_s(self) -> float:
        return self.wall_time_s / max(self.iterations, 1)

    def __repr__(self) -> str:
        return (
            f"ILQRResult(method={self.method}, status={self.status.name}, "
            f"iterations={self.iterations}, objective={self.objective:.10g}, "
            f"grad_norm={self.grad_norm:.3e}, defect_norm={self.defect_norm:.3e}, "
            f"wall_time_s={self.wall_time_s:.4f})"
        )
