"""Where a maximal-coordinate RIPM problem keeps each knot's and body's state, joint forces and
multibody rows in its KKT matrix (for the joint-eliminated KKT study,
:mod:`mbplan.benchmarks.reduced_kkt`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError


@dataclass(frozen=True)
class MaximalLayout:
    """Where the state, joint forces and multibody rows of every knot and body sit in the KKT
    of a maximal-coordinate problem (``-1`` where a knot is data)."""

    n: int
    n_eq: int
    n_ineq: int
    parent: np.ndarray  # (nb,) parent body, -1 for the world; parent < child
    s_cols: np.ndarray  # (N+1, nb, 12) R, F, p, v tangent coordinates
    lam_cols: np.ndarray  # (N+1, nb, 5)
    kin_rows: np.ndarray  # (N, nb, 6) equality rows of step k
    dyn_rows: np.ndarray  # (N, nb, 6)
    con_rows: np.ndarray  # (N+1, nb, 5) joint constraint h(X_{k+1}) of the body's joint, on s_k

    @property
    def N(self) -> int:
        return self.kin_rows.shape[0]

    @property
    def nb(self) -> int:
        return self.kin_rows.shape[1]


def maximal_layout(problem, eq_jacobian: sp.spmatrix) -> MaximalLayout:
    """The :class:`MaximalLayout` of the RIPM problem of :mod:`mbplan.formulations.maximal`
    (revolute and prismatic joints with a constraint row group on every body) from the
    pattern of its equality Jacobian."""
    v = problem.variables
    nb = v.blocks["R"].count
    knots = v.blocks["R"].knots

    def cols(name: str) -> np.ndarray:
        idx = v.tangent_index(name)
        return idx.reshape(knots, nb, idx.shape[1])

    s_cols = np.concatenate([cols(n) for n in ("R", "F", "p", "v")], axis=2)
    lam_cols = cols("lam")
    body_of_col = np.full(problem.n, -1, np.int64)
    knot_of_col = np.full(problem.n, -1, np.int64)
    kk, bb = np.meshgrid(np.arange(knots), np.arange(nb), indexing="ij")
    for c in (s_cols, lam_cols):
        free = c >= 0
        body_of_col[c[free]] = np.broadcast_to(bb[..., None], c.shape)[free]
        knot_of_col[c[free]] = np.broadcast_to(kk[..., None], c.shape)[free]
    rows_of = problem.term_rows("eq")
    N = knots - 1
    kin_rows = rows_of["body_kinematics"].reshape(N, nb, 6)
    dyn_rows = rows_of["body_dynamics"].reshape(N, nb, 6)
    con_rows = -np.ones((knots, nb, 5), np.int64)
    parent = np.full(nb, -2, np.int64)
    jac = sp.csr_matrix(eq_jacobian)
    for name, term_rows in rows_of.items():
        if "joint_constraints" not in name:
            continue
        for rows in term_rows:
            support = np.concatenate([jac.indices[jac.indptr[r] : jac.indptr[r + 1]] for r in rows])
            bodies = np.unique(body_of_col[support])
            k = np.unique(knot_of_col[support])
            if len(k) != 1 or bodies.min() < 0:
                raise InputError(f"{name}: a joint constraint row outside one knot's bodies")
            child = int(bodies.max())
            con_rows[k[0], child] = rows
            parent[child] = int(bodies.min()) if len(bodies) > 1 else -1
    if np.any(parent == -2) or np.any(con_rows[1:] < 0):
        raise InputError("maximal_layout: every body needs a joint constraint at every knot")
    if np.any(parent >= np.arange(nb)):
        raise InputError("maximal_layout: bodies must be numbered parents first")
    return MaximalLayout(
        problem.n, problem.n_eq, problem.n_ineq, parent, s_cols, lam_cols, kin_rows, dyn_rows,
        con_rows,
    )  # fmt: skip
