"""An elimination plan: which equality rows and primal columns of the KKT matrix
(:mod:`mbplan.solvers.kkt.system`) form small nonsingular pairs that
:class:`~mbplan.solvers.kkt.reduced.system.ReducedKKTSystem` eliminates exactly before the sparse
LDLᵀ. Pure index arrays, supplied by the problem (``problem.elimination_plan(eq_jacobian)``):
the solver knows nothing of what the rows mean.

Two congruences of ``K`` (rows padded with ``-1``):

1. *row groups* (dual): group ``j`` replaces ``r`` of its ``targets`` by the combinations
   ``M_j A[sources] - A[subtract]`` with ``M_j = A[subtract, cancel] A[sources, cancel]⁺``
   (``r = len(subtract)``), which vanish on the columns ``cancel`` (the caller guarantees that
   ``A[subtract, cancel]`` lies in the row span of ``A[sources, cancel]``; the round-off left
   there is dropped, and iterative refinement against ``K`` removes its effect);
2. *blocks* (primal): block ``b``'s local rows (the new rows of group ``groups[b]``, if any, and
   ``rows[b]``) touch only its candidate ``cols[b]`` and columns of earlier blocks; as many
   of its columns as it has local rows become dependent, ``x_dep = u - E x_free``, and the pair
   (dependent columns, local rows) drops out of the reduced matrix with inertia ``(m, m, 0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbplan.errors import InputError

PLAN_ERRORS = (InputError, ValueError, IndexError, KeyError, np.linalg.LinAlgError)
"""What building a reduction from a plan that does not fit the matrix raises."""


@dataclass(frozen=True)
class EliminationPlan:
    """Index arrays of the two congruences (module docstring); ``-1`` pads rows."""

    group_targets: np.ndarray  # (J, t) rows of which r are replaced
    group_sources: np.ndarray  # (J, g) rows combined (targets among them)
    group_subtract: np.ndarray  # (J, r)
    group_cancel: np.ndarray  # (J, c) columns where the combinations vanish
    block_groups: np.ndarray  # (B,) group whose new rows are local to the block, or -1
    block_rows: np.ndarray  # (B, q) further local rows
    block_cols: np.ndarray  # (B, p) candidate columns

    def __post_init__(self) -> None:
        J, B = len(self.group_targets), len(self.block_cols)
        for name in ("group_sources", "group_subtract", "group_cancel"):
            if len(getattr(self, name)) != J:
                raise InputError(f"EliminationPlan.{name}: expected {J} groups")
        for name in ("block_groups", "block_rows"):
            if len(getattr(self, name)) != B:
                raise InputError(f"EliminationPlan.{name}: expected {B} blocks")
        if np.any(self.block_groups >= J):
            raise InputError("EliminationPlan.block_groups: a group out of range")
        used = self.block_groups[self.block_groups >= 0]
        if len(np.unique(used)) != len(used):
            raise InputError("EliminationPlan.block_groups: a group's rows in two blocks")
        if len(used) != J:
            raise InputError(
                f"EliminationPlan.block_groups: {J - len(used)} of {J} groups in no block "
                "(a group's new rows must be local to a block)"
            )
        r = (self.group_subtract >= 0).sum(axis=1)
        if np.any(r > (self.group_targets >= 0).sum(axis=1)):
            raise InputError("EliminationPlan: a group replaces more rows than it targets")
        local = (self.block_rows >= 0).sum(axis=1) + np.append(r, 0)[self.block_groups]
        if np.any(local > (self.block_cols >= 0).sum(axis=1)):
            raise InputError("EliminationPlan: a block has more local rows than columns")

    @property
    def n_groups(self) -> int:
        return len(self.group_targets)

    @property
    def n_blocks(self) -> int:
        return len(self.block_cols)
