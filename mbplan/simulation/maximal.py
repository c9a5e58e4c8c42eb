"""Forward simulation of the maximal-coordinate LGVI: one Newton solve per step (§V.A).

Given ``x_k``, ``x_{k+1} = (R_k F_k, p_k + v_k Δt)`` is explicit; the unknowns of a step are
``F_{k+1}, v_{k+1}`` of every body and ``λ_{k+1}`` of every joint and loop closure, solved from
the body LGVI rows and the joint and closure constraints on ``x_{k+2}`` with the engine's exact
Riemannian Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from mbplan.engine.jit import jit_available
from mbplan.errors import InputError, MbplanError
from mbplan.lie import SO3
from mbplan.multibody import MaximalModel, body_poses
from mbplan.multibody.loops import loop_residuals
from mbplan.transcription.loops import multiplier_blocks, stack_multipliers
from mbplan.transcription.multibody import LAMBDA_DIM, multibody_layout
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import TrajectoryVariables

CLOSURE_TOLERANCE = 1e-8  # m or rad: how far the start configurations may be off a loop closure


@dataclass(frozen=True)
class MaximalTrajectory:
    """States at knots ``0 … N`` (``F_k``, ``v_k`` map knot ``k`` to ``k+1``)."""

    R: np.ndarray  # (N+1, nb, 3, 3)
    p: np.ndarray  # (N+1, nb, 3)
    F: np.ndarray  # (N+1, nb, 3, 3)
    v: np.ndarray  # (N+1, nb, 3)
    lam: np.ndarray  # (N+1, nj, 5) per joint slot (MaximalModel.jointed)
    newton_iterations: np.ndarray  # (N,)
    max_residual: float  # worst ‖step residual‖∞ at convergence
    loop_lam: np.ndarray  # (N+1, m) multipliers of the loop closures (mm.loops order)


def initial_state(mm: MaximalModel, q0: np.ndarray, q1: np.ndarray, dt: float) -> tuple:
    """``(R₀, p₀, F₀, v₀)`` from the configurations at ``t = 0`` and ``t = Δt``.

    Both knots satisfy the joint constraints exactly; ``F₀ = R₀ᵀR₁``, ``v₀ = (p₁ - p₀)/Δt``.
    :class:`InputError` if either does not close the loop closures (within
    :data:`CLOSURE_TOLERANCE`).
    """
    R0, p0 = body_poses(mm, q0)
    R1, p1 = body_poses(mm, q1)
    for name, (R, p) in (("q0", (R0, p0)), ("q1", (R1, p1))):
        gap = float(np.max(np.abs(loop_residuals(mm.loops, R, p)), initial=0.0))
        if gap > CLOSURE_TOLERANCE:
            names = ", ".join(lp.name for lp in mm.loops)
            raise InputError(
                f"{name} does not close the loops ({names}): residual {gap:.3g} > "
                f"{CLOSURE_TOLERANCE:g} (mbplan.robots.loops.close_loops)"
            )
    return R0, p0, np.swapaxes(R0, -1, -2) @ R1, (p1 - p0) / dt


def simulate_maximal(
    mm: MaximalModel,
    q0: np.ndarray,
    q1: np.ndarray,
    tau: np.ndarray,
    dt: float,
    N: int,
    *,
    tol: float = 1e-12,
    max_newton: int = 20,
    jit: bool | None = None,
) -> MaximalTrajectory:
    """Simulate ``N`` steps from configurations ``q0`` (t = 0) and ``q1`` (t = Δt).

    ``tau``: joint torques (forces for prismatic joints), ``(nj,)`` constant or ``(N+1, nj)``
    per knot, one per joint slot (:attr:`MaximalModel.jointed`: every body but a floating base;
    knot 0 unused; knot ``k`` acts at ``t = kΔt``). Joints with ``mm.damping > 0``
    are damped (:mod:`mbplan.dynamics.damping`). Both configurations must close ``mm.loops``
    (:func:`initial_state`).
    """
    jit = jit_available() if jit is None else jit
    if N < 1 or dt <= 0:
        raise InputError(f"need N >= 1 and dt > 0, got N={N}, dt={dt}")
    tau = np.asarray(tau, dtype=float)
    if tau.shape not in ((mm.nj,), (N + 1, mm.nj)):
        raise InputError(f"tau: expected shape ({mm.nj},) or ({N + 1}, {mm.nj}), got {tau.shape}")
    tau = np.broadcast_to(tau, (N + 1, mm.nj))
    if not np.all(np.isfinite(tau)):
        raise InputError("tau contains NaN or inf")
    layout = multibody_layout(mm, 1, dt, jit=jit, kinematics=False, fixed_tau_knots=(0, 1))
    variables = TrajectoryVariables(layout.blocks)
    problem = TrajectoryProblem(variables, layout.terms)
    if problem.n != problem.n_eq:
        raise MbplanError(
            f"one LGVI step is not square: {problem.n} unknowns, {problem.n_eq} equations"
        )

    nb = mm.nb
    R, p, F, v = (np.empty((N + 1, nb, *s)) for s in ((3, 3), (3,), (3, 3), (3,)))
    lam = np.zeros((N + 1, mm.nj, LAMBDA_DIM))
    loop_lam = np.zeros((N + 1, sum(lp.dim for lp in mm.loops)))
    R[0], p[0], F[0], v[0] = initial_state(mm, q0, q1, dt)
    iterations = np.zeros(N, dtype=int)
    worst = 0.0
    for k in range(N):
        R[k + 1] = R[k] @ F[k]
        p[k + 1] = p[k] + v[k] * dt
        # Constant-acceleration predictor for the unknowns of the step.
        F_guess = F[k] @ SO3.exp(SO3.log(np.swapaxes(F[k - 1], -1, -2) @ F[k])) if k else F[k]
        v_guess = 2 * v[k] - v[k - 1] if k else v[k] + mm.gravity * dt
        point = {
            "R": R[k : k + 2],
            "p": p[k : k + 2],
            "F": np.stack([F[k], F_guess]),
            "v": np.stack([v[k], v_guess]),
            "lam": np.stack([lam[k], lam[k]]),
            "tau": tau[k : k + 2, :, None],
        } | multiplier_blocks(mm, loop_lam[[k, k]])
        point, it, res = _newton(problem, point, tol, max_newton, k)
        iterations[k] = it
        worst = max(worst, res)
        F[k + 1], v[k + 1], lam[k + 1] = point["F"][1], point["v"][1], point["lam"][1]
        loop_lam[k + 1] = stack_multipliers(mm, point, 2)[1]
    return MaximalTrajectory(R, p, F, v, lam, iterations, worst, loop_lam)


def discrete_energy(
    mm: MaximalModel, p: np.ndarray, F: np.ndarray, v: np.ndarray, dt: float
) -> np.ndarray:
    """Discrete energy of each step ``k → k+1`` (eq. 33): ``(K,)``.

    ``E_k = Σ_b tr((I - F_k) J_b)/Δt² + ½ m_b‖v_k‖² - m_b gᵀ(p_k + p_{k+1})/2``; the rotational
    term equals ``tr((F_k - I) J (F_k - I)ᵀ)/(2Δt²)``, i.e. ``T_d/Δt`` of eq. 33, and tends to
    ``½ ωᵀ I_b ω``.
    """
    rot = np.einsum("kbij,bji->kb", np.eye(3) - F, mm.inertia_nonstandard) / dt**2
    trans = 0.5 * mm.mass * np.einsum("kbi,kbi->kb", v, v)
    mid = p + 0.5 * dt * v  # (p_k + p_{k+1}) / 2 with p_{k+1} = p_k + v_k Δt (eq. 30)
    potential = -mm.mass * np.einsum("kbi,i->kb", mid, mm.gravity)
    return (rot + trans + potential).sum(axis=1)


def _newton(problem: TrajectoryProblem, point: dict, tol: float, max_iter: int, step: int):
    """Newton's method on the manifold with backtracking on ``‖residual‖∞``; a residual below
    ``100 tol`` that a step no longer halves is accepted as converged (round-off floor)."""
    ev = problem.evaluate(point, hessian=False)
    res = float(np.max(np.abs(ev.eq)))
    for it in range(max_iter + 1):
        if res <= tol:
            return point, it, res
        if it == max_iter:
            break
        dx = spla.spsolve(ev.eq_jacobian.tocsc(), -ev.eq)
        if not np.all(np.isfinite(dx)):
            raise MbplanError(f"LGVI step {step}: singular Newton system")
        alpha = 1.0
        while True:
            trial = problem.retract(point, alpha * dx)
            trial_res = float(np.max(np.abs(problem.values(trial)[1])))
            if trial_res < res or alpha < 1e-4:
                break
            alpha *= 0.5
        if res <= 100.0 * tol and trial_res > 0.5 * res:
            return (trial, it + 1, trial_res) if trial_res < res else (point, it, res)
        point = trial
        ev = problem.evaluate(point, hessian=False)
        res = float(np.max(np.abs(ev.eq)))
    raise MbplanError(f"LGVI step {step}: Newton did not converge (residual {res:.2e})")


def discrete_momentum(
    mm: MaximalModel, traj: MaximalTrajectory, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """The discrete linear and angular momentum (about the world origin) after each step,
    less gravity's impulses so far: ``(N+1, 3)`` each, constant in free flight (joint forces
    and torques are internal).

    Linear ``Σ m v_k - k Δt M g`` (eq. 35); angular ``Σ R_k Π_k + p_{k+1} × m v_k`` with
    ``Π_k = (F_k J - J F_kᵀ)^∨/Δt`` (eq. 34 reads ``Π_{k+1} = F_kᵀ Π_k + τ Δt``), less
    ``Σ_{j<k} Σ m p_{j+1} × g Δt``."""
    m, g = mm.mass, mm.gravity
    K = len(traj.v)
    linear = np.einsum("b,kbi->ki", m, traj.v) - np.arange(K)[:, None] * dt * m.sum() * g
    J, F = mm.inertia_nonstandard, traj.F
    skew = F @ J - J @ np.swapaxes(F, -1, -2)
    spin = np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], -1) / dt
    p_next = traj.p + traj.v * dt
    angular = np.einsum("kbij,kbj->ki", traj.R, spin) + np.einsum(
        "b,kbi->ki", m, np.cross(p_next, traj.v)
    )
    impulse = np.einsum("b,kbi->ki", m, np.cross(p_next, g)) * dt  # gravity's, step k -> k+1
    angular[1:] -= np.cumsum(impulse[:-1], axis=0)
    return linear, angular
