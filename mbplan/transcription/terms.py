"""A term evaluates one :class:`~mbplan.engine.SiteFunction` (CasADi or callback) at ``K`` sites.

Each function argument is bound to a block and, per site, the flat index of an element of that
block (``knot * count + element``). :meth:`Term.at_knots` covers the common case: with
``bind={"R0": ("R", 0), "R1": ("R", 1)}`` and ``knots=range(N)``, site ``k`` evaluates the
function on ``R[k], R[k+1]``. Parameters are shared (one value) or per site (leading dim ``K``).

Residual rows are fresh by default; ``rows`` (K, m) instead adds the term into rows that other
terms of the same kind own (e.g. joint constraint forces into the bodies' dynamics rows).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from mbplan.engine import SiteFunction
from mbplan.errors import InputError

Kind = Literal["cost", "eq", "ineq"]


@dataclass
class Term:
    """``kind`` is ``"cost"`` (scalar residual, summed), ``"eq"`` (r = 0) or ``"ineq"`` (r ≤ 0)."""

    name: str
    kind: Kind
    function: SiteFunction
    bind: Mapping[str, tuple[str, np.ndarray]]
    parameters: Mapping[str, Any] = field(default_factory=dict)
    rows: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("cost", "eq", "ineq"):
            raise InputError(
                f"term {self.name!r}: kind must be cost, eq or ineq, got {self.kind!r}"
            )
        if self.kind == "cost" and self.function.m != 1:
            raise InputError(
                f"term {self.name!r}: a cost must be scalar, got {self.function.m} rows"
            )
        names = {s.name for s in self.function.variables}
        if set(self.bind) != names:
            raise InputError(
                f"term {self.name!r}: bind {sorted(self.bind)} must name {sorted(names)}"
            )
        self.bind = {
            a: (blk, np.asarray(ix, dtype=np.int64).ravel()) for a, (blk, ix) in self.bind.items()
        }
        sizes = {len(ix) for _, ix in self.bind.values()}
        if len(sizes) != 1:
            raise InputError(
                f"term {self.name!r}: bound index arrays differ in length {sorted(sizes)}"
            )
        self.sites = sizes.pop()
        if self.rows is not None:
            self.rows = np.asarray(self.rows, dtype=np.int64)
            if self.rows.shape != (self.sites, self.function.m):
                raise InputError(
                    f"term {self.name!r}: rows must have shape {(self.sites, self.function.m)}"
                )
            if self.rows.size and self.rows.min() < 0:
                raise InputError(f"term {self.name!r}: rows must be non-negative")

    @classmethod
    def at_knots(
        cls,
        name: str,
        kind: Kind,
        function: SiteFunction,
        bind: Mapping[str, tuple[str, int]],
        knots: Sequence[int],
        parameters: Mapping[str, Any] | None = None,
    ) -> Term:
        """Bind each argument to ``block[k + offset]`` for every ``k`` in ``knots``."""
        k = np.asarray(knots, dtype=np.int64)
        return cls(
            name,
            kind,
            function,
            {a: (b, k + off) for a, (b, off) in bind.items()},
            parameters or {},
        )

    def gather(self, flat_point: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The function's variables at every site, from blocks flattened to ``(knots*count, …)``."""
        return {arg: flat_point[block][ix] for arg, (block, ix) in self.bind.items()}

    def tangent_columns(self, index: Mapping[str, np.ndarray]) -> np.ndarray:
        """``(K, n_f)`` global tangent coordinate of each local coordinate (``-1`` if fixed)."""
        cols = np.empty((self.sites, self.function.n), dtype=np.int64)
        for s in self.function.variables:
            block, ix = self.bind[s.name]
            cols[:, s.tangent] = index[block][ix]
        return cols
