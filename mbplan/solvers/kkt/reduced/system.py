"""The KKT system of :mod:`mbplan.solvers.kkt.system` factorized through an
:class:`~mbplan.solvers.kkt.elimination.EliminationPlan`: two congruences
``K₁ = diag(T̃ᵀ, S, I) K diag(T̃, Sᵀ, I)`` (``S`` the row groups' combinations, ``T̃`` the
blocks' variable reduction ``x_dep = u - E x_free``) make the local rows touch only the
dependent columns, so ``K₁ = [[G, Cᵀ, Bᵀ], [C, K_r, 0], [B, 0, 0]]`` (unknowns ordered
dependent, rest, local rows) with ``B`` square lower block triangular. Then
``inertia(K) = inertia(K_r) + (m, m, 0)`` (``m`` dependent columns) and ``K x = b`` takes
``x_U = B⁻¹ b_Y``, ``x_R = K_r⁻¹ (b_R - C x_U)``, ``x_Y = B⁻ᵀ (b_U - G x_U - Cᵀ x_R)``.

``K_r = [[Tᵀ (H + D_x) T, (A_E,kept T)ᵀ, (A_I T)ᵀ], [·, D_kept, 0], [·, 0, D_I]]`` has its
inequality rows folded in (``D_I < 0``, ``Σ = -D_I⁻¹``: inertia ``(0, m_I, 0)``) and the rest,
``[[Tᵀ (H + D_x) T + (A_I T)ᵀ Σ (A_I T), (A_E,kept T)ᵀ], [·, D_kept]]``, is factorized by a
:class:`KKTSystem` of its own; a solve refines ``K_r``'s solve to a tenth of the requested
residual ratio, then against the full ``K`` (IPOPT's ratio).

The symbolic phase (once per pattern of a system) picks the replaced rows and dependent
columns by QR with column pivoting on the problem's reference values of ``A_E`` if it supplies
them (``pick_reference``: values of a canonical state, the same for every problem of a family,
which then share the phase), else on the values of the system's first matrix of the pattern
(once more on those of a matrix they break down on) and builds every index array
(:func:`~mbplan.solvers.kkt.reduced.reduction.reduction`);
the numeric phase is compiled (:mod:`mbplan.solvers.kkt.reduced.kernels`,
:mod:`~mbplan.solvers.kkt.reduced.products`, :mod:`~mbplan.solvers.kkt.reduced.solves`).
The full factorization is the fallback: a nonzero diagonal on an eliminated row (``δ_c > 0``,
restoration), a pivot breakdown in the reduction or in ``K_r``, or a refined solve that does
not converge.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.solvers.kkt.elimination import PLAN_ERRORS, EliminationPlan
from mbplan.solvers.kkt.pattern import _BlockPattern, _same_pattern
from mbplan.solvers.kkt.reduced.reduction import Reduction, reduction
from mbplan.solvers.kkt.system import Inertia, KKTSystem, _csr
from mbplan.workspace import Workspace

INNER_RATIO = 0.1
"""Each solve through the reduction refines ``K_r``'s solve to this times the requested residual
ratio: one pass then usually meets the ratio against ``K``."""


class ReducedKKTSystem:
    """:class:`KKTSystem`'s interface, factorizing through the plan ``plan_of(A_E)`` returns
    for each new pattern (module docstring); the full factorization when the plan is ``None``
    or the reduction does not apply (``strict``: an invalid plan raises instead);
    ``reference_of(A_E)``: the values of ``A_E``'s entries to pick on (``None``, or none
    returned: the first matrix's); ``workspace``: where the patterns, analyses and reductions
    are kept (``None``: this system's own).
    ``n_reduced``: factorizations through the reduction;
    ``n_fallbacks``: refined solves that missed ``ratio_max`` and were redone in full."""

    def __init__(
        self,
        n: int,
        n_eq: int,
        n_ineq: int,
        plan_of: Callable[[sp.csr_matrix], EliminationPlan | None],
        *,
        reference_of: Callable[[sp.csr_matrix], np.ndarray | None] | None = None,
        ordering: str = "amd",
        pivot_threshold: float = 0.0,
        strict: bool = False,
        workspace: Workspace | None = None,
    ) -> None:
        self.workspace = Workspace() if workspace is None else workspace
        self.full = KKTSystem(
            n,
            n_eq,
            n_ineq,
            ordering=ordering,
            pivot_threshold=pivot_threshold,
            workspace=self.workspace,
        )
        self.n, self.n_eq, self.n_ineq, self.dim = n, n_eq, n_ineq, self.full.dim
        self.ordering, self.pivot_threshold = ordering, pivot_threshold
        self.plan_of, self.reference_of, self.strict = plan_of, reference_of, strict
        self._red: Reduction | None = None
        self._plan: EliminationPlan | None = None
        self._patterns: tuple[_BlockPattern, ...] = ()
        self._active = self._values = self._pending = self._repicked = False
        self._diag = self._hess = np.zeros(0)
        self._reg = 0.0
        self.n_reduced = 0
        self.n_fallbacks = 0

    @property
    def n_factorizations(self) -> int:
        return self.full.n_factorizations + self.n_reduced

    @property
    def reduction(self) -> Reduction | None:
        """The reduction of the current pattern (``None``: no plan)."""
        return self._red

    def set_matrices(self, hessian, jac_eq, jac_ineq) -> None:
        """As :meth:`KKTSystem.set_matrices` (``hessian=None``: the full factorization). While
        the reduction applies, the full system gets the matrices only when it is needed (a
        fallback)."""
        self._active = self._pending = False
        if hessian is None:
            self.full.set_matrices(hessian, jac_eq, jac_ineq)
            self._values = False
            return
        blocks = (
            _csr(hessian, (self.n, self.n)),
            _csr(jac_eq, (self.n_eq, self.n)),
            _csr(jac_ineq, (self.n_ineq, self.n)),
        )
        if not (self._patterns and all(map(_same_pattern, blocks, self._patterns))):
            self._new_pattern(*blocks)
        self._values = self._red is not None and self._set_values(*blocks)
        if self._values:
            self._pending, self._hess = True, blocks[0].data.copy()
        else:
            self.full.set_matrices(*blocks)

    def _new_pattern(self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix) -> None:
        """The reduction of a new pattern (``None``: no plan or an unusable one)."""
        self._red, self._plan, self._repicked = None, None, False
        self._patterns = tuple(
            _BlockPattern(a.shape, a.indptr.copy(), a.indices.copy()) for a in (hess, ae, ai)
        )
        try:
            self._plan = self.plan_of(ae)
            if self._plan is not None:
                self._red = self._reference(hess, ae, ai) or reduction(
                    self._plan, hess, ae, ai, self.ordering, self.pivot_threshold, self.workspace
                )
        except InputError:
            if self.strict:
                raise
        except PLAN_ERRORS as err:  # a plan that does not fit
            if self.strict:
                raise InputError(f"kkt_method='reduced': unusable elimination plan: {err}") from err

    def _reference(
        self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix
    ) -> Reduction | None:
        """The reduction picked on the reference values of ``A_E`` (``None``: there are none,
        or they admit no reduction)."""
        values = None if self.reference_of is None else self.reference_of(ae)
        if values is None:
            return None
        ref = sp.csr_matrix((values, ae.indices, ae.indptr), shape=ae.shape)
        try:
            return reduction(
                self._plan, hess, ref, ai, self.ordering, self.pivot_threshold, self.workspace
            )
        except PLAN_ERRORS:
            return None

    def _set_values(self, hess: sp.csr_matrix, ae: sp.csr_matrix, ai: sp.csr_matrix) -> bool:
        """The reduction's values; on a breakdown (its replaced rows and dependent columns were
        picked on the reference or an earlier matrix), once per pattern, a reduction picked on
        these values
        (none if they admit none: rank deficient rows, or a breakdown on the very values it was
        picked on)."""
        if self._red.set_values(hess, ae, ai):
            return True
        if self._repicked:
            return False
        self._repicked = True
        try:
            red = reduction(
                self._plan, hess, ae, ai, self.ordering, self.pivot_threshold, self.workspace
            )
        except PLAN_ERRORS:
            return False
        if not red.set_values(hess, ae, ai):
            return False
        self._red = red
        return True

    def _full(self) -> KKTSystem:
        """The full system, with the current matrices."""
        if self._pending:
            red, (ph, pe, pi) = self._red, self._patterns
            self.full.set_matrices(
                sp.csr_matrix((self._hess, ph.indices, ph.indptr), shape=ph.shape),
                sp.csr_matrix((red.ae_data, pe.indices, pe.indptr), shape=pe.shape),
                sp.csr_matrix((red.ai_data, pi.indices, pi.indptr), shape=pi.shape),
            )
            self._pending = False
        return self.full

    def factorize(self, diagonal: np.ndarray, static_reg: float = 0.0) -> Inertia | None:
        """As :meth:`KKTSystem.factorize`: the inertia of the full ``K``."""
        diagonal = np.asarray(diagonal, dtype=np.float64)
        if diagonal.shape != (self.dim,):
            raise InputError(f"KKT diagonal has shape {diagonal.shape}, expected ({self.dim},)")
        self._diag, self._reg = diagonal, static_reg
        inertia = self._red.factorize(diagonal, static_reg) if self._values else None
        self._active = inertia is not None
        if not self._active:
            return self._full().factorize(diagonal, static_reg)
        self.n_reduced += 1
        return inertia

    def matvec(self, v: np.ndarray) -> np.ndarray:
        """``K v`` with the last factorized matrix."""
        if self._active:
            return self._red.matvec(np.asarray(v, dtype=np.float64), self._diag)
        return self._full().matvec(v)

    def solve(
        self,
        rhs: np.ndarray,
        max_refinement: int = 10,
        ratio_max: float = 1e-10,
        min_refinement: int = 1,
    ) -> tuple[np.ndarray, float]:
        """As :meth:`KKTSystem.solve`: refinement against ``K`` (a solve through the reduction
        that misses ``ratio_max`` is redone with the full factorization; ``min_refinement``
        applies to the solves of the reduced system)."""
        if not self._active:
            return self._full().solve(rhs, max_refinement, ratio_max, min_refinement)
        rhs = np.asarray(rhs, dtype=np.float64)
        if rhs.shape != (self.dim,):
            raise InputError(f"KKTSystem.solve: rhs has shape {rhs.shape}, expected ({self.dim},)")
        red, diag = self._red, self._diag
        inner = INNER_RATIO * ratio_max
        x = red.solve_once(rhs, diag, inner, min_refinement)
        res, ratio = red.residual(rhs, x, diag)
        for _ in range(max_refinement):
            if ratio <= ratio_max:
                break
            x_new = x + red.solve_once(res, diag, inner, min_refinement)
            res_new, ratio_new = red.residual(rhs, x_new, diag)
            if not ratio_new < ratio:
                break
            x, res, ratio = x_new, res_new, ratio_new
        if ratio <= ratio_max and np.isfinite(x).all():
            return x, ratio
        self.n_fallbacks += 1
        self._active = False
        if self._full().factorize(self._diag, self._reg) is None:  # a breakdown: no usable step
            return np.full(self.dim, np.nan), np.inf
        return self.full.solve(rhs, max_refinement, ratio_max, min_refinement)


KKT_METHODS = ("full", "reduced", "auto")


def kkt_system(
    problem,
    method: str,
    ordering: str,
    pivot_threshold: float = 0.0,
    workspace: Workspace | None = None,
) -> KKTSystem | ReducedKKTSystem:
    """The RIPM's KKT system for ``problem``: ``"full"``, ``"reduced"`` (through the problem's
    ``elimination_plan(A_E)``, an :class:`InputError` if it has none or it is invalid) or
    ``"auto"`` (reduced when the problem has a valid plan, the full factorization otherwise),
    picked on the problem's ``pick_reference(A_E)`` if it has one; its patterns, analyses and
    reductions kept in ``workspace``."""
    if method not in KKT_METHODS:
        raise InputError(f"kkt_method: expected one of {KKT_METHODS}, got {method!r}")
    n, me, mi = int(problem.n), int(problem.n_eq), int(problem.n_ineq)
    plan_of = getattr(problem, "elimination_plan", None)
    if method == "full" or (method == "auto" and plan_of is None):
        return KKTSystem(
            n, me, mi, ordering=ordering, pivot_threshold=pivot_threshold, workspace=workspace
        )
    if plan_of is None:
        raise InputError("kkt_method='reduced': the problem provides no elimination_plan")
    return ReducedKKTSystem(
        n,
        me,
        mi,
        plan_of,
        reference_of=getattr(problem, "pick_reference", None),
        ordering=ordering,
        pivot_threshold=pivot_threshold,
        strict=method == "reduced",
        workspace=workspace,
    )
