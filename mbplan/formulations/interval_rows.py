"""Rows with their own derivatives in ``q`` placed in the generalized NLP: at the knots (coal
distances) and between the knots (obstacle residuals with ``between_knots``).

Eq. (61) moves the arm over interval ``k`` from ``(q_k, v_k)`` with the constant acceleration
``a_k = (v_{k+1} - v_k)/Δt`` of its dynamics row; its explicit-Euler kinematics keeps only the
first-order term, ``q_{k+1} = q_k + Δt v_k``, so the motion does not end at the next knot. The
configuration at the fraction ``s ∈ [0, 1]`` of the interval is::

    q_k(s) = q_k + sΔt v_k + ½s²Δt (v_{k+1} - v_k),

the verifier's replay to second order. Obstacle rows between knots are the secant of the row
through two configurations of the interval, ``s₁,₃ = ½ ∓ δ``
(:data:`~mbplan.transcription.intervals.SECANT_HALF_WIDTH`), evaluated
at both ends ``σ = 0, 1``, and the row at ``s = ½``:
``ℓ_σ = Σ_j w_σj r(q_k(s_j))``. Where the row is concave along the interval (a distance to a
convex obstacle along a straight motion), its secant lies above it outside ``[s₁, s₃]``, so
``ℓ_0, ℓ_1 ≤ 0`` keep it ``≤ 0`` there, up to the motion's end
``q_k + ½Δt (v_k + v_{k+1})``, which the knot ``q_{k+1}`` does not pin (it lies ``½Δt²‖a_k‖``
away). Each row reads knots ``k`` and ``k+1`` only, and the configurations are linear in the
variables, so the derivatives are those of the residual at ``q_k(s)`` times the coefficients:
``∂r/∂x_t = c_t ∂r/∂q``, ``∂²(μᵀr)/∂x_t∂x_u = c_t c_u ∇²_q(μᵀr)``, and the secant's are their
weighted sums.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mbplan.ocp.problem import Item
from mbplan.transcription.intervals import INTERVAL_ROWS, secant_weights


def secant() -> tuple[np.ndarray, np.ndarray]:
    """The samples ``s_j (3,)`` of every interval's rows and their weights ``w (3, 3)``
    ``[row, sample]`` (:func:`~mbplan.transcription.intervals.secant_weights` centred at ``½``)."""
    samples, weights = secant_weights(np.array([0.5]))
    return samples[0], weights[0]


def _gather(arrays: list[np.ndarray], masks: list[np.ndarray]) -> np.ndarray:
    """The entries of each array (broadcast to its mask) where its mask holds, concatenated."""
    pieces = [np.broadcast_to(a, m.shape)[m] for a, m in zip(arrays, masks, strict=True)]
    return np.concatenate(pieces)


def _configurations(terms: list, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``Σ_t c_t X_t[k_t]`` ``(K, nv)`` of ``terms`` (:class:`ConfigurationRows`)."""
    X = {"q": q, "v": v}
    return sum(c[:, None] * X[b][k] for b, k, c in terms)


class ConfigurationRows:
    """The rows ``form`` (own derivatives in ``q``, ``P`` per site) at ``K`` site configurations
    ``Q_i = Σ_t c_ti X_t[k_ti]``, linear in knot variables: ``terms`` lists ``(block, knots
    (K,), coefficients (K,))`` with block ``"q"`` or ``"v"``. ``nlp`` gives the columns of the
    knots' variables in ``z`` (knot 0 is data: no column). Rows ``row0 + i·P + p``; the
    Hessian's pattern is that of the sites ``hessian_sites`` (all by default)."""

    def __init__(
        self,
        nlp: Any,
        item: Item,
        form: Any,
        terms: list,
        row0: int,
        hessian_sites: slice = slice(None),
    ):
        self.item, self.form, self.row0 = item, form, row0
        self.terms = [(b, np.asarray(k, np.int64), np.asarray(c, float)) for b, k, c in terms]
        self.K, self.P = len(self.terms[0][1]), form.size
        self.size = self.K * self.P
        index = {"q": nlp.iq, "v": nlp.iv}
        cols = [np.where(k[:, None] > 0, index[b](k), -1) for b, k, _ in self.terms]
        support = form.jacobian_support()[None]  # (1, P, nv)
        self._jac = [support & (c[:, None, :] >= 0) for c in cols]
        rows = self.row0 + np.arange(self.size).reshape(self.K, self.P, 1)
        self.jac_rows = _gather([rows] * len(cols), self._jac)
        self.jac_cols = _gather([c[:, None, :] for c in cols], self._jac)
        n = len(cols)
        self._pairs = [(t, u) for t in range(n) for u in range(n)]
        cols = [c[hessian_sites] for c in cols]
        blocks = [(cols[t][:, :, None], cols[u][:, None, :]) for t, u in self._pairs]
        self._hess = [(r >= 0) & (c >= 0) for r, c in blocks]
        self.hess_rows = _gather([r for r, _ in blocks], self._hess)
        self.hess_cols = _gather([c for _, c in blocks], self._hess)

    def configurations(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``Q (K, nv)`` of the trajectory ``q, v (N+1, nv)``."""
        return _configurations(self.terms, q, v)

    def values(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return self.form.values(self.configurations(q, v)).ravel()

    def jacobian_values(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Values in the order of ``jac_rows, jac_cols``."""
        G = self.form.jacobian(self.configurations(q, v))  # (K, P, nv)
        return _gather([c[:, None, None] * G for _, _, c in self.terms], self._jac)

    def hessian_values(self, q: np.ndarray, v: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """Values of ``∇²(μᵀr)`` (``μ``: this block's multipliers in ``lam``) in the order of
        ``hess_rows, hess_cols``."""
        mu = lam[self.row0 : self.row0 + self.size].reshape(self.K, self.P)
        H = self.form.hessian(self.configurations(q, v), mu)  # (K, nv, nv)
        c = [coefficients for _, _, coefficients in self.terms]
        return _gather([(c[t] * c[u])[:, None, None] * H for t, u in self._pairs], self._hess)


def knot_rows(nlp: Any, item: Item, form: Any, row0: int) -> ConfigurationRows:
    """``form`` at the item's knots ``q_k``."""
    return ConfigurationRows(nlp, item, form, [("q", item.knots, np.ones(len(item.knots)))], row0)


def _interval_terms(k: np.ndarray, s: np.ndarray, dt: float) -> list:
    """The terms of ``q_k(s)`` (module docstring) of intervals ``k`` at fractions ``s``."""
    return [
        ("q", k, np.ones(k.size)),
        ("v", k, (s - 0.5 * s * s) * dt),
        ("v", k + 1, 0.5 * s * s * dt),
    ]


class SecantRows(ConfigurationRows):
    """``form``'s rows ``ℓ_σ`` (module docstring) of the intervals ``k = knot - 1`` ending at
    the item's knots, rows ``row0 + (Ri + σ)·P + p`` for interval ``i`` (``R``:
    :data:`~mbplan.transcription.intervals.INTERVAL_ROWS`). The Jacobian's sparsity is that of
    :class:`ConfigurationRows` over the same knots; the Hessian of an interval's rows has the
    pattern of one site."""

    def __init__(self, nlp: Any, item: Item, form: Any, row0: int):
        k = np.repeat(np.asarray(item.knots) - 1, INTERVAL_ROWS)
        terms = _interval_terms(k, np.zeros(k.size), nlp.dt)
        super().__init__(nlp, item, form, terms, row0, slice(None, None, INTERVAL_ROWS))
        self.samples, self.weights = secant()
        intervals = k[::INTERVAL_ROWS]
        self._sample_terms = [
            _interval_terms(intervals, np.full(intervals.size, t), nlp.dt) for t in self.samples
        ]

    def sample_configurations(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``q_k(s_j)`` ``(S, K, nv)`` of the samples ``s_j`` of every interval."""
        return np.stack([_configurations(terms, q, v) for terms in self._sample_terms])

    def values(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        r = np.stack([self.form.values(Q) for Q in self.sample_configurations(q, v)])  # (S, K, P)
        return np.einsum("sj,jkp->ksp", self.weights, r).ravel()

    def jacobian_values(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        G = [self.form.jacobian(Q) for Q in self.sample_configurations(q, v)]  # (K, P, nv)
        pieces = []
        for t in range(len(self.terms)):
            c = [terms[t][2] for terms in self._sample_terms]
            Gt = sum(
                self.weights[None, :, j, None, None] * (c[j][:, None, None] * G[j])[:, None]
                for j in range(len(self.samples))
            )  # (K, σ, P, nv)
            pieces.append(Gt.reshape(-1, *Gt.shape[2:]))
        return _gather(pieces, self._jac)

    def hessian_values(self, q: np.ndarray, v: np.ndarray, lam: np.ndarray) -> np.ndarray:
        mu = lam[self.row0 : self.row0 + self.size].reshape(-1, INTERVAL_ROWS, self.P)
        H = [
            self.form.hessian(Q, np.einsum("ksp,s->kp", mu, self.weights[:, j]))
            for j, Q in enumerate(self.sample_configurations(q, v))
        ]  # (K, nv, nv) each
        blocks = []
        for t, u in self._pairs:
            c = [(terms[t][2] * terms[u][2])[:, None, None] for terms in self._sample_terms]
            blocks.append(sum(cj * Hj for cj, Hj in zip(c, H, strict=True)))
        return _gather(blocks, self._hess)


def interval_rows(nlp: Any, item: Item, form: Any, row0: int) -> SecantRows:
    """``form``'s secant rows between the knots (:class:`SecantRows`)."""
    return SecantRows(nlp, item, form, row0)
