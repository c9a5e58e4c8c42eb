"""Loop closures in generalized coordinates: the closure rows and the loop forces of eq. (61).

A robot with loops (:mod:`mbplan.robots.loops`) adds to the generalized NLP the imposed closure
rows ``r(q_k) = 0`` (position level) at the state knots ``k = 2..N`` and ``r(q_N + Δt v_N) = 0``,
and on every interval ``k = 0..N-1`` the loop forces ``λ_k`` (one per imposed row) to the
dynamics::

    RNEA(q_k, v_k, a_k) + D v_{k+1} - τ_k - J_c(q_k)ᵀ λ_k = 0,   J_c = ∂r/∂q

(1-dof joints: ``q`` is its own tangent space). Each ``λ_k`` is fixed by one block of rows: the
configuration after the next step, ``q_{k+1} + Δt v_{k+1}``, closes, so every knot velocity is a
secant of the closure manifold (``J_c v_k = O(Δt |v|²)``); the last one closes a virtual knot
``N + 1``. Without that block ``v_N`` and ``λ_{N-1}`` are free along the closure's normals; a
tangent ``J_c(q_N) v_N = 0`` instead contradicts the secant ``v_{N-1}`` and puts an ``O(1)``
acceleration error into the last interval (its replay deviation then shrinks like ``Δt``, the
others' like ``Δt²``). Knot 1, ``q_0 + Δt v_0``, is fixed by the start: :func:`check_first_step`
requires it to close (true at rest), so a plan whose torques are all given is a well-posed
simulation (as many equations as unknowns). A terminal rest constraint makes the last block
redundant with ``r(q_N) = 0``, consistently (IPOPT solves the four-bar's rest-to-rest plans in
7 iterations at N = 20 and 40).

``r`` is built on the symbolic forward kinematics of
:func:`~mbplan.formulations.joint_space.symbolic_placements` with
:func:`~mbplan.robots.loops.loop_residual`, so ``J_c`` and the Hessian of ``μᵀ J_c(q)ᵀ λ`` are
CasADi's exact derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.formulations.joint_space import symbolic_placements
from mbplan.ocp.problem import LOOP_START_TOLERANCE
from mbplan.robots.loops import closure_residual, loop_residual
from mbplan.robots.robot import Robot


@dataclass(frozen=True, eq=False)
class LoopFunctions:
    """The closure rows ``r(q)`` ``(nc,)``, their Jacobian ``J_c(q)`` ``(nc, nv)`` and the loop
    forces' term ``-J_c(q)ᵀ λ`` of the dynamics rows as a function of ``x = (q, λ)``."""

    size: int
    closure: cs.Function
    jacobian: cs.Function
    force: cs.Function


def symbolic_closure(robot: Robot, q: cs.SX) -> cs.SX:
    """The imposed rows of every loop of ``robot`` at the symbolic ``q`` (stacked)."""
    model = robot.model
    placements = symbolic_placements(model, q)
    parts = []
    for loop in robot.loops:
        frames = []
        for joint, M in ((loop.joint1, loop.placement1), (loop.joint2, loop.placement2)):
            R, p = placements[model.getJointId(joint)]
            frames += [cs.mtimes(R, cs.DM(M[:3, :3])), p + cs.mtimes(R, cs.DM(M[:3, 3]))]
        full = loop_residual(loop.kind, *frames, xp=cs)
        parts += [full[int(i)] for i in loop.rows]
    return cs.vertcat(*parts)


# process-wide cache, result-neutral: CasADi functions of the robot's loops alone
@lru_cache(maxsize=16)
def loop_functions(robot: Robot) -> LoopFunctions:
    """:class:`LoopFunctions` of a robot with loops (built once per robot)."""
    nv = robot.nv
    x = cs.SX.sym("x", nv + sum(loop.dim for loop in robot.loops))
    q, lam = x[:nv], x[nv:]
    r = symbolic_closure(robot, q)
    J = cs.jacobian(r, q)
    return LoopFunctions(
        size=r.numel(),
        closure=cs.Function("closure", [q], [r]),
        jacobian=cs.Function("closure_jacobian", [q], [J]),
        force=cs.Function("loop_force", [x], [-cs.mtimes(J.T, lam)]),
    )


def loop_blocks(
    nlp: Any, loops: LoopFunctions, row: int
) -> list[tuple[cs.SX, cs.SX, np.ndarray, int]]:
    """``(x, rows(x), columns (K, nx) in z, first row)`` of the loops' blocks of the
    generalized NLP ``nlp``: the closure rows ``r(q_k)``, ``k = 2..N``, and ``r(q_N + Δt v_N)``
    (:func:`loop_rows` rows from ``row`` on), and the loop forces'
    ``-J_c(q_k)ᵀλ_k``, ``k = 0..N-1``, added to the dynamics rows (interval 0 at the fixed
    ``q_0``)."""
    N, nv, nc = nlp.N, nlp.nv, loops.size
    q, x, y = cs.SX.sym("q", nv), cs.SX.sym("x", nv + nc), cs.SX.sym("y", 2 * nv)
    lam = cs.SX.sym("lam", nc)
    inner, last = np.arange(1, N), np.array([N])
    forces = np.concatenate([nlp.iq(inner), nlp.ilam(inner)], axis=1)
    first = loops.force(cs.vertcat(cs.DM(nlp.ocp.q0), lam))
    return [
        (q, loops.closure(q), nlp.iq(np.arange(2, N + 1)), row),
        (
            y,
            loops.closure(y[:nv] + nlp.dt * y[nv:]),
            np.concatenate([nlp.iq(last), nlp.iv(last)], axis=1),
            row + (N - 1) * nc,
        ),
        (x, loops.force(x), forces, (N + 1) * nv),
        (lam, first, nlp.ilam(np.arange(1)), N * nv),
    ]


def loop_rows(N: int, loops: LoopFunctions) -> int:
    """How many rows :func:`loop_blocks` adds: ``N`` times the imposed closure rows."""
    return N * loops.size


def check_first_step(robot: Robot, q0: np.ndarray, v0: np.ndarray, dt: float) -> None:
    """:class:`InputError` unless knot 1, ``q_0 + Δt v_0``, closes the loops within
    :data:`~mbplan.ocp.problem.LOOP_START_TOLERANCE` (module docstring)."""
    gap = float(np.max(np.abs(closure_residual(robot.model, robot.loops, q0 + dt * v0))))
    if gap > LOOP_START_TOLERANCE:
        names = ", ".join(loop.name for loop in robot.loops)
        raise InputError(
            f"the first step q0 + dt v0 does not close the loops ({names}): residual {gap:.3g}; "
            "the generalized transcription (explicit Euler) needs it closed: start at rest "
            "(v0 = 0)"
        )


def guess_forces(
    robot: Robot, loops: LoopFunctions, q: np.ndarray, demand: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Loop forces ``λ (K, nc)`` and torques ``τ (K, nv)`` with ``τ_k + J_c(q_k)ᵀλ_k =
    demand_k`` (the inverse dynamics): ``λ_k`` the least-squares solution of the passive joints'
    rows (``τ = 0`` there; ``λ = 0`` without passive joints), ``τ`` the rest."""
    passive = robot.joint_indices(robot.passive)
    lam = np.zeros((len(q), loops.size))
    for k, qk in enumerate(q):
        A = np.asarray(loops.jacobian(qk))[:, passive].T
        if A.size:
            lam[k] = np.linalg.lstsq(A, demand[k, passive], rcond=None)[0]
    pull = [np.asarray(loops.jacobian(qk)).T @ lk for qk, lk in zip(q, lam, strict=True)]
    return lam, demand - np.array(pull)
