"""Quaternion baseline of §VIII.B / Table II: the docking task in ambient R⁴ coordinates, IPOPT.

Orientation ``q_k`` and discrete rotation ``f_k`` are quaternions ``(w, x, y, z)`` (scalar first)
in R⁴, as in the variational integrator of the paper's ref. [7] with its full 4-vector form
(footnote 1), and every derivative is taken in the ambient space by CasADi. With the quadratic map
``Rot(q) = (w² - ‖q_v‖²) I + 2 q_v q_vᵀ + 2 w q_v^`` (a rotation when ``‖q‖ = 1``) the
constraints per step ``k = 0..N-1`` are the discrete dynamics of :mod:`mbplan.tasks.drone`::

    q_{k+1} = q_k ⊗ f_k                                                 (30): R_{k+1} = R_k F_k
    p_{k+1} = p_k + v_k Δt                                              (30)
    (Rot(f_{k+1}) J - J Rot(f_{k+1})ᵀ - J Rot(f_k) + Rot(f_k)ᵀ J)^∨ / Δt² = τ_k    (34, 60)
    m (v_{k+1} - v_k) / Δt = m g + Rot(q_{k+1}) e_z u_{z,k}             (35, 60)

(the dynamics rows divided by Δt² and Δt, i.e. in N m and N), together with ``‖q_k‖² = 1``,
``w(q_k) ≥ 0`` (one branch of the double cover), ``w(f_k) ≥ 0`` and ``‖f_N‖² = 1``. Norms that
already follow from the others are not imposed again, since a redundant row makes the constraint
Jacobian rank deficient: ``‖f_k‖``, ``k < N``, follows from ``q_{k+1} = q_k ⊗ f_k`` and
``‖q_1‖`` from the fixed unit ``q_0, f_0``. In quaternion form the
rotational row is ref. [7]'s ``2 (w⁺ I_b f_v⁺ + f_v⁺ × I_b f_v⁺) - 2 (w I_b f_v - f_v × I_b f_v)``.
Costs (57) and (59) use ``Rot(q)`` and ``Rot(f)``; ``x_0`` is fixed to the task's initial state.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as cs
import numpy as np

from mbplan.baselines.ipopt import IpoptStats, base_options
from mbplan.formulations.quaternion import quat_mul as _quat_mul
from mbplan.formulations.quaternion import quat_to_rot as _quat_to_rot
from mbplan.formulations.quaternion import to_quaternions as _to_quaternions
from mbplan.formulations.quaternion import to_rotations as _to_rotations
from mbplan.lie import SO3
from mbplan.tasks.drone import DockingTask, geodesic_initial_guess
from mbplan.validation import as_arrays


@dataclass(frozen=True, eq=False)
class QuaternionIpoptResult:
    """Outcome of :func:`solve_quaternion_ipopt`.

    ``success`` is IPOPT's ``Solve_Succeeded`` with a finite solution and objective.
    ``solve_time`` is IPOPT's wall time; ``time_per_iteration`` divides it by the iteration count
    and ``solver_time_per_iteration`` first removes the function and derivative evaluations (the
    metric of Table II). ``inf_pr``/``inf_du`` are IPOPT's primal/dual infeasibility per iteration
    (iteration 0 first) and ``kkt_history`` their maximum. ``R, F (N+1,3,3)`` are the rotations
    of the normalised ``q, f (N+1,4)``; ``p, v (N+1,3)``, ``u (N,4)``.
    """

    status: str
    success: bool
    iterations: int
    solve_time: float
    time_per_iteration: float
    solver_time_per_iteration: float
    objective: float
    inf_pr: np.ndarray
    inf_du: np.ndarray
    kkt_history: np.ndarray
    q: np.ndarray
    f: np.ndarray
    R: np.ndarray
    F: np.ndarray
    p: np.ndarray
    v: np.ndarray
    u: np.ndarray


def _chordal(R: cs.SX, R_ref: np.ndarray) -> cs.SX:
    """Eq. (57) with ``W = I``: ``½ ‖R R_refᵀ - I‖_F²``."""
    return 0.5 * cs.sumsqr(cs.mtimes(R, cs.DM(R_ref.T)) - cs.DM.eye(3))


def _transcribe(
    task: DockingTask, redundant_norms: bool
) -> tuple[dict[str, cs.SX], np.ndarray, np.ndarray, list[cs.SX]]:
    """NLP ``{x, f, g}``, bounds on ``g`` and the decision blocks ``[q, f, p, v, u]``."""
    N, dt, prm, w = task.N, task.dt, task.params, task.weights
    J, m = prm.nonstandard_inertia, prm.mass
    Q, Fq = cs.SX.sym("q", 4, N), cs.SX.sym("f", 4, N)
    P, V, U = cs.SX.sym("p", 3, N), cs.SX.sym("v", 3, N), cs.SX.sym("u", 4, N)
    q0, f0 = _to_quaternions(np.stack([task.R0, task.F0]))
    q = [cs.DM(q0), *(Q[:, k] for k in range(N))]
    f = [cs.DM(f0), *(Fq[:, k] for k in range(N))]
    p = [cs.DM(task.p0), *(P[:, k] for k in range(N))]
    v = [cs.DM(task.v0), *(V[:, k] for k in range(N))]
    Rq = [_quat_to_rot(qk) for qk in q]
    Rf = [_quat_to_rot(fk) for fk in f]

    cost = 0
    for k in range(1, N + 1):  # knot 0 is fixed; same objective as trajectory_cost
        scale = w.terminal_factor if k == N else 1.0
        cost += scale * (
            w.w_R * _chordal(Rq[k], task.R_goal)
            + w.w_F * _chordal(Rf[k], np.eye(3))
            + 0.5 * w.w_p * cs.sumsqr(p[k] - task.p_goal)
            + 0.5 * w.w_v * cs.sumsqr(v[k])
        )
    cost += 0.5 * w.w_u * cs.sumsqr(U - cs.repmat(cs.DM(prm.hover_input), 1, N))

    g, lbg, ubg = [], [], []

    def add(expr: cs.SX, lower: float, upper: float) -> None:
        g.append(expr)
        lbg.extend([lower] * expr.numel())
        ubg.extend([upper] * expr.numel())

    e_z = cs.DM([0.0, 0.0, 1.0])
    for k in range(N):
        momentum = cs.mtimes(Rf[k + 1], J) - cs.mtimes(J, Rf[k + 1].T)
        momentum -= cs.mtimes(J, Rf[k]) - cs.mtimes(Rf[k].T, J)
        add(q[k + 1] - _quat_mul(q[k], f[k]), 0.0, 0.0)
        if redundant_norms or k > 0:  # q_1 = q_0 ⊗ f_0 is fixed by the unit initial state
            add(cs.sumsqr(q[k + 1]) - 1.0, 0.0, 0.0)
        if redundant_norms or k == N - 1:
            add(cs.sumsqr(f[k + 1]) - 1.0, 0.0, 0.0)
        add(p[k + 1] - p[k] - v[k] * dt, 0.0, 0.0)
        add(SO3.vee(momentum) / dt**2 - U[1:, k], 0.0, 0.0)
        add(
            m * (v[k + 1] - v[k]) / dt
            - m * cs.DM(prm.gravity)
            - cs.mtimes(Rq[k + 1], e_z) * U[0, k],
            0.0,
            0.0,
        )
        for xc, yc, r in task.obstacles:
            add((p[k + 1][0] - xc) ** 2 + (p[k + 1][1] - yc) ** 2 - r**2, 0.0, np.inf)

    blocks = [Q, Fq, P, V, U]
    nlp = {"x": cs.vertcat(*(cs.vec(b) for b in blocks)), "f": cost, "g": cs.vertcat(*g)}
    return nlp, np.array(lbg), np.array(ubg), blocks


def solve_quaternion_ipopt(
    task: DockingTask,
    *,
    max_iter: int = 1000,
    tol: float = 1e-6,
    initial_guess: Mapping[str, np.ndarray] | None = None,
    ipopt_options: Mapping[str, Any] | None = None,
    redundant_norms: bool = False,
) -> QuaternionIpoptResult:
    """Solve ``task`` with the quaternion transcription and IPOPT (exact Hessian, MUMPS).

    ``initial_guess`` has the keys of :func:`mbplan.tasks.geodesic_initial_guess` (the default);
    its knot 0 is ignored since ``x_0`` is fixed. ``ipopt_options`` are passed as ``ipopt.*``.
    ``redundant_norms=True`` imposes ``‖q_k‖² = ‖f_k‖² = 1`` at every knot ``k >= 1``, the literal
    ambient formulation, whose constraint Jacobian is rank deficient (IPOPT then relies on its
    regularisation and converges less often).
    """
    options = base_options(max_iter, tol)
    N = task.N
    guess = as_arrays(
        geodesic_initial_guess(task) if initial_guess is None else initial_guess,
        {"R": (N + 1, 3, 3), "p": (N + 1, 3), "F": (N + 1, 3, 3), "v": (N + 1, 3), "u": (N, 4)},
        "initial_guess",
    )

    nlp, lbg, ubg, blocks = _transcribe(task, redundant_norms)
    lower = [np.full(b.shape, -np.inf, order="F") for b in blocks]
    upper = [np.full(b.shape, np.inf, order="F") for b in blocks]
    lower[0][0, :] = 0.0  # w(q_k) >= 0
    lower[1][0, :] = 0.0  # w(f_k) >= 0
    if task.with_input_limits:  # u_z ∈ [0, u_lim], τ ∈ [-τ_lim, τ_lim]³ (§VIII.B)
        tau = task.params.torque_limit
        lower[4][:] = np.array([[0.0], [-tau], [-tau], [-tau]])
        upper[4][:] = np.array([[task.params.thrust_limit], [tau], [tau], [tau]])
    start = [
        _to_quaternions(guess["R"][1:]).T,
        _to_quaternions(guess["F"][1:]).T,
        guess["p"][1:].T,
        guess["v"][1:].T,
        guess["u"].T,
    ]

    def flat(arrays: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([np.ravel(a, order="F") for a in arrays])

    options.update(ipopt_options or {})
    solver = cs.nlpsol(
        "quaternion_docking",
        "ipopt",
        nlp,
        {"ipopt": options, "print_time": False, "record_time": True},
    )
    sol = solver(x0=flat(start), lbx=flat(lower), ubx=flat(upper), lbg=lbg, ubg=ubg)
    stats = solver.stats()
    ipopt = IpoptStats.of(stats)

    x = np.asarray(sol["x"]).ravel()
    sizes = np.cumsum([b.numel() for b in blocks])[:-1]
    q, f, p, v, u = (
        part.reshape(b.shape, order="F").T
        for part, b in zip(np.split(x, sizes), blocks, strict=True)
    )
    q = np.vstack([_to_quaternions(task.R0[None]), q])
    f = np.vstack([_to_quaternions(task.F0[None]), f])
    p = np.vstack([task.p0, p])
    v = np.vstack([task.v0, v])
    R, F = _to_rotations(q), _to_rotations(f)

    objective = float(sol["f"])
    finite = all(np.all(np.isfinite(a)) for a in (q, f, R, F, p, v, u)) and np.isfinite(objective)
    return QuaternionIpoptResult(
        status=ipopt.status,
        success=bool(stats["success"]) and ipopt.status == "Solve_Succeeded" and bool(finite),
        iterations=ipopt.iterations,
        solve_time=ipopt.solve_time,
        time_per_iteration=ipopt.time_per_iteration,
        solver_time_per_iteration=ipopt.solver_time_per_iteration,
        objective=objective,
        inf_pr=ipopt.inf_pr,
        inf_du=ipopt.inf_du,
        kkt_history=np.maximum(ipopt.inf_pr, ipopt.inf_du),
        q=q,
        f=f,
        R=R,
        F=F,
        p=p,
        v=v,
        u=u,
    )
