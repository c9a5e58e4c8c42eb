"""Reference problems for the RIPM: HS071 (Hock-Schittkowski no. 71, IPOPT's tutorial problem),
two infeasible problems (restoration and infeasibility detection) and a block-banded, vectorised
optimal-control NLP whose KKT matrix has the structure of a trajectory optimization (used by the
tests)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mbplan.solvers.nlp import EuclideanNLP, ManifoldNLP

HS071_X0 = np.array([1.0, 5.0, 5.0, 1.0])
INFEASIBLE_X0 = np.array([1.0, 3.0])


def infeasible_equality() -> EuclideanNLP:
    """``min x₁² + (x₂ - 1)²`` s.t. ``x₁² + 1 = 0``: no feasible point; the infeasibility
    ``x₁² + 1`` is least at ``x₁ = 0``. Start at :data:`INFEASIBLE_X0`."""
    return EuclideanNLP(
        2,
        lambda x: x[0] ** 2 + (x[1] - 1) ** 2,
        lambda x: np.array([2 * x[0], 2 * (x[1] - 1)]),
        lambda x, s, y, z: np.diag([2 * s + 2 * y[0], 2 * s]),
        eq=lambda x: np.array([x[0] ** 2 + 1]),
        eq_jacobian=lambda x: np.array([[2 * x[0], 0.0]]),
        n_eq=1,
    )


def infeasible_inequalities() -> EuclideanNLP:
    """``min x₁ + x₂`` s.t. ``x₁² + 1 ≤ 0``, ``x₂ ≥ 0``: no feasible point. Start at
    :data:`INFEASIBLE_X0`."""
    return EuclideanNLP(
        2,
        lambda x: x[0] + x[1],
        lambda x: np.ones(2),
        lambda x, s, y, z: np.diag([2 * z[0], 0.0]),
        ineq=lambda x: np.array([x[0] ** 2 + 1, -x[1]]),
        ineq_jacobian=lambda x: np.array([[2 * x[0], 0.0], [0.0, -1.0]]),
        n_ineq=2,
    )


def hs071() -> EuclideanNLP:
    """``min x₁x₄(x₁+x₂+x₃) + x₃`` s.t. ``x₁x₂x₃x₄ ≥ 25``, ``Σxᵢ² = 40``, ``1 ≤ xᵢ ≤ 5``.

    Inequalities (``g ≤ 0``): ``25 - Πx``, ``1 - x``, ``x - 5``. Start at :data:`HS071_X0`."""

    def objective(x: np.ndarray) -> float:
        return x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2]

    def gradient(x: np.ndarray) -> np.ndarray:
        return np.array(
            [
                x[3] * (2 * x[0] + x[1] + x[2]),
                x[0] * x[3],
                x[0] * x[3] + 1.0,
                x[0] * (x[0] + x[1] + x[2]),
            ]
        )

    def hessian(x: np.ndarray, sigma: float, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        hf = np.zeros((4, 4))
        hf[0, 0] = 2 * x[3]
        hf[1, 0] = hf[2, 0] = x[3]
        hf[3, 0] = 2 * x[0] + x[1] + x[2]
        hf[3, 1] = hf[3, 2] = x[0]
        hp = np.zeros((4, 4))  # Hessian of Πx, lower triangle
        for i in range(4):
            for j in range(i):
                hp[i, j] = np.prod(np.delete(x, [i, j]))
        return sigma * hf + 2 * y[0] * np.eye(4) - z[0] * hp

    def ineq(x: np.ndarray) -> np.ndarray:
        return np.concatenate([[25.0 - np.prod(x)], 1.0 - x, x - 5.0])

    def ineq_jacobian(x: np.ndarray) -> np.ndarray:
        grad_prod = np.array([np.prod(np.delete(x, i)) for i in range(4)])
        return np.vstack([-grad_prod, -np.eye(4), np.eye(4)])

    return EuclideanNLP(
        4,
        objective,
        gradient,
        hessian,
        eq=lambda x: np.array([x @ x - 40.0]),
        eq_jacobian=lambda x: 2 * x[None, :],
        n_eq=1,
        ineq=ineq,
        ineq_jacobian=ineq_jacobian,
        n_ineq=9,
    )


class BandedControlNLP(ManifoldNLP):
    """``min Σ w‖x_k‖² + r‖u_k‖² + w_N‖x_N‖²`` over ``N`` knots of ``x_{k+1} = x_k + dt(A x_k +
    B u_k + c sin x_k)``, ``x_0`` fixed, ``|u| ≤ u_max``.

    Variables ``(x_0, u_0, …, x_{N-1}, u_{N-1}, x_N)``; every function is evaluated for all
    knots at once and the Jacobian/Hessian values are scattered into fixed patterns, as a
    trajectory NLP should. The ``sin`` term makes the Lagrangian Hessian indefinite.
    """

    def __init__(
        self, nx: int = 24, nu: int = 7, horizon: int = 40, dt: float = 0.05, seed: int = 0
    ) -> None:
        rng = np.random.default_rng(seed)
        self.nx, self.nu, self.N, self.dt = nx, nu, horizon, dt
        self.A = rng.normal(size=(nx, nx)) / np.sqrt(nx)
        self.B = rng.normal(size=(nx, nu))
        self.c, self.w, self.r, self.w_final, self.u_max = 2.0, 1.0, 0.1, 10.0, 1.0
        self.x_init = rng.normal(size=nx)
        nk = nx + nu
        n = horizon * nk + nx
        self.ix = np.arange(horizon + 1)[:, None] * nk + np.arange(nx)  # (N+1, nx)
        self.iu = np.arange(horizon)[:, None] * nk + nx + np.arange(nu)  # (N, nu)
        # equality rows: x_0 - x_init (nx), dynamics (N nx)
        n_eq = (horizon + 1) * nx
        k = np.arange(horizon)
        dyn_rows = nx + k[:, None, None] * nx + np.arange(nx)[None, :, None]  # (N, nx, 1)
        cols_x = self.ix[:-1][:, None, :]
        cols_u = self.iu[:, None, :]
        cols_next = self.ix[1:][:, :, None]
        rows = [
            np.arange(nx),
            np.broadcast_to(dyn_rows, (horizon, nx, nx)).ravel(),
            np.broadcast_to(dyn_rows, (horizon, nx, nu)).ravel(),
            dyn_rows.ravel(),
        ]
        cols = [
            np.arange(nx),
            np.broadcast_to(cols_x, (horizon, nx, nx)).ravel(),
            np.broadcast_to(cols_u, (horizon, nx, nu)).ravel(),
            cols_next.ravel(),
        ]
        self._jac_eq = _Pattern(np.concatenate(rows), np.concatenate(cols), (n_eq, n))
        n_ineq = 2 * horizon * nu
        self._jac_in = _Pattern(np.arange(n_ineq), np.tile(self.iu.ravel(), 2), (n_ineq, n))
        self._hess = _Pattern(np.arange(n), np.arange(n), (n, n))
        self._sizes = (n, n_eq, n_ineq)

    @property
    def n(self) -> int:
        return self._sizes[0]

    @property
    def n_eq(self) -> int:
        return self._sizes[1]

    @property
    def n_ineq(self) -> int:
        return self._sizes[2]

    def retract(self, z: np.ndarray, dz: np.ndarray) -> np.ndarray:
        return z + dz

    def initial_guess(self) -> np.ndarray:
        """States decaying linearly from ``x_init`` to 0, zero controls."""
        z = np.zeros(self.n)
        z[self.ix] = np.linspace(1.0, 0.0, self.N + 1)[:, None] * self.x_init
        return z

    def objective(self, z: np.ndarray) -> float:
        x, u = z[self.ix], z[self.iu]
        return float(
            self.w * np.sum(x[:-1] ** 2) + self.w_final * np.sum(x[-1] ** 2) + self.r * np.sum(u**2)
        )

    def gradient(self, z: np.ndarray) -> np.ndarray:
        g = np.zeros(self.n)
        g[self.ix[:-1]] = 2 * self.w * z[self.ix[:-1]]
        g[self.ix[-1]] = 2 * self.w_final * z[self.ix[-1]]
        g[self.iu] = 2 * self.r * z[self.iu]
        return g

    def eq(self, z: np.ndarray) -> np.ndarray:
        x, u = z[self.ix], z[self.iu]
        f = x[:-1] + self.dt * (x[:-1] @ self.A.T + u @ self.B.T + self.c * np.sin(x[:-1]))
        return np.concatenate([x[0] - self.x_init, (x[1:] - f).ravel()])

    def eq_jacobian(self, z: np.ndarray) -> sp.csr_matrix:
        x = z[self.ix[:-1]]
        nx, N = self.nx, self.N
        dfdx = np.eye(nx) + self.dt * (self.A + self.c * np.cos(x)[:, :, None] * np.eye(nx))
        values = [
            np.ones(nx),
            -dfdx.ravel(),
            np.broadcast_to(-self.dt * self.B, (N, nx, self.nu)).ravel(),
            np.ones(N * nx),
        ]
        return self._jac_eq.assemble(np.concatenate(values))

    def ineq(self, z: np.ndarray) -> np.ndarray:
        u = z[self.iu].ravel()
        return np.concatenate([u - self.u_max, -u - self.u_max])

    def ineq_jacobian(self, z: np.ndarray) -> sp.csr_matrix:
        m = self.N * self.nu
        return self._jac_in.assemble(np.concatenate([np.ones(m), -np.ones(m)]))

    def lagrangian_hessian(
        self, z: np.ndarray, obj_factor: float, y: np.ndarray, mult_in: np.ndarray
    ) -> sp.csr_matrix:
        d = np.zeros(self.n)
        d[self.ix[:-1]] = 2 * obj_factor * self.w
        d[self.ix[-1]] = 2 * obj_factor * self.w_final
        d[self.iu] = 2 * obj_factor * self.r
        lam = y[self.nx : self.nx + self.N * self.nx].reshape(self.N, self.nx)
        d[self.ix[:-1]] += lam * self.dt * self.c * np.sin(z[self.ix[:-1]])
        return self._hess.assemble(d)


class _Pattern:
    """Values at fixed ``(rows, cols)`` (no duplicates) scattered into a canonical CSR matrix."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> None:
        order = np.lexsort((cols, rows))
        self._order = order
        self._indices = cols[order].astype(np.int32)
        counts = np.bincount(rows, minlength=shape[0])
        self._indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        self.shape = shape

    def assemble(self, values: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((values[self._order], self._indices, self._indptr), shape=self.shape)
