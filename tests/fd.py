"""Finite-difference checks shared by the tests: the generalized (joint-space) NLP and the
Riemannian trajectory problems."""

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


def check_problem_derivatives(
    prob, x, rng: np.random.Generator, *, ineq_hessian: bool = True
) -> None:
    """Directional FD checks of a TrajectoryProblem's ∇L, J_h, J_g and Hess L along the
    retraction ``X exp(t d)`` at the point ``x`` (random multipliers and directions;
    ``ineq_hessian=False``: the inequalities' multipliers zero, for rows whose Hessian is not
    exact, as coal distances' fixed-witness-point one)."""
    y = rng.standard_normal(prob.n_eq)
    z = rng.standard_normal(prob.n_ineq) if ineq_hessian else np.zeros(prob.n_ineq)
    ev = prob.evaluate(x, 1.0, y, z)
    H = ev.hessian_lower
    H = (H + H.T).toarray() - np.diag(H.diagonal())

    def lag(pt):
        f, h, g = prob.values(pt)
        return f + y @ h + z @ g

    for _ in range(3):
        d = rng.standard_normal(prob.n)
        h = 1e-6
        xp, xm = prob.retract(x, h * d), prob.retract(x, -h * d)
        _, hp, gp = prob.values(xp)
        _, hm, gm = prob.values(xm)
        grad = ev.gradient + ev.eq_jacobian.T @ y + ev.ineq_jacobian.T @ z
        fd = (lag(xp) - lag(xm)) / (2 * h)
        assert abs(fd - grad @ d) <= 1e-6 * max(1.0, abs(fd))
        np.testing.assert_allclose(
            (hp - hm) / (2 * h), ev.eq_jacobian @ d, atol=1e-6 * max(1, np.abs(hp).max())
        )
        if prob.n_ineq:
            np.testing.assert_allclose(
                (gp - gm) / (2 * h), ev.ineq_jacobian @ d, atol=1e-6 * max(1, np.abs(gp).max())
            )
        h = 1e-4
        fd2 = (lag(prob.retract(x, h * d)) - 2 * lag(x) + lag(prob.retract(x, -h * d))) / h**2
        assert abs(fd2 - d @ H @ d) <= 1e-5 * max(1.0, abs(fd2))
