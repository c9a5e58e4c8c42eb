"""Generalized-coordinate baseline of §VIII.C / Table III: eq. (61) with Pinocchio, solved by IPOPT.

Decision vector ``z = (q_1..q_N, v_1..v_N, τ_0..τ_{N-1})``; knot 0 is fixed at ``(q0, 0)``.
Constraints for ``k = 0..N-1`` (eq. 61, explicit Euler as the paper writes it)::

    (q_{k+1} - q_k)/Δt - v_k = 0                          kinematics (divided by Δt: rad/s)
    RNEA(q_k, v_k, (v_{k+1} - v_k)/Δt) - τ_k = 0           M(q_k) q̈_k + C(q_k, v_k) v_k + G(q_k) = τ_k

and for ``k = 1..N``, every link ``i`` (COM ``p_i``) and cylinder ``c`` (eq. 62)::

    (x_i - x_c)² + (y_i - y_c)² - (r_c + margin)² ≥ 0,

or, for ``obstacle_constraint = "distance"``, every (link geometry, obstacle) pair
(:mod:`mbplan.multibody.collision`)::

    d(q_k) - margin ≥ 0.

Bounds: URDF joint position limits on ``q_k``, the task's velocity limits on ``v_k`` and torque
limits on ``τ_k``. The cost is the joint-space tracking cost of :mod:`mbplan.tasks.obstacle`.

Pinocchio's pip wheel has no CasADi bindings, so the constraint function, its Jacobian and the
Lagrangian Hessian are ``casadi.Callback`` functions given to ``casadi.nlpsol`` (``g`` and the
``jac_g``/``hess_lag`` options; the quadratic cost is a CasADi expression). Each callback
evaluates all knots in one Python call:

* ``g``: ``pinocchio.rnea`` and ``pinocchio.forwardKinematics`` per knot;
* Jacobian (exact): ``computeRNEADerivatives`` gives ``∂τ/∂q``, ``∂τ/∂v`` and ``M = ∂τ/∂a``; the
  COM Jacobian of link ``i`` is ``J_ij = v_j + ω_j × p_i`` for the world-frame joint twists
  ``(v_j, ω_j)`` (``data.J`` of ``computeJointJacobians``) of the joints ``j`` that move ``i``;
  a distance row is ``-nᵀ J₁`` with ``J₁`` the same Jacobian at coal's robot witness point;
* Lagrangian Hessian: the cost part is exact (a constant diagonal) and so is the eq.-62 part,
  from the second derivative of a point moved by a chain of 1-dof joints,
  ``∂²p_i/∂q_j∂q_l = ω_min(j,l) × J_i,max(j,l)``; a distance row contributes
  ``-nᵀ ∂²p₁/∂q²`` (fixed witness point and normal, as in the maximal transcription). The dynamics part ``∇²(λ_kᵀ RNEA)`` is a finite
  difference of Pinocchio's analytic first derivatives contracted with ``λ_k`` (the Python
  bindings of Pinocchio 4.0 do not expose ``ComputeRNEASecondOrderDerivatives``): central
  differences in ``q`` (step :data:`FD_STEP_Q`, error ~1e-9 relative) give every row of the
  ``q`` columns; the ``v``-``v`` block is a forward difference with unit step, exact because
  ``∂τ/∂v`` is affine in ``v``; ``∂²τ/∂a² = ∂²τ/∂a∂v = 0``. The blocks are symmetrised and
  mapped to ``(q_k, v_k, v_{k+1})`` through ``a = (v_{k+1} - v_k)/Δt``. Step 0 adds nothing
  (RNEA is linear in ``a``; ``q_0``, ``v_0`` are fixed). 22 ``computeRNEADerivatives`` calls
  per knot.

Restoration: CasADi's ``stats()['iterations']`` does not record IPOPT's phase, so IPOPT also
writes its iteration log to a temporary ``output_file`` (``file_print_level = 5``), where every
iteration of the restoration phase carries an ``r`` after its number. ``restoration=False`` sets
``max_resto_iter = 0``: IPOPT then stops at the first restoration iteration ("More than 0
successive iterations taken in restoration phase", status ``Maximum_Iterations_Exceeded``) and
its iterates before are unchanged, so a run converges with ``restoration=False`` iff it converges
without entering restoration (the "w/o infeasibility restoration" column of Table III).
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from collections.abc import Callable, Mapping
from typing import Any

import casadi as cs
import numpy as np
import pinocchio as pin
import scipy.sparse as sp
from numpy.typing import ArrayLike

from mbplan.baselines.ipopt import IpoptStats, base_options
from mbplan.errors import InputError
from mbplan.multibody.collision import (
    ChainKinematics,
    chain_kinematics,
    joint_space_contacts,
    joint_support,
    point_hessians,
    point_jacobians,
)
from mbplan.results import PlanResult
from mbplan.tasks.obstacle import (
    ObstacleTask,
    joint_interpolation,
    require_eq62,
    robot_description,
    task_collision_pairs,
    validate,
)
from mbplan.validation import as_arrays

METHOD = "generalized_ipopt"
FD_STEP_Q = 1e-5  # rad: central differences of the analytic RNEA derivatives in q
_ITERATION_LINE = re.compile(r"^\s*\d+(r?)\s+[-+]?\d\.\d+e[-+]\d+\s")


def _block(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triplet indices of dense blocks ``rows (..., a) × cols (..., b)``, in C order of
    ``(..., a, b)`` — the order in which the block values are flattened."""
    shape = (*rows.shape, cols.shape[-1])
    return (
        np.broadcast_to(rows[..., None], shape).ravel(),
        np.broadcast_to(cols[..., None, :], shape).ravel(),
    )


class _Pattern:
    """A fixed sparsity given by triplets (duplicates are summed), kept where ``keep``."""

    def __init__(
        self, shape: tuple[int, int], rows: np.ndarray, cols: np.ndarray, keep: np.ndarray
    ):
        self.shape, self.keep = shape, keep
        linear = cols[keep] * shape[0] + rows[keep]
        unique, self.inverse = np.unique(linear, return_inverse=True)
        self.row, self.col = unique % shape[0], unique // shape[0]
        self.sparsity = cs.Sparsity.triplet(*shape, self.row.tolist(), self.col.tolist())

    def nonzeros(self, values: np.ndarray) -> np.ndarray:
        """Nonzeros in column-major (CCS) order from values listed like the triplets."""
        return np.bincount(self.inverse, weights=values[self.keep], minlength=self.row.size)

    def csc(self, values: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((self.nonzeros(values), (self.row, self.col)), shape=self.shape)


class _Callback(cs.Callback):
    """A CasADi function evaluated by ``fn`` on NumPy vectors."""

    def __init__(
        self,
        name: str,
        sp_in: list[cs.Sparsity],
        sp_out: list[cs.Sparsity],
        fn: Callable[..., list[cs.DM]],
    ):
        cs.Callback.__init__(self)
        self._sp_in, self._sp_out, self._fn = sp_in, sp_out, fn
        self.construct(name, {})

    def get_n_in(self) -> int:
        return len(self._sp_in)

    def get_n_out(self) -> int:
        return len(self._sp_out)

    def get_sparsity_in(self, i: int) -> cs.Sparsity:
        return self._sp_in[i]

    def get_sparsity_out(self, i: int) -> cs.Sparsity:
        return self._sp_out[i]

    def eval(self, arg: list[cs.DM]) -> list[cs.DM]:
        return self._fn(*(a.full().ravel() for a in arg))


class GeneralizedTranscription:
    """Eq. (61)–(62) for ``task``: variable layout, bounds, cost and the NLP callbacks.

    Constraint rows: kinematics of steps ``0..N-1`` (``nv`` each), dynamics of steps
    ``0..N-1``, then eq. 62 for knots ``1..N`` × links × cylinders, then coal distances for
    knots ``1..N`` × pairs (``g ≥ 0``).
    """

    def __init__(self, task: ObstacleTask):
        require_eq62(task, METHOD)
        self.task = task
        self.model = robot_description(task.robot).model
        self.data = self.model.createData()
        N, nv = task.N, self.model.nv
        self.N, self.nv, self.dt = N, nv, task.dt
        self.centers = np.array([c.center_xy for c in task.cylinders]).reshape(-1, 2)
        self.radii = np.array([c.radius + task.margin for c in task.cylinders])
        self.links = np.arange(1, self.model.njoints)
        self.levers = np.array([self.model.inertias[int(j)].lever for j in self.links])
        self.nl, self.nc = len(self.links), len(self.radii)
        self.pairs = (
            task_collision_pairs(task)
            if task.obstacle_constraint == "distance" and task.obstacles
            else None
        )
        self.npairs = 0 if self.pairs is None else self.pairs.size
        self.n = 3 * N * nv
        self.m = 2 * N * nv + N * self.nl * self.nc + N * self.npairs
        a_of_x = np.zeros((3 * nv, 3 * nv))  # (q, v, a) from (q_k, v_k, v_{k+1})
        a_of_x[: 2 * nv, : 2 * nv] = np.eye(2 * nv)
        a_of_x[2 * nv :, nv : 2 * nv] = -np.eye(nv) / self.dt
        a_of_x[2 * nv :, 2 * nv :] = np.eye(nv) / self.dt
        self._a_of_x = a_of_x
        self.weights, self.reference = self._cost()
        self._jacobian_pattern()
        self._hessian_pattern()

    # -- layout ------------------------------------------------------------------------------
    def iq(self, k: ArrayLike) -> np.ndarray:
        """Indices of ``q_k`` (``k = 1..N``) in ``z``, shape ``(*k.shape, nv)``."""
        return (np.asarray(k)[..., None] - 1) * self.nv + np.arange(self.nv)

    def iv(self, k: ArrayLike) -> np.ndarray:
        """Indices of ``v_k`` (``k = 1..N``)."""
        return self.iq(k) + self.N * self.nv

    def itau(self, k: ArrayLike) -> np.ndarray:
        """Indices of ``τ_k`` (``k = 0..N-1``)."""
        return self.iq(np.asarray(k) + 1) + 2 * self.N * self.nv

    def pack(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """``z`` from ``q, v (N+1, nv)`` (knot 0 is dropped) and ``tau (N, nv)``."""
        return np.concatenate([q[1:].ravel(), v[1:].ravel(), tau.ravel()])

    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q, v (N+1, nv)`` with the fixed knot 0, and ``tau (N, nv)``."""
        Q, V, T = np.reshape(z, (3, self.N, self.nv))
        return np.vstack([self.task.q0, Q]), np.vstack([np.zeros(self.nv), V]), T

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``lbz, ubz, lbg, ubg``."""
        N, t, m = self.N, self.task, self.model
        lower = (m.lowerPositionLimit, -t.velocity_limit, -t.torque_limit)
        upper = (m.upperPositionLimit, t.velocity_limit, t.torque_limit)
        lbz = np.concatenate([np.tile(b, N) for b in lower])
        ubz = np.concatenate([np.tile(b, N) for b in upper])
        ubg = np.zeros(self.m)
        ubg[2 * N * self.nv :] = np.inf
        return lbz, ubz, np.zeros(self.m), ubg

    def _cost(self) -> tuple[np.ndarray, np.ndarray]:
        """``w, z_ref`` with the tracking cost ``½ Σ w (z - z_ref)²``."""
        N, nv, w = self.N, self.nv, self.task.weights
        scale = np.ones(N)
        scale[-1] = w.terminal_factor
        weights = np.concatenate(
            [np.repeat(w.w_q * scale, nv), np.repeat(w.w_v * scale, nv), np.full(N * nv, w.w_tau)]
        )
        reference = np.zeros(self.n)
        reference[: N * nv] = np.tile(self.task.q_target, N)
        return weights, reference

    def initial_guess(self) -> dict[str, np.ndarray]:
        """:func:`~mbplan.tasks.obstacle.joint_interpolation` with eq. (61) met exactly:
        ``v_k = (q_{k+1} - q_k)/Δt``, ``v_N = 0``, ``τ_k`` by inverse dynamics (§VIII.C)."""
        q = joint_interpolation(self.task)
        v = np.zeros_like(q)
        v[:-1] = np.diff(q, axis=0) / self.dt
        a = np.diff(v, axis=0) / self.dt
        tau = np.array([pin.rnea(self.model, self.data, q[k], v[k], a[k]) for k in range(self.N)])
        return {"q": q, "v": v, "tau": tau}

    # -- kinematics of the link COMs and witness points ------------------------------------------
    def _kinematics(self, q: np.ndarray) -> ChainKinematics | None:
        """Joint placements and Jacobians at ``q (K, nv)`` if any obstacle row needs them."""
        if not (self.nc or self.npairs):
            return None
        return chain_kinematics(self.model, self.data, q)

    def _coms(self, kin: ChainKinematics) -> np.ndarray:
        """COMs ``(K, nl, 3)`` of the links."""
        R = kin.rotation[:, self.links]
        return kin.translation[:, self.links] + np.einsum("klij,lj->kli", R, self.levers)

    def _clearance_terms(self, p: np.ndarray) -> np.ndarray:
        """``(x_i, y_i) - c`` of every COM and cylinder, ``(K, nl, nc, 2)``."""
        return p[:, :, None, :2] - self.centers

    # -- NLP functions -----------------------------------------------------------------------
    def constraints(self, z: np.ndarray) -> np.ndarray:
        """``g(z)``: kinematics, dynamics (eq. 61), eq. 62."""
        q, v, tau = self.unpack(z)
        a = np.diff(v, axis=0) / self.dt
        kin = np.diff(q, axis=0) / self.dt - v[:-1]
        dyn = np.array([pin.rnea(self.model, self.data, q[k], v[k], a[k]) for k in range(self.N)])
        dyn -= tau
        parts = [kin.ravel(), dyn.ravel()]
        chain = self._kinematics(q[1:])
        if self.nc:
            d = self._clearance_terms(self._coms(chain))
            parts.append((np.sum(d**2, axis=-1) - self.radii**2).ravel())
        if self.npairs:
            contacts, _ = joint_space_contacts(self.pairs, chain)
            parts.append((contacts.distance - self.task.margin).ravel())
        return np.concatenate(parts)

    def _jacobian_pattern(self) -> None:
        N, nv, nl, nc = self.N, self.nv, self.nl, self.nc
        steps, inner = np.arange(N), np.arange(1, N)  # all steps; steps with free (q_k, v_k)
        kin = steps[:, None] * nv + np.arange(nv)
        dyn = kin + N * nv
        obs = 2 * N * nv + np.arange(N * nl * nc).reshape(N, nl, nc)
        support = joint_support(self.model)
        self._obs_mask = np.broadcast_to(support[self.links][None, :, None, :], (N, nl, nc, nv))
        knots = self.iq(np.arange(1, N + 1))[:, None, None, :]
        dist = obs.size + 2 * N * nv + np.arange(N * self.npairs).reshape(N, self.npairs)
        moved = support[self.pairs.joint] if self.npairs else np.zeros((0, nv), bool)
        self._dist_mask = np.broadcast_to(moved[None], (N, self.npairs, nv))
        triplets = [
            (kin.ravel(), self.iq(steps + 1).ravel()),  # I/Δt on q_{k+1}
            (kin[inner].ravel(), self.iq(inner).ravel()),  # -I/Δt on q_k
            (kin[inner].ravel(), self.iv(inner).ravel()),  # -I on v_k
            _block(dyn[inner], self.iq(inner)),  # ∂τ/∂q
            _block(dyn[inner], self.iv(inner)),  # ∂τ/∂v - M/Δt
            _block(dyn, self.iv(steps + 1)),  # M/Δt on v_{k+1}
            (dyn.ravel(), self.itau(steps).ravel()),  # -I on τ_k
            (
                np.broadcast_to(obs[..., None], self._obs_mask.shape)[self._obs_mask],
                np.broadcast_to(knots, self._obs_mask.shape)[self._obs_mask],
            ),
            (
                np.broadcast_to(dist[..., None], self._dist_mask.shape)[self._dist_mask],
                np.broadcast_to(knots[:, 0], self._dist_mask.shape)[self._dist_mask],
            ),
        ]
        rows = np.concatenate([r for r, _ in triplets])
        cols = np.concatenate([c for _, c in triplets])
        self.jac_pattern = _Pattern((self.m, self.n), rows, cols, np.ones(rows.size, bool))
        self._jac_constant = np.concatenate(
            [
                np.full(N * nv, 1.0 / self.dt),
                np.full((N - 1) * nv, -1.0 / self.dt),
                np.full((N - 1) * nv, -1.0),
            ]
        )

    def _jacobian_values(self, z: np.ndarray) -> np.ndarray:
        q, v, _ = self.unpack(z)
        a = np.diff(v, axis=0) / self.dt
        dq, dv, M = (np.empty((self.N, self.nv, self.nv)) for _ in range(3))
        for k in range(self.N):
            derivatives = pin.computeRNEADerivatives(self.model, self.data, q[k], v[k], a[k])
            dq[k], dv[k], M[k] = derivatives  # copies: Pinocchio returns views of its data
        parts = [
            self._jac_constant,
            dq[1:].ravel(),
            (dv[1:] - M[1:] / self.dt).ravel(),
            (M / self.dt).ravel(),
            np.full(self.N * self.nv, -1.0),
        ]
        chain = self._kinematics(q[1:])
        if self.nc:
            p = self._coms(chain)
            J = point_jacobians(chain, self.links, p)
            d = self._clearance_terms(p)
            grad = 2.0 * np.einsum("kica,kija->kicj", d, J[..., :2])
            parts.append(grad[self._obs_mask])
        if self.npairs:
            contacts, J = joint_space_contacts(self.pairs, chain)
            grad = -np.einsum("kpa,kpja->kpj", contacts.normal, J)
            parts.append(grad[self._dist_mask])
        return np.concatenate(parts)

    def jacobian(self, z: np.ndarray) -> sp.csc_matrix:
        """Constraint Jacobian ``∂g/∂z`` (exact)."""
        return self.jac_pattern.csc(self._jacobian_values(z))

    def _hessian_pattern(self) -> None:
        N = self.N
        inner, knots = np.arange(1, N), np.arange(1, N + 1)
        local = np.concatenate([self.iq(inner), self.iv(inner), self.iv(inner + 1)], axis=1)
        triplets = [_block(local, local)]
        if self.nc or self.npairs:
            triplets.append(_block(self.iq(knots), self.iq(knots)))
        triplets.append((np.arange(self.n), np.arange(self.n)))
        rows = np.concatenate([r for r, _ in triplets])
        cols = np.concatenate([c for _, c in triplets])
        self.hess_pattern = _Pattern((self.n, self.n), rows, cols, rows <= cols)

    def _rnea_hessian(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, lam: np.ndarray
    ) -> np.ndarray:
        """``∇²(λᵀ RNEA(q, v, a))`` over ``(q, v, a)``, ``(3nv, 3nv)`` (module docstring)."""
        nv, model, data = self.nv, self.model, self.data

        def gradient(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
            dq, dv, M = pin.computeRNEADerivatives(model, data, qq, vv, a)
            return np.concatenate([lam @ dq, lam @ dv, lam @ M])

        H = np.zeros((3 * nv, 3 * nv))
        step = np.eye(nv)
        for j in range(nv):
            hq = FD_STEP_Q * step[j]
            H[:, j] = (gradient(q + hq, v) - gradient(q - hq, v)) / (2.0 * FD_STEP_Q)
        base = gradient(q, v)[nv : 2 * nv]
        for j in range(nv):
            H[nv : 2 * nv, nv + j] = gradient(q, v + step[j])[nv : 2 * nv] - base
        qq, vv = slice(0, nv), slice(nv, 2 * nv)
        H[qq, qq] = 0.5 * (H[qq, qq] + H[qq, qq].T)
        H[vv, vv] = 0.5 * (H[vv, vv] + H[vv, vv].T)
        H[:nv, nv:] = H[nv:, :nv].T
        return H

    def _hessian_values(self, z: np.ndarray, sigma: float, lam: np.ndarray) -> np.ndarray:
        N, nv, T = self.N, self.nv, self._a_of_x
        q, v, _ = self.unpack(z)
        a = np.diff(v, axis=0) / self.dt
        lam_dyn = lam[N * nv : 2 * N * nv].reshape(N, nv)
        dyn = np.array(
            [T.T @ self._rnea_hessian(q[k], v[k], a[k], lam_dyn[k]) @ T for k in range(1, N)]
        )
        parts = [dyn.ravel()]
        if self.nc or self.npairs:
            chain = self._kinematics(q[1:])
            obstacles = np.zeros((N, nv, nv))
            start = 2 * N * nv
        if self.nc:
            mu = lam[start : start + N * self.nl * self.nc].reshape(N, self.nl, self.nc)
            p = self._coms(chain)
            J = point_jacobians(chain, self.links, p)
            d = self._clearance_terms(p)
            Jxy = J[..., :2]
            obstacles += 2.0 * np.einsum("ki,kija,kila->kjl", mu.sum(axis=2), Jxy, Jxy)
            weight = np.einsum("kic,kica->kia", mu, d)
            P = point_hessians(chain, self.links, J)[..., :2]
            obstacles += 2.0 * np.einsum("kia,kijla->kjl", weight, P)
        if self.npairs:
            mu = lam[start + N * self.nl * self.nc :].reshape(N, self.npairs)
            contacts, J = joint_space_contacts(self.pairs, chain)
            P = point_hessians(chain, self.pairs.joint, J)
            obstacles -= np.einsum("kp,kpa,kpjla->kjl", mu, contacts.normal, P)
        if self.nc or self.npairs:
            parts.append(obstacles.ravel())
        parts.append(sigma * self.weights)
        return np.concatenate(parts)

    def lagrangian_hessian(self, z: np.ndarray, sigma: float, lam: np.ndarray) -> sp.csc_matrix:
        """Upper triangle of ``∇²(σ f + λᵀ g)`` (module docstring)."""
        return self.hess_pattern.csc(self._hessian_values(z, sigma, lam))

    def callbacks(self) -> tuple[_Callback, _Callback, _Callback]:
        """``g(z)``, ``jac_g(z, p) -> (g, ∂g/∂z)`` and ``hess_lag(z, p, σ, λ) -> triu ∇²L``."""
        dense_z, dense_g = cs.Sparsity.dense(self.n, 1), cs.Sparsity.dense(self.m, 1)
        no_p, scalar = cs.Sparsity(0, 1), cs.Sparsity.dense(1, 1)
        jac, hess = self.jac_pattern, self.hess_pattern

        def g(z: np.ndarray) -> list[cs.DM]:
            return [cs.DM(self.constraints(z))]

        def jac_g(z: np.ndarray, _p: np.ndarray) -> list[cs.DM]:
            values = jac.nonzeros(self._jacobian_values(z))
            return [cs.DM(self.constraints(z)), cs.DM(jac.sparsity, values)]

        def hess_lag(
            z: np.ndarray, _p: np.ndarray, sigma: np.ndarray, lam: np.ndarray
        ) -> list[cs.DM]:
            values = hess.nonzeros(self._hessian_values(z, float(sigma[0]), lam))
            return [cs.DM(hess.sparsity, values)]

        return (
            _Callback("eq61_g", [dense_z], [dense_g], g),
            _Callback("eq61_jac_g", [dense_z, no_p], [dense_g, jac.sparsity], jac_g),
            _Callback("eq61_hess_lag", [dense_z, no_p, scalar, dense_g], [hess.sparsity], hess_lag),
        )


def _restoration_iterations(log: str) -> int:
    """Number of iteration lines of IPOPT's log marked ``r`` (restoration phase)."""
    marks = (_ITERATION_LINE.match(line) for line in log.splitlines())
    return sum(1 for mark in marks if mark is not None and mark.group(1) == "r")


def solve_generalized_ipopt(
    task: ObstacleTask,
    *,
    initial_guess: Mapping[str, ArrayLike] | None = None,
    max_iter: int = 500,
    tol: float = 1e-6,
    restoration: bool = True,
    ipopt_options: Mapping[str, Any] | None = None,
) -> PlanResult:
    """Solve ``task`` in generalized coordinates (eq. 61, 62) with IPOPT (exact Hessian, MUMPS).

    :func:`~mbplan.tasks.obstacle.validate` runs first (an obstacle overlapping the start raises
    :class:`~mbplan.errors.InfeasibleRequestError`). ``initial_guess`` has keys ``q, v (N+1, nv)``
    and ``tau (N, nv)`` (knot 0 is ignored); default
    :meth:`GeneralizedTranscription.initial_guess`. ``max_iter = 500`` and ``tol = 1e-6`` as in
    Table III; otherwise IPOPT defaults, plus ``ipopt_options`` (IPOPT names, no prefix; not
    ``output_file``/``file_print_level``, which detect restoration).
    ``restoration=False`` disables the restoration phase (module docstring). ``success`` means
    ``Solve_Succeeded`` with a finite solution. ``extra`` holds ``objective``,
    ``restoration_iterations``, ``eval_time_s`` (callbacks and cost), ``build_time_s``,
    ``solver_time_per_iter_s`` (IPOPT's time per iteration without function evaluations, the
    metric of Table III), ``n_variables`` and ``n_constraints``.
    """
    start = time.perf_counter()
    if not isinstance(task, ObstacleTask):
        raise InputError(f"task: expected ObstacleTask, got {type(task).__name__}")
    options = base_options(max_iter, tol)
    reserved = {"output_file", "file_print_level"} & set(ipopt_options or {})
    if reserved:
        raise InputError(f"ipopt_options: {sorted(reserved)} are used to detect restoration")
    validate(task)
    tr = GeneralizedTranscription(task)
    guess = as_arrays(
        tr.initial_guess() if initial_guess is None else initial_guess,
        {"q": (tr.N + 1, tr.nv), "v": (tr.N + 1, tr.nv), "tau": (tr.N, tr.nv)},
        "initial_guess",
    )
    g_fn, jac_fn, hess_fn = tr.callbacks()
    z = cs.MX.sym("z", tr.n)
    cost = 0.5 * cs.dot(cs.DM(tr.weights), (z - cs.DM(tr.reference)) ** 2)
    fd, log_path = tempfile.mkstemp(prefix="ipopt_", suffix=".log")
    os.close(fd)
    options |= {"output_file": log_path, "file_print_level": 5}
    if not restoration:
        options["max_resto_iter"] = 0
    options.update(ipopt_options or {})
    try:
        solver = cs.nlpsol(
            "eq61_ipopt",
            "ipopt",
            {"x": z, "f": cost, "g": g_fn(z)},
            {
                "jac_g": jac_fn,
                "hess_lag": hess_fn,
                "no_nlp_grad": True,
                "print_time": False,
                "record_time": True,
                "ipopt": options,
            },
        )
        lbz, ubz, lbg, ubg = tr.bounds()
        build_time = time.perf_counter() - start
        sol = solver(
            x0=tr.pack(guess["q"], guess["v"], guess["tau"]), lbx=lbz, ubx=ubz, lbg=lbg, ubg=ubg
        )
        stats = IpoptStats.of(solver.stats())
        with open(log_path, encoding="utf-8", errors="replace") as fh:
            resto = _restoration_iterations(fh.read())
    finally:
        os.unlink(log_path)

    q, v, tau = tr.unpack(np.asarray(sol["x"]).ravel())
    finite = all(np.all(np.isfinite(x)) for x in (q, v, tau))
    success = stats.status == "Solve_Succeeded" and finite
    message = stats.status.replace("_", " ")
    if not restoration and resto:
        message = "stopped on entering the restoration phase, which is disabled (max_resto_iter=0)"
    elif not finite:
        message = f"{message}; the solution contains NaN or inf"
    return PlanResult(
        method=METHOD,
        status=stats.status,
        success=success,
        message=message,
        iterations=stats.iterations,
        solve_time_s=stats.solve_time,
        total_time_s=time.perf_counter() - start,
        time_per_iter_s=stats.time_per_iteration,
        q=q,
        v=v,
        tau=tau,
        dt=task.dt,
        kkt_history=np.column_stack([stats.inf_pr, stats.inf_du]).reshape(-1, 2),
        entered_restoration=resto > 0,
        extra={
            "objective": float(sol["f"]),
            "restoration_iterations": resto,
            "eval_time_s": stats.eval_time,
            "build_time_s": build_time,
            "solver_time_per_iter_s": stats.solver_time_per_iteration,
            "n_variables": tr.n,
            "n_constraints": tr.m,
        },
    )
