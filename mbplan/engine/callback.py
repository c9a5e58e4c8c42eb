"""Site functions evaluated by NumPy code that supplies its own Riemannian derivatives.

For residuals that CasADi cannot express, such as distances computed by coal: the code receives
the variables of all ``K`` sites at once and returns values, Jacobian nonzeros and lower-triangle
Hessian nonzeros of ``λᵀr`` in the fixed patterns given at construction, exactly like a
:class:`~mbplan.engine.RiemannianFunction`, so the transcription treats both alike and
:func:`~mbplan.engine.check_derivatives` checks both along the retraction.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from mbplan.engine.site_function import ORDER, SiteFunction
from mbplan.errors import InputError

# evaluate(variables {name: (K, *shape)}, parameters (K, np), multipliers (K, m) or None,
#          order 0/1/2) -> [r (K, m)] + [jac_nz (K, jac_nnz)] + [hess_nz (K, hess_nnz)]
Evaluate = Callable[[dict[str, np.ndarray], np.ndarray, np.ndarray | None, int], list[np.ndarray]]


class CallbackFunction(SiteFunction):
    """A residual with ``m`` rows evaluated by ``evaluate`` (see the module docstring).

    ``jacobian_pattern = (rows, cols)`` and ``hessian_pattern = (rows, cols)`` (lower triangle,
    ``rows >= cols``) fix the order of the nonzeros ``evaluate`` returns.
    """

    def __init__(
        self,
        name: str,
        variables: Sequence[tuple[str, Any]],
        parameters: Sequence[tuple[str, int | tuple[int, ...]]],
        m: int,
        jacobian_pattern: tuple[Sequence[int], Sequence[int]],
        hessian_pattern: tuple[Sequence[int], Sequence[int]],
        evaluate: Evaluate,
    ) -> None:
        super().__init__(name, variables, parameters)
        self.m = m
        self.jac_rows, self.jac_cols = (np.asarray(a, dtype=np.int64) for a in jacobian_pattern)
        self.hess_rows, self.hess_cols = (np.asarray(a, dtype=np.int64) for a in hessian_pattern)
        if (
            np.any(self.jac_rows >= m)
            or np.any(self.jac_cols >= self.n)
            or np.any(self.hess_rows >= self.n)
            or np.any(self.hess_rows < self.hess_cols)
        ):
            raise InputError(f"{name}: sparsity patterns outside (m, n) or not lower triangular")
        self._evaluate = evaluate

    def __repr__(self) -> str:
        return (
            f"CallbackFunction({self.name!r}, m={self.m}, n={self.n}, "
            f"nnz_jac={self.jac_nnz}, nnz_hess={self.hess_nnz})"
        )

    def _call(self, kind: str, inputs: list[np.ndarray]) -> list[np.ndarray]:
        z, p, *lam = inputs
        order = ORDER[kind]
        outs = self._evaluate(self.unpack_variables(z), p, lam[0] if lam else None, order)
        K = len(z)
        for out, width in zip(outs, self._output_widths(kind), strict=True):
            if out.shape != (K, width):
                raise InputError(
                    f"{self.name}: callback returned {out.shape}, expected {(K, width)}"
                )
        return outs
