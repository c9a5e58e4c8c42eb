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

All outputs are evaluated for ``K`` knots in one call (compiled: one C loop over the sites,
:mod:`mbplan.engine.site_loop_source`; else ``casadi.Function.map``). Sparsity
patterns are fixed at construction: ``jac_rows/jac_cols`` and ``hess_rows/hess_cols`` (lower
triangle) index the nonzero arrays returned per knot, so callers assemble sparse matrices by
index arithmetic with no Python loop over knots.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import casadi as cs
import numpy as np

from mbplan.engine import disk_cache
from mbplan.engine.compile_clock import compiling
from mbplan.engine.jit import (
    DEFAULT_FLAGS,
    SiteLoop,
    cache_dir,
    check_site_arrays,
    compiler,
    library_paths,
    load_site_loops,
)
from mbplan.engine.site_function import ORDER, SiteFunction, Slot
from mbplan.engine.site_loop_source import GENERATOR_KEY


def _unpack(vec: cs.SX, slots: Sequence[Slot]) -> dict[str, cs.SX]:
    out = {}
    for s in slots:
        piece = vec[s.offset : s.offset + s.size]
        out[s.name] = cs.reshape(piece, *s.shape) if len(s.shape) == 2 else piece
    return out


class RiemannianFunction(SiteFunction):
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
        super().__init__(name, variables, parameters)
        self.jit = jit
        self._loops: dict[str, SiteLoop] = {}
        with compiling():
            self._build(name, residual)
        self._maps: dict[tuple[str, int], cs.Function] = {}
        self._buffers: dict[tuple[str, int], tuple] = {}

    def _build(self, name: str, residual: Callable[..., cs.SX]) -> None:
        """The derivatives (symbolic) and the three functions, compiled if ``jit``: a compiled
        function's derivatives' patterns and shared objects are kept on disk by its value's
        expression (:mod:`mbplan.engine.disk_cache`), and a new process loads them instead of
        deriving and hashing the derivatives again."""
        z = cs.SX.sym("z", self.nz)
        p = cs.SX.sym("p", self.np)
        args = _unpack(z, self.variables) | _unpack(p, self.parameters)
        # dense: the value buffers are dense, a structural zero row would be left unwritten
        r0 = cs.densify(cs.vec(cs.SX(residual(**args))))
        self.m = r0.size1()
        value = cs.Function(f"{name}_value", [z, p], [r0])
        key = self._key(value) if self.jit and disk_cache.enabled() else None
        if key is not None and self._load(disk_cache.lookup("riemannian", key)):
            return
        self._derive(name, residual, z, p, args, r0)
        if self.jit:
            paths = library_paths(self._functions)
            libraries = {k: (fn.name(), paths[k]) for k, fn in self._functions.items()}
            self._load_libraries(libraries)
            if key is not None:
                entry = {
                    "patterns": (self.jac_rows, self.jac_cols, self.hess_rows, self.hess_cols),
                    "libraries": {k: (n, p.name) for k, (n, p) in libraries.items()},
                }
                disk_cache.store("riemannian", key, entry)

    def _key(self, value: cs.Function) -> tuple:
        """What the derivatives and their compiled code are a function of besides this module's
        and the groups' code (:func:`~mbplan.engine.disk_cache.code_version`): the value's
        expression, the variables' groups and slots, the compiler and its flags."""
        slots = tuple(
            (s.name, s.shape, s.offset, s.tangent.start, s.tangent.stop, type(s.group).__qualname__,
             s.group.dim, tuple(s.group.element_shape))
            for s in self.variables
        )  # fmt: skip
        return (value.serialize(), slots, compiler(), DEFAULT_FLAGS, cs.__version__, GENERATOR_KEY)

    def _load(self, entry: Any) -> bool:
        """Take the patterns and load the shared objects of a stored entry; False (nothing
        taken) if there is none or a shared object is missing."""
        try:
            patterns, stored = entry["patterns"], entry["libraries"]
            libraries = {k: (str(n), cache_dir() / str(f)) for k, (n, f) in stored.items()}
        except (TypeError, KeyError, ValueError):
            return False
        if set(libraries) != set(ORDER) or not all(p.is_file() for _, p in libraries.values()):
            return False
        self.jac_rows, self.jac_cols, self.hess_rows, self.hess_cols = patterns
        self._load_libraries(libraries)
        return True

    def _load_libraries(self, libraries: dict[str, tuple[str, Path]]) -> None:
        compiled = load_site_loops(libraries)
        self._functions = {k: fn for k, (fn, _) in compiled.items()}
        self._loops = {k: loop for k, (_, loop) in compiled.items()}

    def _derive(
        self,
        name: str,
        residual: Callable[..., cs.SX],
        z: cs.SX,
        p: cs.SX,
        args: dict[str, cs.SX],
        r0: cs.SX,
    ) -> None:
        """The derivatives along the retraction and the three functions (CasADi SX)."""
        xi = cs.SX.sym("xi", self.n)
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

    def __repr__(self) -> str:
        return (
            f"RiemannianFunction({self.name!r}, m={self.m}, n={self.n}, "
            f"nnz_jac={self.jac_nnz}, nnz_hess={self.hess_nnz}, jit={self.jit})"
        )

    def _mapped(self, kind: str, K: int) -> cs.Function:
        """The ``K``-fold map of a function (the function itself for ``K = 1``), cached."""
        fn = self._maps.get((kind, K))
        if fn is None:
            fn = self._functions[kind] if K == 1 else self._functions[kind].map(K, "serial")
            self._maps[(kind, K)] = fn
        return fn

    def _call(self, kind: str, inputs: list[np.ndarray]) -> list[np.ndarray]:
        """Evaluate a function at the sites of C-ordered ``(K, ·)`` arrays, zero-copy: compiled,
        its site loop (what :meth:`bind` calls); else the ``K``-fold map."""
        if kind in self._loops:
            return self._loops[kind].evaluate(inputs)
        K = inputs[0].shape[0]
        key = (kind, K)
        cached = self._buffers.get(key)
        if cached is None:
            fn = self._mapped(kind, K)
            buf, evaluate = fn.buffer()
            cached = (buf, evaluate, [fn.size1_out(i) for i in range(fn.n_out())])
            self._buffers[key] = cached
        buf, evaluate, sizes = cached
        for i, a in enumerate(inputs):
            buf.set_arg(i, memoryview(a))
        outs = [np.empty((K, size)) for size in sizes]
        for i, o in enumerate(outs):
            buf.set_res(i, memoryview(o))
        evaluate()
        return outs

    def bind(
        self, kind: str, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]
    ) -> Callable[[], None]:
        """:meth:`SiteFunction.bind`: compiled, one C loop over the sites (:class:`SiteLoop`);
        else a CasADi buffer of its own pointing at the arrays once."""
        if kind in self._loops:
            return self._loops[kind].bind(inputs, outputs)
        site = self._functions[kind]
        K = check_site_arrays(
            self.name,
            inputs,
            outputs,
            [site.nnz_in(i) for i in range(site.n_in())],
            [site.nnz_out(i) for i in range(site.n_out())],
        )
        if K == 0:  # CasADi has no 0-fold map: the shared path's empty call
            return super().bind(kind, inputs, outputs)
        fn = self._mapped(kind, K)
        buf, evaluate = fn.buffer()
        for i, a in enumerate(inputs):
            buf.set_arg(i, memoryview(a))
        for i, o in enumerate(outputs):
            buf.set_res(i, memoryview(o))
        return _BoundCall(evaluate, (buf, tuple(inputs), tuple(outputs)))


class _BoundCall:
    """A CasADi buffer's evaluation, holding the buffer and the arrays it points into."""

    __slots__ = ("_evaluate", "_keep")

    def __init__(self, evaluate: Callable[[], None], keep: tuple) -> None:
        self._evaluate, self._keep = evaluate, keep

    def __call__(self) -> None:
        self._evaluate()
