"""Finite-difference diagnostics of engine derivatives along the exact retraction ``X exp(tξ)``.

Like pymanopt's gradient check: the Jacobian is compared with central differences of
``r(X exp(h e_j))`` and the Hessian of ``λᵀr`` with the four-point mixed differences of the
pullback ``ξ ↦ λᵀ r(X exp(ξ))``, all perturbations evaluated in one vectorised call.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbplan.engine.site_function import SiteFunction


@dataclass(frozen=True)
class DerivativeCheck:
    """Relative errors ``‖A_fd - A‖ / max(‖A‖, 1)`` (Frobenius, worst knot)."""

    jacobian_error: float
    hessian_error: float

    def ok(self, tol: float = 1e-6) -> bool:
        return self.jacobian_error <= tol and self.hessian_error <= tol


def _perturbed(f: SiteFunction, variables: Mapping[str, Any], xis: np.ndarray) -> dict:
    """Variables of one knot moved along each row of ``xis`` (P, n), as a batch of P knots."""
    tiled = {
        s.name: np.broadcast_to(np.asarray(variables[s.name], dtype=float), (len(xis), *s.shape))
        for s in f.variables
    }
    return f.retract(tiled, xis)


def check_derivatives(
    f: SiteFunction,
    variables: Mapping[str, Any],
    parameters: Mapping[str, Any] | None = None,
    multipliers: np.ndarray | None = None,
    *,
    step_jacobian: float = 1e-6,
    step_hessian: float = 1e-4,
    rng: np.random.Generator | None = None,
) -> DerivativeCheck:
    """Check ``f``'s Jacobian and Hessian at one knot (unbatched ``variables``)."""
    rng = rng or np.random.default_rng(0)
    lam = rng.standard_normal(f.m) if multipliers is None else np.asarray(multipliers, dtype=float)
    _, jnz, hnz = f.hessian(variables, parameters, lam)
    J = f.dense_jacobian(jnz)[0]
    H = f.dense_hessian(hnz)[0]
    n = f.n
    eye = np.eye(n)

    h = step_jacobian
    rows = np.concatenate([h * eye, -h * eye])
    r = f.value(_perturbed(f, variables, rows), parameters)
    J_fd = (r[:n] - r[n:]).T / (2 * h)

    h = step_hessian
    i, j = np.triu_indices(n)
    signs = [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    rows = np.concatenate([h * (a * eye[i] + b * eye[j]) for a, b in signs])
    g = f.value(_perturbed(f, variables, rows), parameters) @ lam
    g = g.reshape(4, len(i))
    upper = (g[0] - g[1] - g[2] + g[3]) / (4 * h * h)
    H_fd = np.zeros((n, n))
    H_fd[i, j] = upper
    H_fd[j, i] = upper

    def rel(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1.0))

    return DerivativeCheck(rel(J_fd, J), rel(H_fd, H))
