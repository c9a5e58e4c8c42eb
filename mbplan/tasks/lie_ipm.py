"""The MLG-IPM paper's test problems (10) on SO(n)² and (11) on SL(n)², with seeded instances.

Both are separable over the elements ``G_1, G_2``: each element carries one objective term and
its own inequalities, so every derivative is block diagonal. For each function we form its
gradient ``∇φ`` along ``G exp(ζ^)`` and the paper's curvature matrix 𝕳_φ (Def. 5: the Jacobian of
the gradient field, ``[𝕳]_kl = ∂_l ∇φ_k(G exp(ζ^))``), in closed form; the Riemannian Hessian of
the pullback ``ζ ↦ φ(G exp(ζ^))`` is its symmetric part (their difference ``½ ∇φ·[E_l, E_k]^∨`` is
antisymmetric).

* (10): ``min ½ Σ_i ‖log(G_dᵀ G_i)‖_F`` (``objective="literal"``) or ``½ Σ_i ½‖log(G_dᵀG_i)‖²_F``
  (``"squared"``) s.t. ``G_i[0,0] ≤ c₁``, ``G_i[1,1] ≤ c₂``; ``(c₁, c₂) = (0.5, 0.3)``
  (``constants="rendered"``) or ``(5, 3)`` (``"alt-text"``, never active).
* (11): ``min ½ Σ_i t_i²`` s.t. ``c - t_i² ≤ 0``, ``t_i = Tr(G_d⁻¹ G_i)``; ``c = 0.2`` or ``2``.
  Every minimiser has ``t_i² = c`` (objective ``c``, ν = ½): a certificate of the optimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.lie import SL, SO, MatrixLieGroup
from mbplan.solvers.nlp import ManifoldNLP, NLPEvaluation

CONSTANTS = {
    "so": {"rendered": (0.5, 0.3), "alt-text": (5.0, 3.0)},
    "sl": {"rendered": (0.2,), "alt-text": (2.0,)},
}
OBJECTIVES = ("squared", "literal")


def haar_so(n: int, rng: np.random.Generator) -> np.ndarray:
    """A Haar-distributed rotation: QR of a Gaussian, columns' signs fixed by ``diag R > 0``,
    one column flipped if the determinant is -1 (Mezzadri 2007)."""
    Q, R = np.linalg.qr(rng.standard_normal((n, n)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def sample_sl(n: int, rng: np.random.Generator) -> np.ndarray:
    """An SL(n) element: a standard Gaussian ``A`` with its first row negated if ``det A < 0``,
    scaled by ``|det A|^{-1/n}`` (a Gaussian conditioned on the sign, projected radially)."""
    A = rng.standard_normal((n, n))
    d = np.linalg.det(A)
    if d < 0:
        A[0] = -A[0]
    return A / abs(d) ** (1.0 / n)


@dataclass(frozen=True)
class LieIPMInstance:
    """One random instance: the target ``G_d`` and the initial iterate ``G0`` (shape (2, n, n))."""

    problem: str
    seed: int
    index: int
    Gd: np.ndarray
    G0: np.ndarray


def sample_instance(problem: str, seed: int, index: int, n: int = 7) -> LieIPMInstance:
    """Instance ``index`` of the stream ``seed``: G_d, G_1, G_2 sampled independently (Haar on
    SO(n), :func:`sample_sl` on SL(n)) from ``default_rng([seed, index])``."""
    if problem not in ("so", "sl"):
        raise InputError(f"problem must be 'so' or 'sl', got {problem!r}")
    rng = np.random.default_rng([seed, index])
    draw = haar_so if problem == "so" else sample_sl
    mats = [draw(n, rng) for _ in range(3)]
    return LieIPMInstance(problem, seed, index, mats[0], np.stack(mats[1:]))


@dataclass(frozen=True)
class Terms:
    """One element's objective term ``f`` and inequalities ``g`` (shape (q,)), their gradients
    (``(d,)``, ``(q, d)``) and curvature matrices (``(d, d)``, ``(q, d, d)``) up to some order."""

    f: float
    g: np.ndarray
    grad_f: np.ndarray | None = None
    jac_g: np.ndarray | None = None
    curv_f: np.ndarray | None = None
    curv_g: np.ndarray | None = None


def _brackets(basis: np.ndarray) -> np.ndarray:
    """``EE[l, k] = E_l E_k`` for the curvature of linear functions of ``G``."""
    return np.einsum("lab,kbc->lkac", basis, basis)


class _SeparableLieNLP(ManifoldNLP):
    """``k`` elements of one matrix Lie group; subclasses give per-element blocks."""

    def __init__(self, group: MatrixLieGroup, k: int, per_element_ineq: int) -> None:
        self.group, self.k, self.d = group, k, group.dim
        self.q = per_element_ineq
        self.E = group.basis()
        self.EE = _brackets(self.E)
        n = k * self.d
        rows, cols = np.indices((self.d, self.d)).reshape(2, -1)
        off = np.arange(k)[:, None] * self.d
        self._h_rows = (off + rows).ravel()
        self._h_cols = (off + cols).ravel()
        self._j_rows = np.repeat(np.arange(k * self.q), self.d)
        self._j_cols = (np.repeat(off, self.q, axis=0) + np.arange(self.d)).ravel()
        self._n = n
        self._cache: tuple | None = None

    @property
    def n(self) -> int:
        return self._n

    @property
    def n_eq(self) -> int:
        return 0

    @property
    def n_ineq(self) -> int:
        return self.k * self.q

    def check_point(self, x: np.ndarray) -> np.ndarray:
        a = np.asarray(x, dtype=float)
        if a.shape != (self.k, self.group.n, self.group.n):
            raise InputError(
                f"point must have shape {(self.k, self.group.n, self.group.n)}, got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise InputError("point contains NaN or infinite entries")
        for i in range(self.k):
            self.group.check(a[i])
        return a

    def retract(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``G_i exp(Δζ_i^)`` for every element (update (4))."""
        A = np.einsum("kd,dab->kab", dx.reshape(self.k, self.d), self.E)
        return np.stack([x[i] @ scipy.linalg.expm(A[i]) for i in range(self.k)])

    def _element(self, G: np.ndarray, level: int) -> Terms:
        """One element's objective term and inequalities up to derivative order ``level``."""
        raise NotImplementedError

    def _terms(self, x: np.ndarray, level: int = 2) -> list[Terms]:
        """Per element, computed once per point (a cached higher level serves lower ones)."""
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key and self._cache[1] >= level:
            return self._cache[2]
        terms = [self._element(G, level) for G in x]
        self._cache = (key, level, terms)
        return terms

    def evaluate(
        self,
        x: np.ndarray,
        obj_factor: float = 1.0,
        y: np.ndarray | None = None,
        z: np.ndarray | None = None,
        hessian: bool = True,
    ) -> NLPEvaluation:
        """All quantities at ``x`` from one pass over the elements."""
        terms = self._terms(x, 2 if hessian else 1)
        z = np.zeros(self.n_ineq) if z is None else np.asarray(z, dtype=float)
        return NLPEvaluation(
            objective=float(sum(t.f for t in terms)),
            gradient=np.concatenate([t.grad_f for t in terms]),
            eq=np.zeros(0),
            eq_jacobian=sp.csr_matrix((0, self.n)),
            ineq=np.concatenate([t.g for t in terms]),
            ineq_jacobian=self._jacobian(np.concatenate([t.jac_g for t in terms])),
            hessian_lower=self.lagrangian_hessian(x, obj_factor, np.zeros(0), z)
            if hessian
            else None,
        )

    def values(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        terms = self._terms(x, 0)
        return (
            float(sum(t.f for t in terms)),
            np.zeros(0),
            np.concatenate([t.g for t in terms]),
        )

    def _jacobian(self, J: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((J.ravel(), (self._j_rows, self._j_cols)), shape=(self.n_ineq, self.n))

    def objective(self, x: np.ndarray) -> float:
        return self.values(x)[0]

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([t.grad_f for t in self._terms(x, 1)])

    def ineq(self, x: np.ndarray) -> np.ndarray:
        return self.values(x)[2]

    def ineq_jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        return self._jacobian(np.concatenate([t.jac_g for t in self._terms(x, 1)]))

    def curvature_blocks(self, x: np.ndarray, obj_factor: float, z: np.ndarray) -> np.ndarray:
        """𝕳_ℒ per element, shape (k, d, d) (Def. 5 and §III-A)."""
        z = np.asarray(z, dtype=float).reshape(self.k, self.q)
        terms = self._terms(x, 2)
        out = np.empty((self.k, self.d, self.d))
        for i, e in enumerate(terms):
            out[i] = obj_factor * e.curv_f + np.einsum("j,jab->ab", z[i], e.curv_g)
        return out

    def _block_diag(self, blocks: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((blocks.ravel(), (self._h_rows, self._h_cols)), shape=(self.n, self.n))

    def lagrangian_curvature(
        self, x: np.ndarray, obj_factor: float, y: np.ndarray, z: np.ndarray
    ) -> sp.csr_matrix:
        """The paper's non-symmetric curvature matrix 𝕳_ℒ (block diagonal, full pattern)."""
        return self._block_diag(self.curvature_blocks(x, obj_factor, z))

    def lagrangian_hessian(
        self, x: np.ndarray, obj_factor: float, y: np.ndarray, z: np.ndarray
    ) -> sp.csr_matrix:
        """Riemannian Hessian: the symmetric part of 𝕳_ℒ (full block pattern)."""
        H = self.curvature_blocks(x, obj_factor, z)
        return self._block_diag(0.5 * (H + np.swapaxes(H, 1, 2)))

    def _linear_entry(self, G: np.ndarray, a: int, level: int) -> tuple:
        """``G[a, a]`` with gradient ``(G E_k)[a,a]`` and curvature ``(G E_l E_k)[a,a]``."""
        grad = np.einsum("b,kb->k", G[a], self.E[:, :, a]) if level >= 1 else None
        curv = np.einsum("b,lkb->kl", G[a], self.EE[:, :, :, a]) if level >= 2 else None
        return float(G[a, a]), grad, curv


def _so_jac_right_inv(ad: np.ndarray) -> np.ndarray:
    """``J_r(ξ)⁻¹ = ad/(1 - e^{-ad})`` for a skew ``ad = ad_ξ`` (SO(n) basis), by ``eigh`` of the
    Hermitian ``i·ad``: eigenvalues ``x = -iw``, ``x/(1 - e^{-x}) → 1`` at ``x = 0``."""
    w, V = np.linalg.eigh(1j * ad)
    x = -1j * w
    small = np.abs(w) < 1e-8
    f = np.where(small, 1.0 + x / 2, x / np.where(small, 1.0, 1.0 - np.exp(-x)))
    return ((V * f) @ V.conj().T).real


class SOLogProblem(_SeparableLieNLP):
    """Problem (10) on SO(n)^k; see the module docstring."""

    def __init__(
        self,
        Gd: np.ndarray,
        objective: str = "squared",
        constants: str = "rendered",
        n: int = 7,
        k: int = 2,
        bounds: tuple[float, float] | None = None,
    ) -> None:
        """``bounds`` overrides ``(c₁, c₂)`` (e.g. an infeasible ``c₁ < -1`` for tests)."""
        if objective not in OBJECTIVES:
            raise InputError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
        if constants not in CONSTANTS["so"]:
            raise InputError(f"constants must be 'rendered' or 'alt-text', got {constants!r}")
        super().__init__(SO(n), k, 2)
        self.Gd = self.group.check(Gd)
        self.objective_kind, self.constants = objective, constants
        self.c = np.array(CONSTANTS["so"][constants] if bounds is None else bounds, dtype=float)

    def _element(self, G: np.ndarray, level: int) -> Terms:
        xi = self.group.log(self.Gd.T @ G)
        # ‖ξ^‖²_F = 2‖ξ‖² in the basis E_ij; the gradient field along G exp(ζ^) is ∝ ξ
        # (J_r(ξ)⁻ᵀ ξ = ξ on SO(n)) and ∂ξ/∂ζ = J_r(ξ)⁻¹.
        Jinv = _so_jac_right_inv(self.group.ad(xi)) if level >= 2 else None
        r = float(np.linalg.norm(xi))
        if self.objective_kind == "squared":
            f, grad, curv = 0.5 * r * r, xi, Jinv
        else:
            w = 0.5 * np.sqrt(2.0)
            u = xi / r if r > 1e-300 else np.zeros(self.d)
            f, grad = w * r, w * u
            if level >= 2:
                curv = np.zeros((self.d, self.d))
                if r > 1e-300:
                    curv = w * (np.eye(self.d) - np.outer(u, u)) / r @ Jinv
        parts = [self._linear_entry(G, a, level) for a in (0, 1)]
        g = np.array([p[0] for p in parts]) - self.c
        return Terms(
            f,
            g,
            grad if level >= 1 else None,
            np.stack([p[1] for p in parts]) if level >= 1 else None,
            curv if level >= 2 else None,
            np.stack([p[2] for p in parts]) if level >= 2 else None,
        )

    def optimum(self) -> float | None:
        """The optimal value where it is known: 0 at ``G_i = G_d`` when ``G_d`` is feasible."""
        feasible = self.Gd[0, 0] <= self.c[0] and self.Gd[1, 1] <= self.c[1]
        return 0.0 if feasible else None


class SLTraceProblem(_SeparableLieNLP):
    """Problem (11) on SL(n)^k; see the module docstring."""

    def __init__(self, Gd: np.ndarray, constants: str = "rendered", n: int = 7, k: int = 2) -> None:
        if constants not in CONSTANTS["sl"]:
            raise InputError(f"constants must be 'rendered' or 'alt-text', got {constants!r}")
        super().__init__(SL(n), k, 1)
        self.Gd = self.group.check(Gd)
        self.A = np.linalg.inv(self.Gd)
        self.constants = constants
        self.c = CONSTANTS["sl"][constants][0]

    def _element(self, G: np.ndarray, level: int) -> Terms:
        P = self.A @ G
        t = float(np.trace(P))
        f, g = 0.5 * t * t, np.array([self.c - t * t])
        if level == 0:
            return Terms(f, g)
        gt = np.einsum("ab,kba->k", P, self.E)
        if level == 1:
            return Terms(f, g, t * gt, (-2.0 * t * gt)[None])
        Ht = np.einsum("ab,lkba->kl", P, self.EE)
        curv = np.outer(gt, gt) + t * Ht
        return Terms(f, g, t * gt, (-2.0 * t * gt)[None], curv, (-2.0 * curv)[None])

    def optimum(self) -> float:
        """Every minimiser has ``t_i² = c``: the optimal value is ``k c / 2``."""
        return 0.5 * self.k * self.c


def make_problem(
    instance: LieIPMInstance, objective: str = "squared", constants: str = "rendered"
) -> SOLogProblem | SLTraceProblem:
    """The problem of an instance (``objective`` only applies to (10))."""
    if instance.problem == "so":
        return SOLogProblem(instance.Gd, objective, constants, n=instance.Gd.shape[0])
    return SLTraceProblem(instance.Gd, constants, n=instance.Gd.shape[0])
