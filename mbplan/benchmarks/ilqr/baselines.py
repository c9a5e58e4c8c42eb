"""Baselines of the iLQR benchmark on the same scenarios (thesis §4-1, Table 4-1; spec §2.5).

* ``ipopt-quaternion`` — "Embedded Unconstrained": unit quaternions not enforced,
  ``q⁺ = q + (h/2) q ⊗ (0, ω)``, ``p⁺ = p + h R(q) v``, cost ``α_q‖q - q_ref‖²`` (+ ``Q_P‖p - p_ref‖²``).
* ``ipopt-embedded-dynamics`` — "Embedded w. 𝓜 Dynamics": 9 free rotation entries,
  ``𝒳⁺ = 𝒳 exp(hξ)`` (Rodrigues), cost ``α_𝒳‖R - R_ref‖²_F`` (+ ``Q_P``).
* ``ipopt-embedded-manifold`` — "Embedded on 𝓜": same dynamics, the Log cost (2-55).
* ``ripm`` — the direct transcription on the manifold (Terms + TrajectoryProblem) by our RIPM.

All are multiple-shooting style NLPs with states = reference and inputs = 0 as initial guess, the
velocity dynamics of the scenario's own step function, IPOPT ``tol = acceptable_tol = 1e-8`` and
the scenario's iteration cap. "Norm" costs are squared, as in the thesis' scripts.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as cs
import numpy as np

from mbplan.engine import RiemannianFunction
from mbplan.engine.jit import jit_available
from mbplan.lie import SE3, SO3, R
from mbplan.shooting.cost import tracking_value
from mbplan.solvers import RIPMOptions, solve_ripm
from mbplan.tasks.ilqr import Scenario
from mbplan.transcription import Block, Term, TrajectoryProblem, TrajectoryVariables


@dataclass
class BaselineRun:
    """One baseline solve, reported like an :class:`~mbplan.solvers.ilqr.ILQRResult`."""

    method: str
    converged: bool
    status: str
    iterations: int
    time_s: float
    x: np.ndarray
    """States in the scenario's flat state space (rotations projected onto the group)."""
    u: np.ndarray
    max_defect: float
    group_violation: float
    history: dict = field(default_factory=dict)


def _quat_mul(a, b):
    w1, v1 = a[0], a[1:]
    w2, v2 = b[0], b[1:]
    return cs.vertcat(w1 * w2 - cs.dot(v1, v2), w1 * v2 + w2 * v1 + cs.cross(v1, v2))


def _quat_to_rot(q):
    w, v = q[0], q[1:]
    V = cs.skew(v)
    return cs.DM.eye(3) + 2 * w * V + 2 * cs.mtimes(V, V)


def rotation_to_quaternion(Rm: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(w, x, y, z)`` of a rotation sequence, signs made continuous."""
    phi = SO3.log(Rm)
    th = np.linalg.norm(phi, axis=-1, keepdims=True)
    axis = np.where(th > 1e-12, phi / np.maximum(th, 1e-300), 0.0)
    q = np.concatenate([np.cos(th / 2), np.sin(th / 2) * axis], axis=-1)
    for k in range(1, len(q)):
        if q[k] @ q[k - 1] < 0:
            q[k] = -q[k]
    return q


def _project_rotation(Rm: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(Rm)
    D = np.ones(Rm.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def _is_se3(sc: Scenario) -> bool:
    return sc.group is SE3


def _split_ref(sc: Scenario):
    X, xi = sc.problem.space.unpack(sc.problem.x_ref)
    if _is_se3(sc):
        return X[:, :3, :3], X[:, :3, 3], xi
    return X, None, xi


def ipopt_baseline(sc: Scenario, formulation: str, *, seed: int = 0) -> BaselineRun:
    """Solve ``sc`` with one of the three embedded CasADi + IPOPT formulations."""
    if formulation not in ("quaternion", "embedded-dynamics", "embedded-manifold"):
        raise ValueError(f"unknown formulation {formulation!r}")
    pb = sc.problem
    space, N, nu, d = pb.space, pb.N, pb.nu, sc.group.dim
    se3 = _is_se3(sc)
    bw = sc.baseline_weights
    Rref, pref, xiref = _split_ref(sc)
    X0, xi0 = space.unpack(pb.x0)
    quat = formulation == "quaternion"
    nr = 4 if quat else 9
    npos = 3 if se3 else 0
    ns = nr + npos + d
    Z = cs.SX.sym("z", ns * (N + 1) + nu * N)
    S = [Z[k * ns : (k + 1) * ns] for k in range(N + 1)]
    Us = [Z[ns * (N + 1) + k * nu : ns * (N + 1) + (k + 1) * nu] for k in range(N)]
    qref = rotation_to_quaternion(Rref)
    if quat and qref[0] @ rotation_to_quaternion(X0[:3, :3][None])[0] < 0:
        qref = -qref

    def parts(s):
        rot = s[:nr]
        Rm = _quat_to_rot(rot) if quat else cs.reshape(rot, 3, 3)
        p = s[nr : nr + npos] if se3 else None
        return rot, Rm, p, s[nr + npos :]

    def pose(Rm, p):
        return cs.vertcat(cs.horzcat(Rm, p), cs.DM([[0, 0, 0, 1]])) if se3 else Rm

    g, obj = [], 0.0
    wxi = sc.problem.state_weights[d:]
    for k in range(N + 1):
        rot, Rm, p, xi = parts(S[k])
        scale = 1.5 if k == N else 1.0
        if formulation == "embedded-manifold":
            ref = cs.DM(pb.x_ref[k])
            w = pb.state_weights if k < N else pb.terminal_weights
            q_flat = space.sym_pack([pose(Rm, p), xi])
            obj += tracking_value(space, q_flat, cs.DM.zeros(1), ref, cs.DM.zeros(1), w, 0)
        else:
            if quat:
                obj += scale * bw["alpha_q"] * cs.sumsqr(rot - qref[k])
            else:
                obj += scale * bw["alpha_X"] * cs.sumsqr(Rm - Rref[k])
            if se3:
                obj += scale * bw["Q_P"] * cs.sumsqr(p - pref[k])
            obj += scale * cs.dot(wxi * (xi - xiref[k]), xi - xiref[k])
        if k == N:
            break
        u = Us[k]
        obj += cs.dot(pb.input_weights * u, u)
        nxt = pb.dynamics.step_function(space.sym_pack([pose(Rm, p), xi]), u)
        Xn, xin = space.sym_unpack(nxt)
        rot1, _, p1, xi1 = parts(S[k + 1])
        if quat:
            w_body = xi[3:] if se3 else xi
            rot_next = rot + 0.5 * sc.dt * _quat_mul(rot, cs.vertcat(0, w_body))
            g.append(rot1 - rot_next)
            if se3:
                g.append(p1 - (p + sc.dt * cs.mtimes(Rm, xi[:3])))
        else:
            g.append(rot1 - cs.vec(Xn[:3, :3]))
            if se3:
                g.append(p1 - Xn[:3, 3])
        g.append(xi1 - xin)
    G = cs.vertcat(*g)
    rot0 = rotation_to_quaternion(X0[:3, :3][None])[0] if quat else X0[:3, :3].T.ravel()
    s0 = np.concatenate([rot0, X0[:3, 3] if se3 else [], xi0])
    # Initial guess: states on the reference, inputs zero (pendulum w. 𝓜 dynamics: perturbed ξ).
    guess = []
    rng = np.random.default_rng(seed)
    for k in range(N + 1):
        r = qref[k] if quat else Rref[k].T.ravel()
        xi_g = xiref[k]
        if sc.forcing == "pendulum" and formulation == "embedded-dynamics":
            xi_g = xi_g + 1e-3 * rng.uniform(0, 1, d)
        guess.append(np.concatenate([r, pref[k] if se3 else [], xi_g]))
    guess[0] = s0
    w0 = np.concatenate([*guess, np.zeros(nu * N)])
    lbx = np.full(Z.numel(), -np.inf)
    ubx = np.full(Z.numel(), np.inf)
    lbx[:ns] = ubx[:ns] = s0
    solver = cs.nlpsol(
        "ipopt",
        "ipopt",
        {"x": Z, "f": obj, "g": G},
        {
            "ipopt.tol": 1e-8,
            "ipopt.acceptable_tol": 1e-8,
            "ipopt.max_iter": sc.max_iter,
            "ipopt.print_level": 0,
            "print_time": False,
            "record_time": True,
        },
    )
    t = time.perf_counter()
    sol = solver(x0=w0, lbx=lbx, ubx=ubx, lbg=0, ubg=0)
    wall = time.perf_counter() - t
    stats = solver.stats()
    z = np.asarray(sol["x"]).ravel()
    states = z[: ns * (N + 1)].reshape(N + 1, ns)
    U = z[ns * (N + 1) :].reshape(N, nu)
    if quat:
        qn = states[:, :4]
        viol = float(np.max(np.abs(np.sum(qn**2, axis=1) - 1)))
        Rm = np.stack([_quat_np(q / np.linalg.norm(q)) for q in qn])
    else:
        Rm = np.swapaxes(states[:, :9].reshape(N + 1, 3, 3), -1, -2)
        viol = float(np.max(np.abs(np.swapaxes(Rm, -1, -2) @ Rm - np.eye(3))))
        Rm = _project_rotation(Rm)
    xi = states[:, nr + npos :]
    if se3:
        Xs = np.tile(np.eye(4), (N + 1, 1, 1))
        Xs[:, :3, :3] = Rm
        Xs[:, :3, 3] = states[:, nr : nr + 3]
    else:
        Xs = Rm
    x = space.pack([Xs, xi])
    it = stats.get("iterations", {})
    return BaselineRun(
        method=f"ipopt-{formulation}",
        converged=stats["return_status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level"),
        status=stats["return_status"],
        iterations=int(stats["iter_count"]),
        time_s=float(stats.get("t_wall_total", wall)),
        x=x,
        u=U,
        max_defect=float(np.max(np.abs(np.asarray(sol["g"]))) if G.numel() else 0.0),
        group_violation=viol,
        history={
            "objective": list(map(float, it.get("obj", []))),
            "inf_pr": list(map(float, it.get("inf_pr", []))),
            "inf_du": list(map(float, it.get("inf_du", []))),
        },
    )


def _quat_np(q: np.ndarray) -> np.ndarray:
    w, v = q[0], q[1:]
    V = SO3.hat(v)
    return np.eye(3) + 2 * w * V + 2 * V @ V


def ripm_baseline(sc: Scenario, *, max_iter: int = 300) -> BaselineRun:
    """The direct transcription of ``sc`` (dynamics as equalities ``x_{k+1} ⊖ F(x_k, u_k)``)
    on the product manifold, solved by :func:`~mbplan.solvers.solve_ripm`."""
    pb = sc.problem
    space, N, nu = pb.space, pb.N, pb.nu
    jit = jit_available()
    names = [f"x{i}" for i in range(len(space.groups))]
    blocks = [Block(n, g, N + 1, fixed=(0,)) for n, g in zip(names, space.groups, strict=True)]
    variables = TrajectoryVariables([*blocks, Block("u", R(nu), N)])
    step = pb.dynamics.step_function

    def pack(kw, suffix):
        return space.sym_pack([kw[f"{n}{suffix}"] for n in names])

    def dynamics_residual(**kw):
        return space.sym_local(step(pack(kw, "_0"), kw["u"]), pack(kw, "_1"))

    fvars = [(f"{n}_{i}", g) for i in (0, 1) for n, g in zip(names, space.groups, strict=True)]
    tag = pb.dynamics.name
    dyn_fn = RiemannianFunction(
        f"{tag}_ripm_dynamics", [*fvars, ("u", R(nu))], dynamics_residual, jit=jit
    )
    svars = [(f"{n}_0", g) for n, g in zip(names, space.groups, strict=True)]
    stage_fn = RiemannianFunction(
        f"{tag}_ripm_stage",
        [*svars, ("u", R(nu))],
        lambda **kw: tracking_value(
            space, pack(kw, "_0"), kw["u"], kw["ref"], kw["uref"], kw["wq"], kw["wu"]
        ),
        [("ref", space.nq), ("uref", nu), ("wq", space.nx), ("wu", nu)],
        jit=jit,
    )
    term_fn = RiemannianFunction(
        f"{tag}_ripm_terminal",
        svars,
        lambda **kw: tracking_value(
            space, pack(kw, "_0"), cs.DM.zeros(1), kw["ref"], cs.DM.zeros(1), kw["wq"], 0
        ),
        [("ref", space.nq), ("wq", space.nx)],
        jit=jit,
    )
    bind0 = {f"{n}_0": (n, 0) for n in names}
    bind1 = {f"{n}_1": (n, 1) for n in names}
    terms = [
        Term.at_knots("dynamics", "eq", dyn_fn, bind0 | bind1 | {"u": ("u", 0)}, range(N)),
        Term.at_knots(
            "stage",
            "cost",
            stage_fn,
            bind0 | {"u": ("u", 0)},
            range(N),
            {
                "ref": pb.x_ref[:N],
                "uref": pb.u_ref,
                "wq": np.tile(pb.state_weights, (N, 1)),
                "wu": np.tile(pb.input_weights, (N, 1)),
            },
        ),
        Term.at_knots(
            "terminal",
            "cost",
            term_fn,
            bind0,
            [N],
            {"ref": pb.x_ref[N:], "wq": pb.terminal_weights[None]},
        ),
    ]
    problem = TrajectoryProblem(variables, terms)
    guess = pb.x_ref.copy()
    guess[0] = pb.x0
    point = dict(zip(names, space.unpack(guess), strict=True)) | {"u": np.zeros((N, nu))}
    t = time.perf_counter()
    res = solve_ripm(problem, point, RIPMOptions(tol=1e-8, max_iter=max_iter))
    wall = time.perf_counter() - t
    x = space.pack([res.x[n] for n in names])
    h = res.history
    return BaselineRun(
        method="ripm",
        converged=res.success,
        status=res.status.name,
        iterations=res.iterations,
        time_s=wall,
        x=x,
        u=np.asarray(res.x["u"]),
        max_defect=float(res.inf_pr),
        group_violation=space.violation(x),
        history={
            "objective": list(h.objective),
            "inf_pr": list(h.inf_pr),
            "inf_du": list(h.inf_du),
        },
    )
