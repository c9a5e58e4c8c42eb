"""Finite-difference checks shared by the tests of the generalized (joint-space) NLP."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def central(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float) -> np.ndarray:
    """Central-difference Jacobian of ``fn`` at ``x`` (columns: the coordinates of ``x``)."""
    return np.column_stack([(fn(x + h * e) - fn(x - h * e)) / (2 * h) for e in np.eye(x.size)])


def check_generalized_derivatives(
    nlp, z: np.ndarray, lam: np.ndarray, *, objective_factor: float = 0.7
) -> None:
    """The constraint Jacobian, the objective gradient and the Lagrangian Hessian (upper
    triangle) of ``nlp`` at ``z`` against central differences."""
    J = nlp.jacobian(z).toarray()
    np.testing.assert_allclose(
        J, central(nlp.constraints, z, 1e-6), atol=2e-5 * max(1, np.abs(J).max())
    )
    fd_grad = central(lambda x: np.array([nlp.objective(x)]), z, 1e-6)[0]
    np.testing.assert_allclose(nlp.objective_gradient(z), fd_grad, rtol=1e-6, atol=1e-6)
    U = nlp.lagrangian_hessian(z, objective_factor, lam).toarray()
    H = U + U.T - np.diag(U.diagonal())

    def grad_lagrangian(x: np.ndarray) -> np.ndarray:
        return objective_factor * nlp.objective_gradient(x) + nlp.jacobian(x).T @ lam

    fd = central(grad_lagrangian, z, 1e-5)
    np.testing.assert_allclose(H, 0.5 * (fd + fd.T), atol=1e-4 * max(1, np.abs(H).max()))
