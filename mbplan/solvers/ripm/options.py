"""Parameters of the RIPM, grouped as IPOPT's documentation groups them: Table IV of the RIPM
paper where it gives one, IPOPT's defaults (Wächter & Biegler 2006, "WB" below) for the rest,
except the barrier strategy (Mehrotra's probing μ capped at μ_init with the corrector) and the
joint-eliminated Newton step, chosen on the benchmark tasks (docs/ripm-design.md).

Each group is a frozen dataclass handed to the component it configures; :class:`RIPMOptions`
holds one of each and takes and gives every parameter by its own name as well
(``RIPMOptions(tol=1e-8).tol``, ``options.replace(max_iter=50)``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from mbplan.errors import InputError
from mbplan.solvers.kkt.pattern import ORDERINGS
from mbplan.solvers.kkt.reduced.system import KKT_METHODS

_KINDS = {
    "int": (int, np.integer),
    "float": (int, float, np.integer, np.floating),
    "bool": (bool, np.bool_),
    "str": str,
}


class _Group:
    """Type and range checks of a group's fields (``_checks``: field name → valid)."""

    def _checks(self) -> dict[str, bool]:
        return {}

    def __post_init__(self) -> None:
        wrong = [
            f"{f.name}={getattr(self, f.name)!r} (expected {f.type})"
            for f in dataclasses.fields(self)  # type: ignore[arg-type]
            if not isinstance(getattr(self, f.name), _KINDS[f.type])
            or (f.type != "bool" and isinstance(getattr(self, f.name), bool))
        ]
        if wrong:
            raise InputError(f"RIPM option(s) of the wrong type: {', '.join(wrong)}")
        bad = [name for name, ok in self._checks().items() if not ok]
        if bad:
            values = ", ".join(f"{name}={getattr(self, name)!r}" for name in bad)
            raise InputError(f"RIPM option(s) out of range: {values}")


@dataclass(frozen=True)
class TerminationOptions(_Group):
    """When the solve stops (IPOPT's "Termination")."""

    tol: float = 1e-11
    """ε_tol (Table IV): termination when the scaled KKT error E_0 (eq. 55-56) is below it."""
    max_iter: int = 200
    """N_max (Table IV): iterations, restoration iterations included."""
    acceptable_tol: float = 1e-6
    """E_0 ≤ acceptable_tol for ``acceptable_iter`` consecutive iterations ends with ACCEPTABLE."""
    acceptable_iter: int = 15
    constr_viol_tol: float = 1e-4
    """A point with ‖h, g + s‖∞ above it that minimizes the infeasibility is locally infeasible."""
    s_max: float = 100.0
    """Scaling threshold of s_d, s_c in the KKT error (WB eq. 5)."""

    def _checks(self) -> dict[str, bool]:
        return {"max_iter": self.max_iter >= 0, "tol": self.tol > 0}


@dataclass(frozen=True)
class BarrierOptions(_Group):
    """The barrier parameter μ and the fraction to the boundary (IPOPT's "Barrier Parameter")."""

    mu_strategy: str = "adaptive"
    """``"adaptive"``: the free-mode oracle (``mu_oracle``) every iteration while ``E_0``
    decreases, with IPOPT's fall-back to the monotone rule (``adaptive_mu_globalization=
    kkt-error``); ``"monotone"``: Fiacco-McCormick (WB eq. 7, Algorithm 1; IPOPT's default)."""
    mu_oracle: str = "probing"
    """Free-mode μ of ``mu_strategy="adaptive"``: ``"loqo"`` (Vanderbei & Shanno's rule on the
    complementarity spread) or ``"probing"`` (Mehrotra's predictor: an affine-scaling step with
    the iteration's factorization, ``μ = (μ_aff/μ_avg)³ μ_avg``; IPOPT's ``mu_oracle=probing``)."""
    mu_init: float = 0.1
    mu_max_fact: float = 0.0
    """Upper bound of the adaptive μ: ``max(μ_init, mu_max_fact · sᵀz/m)`` at the start (IPOPT's
    ``mu_max_fact``, 1e3 there); 0 caps it at ``μ_init``."""
    kappa_mu: float = 0.99
    """κ_μ (Table IV): linear decrease of μ (WB eq. 7)."""
    theta_mu: float = 1.99
    """θ_μ (Table IV): superlinear decrease of μ (WB eq. 7)."""
    kappa_eps: float = 10.0
    """μ is decreased once E_μ ≤ κ_ε μ (WB eq. 7; Algorithm 1 uses 10)."""
    tau_min: float = 0.995
    """τ_min (Table IV): fraction to the boundary τ = max(τ_min, 1 - μ) (WB eq. 8)."""
    corrector: bool = True
    """Mehrotra's second-order corrector: the complementarity row's right-hand side
    ``μe - (α_s ΔS_aff)(α_z Δz_aff)`` from the affine-scaling step (the probing oracle's when it
    runs), kept if it reaches as far before the boundary as the affine step, else unless the
    uncorrected step reaches farther; all with the step's factorization. Main phase only."""

    def _checks(self) -> dict[str, bool]:
        return {
            "mu_strategy": self.mu_strategy in ("monotone", "adaptive"),
            "mu_oracle": self.mu_oracle in ("loqo", "probing"),
            "mu_init": self.mu_init > 0,
            "mu_max_fact": self.mu_max_fact >= 0,
            "kappa_mu": 0 < self.kappa_mu < 1,
            "theta_mu": 1 < self.theta_mu < 2,
            "tau_min": 0 < self.tau_min < 1,
        }


@dataclass(frozen=True)
class LineSearchOptions(_Group):
    """The filter line search and the multipliers' step (IPOPT's "Line Search")."""

    max_ls_trials: int = 30
    """J_max (Table IV): trial points per line search."""
    beta: float = 0.5
    """β (Table IV): backtracking factor of the step size."""
    theta_max_fact: float = 1e4
    """θ_max = theta_max_fact · max(1, θ(x_0)): the filter's upper bound on the infeasibility."""
    theta_min_fact: float = 1e-4
    """θ_min = theta_min_fact · max(1, θ(x_0)) (Table IV): below it the switching rule applies."""
    gamma_theta: float = 1e-4
    """γ_θ (Table IV): sufficient decrease of the infeasibility (WB eq. 18)."""
    gamma_phi: float = 1e-6
    """γ_φ (Table IV): sufficient decrease of the barrier objective (WB eq. 18)."""
    eta_phi: float = 1e-4
    """η_φ (Table IV): Armijo factor (WB eq. 20)."""
    delta: float = 1.0
    s_theta: float = 1.1
    s_phi: float = 2.3
    gamma_alpha: float = 0.05
    """Safety factor of α_min (WB eq. 23)."""
    second_order_correction: bool = True
    max_soc: int = 4
    kappa_soc: float = 0.99
    kappa_sigma: float = 1e10
    """Safeguard κ_Σ of the multipliers z against μ/s (WB eq. 16)."""
    dual_step_cap: float = 1e-2
    """When the fraction-to-the-boundary rule cuts the slacks' step to ``α_s`` below this, the
    multipliers ``z`` step at most ``α_s`` too instead of their own ``α_z`` (WB eq. 15): a
    primal step blocked at ``α_s ≪ 1`` must not take the full ``dz ≈ -z ds/s`` that the whole
    ``ds`` implies (multipliers of violated rows grow without bound otherwise); 0: always ``α_z`` (IPOPT)."""
    tiny_step_tol: float = 10 * float(np.finfo(float).eps)

    def _checks(self) -> dict[str, bool]:
        return {
            "max_ls_trials": self.max_ls_trials >= 1,
            "beta": 0 < self.beta < 1,
            "gamma_theta": 0 < self.gamma_theta < 1,
            "gamma_phi": 0 < self.gamma_phi < 1,
            "eta_phi": 0 < self.eta_phi < 0.5,
            "kappa_soc": 0 < self.kappa_soc < 1,
            "dual_step_cap": 0 <= self.dual_step_cap <= 1,
        }


@dataclass(frozen=True)
class InitializationOptions(_Group):
    """The starting point's slacks and multipliers (IPOPT's "Initialization")."""

    bound_push: float = 1e-2
    """Initial slacks s_0 = max(-g(x_0), bound_push)."""
    bound_mult_init_val: float = 1.0
    """Initial multipliers z_0 of the inequalities."""
    constr_mult_init_max: float = 1.0
    """Least-squares initial y_0 is discarded (y_0 = 0) if larger than this in max norm
    (IPOPT: 1e3; larger multipliers cost the drone iterations; 0: always y_0 = 0)."""

    def _checks(self) -> dict[str, bool]:
        return {
            "bound_push": self.bound_push > 0,
            "bound_mult_init_val": self.bound_mult_init_val > 0,
            "constr_mult_init_max": self.constr_mult_init_max >= 0,
        }


@dataclass(frozen=True)
class InertiaOptions(_Group):
    """The inertia correction δ_w, δ_c (WB Algorithm IC; IPOPT's "Hessian Perturbation")."""

    delta_w_init: float = 1e-4
    delta_w_min: float = 1e-20
    delta_w_max: float = 1e40
    kappa_w_minus: float = 1.0 / 3.0
    kappa_w_plus: float = 8.0
    kappa_w_plus_first: float = 100.0
    delta_c_bar: float = 1e-8
    kappa_c: float = 0.25
    degenerate_iters: int = 2
    """After this many consecutive iterations that needed ``δ_w > 0``, the first trial is
    ``κ_w⁻ δ_w,last`` instead of 0 (one factorization fewer per such iteration; 0: always try
    ``δ_w = 0`` first, WB Algorithm IC). IPOPT enters this mode only for singular matrices,
    not for wrong inertia: measured worse here."""
    kappa_curvature: float = 1e-8
    """A factorization with more negative pivots than constraints is kept when its step ``dx``
    has ``dxᵀ(W + δ_w I + A_Iᵀ Σ A_I) dx ≥ kappa_curvature · dxᵀdx`` (the inertia-free test of
    Chiang & Zavala 2016; main phase, nearly feasible iterates: ``CURVATURE_TEST_INF_PR`` of
    :mod:`mbplan.solvers.ripm.newton`): the statically regularized LDLᵀ counts negative
    curvature off the constraints' tangent space where ``A_E`` is nearly rank deficient, and
    ``δ_w`` would otherwise grow to ~10⁻² and the iterates crawl. 0: the inertia alone."""
    degenerate_zero_below: float = 1e-2
    """In the mode of ``degenerate_iters``, a first trial ``κ_w⁻ δ_w,last`` below this is
    ``δ_w = 0`` instead: the zero trial is skipped only while the perturbation is large, so an iterate
    whose Hessian has become positive definite stops being regularized. 0: never."""

    def _checks(self) -> dict[str, bool]:
        return {
            "delta_w_min": 0 <= self.delta_w_min <= self.delta_w_init <= self.delta_w_max,
            "kappa_w_minus": 0 < self.kappa_w_minus < 1,
            "kappa_w_plus": self.kappa_w_plus > 1,
            "kappa_w_plus_first": self.kappa_w_plus_first > 1,
            "degenerate_iters": self.degenerate_iters >= 0,
            "degenerate_zero_below": self.degenerate_zero_below >= 0,
            "kappa_curvature": self.kappa_curvature >= 0,
        }


@dataclass(frozen=True)
class LinearSolverOptions(_Group):
    """The KKT factorization and its solves (IPOPT's "Linear Solver")."""

    kkt_method: str = "auto"
    """``"full"``: factorize the whole KKT matrix; ``"reduced"``: eliminate the pairs of the
    problem's ``elimination_plan`` first (:mod:`mbplan.solvers.kkt.reduced.system`; the full
    factorization where it does not apply, e.g. ``δ_c > 0``); ``"auto"``: reduced when the
    problem has a valid plan, else the full factorization (no error)."""
    kkt_ordering: str = "amd"
    """Elimination order of the KKT factorization: ``"amd"`` (approximate minimum degree),
    ``"metis"`` (METIS nested dissection), ``"auto"`` (AMD, or METIS when AMD needs at least
    ``AUTO_MIN_FLOPS`` multiply-adds and METIS predicts fewer) or ``"nested"`` (nested
    dissection along the trajectory's level structure), :mod:`mbplan.solvers.kkt.ordering`. AMD is
    the default: the LDLᵀ without pivoting breaks down more often with METIS orders
    (with ``kkt_pivot_threshold = 1e-10`` it does not on the
    benchmark tasks)."""
    kkt_pivot_threshold: float = 0.0
    """Threshold ``u`` of 1 × 1 / 2 × 2 pivoting inside each supernode of the KKT
    factorization (MA57's test ``|d| >= u · max |column|``; tiny pivots without an acceptable
    replacement perturbed, :class:`~mbplan.solvers.kkt.system.KKTSystem`); 0: no pivoting."""
    static_regularization: float = 1e-9
    """±ε on the diagonal of the factorized KKT matrix only (removed by iterative refinement),
    so that the LDLᵀ factorization, which does not pivot, never meets an exact zero pivot."""
    max_refinement_steps: int = 10
    residual_ratio_max: float = 1e-10
    residual_ratio_singular: float = 1e-5

    def _checks(self) -> dict[str, bool]:
        return {
            "kkt_method": self.kkt_method in KKT_METHODS,
            "kkt_ordering": self.kkt_ordering in ORDERINGS,
            "kkt_pivot_threshold": 0 <= self.kkt_pivot_threshold <= 1,
        }


@dataclass(frozen=True)
class RestorationOptions(_Group):
    """The soft and the ℓ1 feasibility restoration phases (WB §3.3; IPOPT's "Restoration
    Phase")."""

    restoration: bool = True
    """Enter a restoration phase when the line search or the inertia correction fails."""
    kappa_resto: float = 0.9
    """Restoration returns once θ ≤ kappa_resto · θ at its start and the filter accepts."""
    resto_penalty: float = 1e3
    """ρ of the elastic restoration problem (IPOPT's resto_penalty_parameter)."""
    resto_proximity_weight: float = 1.0
    """ζ = resto_proximity_weight · √μ on ½‖ξ‖² (IPOPT's resto_proximity_weight)."""
    bound_mult_reset_threshold: float = 1e3
    """After restoration z = μ/s, or all z = 1 if max(μ/s) exceeds this (IPOPT's rule)."""
    resto_ls_multipliers: bool = False
    """After restoration, y from least squares instead of 0 (IPOPT's
    constr_mult_reset_threshold > 0)."""
    max_soft_resto_iters: int = 10
    """IPOPT's soft restoration phase: when the line search fails, steps to the boundary are
    taken while they reduce the primal-dual error, at most this many in a row (0: none)."""
    soft_resto_pderror_reduction_factor: float = 0.9999
    """A soft restoration step must reduce the primal-dual error by this factor (IPOPT's)."""

    def _checks(self) -> dict[str, bool]:
        factor = self.soft_resto_pderror_reduction_factor
        return {
            "kappa_resto": 0 < self.kappa_resto < 1,
            "resto_penalty": self.resto_penalty > 0,
            "resto_proximity_weight": self.resto_proximity_weight >= 0,
            "max_soft_resto_iters": self.max_soft_resto_iters >= 0,
            "soft_resto_pderror_reduction_factor": 0 < factor < 1,
        }


@dataclass(frozen=True)
class OutputOptions(_Group):
    """What the solve prints (IPOPT's "Output")."""

    print_level: int = 0
    """0: silent; 1: an IPOPT-like line per iteration and a summary."""

    def _checks(self) -> dict[str, bool]:
        return {"print_level": self.print_level >= 0}


@dataclass(frozen=True, init=False)
class RIPMOptions:
    """Every parameter of :func:`~mbplan.solvers.ripm.driver.solve_ripm`, one group per
    component; construct, read and :meth:`replace` any parameter by its own name."""

    termination: TerminationOptions = field(default_factory=TerminationOptions)
    barrier: BarrierOptions = field(default_factory=BarrierOptions)
    line_search: LineSearchOptions = field(default_factory=LineSearchOptions)
    initialization: InitializationOptions = field(default_factory=InitializationOptions)
    inertia: InertiaOptions = field(default_factory=InertiaOptions)
    linear_solver: LinearSolverOptions = field(default_factory=LinearSolverOptions)
    restoration_phase: RestorationOptions = field(default_factory=RestorationOptions)
    output: OutputOptions = field(default_factory=OutputOptions)

    GROUPS: ClassVar[dict[str, type]] = {
        "termination": TerminationOptions,
        "barrier": BarrierOptions,
        "line_search": LineSearchOptions,
        "initialization": InitializationOptions,
        "inertia": InertiaOptions,
        "linear_solver": LinearSolverOptions,
        "restoration_phase": RestorationOptions,
        "output": OutputOptions,
    }
    OWNER: ClassVar[dict[str, str]] = {
        f.name: group for group, cls in GROUPS.items() for f in dataclasses.fields(cls)
    }
    """The group of each parameter."""

    def __init__(self, **values: Any) -> None:
        unknown = sorted(set(values) - set(self.OWNER) - set(self.GROUPS))
        if unknown:
            raise InputError(f"unknown RIPM option(s): {unknown}")
        for group, cls in self.GROUPS.items():
            own = {k: v for k, v in values.items() if self.OWNER.get(k) == group}
            base = values.get(group)
            if base is not None and not isinstance(base, cls):
                raise InputError(f"RIPM option {group} must be a {cls.__name__}")
            value = dataclasses.replace(base, **own) if base is not None else cls(**own)
            object.__setattr__(self, group, value)

    def __getattr__(self, name: str) -> Any:
        group = type(self).OWNER.get(name)
        if group is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(getattr(self, group), name)

    def replace(self, **overrides: Any) -> RIPMOptions:
        """A copy with some parameters changed; unknown names raise :class:`InputError`."""
        groups = {group: getattr(self, group) for group in self.GROUPS}
        return RIPMOptions(**(groups | overrides))
