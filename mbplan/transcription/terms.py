"""A term applies one :class:`~mbplan.engine.RiemannianFunction` at a range of knots.

Each function argument is bound to a block and a knot offset: with ``bind={"R0": ("R", 0),
"R1": ("R", 1)}`` and ``knots=range(N)``, knot ``k`` evaluates the function on ``R[k], R[k+1]``.
Parameters are either shared (one value) or per knot (leading dimension ``len(knots)``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError

Kind = Literal["cost", "eq", "ineq"]


@dataclass
class Term:
    """``kind`` is ``"cost"`` (scalar residual, summed), ``"eq"`` (r = 0) or ``"ineq"`` (r ≤ 0)."""

    name: str
    kind: Kind
    function: RiemannianFunction
    bind: Mapping[str, tuple[str, int]]
    knots: Sequence[int]
    parameters: Mapping[str, Any] = field(default_factory=dict)

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
        self.knots = np.asarray(self.knots, dtype=np.int64)

    @property
    def rows(self) -> int:
        """Number of scalar residuals of the term over all its knots."""
        return len(self.knots) * self.function.m

    def gather(self, point: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The function's variables at every knot of the term, as ``(K, *shape)`` arrays."""
        return {arg: point[block][self.knots + off] for arg, (block, off) in self.bind.items()}

    def tangent_columns(self, index: Mapping[str, np.ndarray]) -> np.ndarray:
        """``(K, n_f)`` global tangent coordinate of each local coordinate (``-1`` if fixed)."""
        cols = np.empty((len(self.knots), self.function.n), dtype=np.int64)
        for s in self.function.variables:
            block, off = self.bind[s.name]
            cols[:, s.tangent] = index[block][self.knots + off]
        return cols
