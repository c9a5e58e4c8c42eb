"""The common interface of residual functions evaluated at ``K`` sites with Riemannian derivatives.

A :class:`SiteFunction` has named group-valued and Euclidean variables, fixed parameters, ``m``
residual rows, ``n`` tangent coordinates (the variables' tangent spaces, in order) and fixed
sparsity patterns of its Jacobian (``jac_rows/jac_cols``) and of the lower triangle of the
Hessian of ``λᵀr`` (``hess_rows/hess_cols``) along the retraction ``X exp(ξ)`` (``y + ξ``).
Subclasses provide :meth:`SiteFunction._call`: :class:`~mbplan.engine.RiemannianFunction`
(CasADi, symbolic derivatives) and :class:`~mbplan.engine.CallbackFunction` (NumPy code with
hand-derived derivatives, e.g. distances computed by coal).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

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
        return int(math.prod(self.shape))


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
        offset += int(math.prod(shape))
    return slots, offset, tangent


ORDER = {"value": 0, "jacobian": 1, "hessian": 2}
"""The evaluation kinds and their derivative order (their outputs: the first ``order + 1`` of
residuals, Jacobian nonzeros, Hessian nonzeros)."""

Parameters = Mapping[str, Any] | np.ndarray | None
"""Named parameters, or a ``(K, np)`` array from :meth:`SiteFunction.pack_parameters`."""


def _tile(a: np.ndarray, K: int) -> np.ndarray:
    """A C-contiguous ``(K, ·)`` array, repeating a single row if needed."""
    return np.ascontiguousarray(np.broadcast_to(a, (K, a.shape[1])))


class SiteFunction(ABC):
    """Packing, evaluation entry points and dense views shared by all site functions."""

    name: str
    m: int
    jac_rows: np.ndarray
    jac_cols: np.ndarray
    hess_rows: np.ndarray
    hess_cols: np.ndarray

    def __init__(
        self,
        name: str,
        variables: Sequence[tuple[str, Any]],
        parameters: Sequence[tuple[str, int | tuple[int, ...]]],
    ) -> None:
        if not name.isidentifier():
            raise InputError(f"function name {name!r} must be a valid identifier")
        self.name = name
        self.variables, self.nz, self.n = _layout(variables, is_variable=True)
        self.parameters, self.np, _ = _layout(parameters, is_variable=False)
        names = [s.name for s in (*self.variables, *self.parameters)]
        if len(set(names)) != len(names):
            raise InputError(f"{name}: duplicate argument names in {names}")

    @cached_property
    def layout_key(self) -> tuple:
        """All a transcription reads of the function besides evaluating it: the variables'
        slots, the sizes and the derivatives' sparsity patterns (equal keys: equal index maps)."""
        slots = tuple(
            (s.name, s.shape, s.offset, s.tangent.start, s.tangent.stop) for s in self.variables
        )
        patterns = (self.jac_rows, self.jac_cols, self.hess_rows, self.hess_cols)
        return (slots, self.nz, self.n, self.m, tuple((a.dtype.str, a.tobytes()) for a in patterns))

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
        K = 1 if K is None else K
        bad = next(
            (s.name for s, a in zip(slots, arrays, strict=True) if not np.isfinite(a).all()), None
        )
        if bad is not None:  # checked on the arguments: a row given once counts at no sites too
            raise InputError(f"{self.name}: {what} {bad!r} contains NaN or inf")
        out = np.empty((K, width))
        for s, a in zip(slots, arrays, strict=True):
            # Column-major flattening per knot, as CasADi reshapes.
            out[:, s.offset : s.offset + s.size] = np.swapaxes(a, 1, -1).reshape(a.shape[0], s.size)
        return out

    def pack_parameters(self, parameters: Mapping[str, Any] | None, K: int) -> np.ndarray:
        """Parameters packed once as a ``(K, np)`` array, to pass instead of the mapping."""
        return _tile(self.pack(self.parameters, parameters or {}, self.np, "parameters", K), K)

    @abstractmethod
    def _call(self, kind: str, inputs: list[np.ndarray]) -> list[np.ndarray]:
        """``kind`` is ``value``, ``jacobian`` or ``hessian``; ``inputs`` are C-ordered
        ``(K, nz)`` variables, ``(K, np)`` parameters (and ``(K, m)`` multipliers)."""

    def call_packed(self, kind: str, inputs: list[np.ndarray]) -> list[np.ndarray]:
        """:meth:`_call` on inputs already packed as :meth:`pack` does, without validation: the
        fast path for a caller that packs (and validates) a whole point once. At no sites
        (``K = 0``) the outputs are empty ``(0, ·)`` arrays and :meth:`_call` is not called."""
        if inputs[0].shape[0] == 0:
            return [np.empty((0, width)) for width in self._output_widths(kind)]
        return self._call(kind, inputs)

    def _output_widths(self, kind: str) -> tuple[int, ...]:
        """The widths of the outputs of ``kind``: residuals, Jacobian and Hessian nonzeros."""
        if kind not in ORDER:
            raise InputError(f"{self.name}: unknown evaluation {kind!r}; choose from {list(ORDER)}")
        return (self.m, self.jac_nnz, self.hess_nnz)[: ORDER[kind] + 1]

    def bind(
        self, kind: str, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]
    ) -> Callable[[], None]:
        """A call of ``kind`` bound to fixed arrays: every call reads ``inputs`` (packed as for
        :meth:`call_packed`) and writes the results into ``outputs`` (C-ordered ``(K, ·)``), so a
        caller refills the inputs in place and evaluates with no allocation or argument
        handling per call."""

        def call() -> None:
            for out, res in zip(outputs, self.call_packed(kind, list(inputs)), strict=True):
                out[...] = res

        return call

    def _inputs(
        self, variables: Mapping[str, Any], parameters: Parameters, sites: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """Packed variables and parameters at one common number of sites (at least ``sites``,
        the multipliers' count): an argument given once (one row) is repeated at every site,
        any other count must agree."""
        z = self.pack(self.variables, variables, self.nz, "variables")
        K = z.shape[0] if z.shape[0] != 1 else None
        if isinstance(parameters, np.ndarray):
            p = np.asarray(parameters, dtype=float)
            if p.ndim != 2 or p.shape[1] != self.np or (K is not None and p.shape[0] not in (1, K)):
                rows = "K" if K is None else f"1 or {K}"
                raise InputError(
                    f"{self.name}: packed parameters must have shape ({rows}, {self.np}), "
                    f"got {p.shape}"
                )
            if not np.isfinite(p).all():
                raise InputError(f"{self.name}: packed parameters contain NaN or inf")
        else:
            p = self.pack(self.parameters, parameters or {}, self.np, "parameters", K)
        K = z.shape[0] if z.shape[0] != 1 else p.shape[0]
        if sites != 1:
            if K not in (1, sites):
                raise InputError(f"{self.name}: multipliers have {sites} knots, expected 1 or {K}")
            K = sites
        return _tile(z, K), _tile(p, K)

    # ------------------------------------------------------------------ evaluation
    def value(self, variables: Mapping[str, Any], parameters: Parameters = None) -> np.ndarray:
        """Residuals, shape ``(K, m)``."""
        return self.call_packed("value", list(self._inputs(variables, parameters)))[0]

    def jacobian(
        self, variables: Mapping[str, Any], parameters: Parameters = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Residuals ``(K, m)`` and Jacobian nonzeros ``(K, jac_nnz)``."""
        r, j = self.call_packed("jacobian", list(self._inputs(variables, parameters)))
        return r, j

    def hessian(
        self,
        variables: Mapping[str, Any],
        parameters: Parameters,
        multipliers: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals, Jacobian nonzeros and lower-triangle Hessian nonzeros of ``λᵀr``; multipliers
        given once (``(m,)`` or one row) are used at every site, and arguments given once are
        repeated at every site of the multipliers."""
        lam = np.asarray(multipliers, dtype=float)
        if lam.ndim == 1:
            lam = lam[None]
        if lam.ndim != 2 or lam.shape[-1] != self.m:
            raise InputError(
                f"{self.name}: multipliers must have shape (K, {self.m}) or ({self.m},), got {lam.shape}"
            )
        if not np.all(np.isfinite(lam)):
            raise InputError(f"{self.name}: multipliers contain NaN or inf")
        z, p = self._inputs(variables, parameters, lam.shape[0])
        r, j, h = self.call_packed("hessian", [z, p, _tile(lam, z.shape[0])])
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

    def unpack_variables(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """The variables ``(K, *shape)`` from packed rows ``z (K, nz)`` (inverse of :meth:`pack`)."""
        out = {}
        for s in self.variables:
            piece = z[:, s.offset : s.offset + s.size].reshape(len(z), *s.shape[::-1])
            out[s.name] = np.swapaxes(piece, 1, -1)
        return out

    def retract(self, variables: Mapping[str, Any], xi: np.ndarray) -> dict[str, np.ndarray]:
        """Move every variable along the exact retraction ``X exp(ξ)`` (``y + ξ``); ``xi`` is (K, n)."""
        out = dict(variables)
        for s in self.variables:
            out[s.name] = s.group.retract(
                np.asarray(variables[s.name], dtype=float), xi[..., s.tangent]
            )
        return out
