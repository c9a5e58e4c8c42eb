"""The primal-dual KKT vector field and its Newton system, shared by MLG-IPM and Lai-Yoshise.

Variables ``(x, ν, λ, s)``: ``x`` a manifold point (tangent coordinates ``ζ ∈ Rⁿ``), ``ν > 0`` the
multipliers of ``g ≤ 0``, ``λ`` those of ``h = 0`` and ``s > 0`` the slacks of ``g + s = 0``.
The field (MLG-IPM paper §III-A) is ::

    F_μ = [∇L;  g + s;  h;  s∘ν - μe],   ∇L = ∇f + J_gᵀν + J_hᵀλ,

and Newton's system (3) ``𝕵_F Δ = -F_μ (+ ρ)`` has the matrix ::

    [[H,   J_gᵀ, J_hᵀ, 0     ]   unknowns (Δζ, Δν, Δλ, Δs)
     [J_g, 0,    0,    I     ]
     [J_h, 0,    0,    0     ]
     [0,   S,    0,    diag ν]]

with ``H`` either the symmetric Riemannian Hessian of the Lagrangian (``problem.evaluate``) or the
paper's non-symmetric curvature matrix 𝕳_ℒ (Def. 5, ``problem.lagrangian_curvature``), which is
``H + ½C`` with ``C`` antisymmetric (a Lie bracket of the gradient); both agree where ``∇L = 0``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg

from mbplan.errors import InputError
from mbplan.solvers.nlp import NLPEvaluation, Point, RIPMProblem

DENSE_LIMIT = 600
"""Newton systems up to this size are solved densely (LU, least squares if singular)."""

CURVATURES = ("symmetric", "exact")


@runtime_checkable
class CurvatureProblem(Protocol):
    """A problem that also offers the paper's curvature matrix 𝕳_ℒ (Def. 5; non-symmetric)."""

    def lagrangian_curvature(
        self, x: Point, obj_factor: float, y: np.ndarray, z: np.ndarray
    ) -> np.ndarray | sp.spmatrix: ...


@dataclass
class PrimalDual:
    """An iterate: point, multipliers and slacks."""

    x: Point
    nu: np.ndarray
    lam: np.ndarray
    s: np.ndarray


@dataclass(frozen=True)
class FieldValue:
    """``F`` at an iterate, by block, with the evaluation it came from."""

    ev: NLPEvaluation
    grad_lagrangian: np.ndarray
    primal_ineq: np.ndarray
    primal_eq: np.ndarray
    complementarity: np.ndarray
    """``s∘ν`` (μ not subtracted)."""

    def vector(self, mu: float) -> np.ndarray:
        return np.concatenate(
            [self.grad_lagrangian, self.primal_ineq, self.primal_eq, self.complementarity - mu]
        )

    def norm(self, mu: float = 0.0) -> float:
        """``‖F_μ‖₂``."""
        return float(np.linalg.norm(self.vector(mu)))

    def inf_pr(self) -> float:
        return _amax(np.concatenate([self.primal_ineq, self.primal_eq]))

    def inf_du(self) -> float:
        return _amax(self.grad_lagrangian)

    def kkt_error(self) -> float:
        """``‖F_0‖∞``: the termination measure of MLG-IPM and of the benchmark."""
        return max(self.inf_pr(), self.inf_du(), _amax(self.complementarity))


def _amax(v: np.ndarray) -> float:
    return float(np.max(np.abs(v))) if v.size else 0.0


def _as_array(a: Any) -> np.ndarray:
    return a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)


def check_curvature(problem: RIPMProblem, curvature: str) -> None:
    if curvature not in CURVATURES:
        raise InputError(f"curvature must be one of {CURVATURES}, got {curvature!r}")
    if curvature == "exact" and not isinstance(problem, CurvatureProblem):
        raise InputError(
            f"curvature='exact' needs problem.lagrangian_curvature; {type(problem).__name__} "
            "offers only the symmetric Hessian (use curvature='symmetric')"
        )


def evaluate_field(problem: RIPMProblem, it: PrimalDual, hessian: bool = True) -> FieldValue:
    """Evaluate the problem at ``it.x`` (derivatives included if ``hessian``) and ``F``'s blocks."""
    ev = problem.evaluate(it.x, 1.0, it.lam, it.nu, hessian=hessian)
    grad = np.asarray(ev.gradient, dtype=float)
    if problem.n_ineq:
        grad = grad + ev.ineq_jacobian.T @ it.nu
    if problem.n_eq:
        grad = grad + ev.eq_jacobian.T @ it.lam
    return FieldValue(
        ev,
        np.asarray(grad, dtype=float).ravel(),
        np.asarray(ev.ineq, dtype=float) + it.s,
        np.asarray(ev.eq, dtype=float),
        it.s * it.nu,
    )


def newton_matrix(
    problem: RIPMProblem, it: PrimalDual, fv: FieldValue, curvature: str
) -> np.ndarray | sp.csc_matrix:
    """𝕵_F of system (3); dense up to :data:`DENSE_LIMIT` unknowns, sparse CSC beyond."""
    n, m1, m2 = problem.n, problem.n_ineq, problem.n_eq
    if curvature == "exact":
        H = problem.lagrangian_curvature(it.x, 1.0, it.lam, it.nu)  # type: ignore[attr-defined]
    else:
        H = fv.ev.hessian_lower
        if H is None:
            raise InputError("evaluate(..., hessian=True) returned no Hessian")
        H = _symmetric_from_lower(H)
    Jg, Jh = fv.ev.ineq_jacobian, fv.ev.eq_jacobian
    size = n + 2 * m1 + m2
    if size <= DENSE_LIMIT:
        K = np.zeros((size, size))
        iv, il, is_ = n, n + m1, n + m1 + m2
        K[:n, :n] = _as_array(H)
        Jg_d, Jh_d = _as_array(Jg).reshape(m1, n), _as_array(Jh).reshape(m2, n)
        K[:n, iv:il] = Jg_d.T
        K[:n, il:is_] = Jh_d.T
        K[iv:il, :n] = Jg_d
        K[iv:il, is_:] = np.eye(m1)
        K[il:is_, :n] = Jh_d
        K[is_:, iv:il] = np.diag(it.s)
        K[is_:, is_:] = np.diag(it.nu)
        return K
    Jg, Jh = sp.csr_matrix(Jg, shape=(m1, n)), sp.csr_matrix(Jh, shape=(m2, n))
    blocks = [
        [sp.csr_matrix(H), Jg.T, Jh.T, None],
        [Jg, None, None, sp.identity(m1)],
        [Jh, None, None, None],
        [None, sp.diags(it.s, shape=(m1, m1)), None, sp.diags(it.nu, shape=(m1, m1))],
    ]
    return sp.bmat(blocks, format="csc")


def _symmetric_from_lower(H: Any) -> np.ndarray | sp.csr_matrix:
    if sp.issparse(H):
        L = sp.tril(H, format="csr")
        return L + sp.tril(L, k=-1, format="csr").T
    L = np.tril(np.asarray(H, dtype=float))
    return L + np.tril(L, -1).T


def solve_newton(K: np.ndarray | sp.spmatrix, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve ``K Δ = rhs``; returns ``(Δ, regular)``. A singular dense ``K`` (the non-isolated
    solutions of problem (11)) gets the minimum-norm least-squares step; a singular sparse one a
    small primal-dual regularisation."""
    if not sp.issparse(K):
        with warnings.catch_warnings():
            warnings.simplefilter("error", scipy.linalg.LinAlgWarning)
            try:
                return scipy.linalg.solve(K, rhs, check_finite=False), True
            except (np.linalg.LinAlgError, scipy.linalg.LinAlgWarning):
                pass
        sol = scipy.linalg.lstsq(K, rhs, cond=1e-12, check_finite=False)[0]
        return sol, False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", scipy.sparse.linalg.MatrixRankWarning)
            sol = scipy.sparse.linalg.splu(K).solve(rhs)
        if np.all(np.isfinite(sol)):
            return sol, True
    except (RuntimeError, scipy.sparse.linalg.MatrixRankWarning):
        pass
    reg = 1e-8 * max(1.0, float(abs(K).max()))
    Kr = K + reg * sp.identity(K.shape[0], format="csc")
    return scipy.sparse.linalg.splu(Kr.tocsc()).solve(rhs), False


def split_step(problem: RIPMProblem, sol: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(Δζ, Δν, Δλ, Δs)`` from the stacked solution."""
    n, m1, m2 = problem.n, problem.n_ineq, problem.n_eq
    return sol[:n], sol[n : n + m1], sol[n + m1 : n + m1 + m2], sol[n + m1 + m2 :]


def max_step(v: np.ndarray, dv: np.ndarray) -> float:
    """``min_{dv_i < 0} -v_i/dv_i`` (``+∞`` on an empty set)."""
    neg = dv < 0
    return float(np.min(-v[neg] / dv[neg])) if np.any(neg) else np.inf


def check_start(problem: RIPMProblem, x0: Point) -> Point:
    """``x0`` validated by the problem (``check_point`` if it has one) and finite."""
    if not point_is_finite(x0):
        raise InputError("initial point contains NaN or infinite entries")
    check = getattr(problem, "check_point", None)
    return check(x0) if check is not None else x0


def point_is_finite(x: Point) -> bool:
    """No NaN/inf in a point (an array or a dict of arrays)."""
    leaves = x.values() if isinstance(x, dict) else [x]
    for leaf in leaves:
        a = np.asarray(leaf)
        if a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
            return False
    return True


def initial_duals(
    problem: RIPMProblem,
    x0: Point,
    nu0: np.ndarray | None,
    lam0: np.ndarray | None,
    s0: np.ndarray | None,
    slack_min: float,
    mult_init: float,
) -> PrimalDual:
    """Slacks ``s0 = max(-g(x0), slack_min)``, ``ν0 = mult_init``, ``λ0 = 0`` unless given."""
    _, _, g = problem.values(x0)
    m1, m2 = problem.n_ineq, problem.n_eq
    s = (
        np.maximum(-np.asarray(g, dtype=float), slack_min)
        if s0 is None
        else _positive(s0, m1, "s0")
    )
    nu = np.full(m1, mult_init) if nu0 is None else _positive(nu0, m1, "nu0")
    lam = np.zeros(m2) if lam0 is None else np.asarray(lam0, dtype=float).reshape(m2)
    if not np.all(np.isfinite(lam)):
        raise InputError("lam0 must be finite")
    return PrimalDual(x0, nu, lam, s)


def _positive(v: np.ndarray, m: int, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (m,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"{name} must be {m} finite positive numbers, got {a!r}")
    return a.copy()


class NewtonSolver:
    """Solves system (3) for one problem, keeping what can be reused between iterations.

    Small systems: dense LU of 𝕵_F (:func:`solve_newton`). Large ones with the symmetric
    Hessian: ``Δs = (b_c - S Δν)/ν`` is eliminated, leaving the symmetric matrix
    ``[[H, J_hᵀ, J_gᵀ], [J_h, 0, 0], [J_g, 0, -S/ν]]``, factorized by the RIPM's sparse LDLᵀ
    (:class:`~mbplan.solvers.kkt.system.KKTSystem`, its pattern analysed once). Large ones
    with the exact (non-symmetric) 𝕳_ℒ: sparse LU of 𝕵_F.
    """

    def __init__(self, problem: RIPMProblem, curvature: str) -> None:
        self.p, self.curvature = problem, curvature
        self._kkt: Any = None

    def solve(self, it: PrimalDual, fv: FieldValue, rhs: np.ndarray) -> np.ndarray:
        p = self.p
        size = p.n + 2 * p.n_ineq + p.n_eq
        if size <= DENSE_LIMIT or self.curvature == "exact":
            return solve_newton(newton_matrix(p, it, fv, self.curvature), rhs)[0]
        sol = self._reduced(it, fv, rhs)
        if sol is None:
            return solve_newton(newton_matrix(p, it, fv, self.curvature), rhs)[0]
        return sol

    def _reduced(self, it: PrimalDual, fv: FieldValue, rhs: np.ndarray) -> np.ndarray | None:
        from mbplan.solvers.kkt.system import KKTSystem

        p = self.p
        n, m1, m2 = p.n, p.n_ineq, p.n_eq
        b_d, b_g, b_h, b_c = split_step(p, rhs)
        if self._kkt is None:
            self._kkt = KKTSystem(n, m2, m1)
        self._kkt.set_matrices(fv.ev.hessian_lower, fv.ev.eq_jacobian, fv.ev.ineq_jacobian)
        diagonal = np.concatenate([np.zeros(n + m2), -it.s / it.nu])
        if self._kkt.factorize(diagonal, static_reg=1e-9) is None:
            return None
        red, ratio = self._kkt.solve(np.concatenate([b_d, b_h, b_g - b_c / it.nu]))
        if not (np.all(np.isfinite(red)) and ratio < 1e-5):
            return None
        dx, dlam, dnu = red[:n], red[n : n + m2], red[n + m2 :]
        ds = (b_c - it.s * dnu) / it.nu
        return np.concatenate([dx, dnu, dlam, ds])
