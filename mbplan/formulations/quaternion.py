"""Generalized coordinates of a free body: unit quaternions in ambient R⁴, for IPOPT (the
quaternion variational integrator of RIPM paper §VIII.B, ref. [7], footnote 1).

Orientation ``q_k`` and rotation step ``f_k`` are quaternions ``(w, x, y, z)`` in R⁴ with the
quadratic map ``Rot(q) = (w² - ‖q_v‖²) I + 2 q_v q_vᵀ + 2 w q_v^``; the constraints of step
``k = 0..N-1`` are eq. (30), (34), (35) with the forcing (60) of the wrench ``(f, τ) = B u``::

    q_{k+1} = q_k ⊗ f_k,   p_{k+1} = p_k + v_k Δt,
    (Rot(f_{k+1}) J - J Rot(f_{k+1})ᵀ - J Rot(f_k) + Rot(f_k)ᵀ J)^∨ / Δt² = B_τ u_k,
    m (v_{k+1} - v_k) / Δt = m g + Rot(q_{k+1}) B_f u_k,

with ``‖q_k‖² = 1`` (``k ≥ 2``), ``‖f_N‖² = 1``, ``w(q_k), w(f_k) ≥ 0`` (the other norms follow
from ``q_{k+1} = q_k ⊗ f_k`` and the fixed unit ``q_0, f_0``; a redundant row would make the
constraint Jacobian rank deficient). Each OCP item is its residual
(:meth:`mbplan.residuals.Residual.body_rows`) on ``Rot(q_k), p_k, Rot(f_k), v_k`` or
``u_k``; input limits are variable bounds.
"""

from __future__ import annotations

import casadi as cs
import numpy as np
from scipy.spatial.transform import Rotation

from mbplan.formulations.free_body import warm_start_inputs
from mbplan.lie import SO3
from mbplan.ocp.problem import OCP
from mbplan.robots.free_body import body_state, free_flyer_state, path_state


def quat_mul(a: cs.SX, b: cs.SX) -> cs.SX:
    """Hamilton product ``a ⊗ b`` with ``Rot(a ⊗ b) = Rot(a) Rot(b)``."""
    aw, av, bw, bv = a[0], a[1:], b[0], b[1:]
    return cs.vertcat(aw * bw - cs.dot(av, bv), aw * bv + bw * av + cs.cross(av, bv))


def quat_to_rot(q: cs.SX) -> cs.SX:
    """Homogeneous quadratic map ``(w² - ‖q_v‖²) I + 2 q_v q_vᵀ + 2 w q_v^``."""
    w, qv = q[0], q[1:]
    return (w**2 - cs.dot(qv, qv)) * cs.DM.eye(3) + 2 * cs.mtimes(qv, qv.T) + 2 * w * cs.skew(qv)


def to_quaternions(R: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternions with ``w ≥ 0`` of a stack of rotations."""
    return Rotation.from_matrix(R).as_quat(canonical=True, scalar_first=True)


def to_rotations(q: np.ndarray) -> np.ndarray:
    """``Rot(q / ‖q‖)`` of a stack; NaN (not an exception) for a zero or non-finite ``q``."""
    with np.errstate(invalid="ignore", divide="ignore"):
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, qv = q[:, 0, None, None], q[:, 1:]
    x, y, z = qv.T
    skew = np.zeros((len(q), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -z, y, -x
    skew -= np.swapaxes(skew, 1, 2)
    dot = np.einsum("ki,ki->k", qv, qv)[:, None, None]
    return (w**2 - dot) * np.eye(3) + 2 * np.einsum("ki,kj->kij", qv, qv) + 2 * w * skew


class QuaternionNLP:
    """The NLP ``{x, f, g}`` of a free-body ``ocp`` and its bounds (module docstring); the
    decision vector is ``[q, f, p, v, u]`` of knots ``1..N`` (intervals ``0..N-1`` for ``u``),
    each block column-major."""

    def __init__(self, ocp: OCP):
        self.ocp = ocp
        body, N, dt = ocp.robot, ocp.N, ocp.dt
        J, m, B = body.nonstandard_inertia, body.mass, cs.DM(body.actuation)
        self.blocks = [cs.SX.sym(n, d, N) for n, d in (("q", 4), ("f", 4), ("p", 3), ("v", 3))]
        self.blocks.append(cs.SX.sym("u", body.nu, N))
        Q, Fq, P, V, U = self.blocks
        start = body_state(ocp.q0, ocp.v0, dt)
        q0, f0 = to_quaternions(np.stack([start["R"][0], start["F"][0]]))
        q = [cs.DM(q0), *(Q[:, k] for k in range(N))]
        f = [cs.DM(f0), *(Fq[:, k] for k in range(N))]
        p = [cs.DM(start["p"][0]), *(P[:, k] for k in range(N))]
        v = [cs.DM(start["v"][0]), *(V[:, k] for k in range(N))]
        Rq, Rf = [quat_to_rot(a) for a in q], [quat_to_rot(a) for a in f]

        g, lbg, ubg = [], [], []

        def add(expr: cs.SX, lower: float, upper: float) -> None:
            g.append(expr)
            lbg.extend([lower] * expr.numel())
            ubg.extend([upper] * expr.numel())

        for k in range(N):
            momentum = cs.mtimes(Rf[k + 1], J) - cs.mtimes(J, Rf[k + 1].T)
            momentum -= cs.mtimes(J, Rf[k]) - cs.mtimes(Rf[k].T, J)
            add(q[k + 1] - quat_mul(q[k], f[k]), 0.0, 0.0)
            if k > 0:  # q_1 = q_0 ⊗ f_0 is fixed by the unit initial state
                add(cs.sumsqr(q[k + 1]) - 1.0, 0.0, 0.0)
            if k == N - 1:
                add(cs.sumsqr(f[k + 1]) - 1.0, 0.0, 0.0)
            add(p[k + 1] - p[k] - v[k] * dt, 0.0, 0.0)
            add(SO3.vee(momentum) / dt**2 - cs.mtimes(B[3:, :], U[:, k]), 0.0, 0.0)
            force = cs.mtimes(Rq[k + 1], cs.mtimes(B[:3, :], U[:, k]))
            add(m * (v[k + 1] - v[k]) / dt - m * cs.DM(body.gravity) - force, 0.0, 0.0)

        lower = [np.full(b.shape, -np.inf, order="F") for b in self.blocks]
        upper = [np.full(b.shape, np.inf, order="F") for b in self.blocks]
        lower[0][0, :] = 0.0  # w(q_k) >= 0
        lower[1][0, :] = 0.0  # w(f_k) >= 0
        cost = 0
        for item in ocp.items:
            r = item.residual
            bounds = r.variable_bounds(ocp.robot) if item.role == "constraint" else None
            if bounds is not None:  # input limits: bounds on u
                lower[4][:, item.knots] = bounds[1][:, None]
                upper[4][:, item.knots] = bounds[2][:, None]
                continue
            params = {k: cs.DM(val) for k, val in r.body_parameters(ocp.scene).items()}
            for k in item.knots:
                if r.space == "control":
                    x = {"u": U[:, k]}
                else:
                    x = {"R": Rq[k], "p": p[k], "F": Rf[k], "v": v[k]}
                expr = r.body_rows(x, params)
                if item.role == "cost":
                    cost += 0.5 * item.weight * cs.sumsqr(expr)
                elif r.sense == "eq":
                    add(expr, 0.0, 0.0)
                else:
                    add(expr, -np.inf, 0.0)
        z = cs.vertcat(*(cs.vec(b) for b in self.blocks))
        self.problem = {"x": z, "f": cost, "g": cs.vertcat(*g)}
        self.lbg, self.ubg = np.array(lbg), np.array(ubg)
        self.lbz, self.ubz = self._flat(lower), self._flat(upper)
        self.n, self.m = z.numel(), len(lbg)

    @staticmethod
    def _flat(arrays: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([np.ravel(a, order="F") for a in arrays])

    def initial_guess(self, q_path: np.ndarray) -> np.ndarray:
        """``z`` along a pose path ``q_path (N+1, 7)`` (:func:`path_state`) with the inputs
        of the maximal formulation's warm start
        (:func:`~mbplan.formulations.free_body.warm_start_inputs`)."""
        ocp = self.ocp
        s = path_state(q_path, ocp.q0, ocp.v0, ocp.dt)
        u = warm_start_inputs(ocp, s)
        parts = [to_quaternions(s["R"][1:]), to_quaternions(s["F"][1:]), s["p"][1:], s["v"][1:]]
        return self._flat([a.T for a in [*parts, u]])

    def trajectory(self, z: np.ndarray) -> dict:
        """PlanResult fields of ``z``: ``q, v`` (free flyer), ``tau = u``, ``R, p``."""
        ocp = self.ocp
        sizes = np.cumsum([b.numel() for b in self.blocks])[:-1]
        q, f, p, v, u = (
            part.reshape(b.shape, order="F").T
            for part, b in zip(np.split(z, sizes), self.blocks, strict=True)
        )
        start = body_state(ocp.q0, ocp.v0, ocp.dt)
        R = np.concatenate([start["R"][:1], to_rotations(q)])
        F = np.concatenate([start["F"][:1], to_rotations(f)])
        p, v = np.vstack([start["p"][:1], p]), np.vstack([start["v"][:1], v])
        finite = np.all(np.isfinite(R)) and np.all(np.isfinite(F))
        if finite:
            qq, vv = free_flyer_state(R, p, F, v, ocp.dt)
        else:
            qq, vv = np.full((ocp.N + 1, 7), np.nan), np.full((ocp.N + 1, 6), np.nan)
        bodies = {"R": R[:, None], "p": p[:, None], "body_names": (ocp.robot.name,)}
        return {"q": qq, "v": vv, "tau": u} | bodies
