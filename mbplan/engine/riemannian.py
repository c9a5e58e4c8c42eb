"""Exact Riemannian derivatives of residuals of group elements, compiled and vectorised.

Given a CasADi expression ``r(X₁…Xₙ, y₁…y_m; p)`` of group elements ``X_i``, Euclidean vectors
``y_j`` and fixed parameters ``p``, :class:`RiemannianFunction` builds

* the value ``r``;
* the Riemannian Jacobian ``∂r(X·exp(ξ))/∂ξ |_{ξ=0}`` (for vectors ``y + ξ``);
* the Hessian of ``λᵀ r`` along the same curves at ``ξ = 0``.

Under a bi-invariant metric the exponential curve is a geodesic (RIPM paper Remark 1, Assumption
1), so the second-order term of ``λᵀ r(X exp(tξ))`` in ``t`` is the Riemannian Hessian (eq. 10).
Only the second-order Taylor polynomial ``X(I + ξ^ + ξ^²/2)`` of the retraction (eq. 43) enters,
so derivatives are exact and free of the removable singularities of closed-form ``exp``.

All outputs are evaluated for ``K`` knots in one call (``casadi.Function.map``). Sparsity
patterns are fixed at construction: ``jac_rows/jac_cols`` and ``hess_rows/hess_cols`` (lower
triangle) index the nonzero arrays returned per knot, so callers assemble sparse matrices by
index arithmetic with no Python loop over knots.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as cs
import numpy as np

from mbplan.engine.jit import compile_function
from mbplan.errors import InputError


@dataclass(frozen=True)
class Slot:
    """One argument of a residual: its name, shape, flat offset and (for variables) tangent slice."""

    name: str
    shape: tuple[int, ...]
    offset: int
    group: Any = None
    tangent: slice | None = None

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))


def _layout(items: Sequence[tuple[str, Any]], is_variable: bool) -> tuple[list[Slot], int, int]:
    slots, offset, tangent = [], 0, 0
    for name, spec in items:
        if is_variable:
            shape = tuple(spec.element_shape)
            tan = slice(tangent, tangent + spec.dim)
            tangent += spec.dim
            slots.append(Slot(name, shape, offset, spec, tan))
        else:
            shape = (spec,) if isinstance(spec, int) else tuple(spec)
            slots.append(Slot(name, shape, offset))
        offset += int(np.prod(shape))
    return slots, offset, tangent


def _tile(a: np.ndarray, K: int) -> np.ndarray:
    """A C-contiguous ``(K, ·)`` array, repeating a single row if needed."""
    return np.ascontiguousarray(np.broadcast_to(a, (K, a.shape[1])))


def _unpack(vec: cs.SX, slots: Sequence[Slot]) -> dict[str, cs.SX]:
    out = {}
    for s in slots:
        piece = vec[s.offset : s.offset + s.size]
        out[s.name] = cs.reshape(piece, *s.shape) if len(s.shape) == 2 else piece
    return out


class RiemannianFunction:
    """A residual of group-valued and Euclidean variables with exact Riemannian derivatives.

    Parameters
    ----------
    name:
        C identifier used for the compiled functions.
    variables:
        ``(name, group)`` pairs; ``group`` is e.g. ``SO3`` or ``R(3)`` from :mod:`mbplan.lie`.
    parameters:
        ``(name, shape)`` pairs of fixed, non-differentiated inputs (an int is a vector length).
    residual:
        Called with keyword CasADi SX arguments (matrices for matrix groups, column vectors
        otherwise) and returns the residual (any shape; flattened column-major).
    jit:
        Compile the three evaluation functions to C (cached on disk, see :mod:`mbplan.engine.jit`).
    """

    def __init__(
        self,
        name: str,
        variables: Sequence[tuple[str, Any]],
        residual: Callable[..., cs.SX],
        parameters: Sequence[tuple[str, int | tuple[int, ...]]] = (),
        *,
        jit: bool = False,
    ) -> None:
        if not name.isidentifier():
            raise InputError(f"function name {name!r} must be a valid identifier")
        self.name = name
        self.variables, self.nz, self.n = _layout(variables, is_variable=True)
        self.parameters, self.np, _ = _layout(parameters, is_variable=False)
        names = [s.name for s in (*self.variables, *self.parameters)]
        if len(set(names)) != len(names):
            raise InputError(f"{name}: duplicate argument names in {names}")
        self.jit = jit

        z = cs.SX.sym("z", self.nz)
        p = cs.SX.sym("p", self.np)
        xi = cs.SX.sym("xi", self.n)
        args = _unpack(z, self.variables) | _unpack(p, self.parameters)
        r0 = cs.vec(cs.SX(residual(**args)))
        self.m = r0.size1()
        lam = cs.SX.sym("lam", self.m)

        perturbed = dict(args)
        for s in self.variables:
            perturbed[s.name] = s.group.retract_second_order(args[s.name], xi[s.tangent])
        r_xi = cs.vec(cs.SX(residual(**perturbed)))
        jac_xi = cs.jacobian(r_xi, xi)
        hess_xi, _ = cs.hessian(cs.dot(lam, r_xi), xi)
        at_zero = cs.Function("at_zero", [z, p, lam, xi], [jac_xi, cs.tril(hess_xi)])
        jac, hess = at_zero(z, p, lam, cs.SX.zeros(self.n))
        jac, hess = cs.sparsify(jac), cs.sparsify(hess)

        self.jac_rows, self.jac_cols = (
            np.asarray(a, dtype=np.int64) for a in jac.sparsity().get_triplet()
        )
        self.hess_rows, self.hess_cols = (
            np.asarray(a, dtype=np.int64) for a in hess.sparsity().get_triplet()
        )
        jac_nz = cs.vertcat(*jac.nonzeros()) if jac.nnz() else cs.SX(0, 1)
        hess_nz = cs.vertcat(*hess.nonzeros()) if hess.nnz() else cs.SX(0, 1)

        self._functions = {
            "value": cs.Function(f"{name}_value", [z, p], [r0]),
            "jacobian": cs.Function(f"{name}_jacobian", [z, p], [r0, jac_nz]),
            "hessian": cs.Function(f"{name}_hessian", [z, p, lam], [r0, jac_nz, hess_nz]),
        }
        if jit:
            self._functions = {k: compile_function(f) for k, f in self._functions.items()}
        self._mapped: dict[tuple[str, int], tuple] = {}

    def __repr__(self) -> str:
        return (
            f"RiemannianFunction({self.name!r}, m={self.m}, n={self.n}, "
            f"nnz_jac={self.jac_nnz}, nnz_hess={self.hess_nnz}, jit={self.jit})"
        )

    @property
    def jac_nnz(self) -> int:
        return len(self.jac_rows)

    @property
    def hess_nnz(self) -> int:
        return len(self.hess_rows)

    # ------------------------------------------------------------------ packing
    def pack(
        self,
        slots: Sequence[Slot],
        values: Mapping[str, Any],
        width: int,
        what: str,
        K: int | None = None,
    ) -> np.ndarray:
        """Stack named arrays ``(K, *shape)`` (or ``shape``, broadcast) into a C-ordered ``(K, width)``.

        Row ``k`` is the column-major flattening of knot ``k``'s arguments, i.e. exactly the memory
        layout CasADi expects for a ``(width, K)`` matrix, so no transpose is ever needed.
        """
        missing = [s.name for s in slots if s.name not in values]
        extra = sorted(set(values) - {s.name for s in slots})
        if missing or extra:
            raise InputError(f"{self.name}: {what} missing {missing} / unexpected {extra}")
        arrays = []
        for s in slots:
            a = np.asarray(values[s.name], dtype=float)
            if a.shape == s.shape or (s.shape == (1,) and a.ndim == 0):
                a = a.reshape(1, *s.shape)
            elif s.shape == (1,) and a.ndim == 1:
                a = a.reshape(-1, 1)  # one scalar per knot
            elif a.ndim != len(s.shape) + 1 or a.shape[1:] != s.shape:
                raise InputError(
                    f"{self.name}: {what} {s.name!r} must have shape (K, *{s.shape}) or {s.shape}, "
                    f"got {a.shape}"
                )
            if a.shape[0] != 1:
                if K not in (None, a.shape[0]):
                    raise InputError(
                        f"{self.name}: {what} {s.name!r} has {a.shape[0]} knots, expected {K}"
                    )
                K = a.shape[0]
            arrays.append(a)
        K = K or 1
        out = np.empty((K, width))
        for s, a in zip(slots, arrays, strict=True):
            # Column-major flattening per knot, as CasADi reshapes.
            out[:, s.offset : s.offset + s.size] = np.swapaxes(a, 1, -1).reshape(a.shape[0], -1)
        if not np.isfinite(out).all():
            bad = next(
                s.name for s, a in zip(slots, arrays, strict=True) if not np.isfinite(a).all()
            )
            raise InputError(f"{self.name}: {what} {bad!r} contains NaN or inf")
        return out

    def pack_parameters(self, parameters: Mapping[str, Any] | None, K: int) -> np.ndarray:
        """Parameters packed once as a ``(K, np)`` array, to pass instead of the mapping."""
        return _tile(self.pack(self.parameters, parameters or {}, self.np, "parameters", K), K)

    def _call(self, kind: str, inputs: list[np.ndarray]) -> list[np.ndarray]:
        """Evaluate the ``K``-fold map of a function on C-ordered ``(K, ·)`` arrays, zero-copy."""
        K = inputs[0].shape[0]
        key = (kind, K)
        cached = self._mapped.get(key)
        if cached is None:
            fn = self._functions[kind] if K == 1 else self._functions[kind].map(K, "serial")
            buf, evaluate = fn.buffer()
            cached = (fn, buf, evaluate)
            self._mapped[key] = cached
        fn, buf, evaluate = cached
        for i, a in enumerate(inputs):
            buf.set_arg(i, memoryview(a))
        outs = [np.empty((K, fn.size1_out(i))) for i in range(fn.n_out())]
        for i, o in enumerate(outs):
            buf.set_res(i, memoryview(o))
        evaluate()
        return outs

    def _inputs(self, variables, parameters, K: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        z = self.pack(self.variables, variables, self.nz, "variables", K)
        if isinstance(parameters, np.ndarray):
            p = parameters
        else:
            p = self.pack(self.parameters, parameters or {}, self.np, "parameters", K)
        K = max(z.shape[0], p.shape[0])
        return _tile(z, K), _tile(p, K)

    # ------------------------------------------------------------------ evaluation
    def value(
        self, variables: Mapping[str, Any], parameters: Mapping[str, Any] | None = None
    ) -> np.ndarray:
        """Residuals, shape ``(K, m)``."""
        return self._call("value", list(self._inputs(variables, parameters)))[0]

    def jacobian(
        self, variables: Mapping[str, Any], parameters: Mapping[str, Any] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Residuals ``(K, m)`` and Jacobian nonzeros ``(K, jac_nnz)``."""
        r, j = self._call("jacobian", list(self._inputs(variables, parameters)))
        return r, j

    def hessian(
        self,
        variables: Mapping[str, Any],
        parameters: Mapping[str, Any] | None,
        multipliers: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals, Jacobian nonzeros and lower-triangle Hessian nonzeros of ``λᵀr``."""
        lam = np.asarray(multipliers, dtype=float)
        if lam.ndim == 1:
            lam = lam[None]
        if lam.ndim != 2 or lam.shape[-1] != self.m:
            raise InputError(
                f"{self.name}: multipliers must have shape (K, {self.m}) or ({self.m},), got {lam.shape}"
            )
        if not np.all(np.isfinite(lam)):
            raise InputError(f"{self.name}: multipliers contain NaN or inf")
        z, p = self._inputs(variables, parameters, lam.shape[0] if lam.shape[0] > 1 else None)
        K = z.shape[0]
        r, j, h = self._call("hessian", [z, p, _tile(np.ascontiguousarray(lam), K)])
        return r, j, h

    # ------------------------------------------------------------------ dense views
    def dense_jacobian(self, jac_nz: np.ndarray) -> np.ndarray:
        """``(K, m, n)`` dense Jacobians from the nonzeros."""
        out = np.zeros((jac_nz.shape[0], self.m, self.n))
        out[:, self.jac_rows, self.jac_cols] = jac_nz
        return out

    def dense_hessian(self, hess_nz: np.ndarray) -> np.ndarray:
        """``(K, n, n)`` symmetric Hessians from the lower-triangle nonzeros."""
        out = np.zeros((hess_nz.shape[0], self.n, self.n))
        out[:, self.hess_rows, self.hess_cols] = hess_nz
        out[:, self.hess_cols, self.hess_rows] = hess_nz
        return out

    def retract(self, variables: Mapping[str, Any], xi: np.ndarray) -> dict[str, np.ndarray]:
        """Move every variable along the exact retraction ``X exp(ξ)`` (``y + ξ``); ``xi`` is (K, n)."""
        out = dict(variables)
        for s in self.variables:
            out[s.name] = s.group.retract(
                np.asarray(variables[s.name], dtype=float), xi[..., s.tangent]
            )
        return out
