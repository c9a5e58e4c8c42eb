"""The trajectory NLP on a product manifold: Problem 2 (RIPM paper eq. 46) from terms.

``min Σ costs  s.t.  eq = 0,  ineq ≤ 0`` over the free knots of :class:`TrajectoryVariables`.
Jacobians are Riemannian (along ``X exp(ξ)``) and the Lagrangian Hessian
``Hess(σ f + yᵀh + zᵀg)`` is exact (eq. 54), both assembled with fixed sparsity patterns, so the
cost of one evaluation is linear in the horizon and in the number of bodies.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mbplan.engine.site_table import bound_calls
from mbplan.errors import InputError
from mbplan.finite import finite_vector
from mbplan.transcription.evaluation_kernels import (
    collect_derivatives,
    collect_values,
    gather_inputs,
)
from mbplan.transcription.sparse import sparse_pattern
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Point, TrajectoryVariables
from mbplan.workspace import Workspace, shared


@dataclass(frozen=True)
class Evaluation:
    """Everything a Newton step needs at one point (Hessian is the lower triangle). The sparse
    matrices share read-only index arrays with every evaluation of their pattern: copy one
    (``.copy()``) before an in-place index operation such as ``eliminate_zeros``."""

    objective: float
    gradient: np.ndarray
    eq: np.ndarray
    eq_jacobian: sp.csr_matrix
    ineq: np.ndarray
    ineq_jacobian: sp.csr_matrix
    hessian_lower: sp.csr_matrix | None


_KINDS = ("cost", "eq", "ineq")  # the order of the terms' kinds in every concatenated map


@dataclass(frozen=True, eq=False)
class _TermIndex:
    """Where one term's residual rows, tangent columns and packed inputs land in the NLP."""

    rows: np.ndarray  # (K, m) global rows within the term's kind
    jac_rows: np.ndarray
    jac_cols: np.ndarray
    hess_rows: np.ndarray
    hess_cols: np.ndarray
    z_index: np.ndarray  # (K, nz) gather map of the term's CasADi input in the packed point

    def __post_init__(self) -> None:
        for a in (
            self.rows,
            self.jac_rows,
            self.jac_cols,
            self.hess_rows,
            self.hess_cols,
            self.z_index,
        ):
            a.setflags(write=False)  # shared by every problem of the structure

    @classmethod
    def of(cls, term: Term, rows: np.ndarray, index: dict, flat_index: dict) -> _TermIndex:
        f = term.function
        cols = term.tangent_columns(index)  # (K, n_f)
        hr, hc = cols[:, f.hess_rows], cols[:, f.hess_cols]
        # the packed point (all blocks' arrays raveled and concatenated) gathered into the
        # term's input as SiteFunction.pack orders it, in one fancy index
        z_index = np.zeros((term.sites, f.nz), np.int64)
        args = term.gather(flat_index)
        for sl in f.variables:
            a = args[sl.name].reshape(term.sites, *sl.shape)
            z_index[:, sl.offset : sl.offset + sl.size] = np.swapaxes(a, 1, -1).reshape(
                term.sites, sl.size
            )
        return cls(
            rows,
            rows[:, f.jac_rows],
            cols[:, f.jac_cols],
            np.maximum(hr, hc),
            np.minimum(hr, hc),
            z_index,
        )


class _Structure:
    """The index maps and sparsity patterns of a :class:`TrajectoryProblem`: a function of the
    variables' blocks and of the terms' names, kinds, bindings, rows and functions' layouts
    only, so every problem of a task family shares one (their parameters differ)."""

    def __init__(
        self,
        variables: TrajectoryVariables,
        terms: Sequence[Term],
        workspace: Workspace | None = None,
    ) -> None:
        names = [t.name for t in terms]
        if len(set(names)) != len(names):
            raise InputError(f"duplicate term names: {names}")
        index = {name: variables.tangent_index(name) for name in variables.blocks}
        for t in terms:
            for arg, (block, ix) in t.bind.items():
                if block not in variables.blocks:
                    raise InputError(
                        f"term {t.name!r}: argument {arg!r} bound to unknown block {block!r}"
                    )
                b = variables.blocks[block]
                if ix.size and (ix.min() < 0 or ix.max() >= b.knots * b.count):
                    raise InputError(
                        f"term {t.name!r}: indices of {arg!r} fall outside block {block!r}"
                    )
        self.n = variables.n
        flat_index, offset = {}, 0
        for name, b in variables.blocks.items():
            size = math.prod(b.shape)
            flat_index[name] = b.flat(np.arange(offset, offset + size))
            offset += size
        self.indices: list[_TermIndex] = []
        sizes = {"cost": 0, "eq": 0, "ineq": 0}
        for t in terms:
            m = t.function.m
            if t.rows is None:
                rows = sizes[t.kind] + np.arange(t.sites * m, dtype=np.int64).reshape(t.sites, m)
                sizes[t.kind] += t.sites * m
            else:
                rows = t.rows.copy()
                sizes[t.kind] = max(sizes[t.kind], int(rows.max(initial=-1)) + 1)
            self.indices.append(_TermIndex.of(t, rows, index, flat_index))
        self.n_eq, self.n_ineq = sizes["eq"], sizes["ineq"]
        # the terms kind by kind (costs, equalities, inequalities), each kind in term order: the
        # order of every concatenated map below and of the problems' buffers
        self.order = tuple(i for kind in _KINDS for i, t in enumerate(terms) if t.kind == kind)
        by_kind = {
            kind: [self.indices[i] for i in self.order if terms[i].kind == kind] for kind in _KINDS
        }
        self.rows = {
            kind: _cat_index([ix.rows.ravel() for ix in ixs]) for kind, ixs in by_kind.items()
        }
        self.jac_patterns = {
            kind: sparse_pattern(
                _cat_index([ix.jac_rows.ravel() for ix in by_kind[kind]]),
                _cat_index([ix.jac_cols.ravel() for ix in by_kind[kind]]),
                (sizes[kind], self.n),
                workspace,
            )  # fixed columns (-1) dropped
            for kind in ("eq", "ineq")
        }
        # gradient column of every cost Jacobian nonzero, n (a bin cut off) where fixed
        cols = _cat_index([ix.jac_cols.ravel() for ix in by_kind["cost"]])
        self.grad_cols = np.where(cols >= 0, cols, self.n)
        ordered = [self.indices[i] for i in self.order]
        # every term's inputs in one array (the problems' input buffers): where each entry comes
        # from in the packed point, and its multiplier in (y, z) (-1: σ)
        self.z_gather = _cat_index([ix.z_index.ravel() for ix in ordered])
        self.lam_source = _cat_index(
            [np.full(ix.rows.size, -1, np.int64) for ix in by_kind["cost"]]
            + [ix.rows.ravel() for ix in by_kind["eq"]]
            + [ix.rows.ravel() + self.n_eq for ix in by_kind["ineq"]]
        )
        self.hess_pattern = sparse_pattern(
            _cat_index([ix.hess_rows.ravel() for ix in ordered]),
            _cat_index([ix.hess_cols.ravel() for ix in ordered]),
            (self.n, self.n),
            workspace,
        )
        for a in (*self.rows.values(), self.grad_cols, self.z_gather, self.lam_source):
            a.setflags(write=False)


def _structure(
    variables: TrajectoryVariables, terms: Sequence[Term], workspace: Workspace | None
) -> _Structure:
    """The :class:`_Structure` of ``variables`` and ``terms``, kept in ``workspace`` by
    everything it reads (of a function: :attr:`~mbplan.engine.SiteFunction.layout_key`)."""

    def key() -> tuple:
        return (
            tuple(variables.blocks.values()),
            tuple(
                (
                    t.name,
                    t.kind,
                    t.function.layout_key,
                    tuple((arg, block, ix.tobytes()) for arg, (block, ix) in t.bind.items()),
                    None if t.rows is None else (t.rows.shape, t.rows.tobytes()),
                )
                for t in terms
            ),
        )

    return shared(
        workspace, "structure", key, lambda: _Structure(variables, terms, workspace), disk=True
    )


class _TermLayout:
    """One term of a problem: its index maps, packed parameters and evaluation buffers."""

    def __init__(self, term: Term, index: _TermIndex, z: np.ndarray, lam: np.ndarray) -> None:
        self.term, self.index = term, index
        self.parameters = term.function.pack_parameters(term.parameters, term.sites)
        # evaluation buffers, views of the problem's arrays: inputs ``(K, nz)`` and multipliers
        # ``(K, m)`` refilled in place, outputs (set by TrajectoryProblem), to which the
        # problem binds the compiled calls on first use
        self.z, self.lam = z, lam
        self.outputs: dict[str, list[np.ndarray]] = {}

    def bind(self, kind: str) -> Callable[[], None]:
        """The term's ``value``/``jacobian``/``hessian`` bound to its buffers."""
        inputs = [self.z, self.parameters] + ([self.lam] if kind == "hessian" else [])
        return self.term.function.bind(kind, inputs, self.outputs[kind])


class TrajectoryProblem:
    """Costs, equalities and inequalities over trajectory variables, evaluated sparsely
    (``workspace``: where the index maps and patterns are kept, shared by the problems of a
    family; ``None``: this problem's own)."""

    def __init__(
        self,
        variables: TrajectoryVariables,
        terms: Sequence[Term],
        workspace: Workspace | None = None,
    ) -> None:
        self.variables = variables
        self.terms = list(terms)
        self._structure = s = _structure(variables, self.terms, workspace)
        self.n, self.n_eq, self.n_ineq = s.n, s.n_eq, s.n_ineq
        ordered = [(self.terms[i], s.indices[i]) for i in s.order]
        # every term's inputs and multipliers as views of one array each, in the structure's
        # order (z_gather, lam_source): one compiled pass fills them
        self._z, z_views = _views([ix.z_index.shape for _, ix in ordered])
        self._lam, lam_views = _views([ix.rows.shape for _, ix in ordered])
        self._all_layouts = [
            _TermLayout(t, ix, z, lam)
            for (t, ix), z, lam in zip(ordered, z_views, lam_views, strict=True)
        ]
        self._layouts: dict[str, list[_TermLayout]] = {
            kind: [lay for lay in self._all_layouts if lay.term.kind == kind] for kind in _KINDS
        }
        self._output_buffers()
        self._bound: dict[str, Callable[[], None]] = {}

    # ------------------------------------------------------------------ buffers
    def _output_buffers(self) -> None:
        """One array per kind for the residuals and for the Jacobian nonzeros, one for all
        Hessian nonzeros (cost, equality, then inequality terms): each term's outputs are
        ``(K, ·)`` views into them, so the evaluated nonzeros are summed without concatenating
        per-term arrays."""
        self._residuals, self._jacobians, self._cost_residuals = {}, {}, []
        for kind, lays in self._layouts.items():
            self._residuals[kind], res = _views(
                [(lay.term.sites * lay.term.function.m,) for lay in lays]
            )
            jac_shapes = [(lay.term.sites * lay.term.function.jac_nnz,) for lay in lays]
            self._jacobians[kind], jac = _views(jac_shapes)
            for lay, r, j in zip(lays, res, jac, strict=True):
                K, f = lay.term.sites, lay.term.function
                r2, j2 = r.reshape(K, f.m), j.reshape(K, f.jac_nnz)
                lay.outputs = {"value": [r2], "jacobian": [r2, j2], "hessian": [r2, j2]}
            if kind == "cost":
                self._cost_residuals = res
        self._hessians, hess = _views(
            [(lay.term.sites * lay.term.function.hess_nnz,) for lay in self._all_layouts]
        )
        for lay, h in zip(self._all_layouts, hess, strict=True):
            lay.outputs["hessian"].append(h.reshape(lay.term.sites, lay.term.function.hess_nnz))

    # ------------------------------------------------------------------ manifold
    def term_rows(self, kind: str) -> dict[str, np.ndarray]:
        """Rows ``(sites, m)`` of every term of ``kind`` (``"cost"``, ``"eq"``, ``"ineq"``) in
        its residual vector, by term name."""
        return {lay.term.name: lay.index.rows for lay in self._layouts[kind]}

    def check_point(self, point: Point, what: str = "initial guess") -> Point:
        return self.variables.check_point(point, what)

    def retract(self, point: Point, dx: np.ndarray) -> Point:
        return self.variables.retract(point, dx)

    def set_parameters(self, term: str, values: Mapping[str, Any]) -> None:
        """Replace parameters of the term named ``term`` (``(sites, ·)`` arrays or one value):
        the structure stays, the next evaluation reads the new values."""
        layouts = [lay for lay in self._all_layouts if lay.term.name == term]
        if not layouts:
            raise InputError(f"no term named {term!r}")
        for lay in layouts:
            lay.term.parameters = {**lay.term.parameters, **values}
            lay.parameters = lay.term.function.pack_parameters(lay.term.parameters, lay.term.sites)
        self._bound.clear()  # the compiled calls hold the old arrays

    # ------------------------------------------------------------------ evaluation
    def _gather(self, point: Point, lam: tuple[float, np.ndarray, np.ndarray] | None) -> None:
        """Every term's packed variables from the point into its input buffer and, given
        ``(σ, y, z)``, its multipliers into its ``lam`` buffer."""
        s = self._structure
        if lam is None:  # an empty source and buffer: no multipliers
            lam, source, out = (0.0, _NO_MULTIPLIERS, _NO_MULTIPLIERS), _NO_INDEX, _NO_MULTIPLIERS
        else:
            source, out = s.lam_source, self._lam
        gather_inputs(self.variables.packed(point), s.z_gather, self._z, *lam, source, out)

    def bind_calls(self, kind: str) -> Callable[[], None]:
        """Every term's ``value``, ``jacobian`` or ``hessian`` call bound anew to the problem's
        buffers, as one call: the compiled terms' C loops in one compiled pass
        (:func:`~mbplan.engine.site_table.bound_calls`). Evaluation binds each kind once."""
        if kind not in _CALL_KINDS:
            raise InputError(f"call kind: expected one of {_CALL_KINDS}, got {kind!r}")
        return bound_calls([lay.bind(kind) for lay in self._all_layouts])

    def _run(self, kind: str) -> None:
        run = self._bound.get(kind)
        if run is None:
            run = self._bound[kind] = self.bind_calls(kind)
        run()

    def values(self, point: Point) -> tuple[float, np.ndarray, np.ndarray]:
        """Objective, equality and inequality residuals (for line-search trials)."""
        self._gather(point, None)
        self._run("value")
        f = float(sum(r.sum() for r in self._cost_residuals))
        s = self._structure
        eq, ineq = collect_values(
            self._residuals["eq"], s.rows["eq"], self.n_eq,
            self._residuals["ineq"], s.rows["ineq"], self.n_ineq,
        )  # fmt: skip
        return f, eq, ineq

    def evaluate(
        self,
        point: Point,
        obj_factor: float = 1.0,
        y: np.ndarray | None = None,
        z: np.ndarray | None = None,
        hessian: bool = True,
    ) -> Evaluation:
        """Values, Riemannian gradient and Jacobians and (optionally) the Lagrangian Hessian."""
        y = np.zeros(self.n_eq) if y is None else np.asarray(y, dtype=float)
        z = np.zeros(self.n_ineq) if z is None else np.asarray(z, dtype=float)
        if y.shape != (self.n_eq,) or z.shape != (self.n_ineq,):
            raise InputError(f"multipliers must have shapes ({self.n_eq},), ({self.n_ineq},)")
        y, z = np.ascontiguousarray(y), np.ascontiguousarray(z)
        if not (math.isfinite(obj_factor) and finite_vector(y) and finite_vector(z)):
            raise InputError("objective factor or multipliers contain NaN or inf")
        self._gather(point, (float(obj_factor), y, z) if hessian else None)
        self._run("hessian" if hessian else "jacobian")
        s = self._structure
        eq_pattern, ineq_pattern = s.jac_patterns["eq"], s.jac_patterns["ineq"]
        hess_pattern = s.hess_pattern
        grad, eq, ineq, eq_data, ineq_data, hess_data = collect_derivatives(
            self._jacobians["cost"], s.grad_cols, self.n,
            self._residuals["eq"], s.rows["eq"], self.n_eq,
            self._residuals["ineq"], s.rows["ineq"], self.n_ineq,
            self._jacobians["eq"], eq_pattern.slot, eq_pattern.nnz,
            self._jacobians["ineq"], ineq_pattern.slot, ineq_pattern.nnz,
            self._hessians, hess_pattern.slot if hessian else _NO_INDEX, hess_pattern.nnz,
        )  # fmt: skip
        return Evaluation(
            objective=float(self._residuals["cost"].sum()),
            gradient=grad,
            eq=eq,
            eq_jacobian=eq_pattern.wrap(eq_data),
            ineq=ineq,
            ineq_jacobian=ineq_pattern.wrap(ineq_data),
            hessian_lower=hess_pattern.wrap(hess_data) if hessian else None,
        )


_CALL_KINDS = ("value", "jacobian", "hessian")
_NO_MULTIPLIERS = np.zeros(0)  # no y, z; as the lam buffer: skips the multipliers (unwritten)
_NO_INDEX = np.zeros(0, np.int64)
_NO_INDEX.setflags(write=False)  # typed as the structure's read-only index arrays


def _views(shapes: list[tuple[int, ...]]) -> tuple[np.ndarray, list[np.ndarray]]:
    """One flat array and its consecutive views of the given shapes."""
    sizes = [math.prod(shape) for shape in shapes]
    flat = np.empty(sum(sizes))
    starts = np.cumsum([0, *sizes])
    views = [
        flat[a:b].reshape(shape)
        for (a, b), shape in zip(itertools.pairwise(starts), shapes, strict=True)
    ]
    return flat, views


def _cat_index(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)
