"""The trajectory NLP on a product manifold: Problem 2 (RIPM paper eq. 46) from terms.

``min Σ costs  s.t.  eq = 0,  ineq ≤ 0`` over the free knots of :class:`TrajectoryVariables`.
Jacobians are Riemannian (along ``X exp(ξ)``) and the Lagrangian Hessian
``Hess(σ f + yᵀh + zᵀg)`` is exact (eq. 54), both assembled with fixed sparsity patterns, so the
cost of one evaluation is linear in the horizon and in the number of bodies.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.transcription.sparse import SparsePattern
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Point, TrajectoryVariables


@dataclass(frozen=True)
class Evaluation:
    """Everything a Newton step needs at one point (Hessian is the lower triangle)."""

    objective: float
    gradient: np.ndarray
    eq: np.ndarray
    eq_jacobian: sp.csr_matrix
    ineq: np.ndarray
    ineq_jacobian: sp.csr_matrix
    hessian_lower: sp.csr_matrix | None


class _TermLayout:
    """Where one term's residual rows and tangent columns land in the global NLP."""

    def __init__(self, term: Term, rows: np.ndarray, index: dict[str, np.ndarray]) -> None:
        f = term.function
        self.term = term
        self.rows = rows  # (K, m) global rows within the term's kind
        self.parameters = f.pack_parameters(term.parameters, term.sites)
        cols = term.tangent_columns(index)  # (K, n_f)
        self.z_index = np.zeros((term.sites, f.nz), np.int64)  # set by TrajectoryProblem
        self.jac_rows = rows[:, f.jac_rows]
        self.jac_cols = cols[:, f.jac_cols]
        hr, hc = cols[:, f.hess_rows], cols[:, f.hess_cols]
        self.hess_rows, self.hess_cols = np.maximum(hr, hc), np.minimum(hr, hc)


class TrajectoryProblem:
    """Costs, equalities and inequalities over trajectory variables, evaluated sparsely."""

    def __init__(self, variables: TrajectoryVariables, terms: Sequence[Term]) -> None:
        self.variables = variables
        self.terms = list(terms)
        names = [t.name for t in self.terms]
        if len(set(names)) != len(names):
            raise InputError(f"duplicate term names: {names}")
        index = {name: variables.tangent_index(name) for name in variables.blocks}
        for t in self.terms:
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
        self._layouts: dict[str, list[_TermLayout]] = {"cost": [], "eq": [], "ineq": []}
        sizes = {"cost": 0, "eq": 0, "ineq": 0}
        for t in self.terms:
            m = t.function.m
            if t.rows is None:
                rows = sizes[t.kind] + np.arange(t.sites * m, dtype=np.int64).reshape(t.sites, m)
                sizes[t.kind] += t.sites * m
            else:
                rows = t.rows
                sizes[t.kind] = max(sizes[t.kind], int(rows.max(initial=-1)) + 1)
            self._layouts[t.kind].append(_TermLayout(t, rows, index))
        self.n_eq, self.n_ineq = sizes["eq"], sizes["ineq"]
        self._rows = {
            kind: np.concatenate([lay.rows.ravel() for lay in lays] or [np.zeros(0, np.int64)])
            for kind, lays in self._layouts.items()
        }
        # kinds whose terms fill the rows in order, once each: the scatter is a concatenation
        self._rows_in_order = {
            kind: np.array_equal(rows, np.arange(len(rows))) for kind, rows in self._rows.items()
        }
        self._blocks = [(name, b.shape) for name, b in variables.blocks.items()]
        self._jac_patterns = {
            kind: self._jacobian_pattern(kind, sizes[kind]) for kind in ("eq", "ineq")
        }
        self._packed_layout()
        self._grad_cols, self._grad_mask = self._gradient_columns()
        self._hess_pattern, self._hess_mask = self._hessian_pattern()

    # ------------------------------------------------------------------ patterns
    def _packed_layout(self) -> None:
        """Where every term input lives in the packed point (all blocks' arrays raveled and
        concatenated): ``lay.z_index`` is the ``(K, nz)`` gather map that builds the term's
        CasADi input, packed as :meth:`SiteFunction.pack` does, in one fancy index."""
        offset = 0
        flat_index = {}
        for name, b in self.variables.blocks.items():
            size = int(np.prod(b.shape))
            flat_index[name] = b.flat(np.arange(offset, offset + size))
            offset += size
        self._packed_size = offset
        for lays in self._layouts.values():
            for lay in lays:
                f, args = lay.term.function, lay.term.gather(flat_index)
                for sl in f.variables:
                    a = args[sl.name].reshape(lay.term.sites, *sl.shape)
                    part = np.swapaxes(a, 1, -1).reshape(lay.term.sites, -1)
                    lay.z_index[:, sl.offset : sl.offset + sl.size] = part

    def _packed(self, point: Point) -> np.ndarray:
        """The point's blocks raveled into one vector (shapes and finiteness checked)."""
        parts = []
        mapping = type(point) is dict or isinstance(point, Mapping)
        for name, shape in self._blocks:
            a = point.get(name) if mapping else None
            if a is None or np.shape(a) != shape:
                got = "missing" if a is None else f"shape {np.shape(a)}"
                raise InputError(f"point: block {name!r} must have shape {shape}, got {got}")
            parts.append(np.asarray(a, dtype=float).reshape(-1))
        vec = np.concatenate(parts)
        if not np.isfinite(vec).all():
            names = self.variables.blocks
            bad = next(n for n, a in zip(names, parts, strict=True) if not np.isfinite(a).all())
            raise InputError(f"point: block {bad!r} contains NaN or inf")
        return vec

    def _jacobian_pattern(self, kind: str, m: int) -> tuple[SparsePattern, _Mask]:
        rows = [lay.jac_rows.ravel() for lay in self._layouts[kind]]
        cols = [lay.jac_cols.ravel() for lay in self._layouts[kind]]
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
        mask = cols >= 0
        return SparsePattern(rows[mask], cols[mask], (m, self.n)), _Mask(mask)

    def _gradient_columns(self) -> tuple[np.ndarray, _Mask]:
        cols = [lay.jac_cols.ravel() for lay in self._layouts["cost"]]
        cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
        mask = cols >= 0
        return cols[mask], _Mask(mask)

    def _hessian_pattern(self) -> tuple[SparsePattern, _Mask]:
        lays = [lay for kind in ("cost", "eq", "ineq") for lay in self._layouts[kind]]
        rows = np.concatenate([lay.hess_rows.ravel() for lay in lays] or [np.zeros(0, np.int64)])
        cols = np.concatenate([lay.hess_cols.ravel() for lay in lays] or [np.zeros(0, np.int64)])
        mask = cols >= 0
        return SparsePattern(rows[mask], cols[mask], (self.n, self.n)), _Mask(mask)

    # ------------------------------------------------------------------ manifold
    def term_rows(self, kind: str) -> dict[str, np.ndarray]:
        """Rows ``(sites, m)`` of every term of ``kind`` (``"cost"``, ``"eq"``, ``"ineq"``) in
        its residual vector, by term name."""
        return {lay.term.name: lay.rows for lay in self._layouts[kind]}

    def check_point(self, point: Point, what: str = "initial guess") -> Point:
        return self.variables.check_point(point, what)

    def retract(self, point: Point, dx: np.ndarray) -> Point:
        return self.variables.retract(point, dx)

    # ------------------------------------------------------------------ evaluation
    def _scatter(self, kind: str, parts: list[np.ndarray]) -> np.ndarray:
        if self._rows_in_order[kind]:
            return _cat(parts) + 0.0  # what bincount gives: 0 + v (-0.0 becomes 0.0)
        size = self.n_eq if kind == "eq" else self.n_ineq
        return np.bincount(self._rows[kind], weights=_cat(parts), minlength=size)

    def values(self, point: Point) -> tuple[float, np.ndarray, np.ndarray]:
        """Objective, equality and inequality residuals (for line-search trials)."""
        vec = self._packed(point)
        out = {"cost": [], "eq": [], "ineq": []}
        for kind, lays in self._layouts.items():
            for lay in lays:
                r = lay.term.function.call_packed("value", [vec[lay.z_index], lay.parameters])[0]
                out[kind].append(r.ravel())
        f = float(sum(v.sum() for v in out["cost"]))
        return f, self._scatter("eq", out["eq"]), self._scatter("ineq", out["ineq"])

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
        if not (np.isfinite(obj_factor) and np.isfinite(y).all() and np.isfinite(z).all()):
            raise InputError("objective factor or multipliers contain NaN or inf")
        vec = self._packed(point)
        vals = {"cost": [], "eq": [], "ineq": []}
        jacs = {"cost": [], "eq": [], "ineq": []}
        hess = []
        for kind, lays in self._layouts.items():
            for lay in lays:
                t, f = lay.term, lay.term.function
                inputs = [vec[lay.z_index], lay.parameters]
                if hessian:
                    if kind == "cost":
                        lam = np.full((t.sites, 1), float(obj_factor))
                    else:
                        lam = (y if kind == "eq" else z)[lay.rows]
                    r, j, h = f.call_packed("hessian", [*inputs, lam])
                    hess.append(h.ravel())
                else:
                    r, j = f.call_packed("jacobian", inputs)
                vals[kind].append(r.ravel())
                jacs[kind].append(j.ravel())
        grad = np.bincount(
            self._grad_cols, weights=_masked(_cat(jacs["cost"]), self._grad_mask), minlength=self.n
        )
        eq_pat, eq_mask = self._jac_patterns["eq"]
        in_pat, in_mask = self._jac_patterns["ineq"]
        return Evaluation(
            objective=float(_cat(vals["cost"]).sum()),
            gradient=grad,
            eq=self._scatter("eq", vals["eq"]),
            eq_jacobian=eq_pat.assemble(_masked(_cat(jacs["eq"]), eq_mask)),
            ineq=self._scatter("ineq", vals["ineq"]),
            ineq_jacobian=in_pat.assemble(_masked(_cat(jacs["ineq"]), in_mask)),
            hessian_lower=self._hess_pattern.assemble(_masked(_cat(hess), self._hess_mask))
            if hessian
            else None,
        )


def _cat(parts: list[np.ndarray]) -> np.ndarray:
    if len(parts) == 1:
        return parts[0]
    return np.concatenate(parts) if parts else np.zeros(0)


def _masked(values: np.ndarray, mask: _Mask) -> np.ndarray:
    return values if mask.all_true else values[mask.mask]


class _Mask:
    """A boolean mask that knows whether it keeps everything (then no copy is made)."""

    def __init__(self, mask: np.ndarray) -> None:
        self.mask, self.all_true = mask, bool(mask.all())
