"""Options of SS-/MS-iLQR (thesis 3-54, 3-87; regularisation after Tassa et al.)."""

from __future__ import annotations

from dataclasses import dataclass

from mbplan.errors import InputError


@dataclass(frozen=True)
class ILQROptions:
    """``multiple_shooting`` selects Alg. 2 (defects, gap-closing rollout, merit) over Alg. 1.

    ``line_search=False`` is the full-step mode the thesis' reported MS-iLQR runs used (α = 1).
    Regularisation ``Q_uu + μI``: increased by Tassa's schedule (factor ``mu_factor``) when
    ``Q_uu`` is not positive definite or no step is accepted, decreased after accepted steps; μ
    below ``mu_min`` is 0. The thesis started at μ₀ = 1; our default is 0 because the
    Gauss–Newton ``Q_uu = 2R + BᵀV'_xxB`` is positive definite for ``R ≻ 0``.
    """

    multiple_shooting: bool = True
    line_search: bool = False
    second_order: bool = False
    """DDP: keep the dynamics' second derivatives in ``Q_xx, Q_ux, Q_uu`` (dropped by iLQR)."""
    max_iter: int = 100
    tol: float = 1e-8
    """Bound on the mean over knots of ``‖∂J/∂u_k‖₂``."""
    defect_tol: float = 1e-8
    """Bound on the 2-norm of the stacked defects (MS only)."""
    mu_init: float = 0.0
    mu_min: float = 1e-6
    mu_max: float = 1e10
    mu_factor: float = 2.0
    alpha_base: float = 1.1
    """Trial steps ``α_j = alpha_base^(-j²)``, j = 0…ls_max_trials-1 (thesis code)."""
    ls_max_trials: int = 13
    merit_sigma: float = 0.5
    merit_gamma_min: float = 10.0
    armijo_kappa: float = 0.05
    divergence_bound: float = 1e8
    """A rollout with a state or input entry above this is treated as diverged."""

    def __post_init__(self) -> None:
        if self.max_iter < 0:
            raise InputError(f"max_iter must be >= 0, got {self.max_iter}")
        for name in ("tol", "defect_tol", "mu_min", "mu_max", "mu_factor", "divergence_bound"):
            v = getattr(self, name)
            if not v > 0:
                raise InputError(f"{name} must be positive, got {v}")
        if self.mu_init < 0 or self.mu_factor <= 1 or self.alpha_base <= 1:
            raise InputError("mu_init >= 0, mu_factor > 1 and alpha_base > 1 are required")
        if self.ls_max_trials < 1:
            raise InputError("ls_max_trials must be >= 1")
