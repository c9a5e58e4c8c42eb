"""Warm start of the multi-body transcription from a joint-space trajectory (RIPM paper §VIII.C).

The configurations give every body's pose ``(R_k, p_k)``, hence ``F_k = R_kᵀR_{k+1}`` and
``v_k = (p_{k+1} - p_k)/Δt`` (eq. 30–32): the kinematics rows and joint constraints hold. At a
fixed configuration the dynamics rows (eq. 27 with 34–35) are linear in the constraint forces
``λ_{k+1}`` and actuation ``τ_{k+1}``, so inverse dynamics in maximal coordinates is a linear
system in the exact Jacobian columns of the ``lam`` and ``tau`` blocks, block diagonal with one
``6nb × 6nb`` block per knot. For a tree of revolute and prismatic joints (every joint actuated)
each block is square and regular, since a joint's 5 multipliers and its torque or force apply a
full 6-D wrench to its child, so the solution is exact and the dynamics rows (with any joint
damping, evaluated on the given motion) vanish up to round-off. Loop closures add their
multipliers as unknowns and passive joints take no torque: a mechanism with as many actuators as
degrees of freedom has square blocks again; otherwise each block is solved in the least-squares
sense (minimum norm: the forces distributed between the joints and the closures). A floating
base has no joint: its six rows per knot are balanced only by a motion that the joints can
produce (least squares otherwise: the warm start leaves the base's dynamics residual).
"""

from __future__ import annotations

import threading

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mbplan.engine.jit import jit_available
from mbplan.errors import InputError, MbplanError
from mbplan.multibody import MaximalModel, body_poses
from mbplan.transcription.loops import loop_blocks, multiplier_blocks
from mbplan.transcription.multibody import LAMBDA_DIM, multibody_layout
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import Point, TrajectoryVariables
from mbplan.workspace import Workspace, shared


def maximal_warm_start(
    mm: MaximalModel,
    q_traj: npt.ArrayLike,
    dt: float,
    *,
    N: int | None = None,
    jit: bool | None = None,
    workspace: Workspace | None = None,
    passive: tuple[int, ...] = (),
) -> Point:
    """A point of ``multibody_layout(mm, N, dt)`` from joint configurations at the knots.

    ``q_traj`` holds the configurations of knots ``0 … N`` (``N`` defaults to ``len(q_traj) - 1``)
    and optionally one more, at ``t = (N+1)Δt``, that defines ``F_N`` and ``v_N``; without it
    the motion stops after knot ``N`` (``F_N = I``, ``v_N = 0``). ``λ_k``, ``τ_k`` and the loop
    closures' multipliers (``k = 1 … N``) solve the dynamics rows of step ``k-1`` (one block per
    knot; least squares if it is not square, module docstring) with zero torque on the
    ``passive`` bodies' joints; knot 0, which no equation uses, repeats knot 1. Raises
    :class:`MbplanError` if the joint forces cannot balance the dynamics (singular system).
    ``workspace``: where the dynamics rows' problem is kept (shared by the warm starts of a
    problem family).
    """
    q = np.asarray(q_traj, dtype=float)
    N = len(q) - 1 if N is None else N
    if q.ndim != 2 or q.shape[1] != mm.nq or N < 1 or len(q) not in (N + 1, N + 2):
        raise InputError(
            f"q_traj must have shape (N+1, {mm.nq}) or (N+2, {mm.nq}) with N >= 1, "
            f"got {q.shape} for N={N}"
        )
    if not np.all(np.isfinite(q)) or not dt > 0:
        raise InputError("q_traj must be finite and dt > 0")
    jit = jit_available() if jit is None else jit
    R, p = body_poses(mm, q)
    if len(q) == N + 1:
        R = np.concatenate([R, R[-1:]])
        p = np.concatenate([p, p[-1:]])
    F = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    v = (p[1:] - p[:-1]) / dt
    nb = mm.nb
    passive = tuple(sorted({int(b) for b in passive}))
    if any(not 0 <= b < nb or mm.free[b] for b in passive):
        raise InputError(f"passive: bodies {passive} are not jointed bodies of 0..{nb - 1}")
    dynamics = _dynamics_rows(mm, N, float(dt), bool(jit), workspace, passive)
    blocks = dynamics.variables.blocks
    m = sum(lp.dim for lp in mm.loops)
    point = {
        "R": R[: N + 1],
        "p": p[: N + 1],
        "F": F,
        "v": v,
        "lam": np.zeros((N + 1, mm.nj, LAMBDA_DIM)),
        "tau": np.zeros((N + 1, mm.nj, 1)),
    } | multiplier_blocks(mm, np.zeros((N + 1, m)))
    point = {k: a.reshape(blocks[k].shape) for k, a in point.items()}
    x = dynamics.solve(point).reshape(N, -1)
    x = np.concatenate([x[:1], x])  # knot 0 repeats knot 1
    nl, active = mm.nj * LAMBDA_DIM, dynamics.active
    tau = np.zeros((N + 1, mm.nj))
    tau[:, active] = x[:, nl : nl + len(active)]
    point["lam"] = x[:, :nl].reshape(blocks["lam"].shape)
    point["tau"] = tau.reshape(blocks["tau"].shape)
    at = nl + len(active)
    for block in loop_blocks(mm, N):  # the unknowns' order (_DynamicsRows)
        size = block.count * block.group.dim
        point[block.name] = x[:, at : at + size].reshape(block.shape)
        at += size
    return point


# largest knot block (6 nb) solved densely: one batched LAPACK solve beats SuperLU up to here
# (iiwa, 42: 0.7 vs 1.1 ms for 40 knots; chain16, 96: 2.9 vs 1.7 ms; chain64, 384: 76 vs 7 ms)
DENSE_BLOCK_MAX = 64


class _DynamicsRows:
    """The dynamics rows of ``multibody_layout(mm, N, dt)`` as the warm start solves them for
    ``λ_k``, the torques ``τ_k`` of the joints not ``passive`` and the loops' multipliers (knots
    1 … N): one ``6nb × d`` block per knot, gathered from the Jacobian's fixed pattern. Shared by
    every warm start of its key (evaluated under a lock)."""

    def __init__(
        self,
        mm: MaximalModel,
        N: int,
        dt: float,
        jit: bool,
        workspace: Workspace | None = None,
        passive: tuple[int, ...] = (),
    ) -> None:
        layout = multibody_layout(mm, N, dt, jit=jit, workspace=workspace)
        self.name = mm.name
        self.variables = TrajectoryVariables(layout.blocks)
        self.problem = TrajectoryProblem(self.variables, layout.terms, workspace)
        self.lock = threading.Lock()
        nb, nj = mm.nb, mm.nj
        self.rows = np.arange(layout.n_dynamics_rows - 6 * N * nb, layout.n_dynamics_rows)
        passive_slots = mm.joint_slot[np.asarray(passive, dtype=np.int64)]
        self.active = np.setdiff1d(np.arange(nj), passive_slots)  # joint slots with a torque
        index = self.variables.tangent_index
        parts = [
            index("lam").reshape(N + 1, nj * LAMBDA_DIM)[1:],
            index("tau").reshape(N + 1, nj)[1:, self.active],
            *(index(b.name).reshape(N + 1, -1)[1:] for b in loop_blocks(mm, N)),
        ]
        # knot-major, like the rows: step k-1's rows and knot k's columns form block k-1
        self.cols = np.concatenate(parts, axis=1).ravel()
        self.N, self.d, self.c = N, 6 * nb, len(self.cols) // N
        self._entries: tuple[np.ndarray, ...] | None = None

    def solve(self, point: Point) -> np.ndarray:
        """The unknowns (class docstring) of knots 1 … N, knot-major, that zero the dynamics rows
        at ``point`` (whose forces are 0; least squares, minimum norm, for blocks that are not
        square); :class:`MbplanError` if a square block is singular."""
        with self.lock:
            ev = self.problem.evaluate(point, hessian=False)
            if self._entries is None:
                self._entries = self._block_entries(ev.eq_jacobian)
        src, row, col, flat = self._entries
        values, b = ev.eq_jacobian.data[src], -ev.eq[self.rows]
        N, d, c = self.N, self.d, self.c
        try:
            if d <= DENSE_BLOCK_MAX or c != d:
                A = np.zeros((N, d, c))
                A.ravel()[flat] = values
                return _block_solve(A, b.reshape(N, d, 1)).ravel()
            A = sp.csc_matrix((values, (row, col)), shape=(N * d, N * c))
            return spla.splu(A).solve(b)
        except (np.linalg.LinAlgError, RuntimeError) as err:  # RuntimeError: SuperLU's singular
            raise MbplanError(
                f"{self.name}: the joint forces cannot balance the body dynamics rows ({err})"
            ) from err

    def _block_entries(self, jac: sp.csr_matrix) -> tuple[np.ndarray, ...]:
        """Which nonzeros of the equality Jacobian (fixed pattern) are the blocks' entries, with
        their row and column in the block-diagonal matrix and their place in ``(N, d, d)``."""
        row_of = np.full(jac.shape[0], -1)
        row_of[self.rows] = np.arange(len(self.rows))
        col_of = np.full(jac.shape[1], -1)
        col_of[self.cols] = np.arange(len(self.cols))
        row = row_of[np.repeat(np.arange(jac.shape[0]), np.diff(jac.indptr))]  # per nonzero
        col = col_of[jac.indices]
        src = np.flatnonzero((row >= 0) & (col >= 0))
        row, col = row[src], col[src]
        d, c = self.d, self.c
        if np.any(row // d != col // c):  # the layout ties step k-1 to knot k only
            raise MbplanError("the warm start's dynamics rows are not block diagonal")
        return src, row, col, (row // d) * d * c + (row % d) * c + col % c


def _block_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x`` of every block ``A x = b`` (``(N, d, c)``, ``(N, d, 1)``): square blocks exactly,
    tall ones (a floating base: more rows than forces) by least squares through the normal
    equations (one batched Cholesky solve; as exact as the SVD's pseudo-inverse for blocks of
    full column rank, 100× faster: solo12's 20 blocks 78 × 66 in 1.5 ms instead of 0.16 s),
    wide ones (loop closures) at minimum norm, and rank-deficient tall ones, by the
    pseudo-inverse."""
    d, c = A.shape[1:]
    if c == d:
        return np.linalg.solve(A, b)
    if c < d:
        At = np.swapaxes(A, 1, 2)
        try:
            np.linalg.cholesky(At @ A)
            return np.linalg.solve(At @ A, At @ b)
        except np.linalg.LinAlgError:
            pass
    return np.linalg.pinv(A) @ b


def _dynamics_rows(
    mm: MaximalModel,
    N: int,
    dt: float,
    jit: bool,
    workspace: Workspace | None = None,
    passive: tuple[int, ...] = (),
) -> _DynamicsRows:
    return shared(
        workspace,
        "dynamics_rows",
        lambda: (mm, N, dt, jit, passive),
        lambda: _DynamicsRows(mm, N, dt, jit, workspace, passive),
    )
