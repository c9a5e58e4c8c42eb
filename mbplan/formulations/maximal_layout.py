"""Where a maximal-coordinate RIPM problem keeps each knot's and body's state, joint forces and
multibody rows in its KKT matrix, and the joint elimination plan built from it
(:mod:`mbplan.solvers.kkt.elimination`, factorized by :mod:`mbplan.solvers.kkt.reduced`).

Loop closures are extra rows and columns of the plan: their constraint rows are never local
rows (they stay in the reduced matrix), their multipliers are candidate columns of the first
wrench block of their knot (the dynamics rows of any body may then read them)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.solvers.kkt.elimination import EliminationPlan
from mbplan.transcription.loops import LOOP_BLOCK
from mbplan.workspace import Workspace, shared


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
    tau_cols: np.ndarray  # (N+1, nb, 1) the joint's torque (force) of the step ending at the knot
    kin_rows: np.ndarray  # (N, nb, 6) equality rows of step k
    dyn_rows: np.ndarray  # (N, nb, 6)
    con_rows: np.ndarray  # (N+1, nb, 5) joint constraint h(X_{k+1}) of the body's joint, on s_k
    loop_cols: np.ndarray  # (N+1, m) the loop closures' multipliers
    free: np.ndarray  # (nb,) bool: a body without a joint (a floating base; no λ, τ, h rows)

    @property
    def N(self) -> int:
        return self.kin_rows.shape[0]

    @property
    def nb(self) -> int:
        return self.kin_rows.shape[1]

    def key(self) -> tuple:
        """The layout as a hashable value: equal layouts, equal keys."""
        values = (np.asarray(getattr(self, f.name)) for f in fields(self))
        return tuple((v.shape, v.dtype.str, v.tobytes()) for v in values)

    @property
    def depths(self) -> np.ndarray:
        """Each body's depth: bodies on its path from the world, itself included."""
        d = np.zeros(self.nb, np.int64)
        for c, p in enumerate(self.parent):
            d[c] = 1 + (d[p] if p >= 0 else 0)
        return d

    @property
    def depth(self) -> int:
        """Bodies on the longest path from the world."""
        return int(self.depths.max(initial=0))


WRENCH_MAX_DEPTH = 8
"""The default plan eliminates the joint wrenches too (:func:`joint_elimination_plan`) for body
trees at most this deep: a wrench block is dense over the free coordinates of the body's
subtree and their paths, so its cost grows with the depth (iiwa: 0.88× the joints-only step's
time per iteration, chain8 equal, chain16 1.1–1.3×)."""

SEGMENT_DEPTH = 8
"""The default plan's segment (:func:`joint_elimination_plan`): every 8th body along a path
keeps its maximal coordinates, so that the reduction's blocks stay dense over at most 8 bodies
(chain64: the joints-only step per iteration 0.46× the full factorization's, one segment
0.8×)."""


def maximal_layout(
    problem, eq_jacobian: sp.spmatrix, workspace: Workspace | None = None
) -> MaximalLayout:
    """The :class:`MaximalLayout` of the RIPM problem of :mod:`mbplan.formulations.maximal`
    (revolute and prismatic joints with a constraint row group on every body but the free
    ones) from the
    pattern of its equality Jacobian; kept in ``workspace`` by everything it reads (the blocks'
    tangent coordinates, the equality terms' rows, the pattern): every case of a task family
    has the same."""
    jac = sp.csr_matrix(eq_jacobian)
    v = problem.variables

    def key() -> tuple:
        rows = problem.term_rows("eq").items()
        return (
            problem.n,
            tuple((name, v.tangent_index(name).tobytes()) for name in v.blocks),
            tuple((name, r.shape, r.tobytes()) for name, r in rows),
            jac.shape,
            jac.indptr.tobytes(),
            jac.indices.tobytes(),
        )

    return shared(workspace, "maximal_layout", key, lambda: _layout(problem, jac))


def _layout(problem, jac: sp.csr_matrix) -> MaximalLayout:
    """:func:`maximal_layout`, built."""
    v = problem.variables
    nb = v.blocks["R"].count
    knots = v.blocks["R"].knots

    def cols(name: str) -> np.ndarray:
        idx = v.tangent_index(name)
        return idx.reshape(knots, nb, idx.shape[1])

    s_cols = np.concatenate([cols(n) for n in ("R", "F", "p", "v")], axis=2)
    loops = [n for n in v.blocks if n.startswith(LOOP_BLOCK.format(""))]
    loop_cols = np.concatenate(
        [np.zeros((knots, 0), np.int64), *(v.tangent_index(n).reshape(knots, -1) for n in loops)],
        axis=1,
    )
    body_of_col = np.full(problem.n, -1, np.int64)
    knot_of_col = np.full(problem.n, -1, np.int64)
    kk, bb = np.meshgrid(np.arange(knots), np.arange(nb), indexing="ij")
    listed = s_cols >= 0
    body_of_col[s_cols[listed]] = np.broadcast_to(bb[..., None], s_cols.shape)[listed]
    knot_of_col[s_cols[listed]] = np.broadcast_to(kk[..., None], s_cols.shape)[listed]
    rows_of = problem.term_rows("eq")
    N = knots - 1
    kin_rows = rows_of["body_kinematics"].reshape(N, nb, 6)
    dyn_rows = rows_of["body_dynamics"].reshape(N, nb, 6)
    con_rows = -np.ones((knots, nb, 5), np.int64)
    parent = np.full(nb, -2, np.int64)
    for name, term_rows in rows_of.items():
        if "joint_constraints" not in name or not term_rows.size:
            continue
        # every row group's support: the bodies and knots of its entries (min and max by group)
        starts = jac.indptr[term_rows.ravel()]
        lengths = np.diff(jac.indptr)[term_rows.ravel()]
        counts = lengths.reshape(term_rows.shape).sum(axis=1)
        if np.any(counts == 0):
            raise InputError(f"{name}: a joint constraint row group without entries")
        entry = np.repeat(starts - np.cumsum(lengths) + lengths, lengths) + np.arange(lengths.sum())
        support = jac.indices[entry]
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        b_min, b_max = (f.reduceat(body_of_col[support], first) for f in (np.minimum, np.maximum))
        k_min, k_max = (f.reduceat(knot_of_col[support], first) for f in (np.minimum, np.maximum))
        if np.any(k_min != k_max) or np.any(b_min < 0):  # knot_of_col is set where body_of_col is
            raise InputError(f"{name}: a joint constraint row outside one knot's bodies")
        con_rows[k_min, b_max] = term_rows
        parent[b_max] = np.where(b_min < b_max, b_min, -1)
    # the bodies without a joint constraint are the free ones (a joint slot per other body)
    free = parent == -2
    jointed = np.flatnonzero(~free)
    if v.blocks["lam"].count != len(jointed) or np.any(con_rows[1:, jointed] < 0):
        raise InputError(
            "maximal_layout: every jointed body needs a joint constraint at every knot"
        )
    parent[free] = -1

    def per_body(name: str, width: int) -> np.ndarray:
        out = -np.ones((knots, nb, width), np.int64)
        block = v.blocks.get(name)
        if block is not None and block.count == len(jointed):
            out[:, jointed] = v.tangent_index(name).reshape(knots, len(jointed), width)
        return out

    lam_cols, tau_cols = per_body("lam", 5), per_body("tau", 1)
    if np.any(parent >= np.arange(nb)):
        raise InputError("maximal_layout: bodies must be numbered parents first")
    return MaximalLayout(
        problem.n, problem.n_eq, problem.n_ineq, parent, s_cols, lam_cols, tau_cols, kin_rows,
        dyn_rows, con_rows, loop_cols, free,
    )  # fmt: skip


def joint_elimination_plan(
    problem,
    eq_jacobian: sp.spmatrix,
    forces: bool | None = None,
    segment: int | None = None,
    workspace: Workspace | None = None,
) -> EliminationPlan:
    """The joints eliminated knot by knot (:mod:`mbplan.solvers.kkt.reduced`): for
    steps ``k = 1…N-1`` five of each body's kinematics rows become ``M g - h`` (``h`` its joint
    constraint on ``s_k``, cancelling ``s_k`` of the body and its parent); at knots ``1…N`` the
    block of a body is its state ``s_k`` with those rows of step ``k-1`` (step 0: its six
    kinematics rows) and ``h`` at knot ``k`` as local rows. ``forces``: then, at knots ``1…N``
    and bodies from the leaves to the root, a block of the body's joint wrench (``λ_k`` and
    ``τ_k``) with its six dynamics rows of step ``k-1`` (inverse dynamics: they touch the
    states, which are blocks before, and the wrenches of its children; the reduced matrix shrinks
    ~5×, the reduction's products grow). ``None``: the wrench
    blocks when every joint has a torque and the tree is at most :data:`WRENCH_MAX_DEPTH`
    deep; the loop closures' multipliers of knot ``k`` are candidates of its first wrench
    block. ``segment`` (``None``: :data:`SEGMENT_DEPTH`): the bodies at depths ``segment + 1,
    2 segment + 1, …`` keep their maximal coordinates (state and wrench blocks without local
    rows: their columns stay in the reduced matrix, with their joint constraints, kinematics
    and dynamics rows), so that an eliminated state depends on the free coordinates of at most
    ``segment`` bodies of its path (and on the state of the cut body above them), an
    eliminated wrench on those of its subtree down to the next cut bodies; a tree at most
    ``segment`` deep is one segment. Kept in ``workspace`` by its layout and options (every
    case of a task family has the same)."""
    lay = maximal_layout(problem, eq_jacobian, workspace)
    actuated = bool(np.all(lay.tau_cols[1:] >= 0))
    if forces is None:
        forces = actuated and lay.depth <= WRENCH_MAX_DEPTH
    elif forces and lay.free.any():
        raise InputError(
            "joint_elimination_plan: no wrench blocks for a free body (a floating base)"
        )
    elif forces and not actuated:
        raise InputError("joint_elimination_plan: the wrench blocks need a torque on every joint")
    segment = SEGMENT_DEPTH if segment is None else segment
    if segment < 1:
        raise InputError(f"joint_elimination_plan: segment must be at least 1, got {segment}")
    return shared(
        workspace,
        "elimination_plan",
        lambda: (lay.key(), bool(forces), int(segment)),
        lambda: _plan_of_layout(lay, forces, segment),
    )


def _plan_of_layout(lay: MaximalLayout, forces: bool, segment: int) -> EliminationPlan:
    """:func:`joint_elimination_plan` of a layout, its options resolved (built)."""
    N, nb, parent = lay.N, lay.nb, lay.parent
    depths = lay.depths
    cut = ((depths > 1) & ((depths - 1) % segment == 0)) | lay.free
    m = lay.loop_cols.shape[1]
    width = max(12, 6 + m)  # a wrench block's candidates: λ (5), τ (1), the loops' (first one)
    pad6 = -np.ones(6, np.int64)
    pad11 = -np.ones(11, np.int64)
    pad12 = -np.ones(12, np.int64)
    targets, sources, subtract, cancel = [], [], [], []
    group = -np.ones((N, nb), np.int64)
    for k in range(1, N):
        for c in np.flatnonzero(~cut):
            p = parent[c]
            group[k, c] = len(targets)
            targets.append(lay.kin_rows[k, c])
            sources.append(
                np.concatenate([lay.kin_rows[k, c], lay.kin_rows[k, p] if p >= 0 else pad6])
            )
            subtract.append(lay.con_rows[k, c])
            cancel.append(np.concatenate([lay.s_cols[k, c], lay.s_cols[k, p] if p >= 0 else pad12]))
    groups, rows, cols = [], [], []
    for k in range(1, N + 1):
        for c in range(nb):
            groups.append(group[k - 1, c])
            if cut[c]:
                rows.append(pad11)
            else:
                rows.append(
                    np.concatenate([lay.kin_rows[0, c] if k == 1 else pad6, lay.con_rows[k, c]])
                )
            cols.append(np.concatenate([lay.s_cols[k, c], -np.ones(width - 12, np.int64)]))
    if forces:
        for k in range(1, N + 1):
            for c in range(nb - 1, -1, -1):
                groups.append(-1)
                dyn = pad6 if cut[c] else lay.dyn_rows[k - 1, c]
                rows.append(np.concatenate([dyn, -np.ones(5, np.int64)]))
                extra = lay.loop_cols[k] if c == nb - 1 else np.zeros(0, np.int64)
                wrench = [lay.lam_cols[k, c], lay.tau_cols[k, c], extra]
                cols.append(np.concatenate([*wrench, -np.ones(width - 6 - len(extra), np.int64)]))

    def stack(a: list, width: int) -> np.ndarray:
        return np.asarray(a, np.int64).reshape(len(a), width)

    return EliminationPlan(
        stack(targets, 6), stack(sources, 12), stack(subtract, 5), stack(cancel, 24),
        np.asarray(groups, np.int64), stack(rows, 11), stack(cols, width),
    )  # fmt: skip


class JointEliminationPlans:
    """``problem.elimination_plan`` of a maximal-coordinate problem: the
    :func:`joint_elimination_plan` of the equality Jacobian's pattern, kept for the last
    pattern (every solve of the problem asks for it); ``forces``: with the joint-wrench blocks,
    ``segment``: bodies per segment (``None``: :func:`joint_elimination_plan`'s rules);
    ``workspace``: where layouts and plans are kept (shared by the problems of a family)."""

    def __init__(
        self,
        problem,
        forces: bool | None = None,
        segment: int | None = None,
        workspace: Workspace | None = None,
    ) -> None:
        self.problem, self.forces, self.segment = problem, forces, segment
        self.workspace = workspace
        self._key: tuple[bytes, bytes] | None = None
        self._plan: EliminationPlan | None = None

    def __call__(self, eq_jacobian: sp.spmatrix) -> EliminationPlan:
        jac = sp.csr_matrix(eq_jacobian)
        key = (jac.indptr.tobytes(), jac.indices.tobytes())
        if key != self._key or self._plan is None:
            self._plan, self._key = (
                joint_elimination_plan(
                    self.problem, jac, self.forces, self.segment, self.workspace
                ),
                key,
            )
        return self._plan
