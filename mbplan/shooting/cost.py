"""Weighted least-squares tracking costs on a :class:`StateSpace` with Gauss–Newton Hessians.

Stage cost (thesis 2-55, no ½, time step absorbed into the weights):
``l_k = Σᵢ q_i e_i(x_k)² + Σⱼ r_j (u_k - u_ref,k)_j²`` with the left error
``e = [log(X X_ref⁻¹) per group factor; x - x_ref per vector factor]``; terminal cost with its own
weights and no input term. Derivatives along ``x ⊕ δx``: ``l_x = 2 Jᵀ Q e``,
``l_xx ≈ 2 Jᵀ Q J`` (the second derivative of ``e`` is dropped, §3-1), ``l_u = 2R(u - u_ref)``,
``l_uu = 2R``, ``l_ux = 0``; ``hessian="exact"`` keeps the second derivative of ``e`` (the
Hessian of the pullback along ``X(I + δ^ + δ^²/2)``).
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.lie import RnGroup
from mbplan.shooting.compiled import BufferedFunction
from mbplan.shooting.space import StateSpace


def left_error(space: StateSpace, q: cs.SX, ref: cs.SX) -> cs.SX:
    """``[log(X X_ref⁻¹) per group factor; x - x_ref per vector factor]`` (2-55)."""
    parts = []
    for g, X, Y in zip(space.groups, space.sym_unpack(q), space.sym_unpack(ref), strict=True):
        if isinstance(g, RnGroup):
            parts.append(X - Y)
        else:
            parts.append(g.log(g.compose(X, g.inverse(Y))))
    return cs.vertcat(*parts)


def tracking_value(space: StateSpace, q, u, ref, uref, wq, wu) -> cs.SX:
    """The stage cost ``Σ q_i e_i² + Σ r_j (u - u_ref)_j²`` as a CasADi expression."""
    e = left_error(space, q, ref)
    eu = u - uref
    return cs.dot(wq * e, e) + cs.dot(wu * eu, eu)


class TrackingCost:
    """Compiled, knot-vectorised values and Gauss–Newton derivatives of the tracking cost."""

    def __init__(
        self, space: StateSpace, nu: int, *, hessian: str = "gauss-newton", jit: bool = True
    ) -> None:
        if hessian not in ("gauss-newton", "exact"):
            raise InputError(f"hessian must be 'gauss-newton' or 'exact', got {hessian!r}")
        self.hessian = hessian
        self.space = space
        self.nu = nu
        self.jit = jit
        nq, nx = space.nq, space.nx
        q, ref = cs.SX.sym("q", nq), cs.SX.sym("ref", nq)
        u, uref = cs.SX.sym("u", nu), cs.SX.sym("uref", nu)
        wq, wu = cs.SX.sym("wq", nx), cs.SX.sym("wu", nu)
        dx = cs.SX.sym("dx", nx)
        e = left_error(space, q, ref)
        e_pert = left_error(space, space.sym_retract(q, dx, second_order=True), ref)
        J = cs.jacobian(e_pert, dx)
        if hessian == "exact":
            lxx, _ = cs.hessian(cs.dot(wq * e_pert, e_pert), dx)
        else:
            lxx = 2 * cs.mtimes(J.T, cs.mtimes(cs.diag(wq), J))
        J, lxx = cs.substitute([J, lxx], [dx], [cs.DM.zeros(nx)])
        eu = u - uref
        value = tracking_value(space, q, u, ref, uref, wq, wu)
        lx = 2 * cs.mtimes(J.T, wq * e)
        lu = 2 * wu * eu
        self._value = cs.Function("tracking_value", [q, u, ref, uref, wq, wu], [value])
        self._derivs = cs.Function(
            "tracking_derivatives",
            [q, u, ref, uref, wq, wu],
            [value, lx, cs.densify(cs.vec(lxx)), cs.densify(lu), cs.densify(cs.diag(2 * wu))],
        )
        self._cache: dict[tuple[str, int], BufferedFunction] = {}

    def _compiled(self, kind: str, K: int) -> BufferedFunction:
        fn = self._cache.get((kind, K))
        if fn is None:
            base = self._value if kind == "value" else self._derivs
            fn = BufferedFunction(base.map(K, "serial") if K > 1 else base, jit=self.jit)
            self._cache[(kind, K)] = fn
        return fn

    def values(self, X, U, Xref, Uref, wq, wu) -> np.ndarray:
        """Per-knot cost ``(K,)``; all arrays have K rows (weights per knot)."""
        return self._compiled("value", len(X))(X, U, Xref, Uref, wq, wu)[0][:, 0]

    def derivatives(self, X, U, Xref, Uref, wq, wu):
        """``(l, l_x, l_xx, l_u, l_uu)`` per knot."""
        K = len(X)
        nx, nu = self.space.nx, self.nu
        l, lx, lxx, lu, luu = self._compiled("derivs", K)(X, U, Xref, Uref, wq, wu)
        return l[:, 0], lx, lxx.reshape(K, nx, nx), lu, luu.reshape(K, nu, nu)
