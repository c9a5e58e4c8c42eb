"""Warm start of the multi-body transcription from a joint-space trajectory (RIPM paper §VIII.C).

The configurations give every body's pose ``(R_k, p_k)``, hence ``F_k = R_kᵀR_{k+1}`` and
``v_k = (p_{k+1} - p_k)/Δt`` (eq. 30–32): the kinematics rows and joint constraints hold. At a
fixed configuration the dynamics rows (eq. 27 with 34–35) are linear in the constraint forces
``λ_{k+1}`` and actuation ``τ_{k+1}``, so inverse dynamics in maximal coordinates is a linear
system in the exact Jacobian columns of the ``lam`` and ``tau`` blocks, block diagonal with one
``6nb × 6nb`` block per knot. For a tree of revolute and prismatic joints (every joint actuated)
each block is square and regular, since a joint's 5 multipliers and its torque or force apply a
full 6-D wrench to its child, so the solution is exact and the dynamics rows (with any joint
damping, evaluated on the given motion) vanish up to round-off.
"""

from __future__ import annotations

import warnings

import numpy as np
import numpy.typing as npt
import scipy.sparse.linalg as spla

from mbplan.engine.jit import jit_available
from mbplan.errors import InputError, MbplanError
from mbplan.multibody import MaximalModel, body_poses
from mbplan.transcription.multibody import LAMBDA_DIM, multibody_layout
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.variables import Point, TrajectoryVariables


def maximal_warm_start(
    mm: MaximalModel,
    q_traj: npt.ArrayLike,
    dt: float,
    *,
    N: int | None = None,
    jit: bool | None = None,
) -> Point:
    """A point of ``multibody_layout(mm, N, dt)`` from joint configurations at the knots.

    ``q_traj`` holds the configurations of knots ``0 … N`` (``N`` defaults to ``len(q_traj) - 1``)
    and optionally one more, at ``t = (N+1)Δt``, that defines ``F_N`` and ``v_N``; without it
    the motion stops after knot ``N`` (``F_N = I``, ``v_N = 0``). ``λ_k`` and ``τ_k``
    (``k = 1 … N``) solve the dynamics rows of step ``k-1`` (one sparse solve for all knots);
    knot 0, which no equation uses, repeats knot 1. Raises :class:`MbplanError` if the joint
    forces cannot balance the dynamics (singular system).
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
    poses = [body_poses(mm, qk) for qk in q]
    R = np.array([r for r, _ in poses])
    p = np.array([t for _, t in poses])
    if len(q) == N + 1:
        R = np.concatenate([R, R[-1:]])
        p = np.concatenate([p, p[-1:]])
    F = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    v = (p[1:] - p[:-1]) / dt
    nb = mm.nb
    layout = multibody_layout(mm, N, dt, jit=jit)
    variables = TrajectoryVariables(layout.blocks)
    problem = TrajectoryProblem(variables, layout.terms)
    point = {
        "R": R[: N + 1],
        "p": p[: N + 1],
        "F": F,
        "v": v,
        "lam": np.zeros((N + 1, nb, LAMBDA_DIM)),
        "tau": np.zeros((N + 1, nb, 1)),
    }
    point = {k: a.reshape(variables.blocks[k].shape) for k, a in point.items()}
    ev = problem.evaluate(point, hessian=False)
    lam_idx = variables.tangent_index("lam").reshape(N + 1, nb * LAMBDA_DIM)[1:]
    tau_idx = variables.tangent_index("tau").reshape(N + 1, nb)[1:]
    rows = np.arange(layout.n_dynamics_rows - 6 * N * nb, layout.n_dynamics_rows)
    cols = np.concatenate([lam_idx, tau_idx], axis=1).ravel()  # knot-major, like the rows
    A = ev.eq_jacobian[rows][:, cols].tocsc()  # block diagonal: step k-1 <-> knot k
    with warnings.catch_warnings():
        warnings.simplefilter("error", spla.MatrixRankWarning)
        try:
            x = spla.spsolve(A, -ev.eq[rows]).reshape(N, nb * (LAMBDA_DIM + 1))
        except spla.MatrixRankWarning as err:
            raise MbplanError(
                f"{mm.name}: the joint forces cannot balance the body dynamics rows ({err})"
            ) from err
    lam = np.concatenate([x[:1, : nb * LAMBDA_DIM], x[:, : nb * LAMBDA_DIM]])
    tau = np.concatenate([x[:1, nb * LAMBDA_DIM :], x[:, nb * LAMBDA_DIM :]])
    point["lam"] = lam.reshape(variables.blocks["lam"].shape)
    point["tau"] = tau.reshape(variables.blocks["tau"].shape)
    return point
