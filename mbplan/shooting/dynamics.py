"""Discrete dynamics ``x_{k+1} = F(x_k, u_k)`` on a :class:`StateSpace`, compiled for shooting.

From one symbolic step function this builds, vectorised over the knots:

* the linearisation ``δx_{k+1} ≈ A_k δx_k + B_k δu_k + d_k`` in the tangent spaces of
  ``F(x̄_k, ū_k)`` (thesis 3-20/21, exact, by AD along ``x ⊕ δx``) and the defects
  ``d_k = F(x̄_k, ū_k) ⊖ x̄_{k+1}`` (3-57);
* the gap-closing nonlinear rollout (3-73), one compiled ``mapaccum`` over the horizon:
  ``u_k = ū_k + α k_k + K_k (x_k ⊖ x̄_k)``,
  ``x_{k+1} = (x̄_{k+1} ⊕ α d_k) ⊕ (F(x_k, u_k) ⊖ F(x̄_k, ū_k))``.
  With zero defects (a single-shooting nominal) this is ``x_{k+1} = F(x_k, u_k)``, so one rollout
  serves SS- and MS-iLQR. Group factors are updated by exponentials, never by products of
  drifting matrices, so the iterates stay on the group to rounding.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as cs
import numpy as np

from mbplan.shooting.compiled import BufferedFunction
from mbplan.shooting.space import StateSpace

StepFunction = Callable[[list[cs.SX], cs.SX], list[cs.SX]]


class DiscreteDynamics:
    """``step(parts, u) -> parts⁺`` (CasADi SX in, SX out) with ``nu`` inputs."""

    def __init__(
        self, name: str, space: StateSpace, nu: int, step: StepFunction, *, jit: bool = True
    ) -> None:
        self.name = name
        self.space = space
        self.nu = nu
        self.jit = jit
        nq, nx = space.nq, space.nx
        q = cs.SX.sym("q", nq)
        u = cs.SX.sym("u", nu)
        self._step_sx = space.sym_pack(step(space.sym_unpack(q), u))
        self.step_function = cs.Function(f"{name}_step", [q, u], [self._step_sx])
        self._step = BufferedFunction(self.step_function, jit=False)
        self._cache: dict[tuple[str, int], BufferedFunction] = {}

        # Linearisation at (q, u) against the next node qn.
        dx = cs.SX.sym("dx", nx)
        du = cs.SX.sym("du", nu)
        qn = cs.SX.sym("qn", nq)
        f_bar = self.step_function(q, u)
        f_pert = self.step_function(space.sym_retract(q, dx, second_order=True), u + du)
        tangent = space.sym_local_linear(f_bar, f_pert)
        AB = cs.jacobian(tangent, cs.vertcat(dx, du))
        AB = cs.substitute([AB], [dx, du], [cs.DM.zeros(nx), cs.DM.zeros(nu)])[0]
        defect = space.sym_local(qn, f_bar)
        # Second derivatives (DDP): the tensor ∂²(F(x̄ ⊕ δx, ū + δu) ⊖ F(x̄, ū))/∂z², z = (δx, δu).
        z = cs.vertcat(dx, du)
        exact = space.sym_local(f_bar, f_pert)
        tensor = cs.jacobian(cs.jacobian(exact, z), z)  # rows: (output i, column j) column-major
        tensor = cs.substitute([tensor], [dx, du], [cs.DM.zeros(nx), cs.DM.zeros(nu)])[0]
        nz = nx + nu
        # Reorder to C-order (i, j, l): row of ``tensor`` is i + nx*j, column l.
        perm = [i + nx * j for i in range(nx) for j in range(nz)]
        self._hessian = cs.Function(
            f"{name}_dynamics_hessian", [q, u], [cs.densify(cs.vec(tensor[perm, :].T))]
        )
        self._linearize = cs.Function(
            f"{name}_linearize",
            [q, u, qn],
            [defect, cs.densify(cs.vec(AB[:, :nx].T)), cs.densify(cs.vec(AB[:, nx:].T))],
        )

        # One step of the gap-closing rollout; accumulated state first.
        xk = cs.SX.sym("xk", nq)
        qb, qbn = cs.SX.sym("qb", nq), cs.SX.sym("qbn", nq)
        ub = cs.SX.sym("ub", nu)
        Kv = cs.SX.sym("K", nu * nx)
        kv = cs.SX.sym("k", nu)
        d = cs.SX.sym("d", nx)
        alpha = cs.SX.sym("alpha")
        K = cs.reshape(Kv, nx, nu).T  # Kv holds K row-major
        uk = ub + alpha * kv + cs.mtimes(K, space.sym_local(qb, xk))
        f_new = self.step_function(xk, uk)
        f_old = self.step_function(qb, ub)
        shifted = space.sym_retract(qbn, alpha * d)
        x_next = space.sym_retract(shifted, space.sym_local(f_old, f_new))
        gap = space.sym_local(x_next, f_new)
        self._rollout_step = cs.Function(
            f"{name}_rollout_step", [xk, qb, qbn, ub, Kv, kv, d, alpha], [x_next, uk, gap]
        )

    def __repr__(self) -> str:
        return f"DiscreteDynamics({self.name!r}, {self.space.name}, nu={self.nu})"

    def _compiled(self, kind: str, N: int) -> BufferedFunction:
        key = (kind, N)
        fn = self._cache.get(key)
        if fn is None:
            if kind == "linearize":
                mapped = self._linearize.map(N, "serial")
            elif kind == "hessian":
                mapped = self._hessian.map(N, "serial")
            elif kind == "simulate":
                mapped = self.step_function.mapaccum(f"{self.name}_simulate", N, 1)
            else:
                mapped = self._rollout_step.mapaccum(f"{self.name}_rollout", N, 1)
            fn = BufferedFunction(mapped, jit=self.jit)
            self._cache[key] = fn
        return fn

    def step(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One step from one state (flat ``(nq,)``) and input ``(nu,)``."""
        return self._step(np.asarray(q, dtype=float), np.asarray(u, dtype=float))[0][0]

    def simulate(self, q0: np.ndarray, U: np.ndarray) -> np.ndarray:
        """Open-loop states ``(N+1, nq)`` under inputs ``U (N, nu)``."""
        q0 = np.asarray(q0, dtype=float)
        U = np.asarray(U, dtype=float)
        Xn = self._compiled("simulate", U.shape[0])(q0, U)[0]
        return np.vstack([q0[None], Xn])

    def linearize(self, X: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Defects ``(N, nx)``, ``A (N, nx, nx)`` and ``B (N, nx, nu)`` along ``(X, U)``."""
        N = U.shape[0]
        nx, nu = self.space.nx, self.nu
        d, A, B = self._compiled("linearize", N)(X[:-1], U, X[1:])
        return d, A.reshape(N, nx, nx), B.reshape(N, nx, nu)

    def second_derivatives(self, X: np.ndarray, U: np.ndarray) -> np.ndarray:
        """``(N, nx, nz, nz)``: Hessians of each tangent component of ``F`` in ``z = (δx, δu)``."""
        N = U.shape[0]
        nx, nz = self.space.nx, self.space.nx + self.nu
        return self._compiled("hessian", N)(X[:-1], U)[0].reshape(N, nx, nz, nz)

    def rollout(
        self,
        Xbar: np.ndarray,
        Ubar: np.ndarray,
        K: np.ndarray,
        k: np.ndarray,
        defects: np.ndarray,
        alpha: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Gap-closing rollout from ``Xbar[0]``: new states, inputs and remaining defects."""
        N = Ubar.shape[0]
        fn = self._compiled("rollout", N)
        Xn, Un, gaps = fn(
            Xbar[0],
            Xbar[:-1],
            Xbar[1:],
            Ubar,
            K.reshape(N, -1),
            k,
            defects,
            np.full(N, float(alpha)),
        )
        return np.vstack([Xbar[:1], Xn]), Un, gaps
