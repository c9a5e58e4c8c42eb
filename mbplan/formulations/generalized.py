"""Generalized coordinates: an :class:`~mbplan.OCP` as eq. (61) with Pinocchio, for IPOPT.

Decision vector ``z = (q_1..q_N, v_1..v_N, τ_0..τ_{N-1}, λ_0..λ_{N-1}, f)``; knot 0 is fixed
at ``(q0, v0)``; the loop forces ``λ_k`` and closure rows exist for a robot with closed loops
(:mod:`mbplan.formulations.generalized_loops`), the contact forces ``f`` with their position and
friction rows for an OCP with contacts (:mod:`mbplan.formulations.generalized_contacts`).
For ``k = 0..N-1`` (eq. 61, explicit Euler as the paper writes it)::

    (q_{k+1} - q_k)/Δt - v_k = 0                          kinematics (divided by Δt: rad/s)
    RNEA(q_k, v_k, (v_{k+1} - v_k)/Δt) + D v_{k+1} - τ_k = 0   dynamics

(a floating base, :mod:`mbplan.formulations.free_flyer`: ``q_k`` holds the base's position and
quaternion in R⁴, the position step is ``(q_{k+1} ⊖ q_k)/Δt - v_k``, a row ``|quat_k|² - 1 = 0``
per knot follows the dynamics rows and the base's six torques are bounded to zero;
``D = diag(model.damping)``: URDF viscous joint damping, zero unless the robot has it; taken at
``v_{k+1}``, implicitly, so that stiff damping of light links, ``λ(M⁻¹D) Δt ≫ 1``, stays stable
and the step relaxes to the quasi-static ``D v = τ - h``), then the OCP's constraints, item by item
and knot by knot (equalities ``r = 0``, inequalities
``r ≤ 0``); joint position, velocity and torque limits become bounds on ``z``. Costs are
``Σ w ½‖r(x_k)‖²`` (a CasADi expression of ``z``). Residuals are their joint-space rows
(:mod:`mbplan.formulations.joint_space`): exact first and second derivatives by CasADi, or the
rows' own derivatives in ``q`` (coal distances: witness-point gradient, fixed-witness-point
Hessian, :mod:`mbplan.residuals.distance`); an obstacle residual with ``between_knots`` adds its
rows at configurations of the motion between knots ``k`` and ``k+1``
(:mod:`mbplan.formulations.interval_rows`).

Pinocchio's pip wheel has no CasADi bindings, so the constraint function, its Jacobian and the
Lagrangian Hessian are ``casadi.Callback`` functions given to ``casadi.nlpsol`` (``g`` and the
``jac_g``/``hess_lag`` options, :func:`~mbplan.formulations.casadi_nlp.callbacks`). Dynamics
Jacobian: ``computeRNEADerivatives``; dynamics Hessian
:func:`~mbplan.formulations.generalized_dynamics.rnea_hessian`, mapped to ``(q_k, v_k, v_{k+1})``
through ``a = (v_{k+1} - v_k)/Δt``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np
import pinocchio as pin
import scipy.sparse as sp
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.formulations.casadi_nlp import SparsePattern, block
from mbplan.formulations.free_flyer import FreeFlyerChart
from mbplan.formulations.generalized_contacts import (
    ContactColumns,
    contact_rows,
    guess_contact_forces,
)
from mbplan.formulations.generalized_dynamics import rnea_hessian
from mbplan.formulations.generalized_loops import (
    check_first_step,
    guess_forces,
    loop_blocks,
    loop_functions,
    loop_rows,
)
from mbplan.formulations.interval_rows import ConfigurationRows, interval_rows, knot_rows
from mbplan.formulations.joint_space import configuration_rows, knot_function
from mbplan.ocp.problem import OCP, Item
from mbplan.residuals.base import SymbolicRows
from mbplan.robots.configuration import difference


@dataclass
class _Rows:
    """Per-knot CasADi functions of an item (None: the loops' rows), their columns ``(K, nx)``
    in ``z`` and first row; rows that share their rows with others add to them."""

    item: Item | None
    value: cs.Function
    jac: cs.Function | None
    hess: cs.Function
    cols: np.ndarray
    row0: int
    m: int
    ineq: bool = False  # rows of no item (loops, contacts): inequalities

    @property
    def K(self) -> int:
        return len(self.cols)

    @property
    def sense(self) -> str:
        if self.item is None:
            return "ineq" if self.ineq else "eq"
        return self.item.sense

    @classmethod
    def of(
        cls,
        item: Item | None,
        x: cs.SX,
        out: cs.SX,
        cols: np.ndarray,
        row0: int,
        ineq: bool = False,
    ) -> _Rows:
        """The rows ``out(x)`` with their exact Jacobian and Hessian by CasADi."""
        lam = cs.SX.sym("lam", out.numel())
        return cls(
            item,
            cs.Function("r", [x], [out]),
            cs.Function("j", [x], [cs.jacobian(out, x)]),
            cs.Function("h", [x, lam], [cs.hessian(cs.dot(lam, out), x)[0]]),
            cols,
            row0,
            out.numel(),
            ineq,
        )


class GeneralizedNLP:
    """The NLP of ``ocp`` in generalized coordinates (module docstring)."""

    def __init__(self, ocp: OCP):
        self.ocp = ocp
        robot = ocp.robot
        self.model, self.data = robot.model, robot.model.createData()
        self.damping = np.array(robot.model.damping, dtype=float)
        N, nq, nv = ocp.N, robot.nq, robot.nv
        self.N, self.nq, self.nv, self.dt = N, nq, nv, ocp.dt
        self.chart = FreeFlyerChart(robot.model) if getattr(robot, "floating", False) else None
        self.loops = loop_functions(robot) if robot.loops else None
        if self.loops:
            check_first_step(robot, ocp.q0, ocp.v0, ocp.dt)
        self.nc = self.loops.size if self.loops else 0
        self.n = N * (nq + 2 * nv) + N * self.nc
        self.force_columns = ContactColumns(ocp.contacts, N, self.n)
        self.n = self.force_columns.end
        a_of_x = np.zeros((nq + 2 * nv, nq + 2 * nv))  # (q, v, a) from (q_k, v_k, v_{k+1})
        a_of_x[: nq + nv, : nq + nv] = np.eye(nq + nv)
        a_of_x[nq + nv :, nq : nq + nv] = -np.eye(nv) / self.dt
        a_of_x[nq + nv :, nq + nv :] = np.eye(nv) / self.dt
        self._a_of_x = a_of_x
        self._bounds()
        row = 2 * N * nv + (N if self.chart is not None else 0)  # the quaternions' norm rows
        self.rows: list[_Rows] = []
        self.costs: list[_Rows] = []
        own = []  # rows with their own derivatives in q, placed after the CasADi rows
        for item in ocp.items:
            r = item.residual
            if item.role == "constraint" and r.variable_bounds(robot) is not None:
                continue
            form = r.joint_space(robot, ocp.scene)
            between = item.role == "constraint" and r.between_knots
            if self.chart is not None and (between or not isinstance(form, SymbolicRows)):
                raise InputError(
                    f"generalized formulation: {item.role} {item.name!r}: rows with their own "
                    "derivatives in q (coal distances) or between knots are not written for a "
                    "floating base; plan it with 'ripm'"
                )
            if not isinstance(form, SymbolicRows):
                own.append((knot_rows, item, form))
            if between:
                sampled = configuration_rows(robot, ocp.scene, r.between_knots_form())
                own.append((interval_rows, item, sampled))
            if not isinstance(form, SymbolicRows):
                continue
            fn = knot_function(robot, ocp.scene, r)
            x = cs.SX.sym("x", fn.size1_in(0))
            out = fn(x)
            cols = self._columns(item)
            if item.role == "cost":
                c = 0.5 * item.weight * cs.sumsqr(out)
                hess = cs.Function("h", [x], [cs.hessian(c, x)[0]])
                self.costs.append(_Rows(item, fn, None, hess, cols, 0, 1))
                continue
            self.rows.append(_Rows.of(item, x, out, cols, row))
            row += out.numel() * len(cols)
        if self.loops:
            for x, out, cols, row0 in loop_blocks(self, self.loops, row):
                self.rows.append(_Rows.of(None, x, out, cols, row0))
            row += loop_rows(N, self.loops)
        blocks, row = contact_rows(self, row)
        for x, out, cols, row0, ineq in blocks:
            self.rows.append(_Rows.of(None, x, out, cols, row0, ineq))
        self.own: list[ConfigurationRows] = []
        for place, item, form in own:
            self.own.append(place(self, item, form, row))
            row += self.own[-1].size
        self.m = row
        self.lbg = np.zeros(self.m)
        self.ubg = np.zeros(self.m)
        for r in self.rows:
            if r.sense == "ineq":
                self.lbg[r.row0 : r.row0 + r.m * r.K] = -np.inf
        for own in self.own:
            if own.item.sense == "ineq":
                self.lbg[own.row0 : own.row0 + own.size] = -np.inf
        self._jacobian_pattern()
        self._hessian_pattern()

    # -- layout --------------------------------------------------------------------------------
    def iq(self, k: ArrayLike) -> np.ndarray:
        """Indices of ``q_k`` (``k = 1..N``) in ``z``, shape ``(*k.shape, nq)``."""
        return (np.asarray(k)[..., None] - 1) * self.nq + np.arange(self.nq)

    def iv(self, k: ArrayLike) -> np.ndarray:
        return (np.asarray(k)[..., None] - 1) * self.nv + np.arange(self.nv) + self.N * self.nq

    def itau(self, k: ArrayLike) -> np.ndarray:
        """Indices of ``τ_k`` (``k = 0..N-1``)."""
        return self.iv(np.asarray(k) + 1) + self.N * self.nv

    def ilam(self, k: ArrayLike) -> np.ndarray:
        """Indices of the loop forces ``λ_k`` (``k = 0..N-1``), shape ``(*k.shape, nc)``."""
        start = self.N * (self.nq + 2 * self.nv)
        return start + np.asarray(k)[..., None] * self.nc + np.arange(self.nc)

    def _columns(self, item: Item) -> np.ndarray:
        k = item.knots
        if item.residual.space == "control":
            return self.itau(k)
        return np.concatenate([self.iq(k), self.iv(k)], axis=1)

    def pack(
        self,
        q: np.ndarray,
        v: np.ndarray,
        tau: np.ndarray,
        lam: np.ndarray | None = None,
        forces: np.ndarray | None = None,
    ) -> np.ndarray:
        """``z`` of knots ``q, v (N+1, nv)``, ``tau (N, nv)``, loop forces ``lam (N, nc)`` and
        contact forces ``forces (N, n_contacts, 3)`` (zero if None)."""
        lam = np.zeros((self.N, self.nc)) if lam is None else lam
        parts = [q[1:].ravel(), v[1:].ravel(), tau.ravel(), lam.ravel()]
        return np.concatenate([*parts, self.force_columns.pack(forces)])

    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Knots ``q (N+1, nq)``, ``v (N+1, nv)`` and torques ``tau (N, nv)`` (a floating base's
        quaternions normalized; :meth:`loop_forces`: ``λ``)."""
        q = self._coordinates(z)
        V, T = np.reshape(z[self.N * self.nq : self.N * (self.nq + 2 * self.nv)], (2, self.N, -1))
        return q if self.chart is None else self.chart.normalize(q), np.vstack([self.ocp.v0, V]), T

    def _coordinates(self, z: np.ndarray) -> np.ndarray:
        """The knots' configuration coordinates in ``z`` as they are, ``(N+1, nq)``."""
        return np.vstack([self.ocp.q0, np.reshape(z[: self.N * self.nq], (self.N, self.nq))])

    def loop_forces(self, z: np.ndarray) -> np.ndarray:
        """The loop forces ``λ (N, nc)`` of the imposed closure rows, per interval."""
        start = self.N * (self.nq + 2 * self.nv)
        return np.reshape(z[start : start + self.N * self.nc], (self.N, self.nc))

    def _bounds(self) -> None:
        self.lbz, self.ubz = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        columns = {"q": self.iq, "v": self.iv, "tau": self.itau}
        for item in self.ocp.constraints:
            bounds = item.residual.variable_bounds(self.ocp.robot)
            if bounds is None:
                continue
            variable, lower, upper = bounds
            index = columns[variable](item.knots)
            if variable == "q":  # by velocity index: the 1-dof joints' coordinates
                joint = np.flatnonzero(self.ocp.robot.q_of_v >= 0)
                index = index[:, self.ocp.robot.q_of_v[joint]]
                lower, upper = np.asarray(lower)[joint], np.asarray(upper)[joint]
            self.lbz[index] = np.maximum(self.lbz[index], lower)
            self.ubz[index] = np.minimum(self.ubz[index], upper)
        if self.chart is not None:  # a floating base takes no torque
            base = self.itau(np.arange(self.N))[:, :6]
            self.lbz[base] = self.ubz[base] = 0.0

    def initial_guess(self, q: np.ndarray) -> np.ndarray:
        """``z`` from a joint path ``q (N+1, nq)`` with eq. (61) met: ``v_k = (q_{k+1} -
        q_k)/Δt``, ``v_N = 0``, ``τ_k`` by inverse dynamics (§VIII.C). With loops, knots
        ``1..N`` are first closed (:meth:`~mbplan.robots.robot.Robot.closed`) and the inverse
        dynamics shared between ``τ`` and ``λ`` by
        :func:`~mbplan.formulations.generalized_loops.guess_forces`."""
        if self.loops:
            q = np.vstack([q[:1], [self.ocp.robot.closed(qk) for qk in q[1:]]])
        v = np.zeros((len(q), self.nv))
        v[:-1] = difference(self.model, q[:-1], q[1:]) / self.dt
        a = np.diff(v, axis=0) / self.dt
        tau = np.array([pin.rnea(self.model, self.data, q[k], v[k], a[k]) for k in range(self.N)])
        tau, lam, forces = tau + self.damping * v[1:], None, None
        if self.ocp.contacts:
            forces, tau = guess_contact_forces(self, q, tau)
        if self.chart is not None:
            tau[:, :6] = 0.0  # the base's rows are left to the solver
        if self.loops:
            lam, tau = guess_forces(self.ocp.robot, self.loops, q[:-1], tau)
        return self.pack(q, v, tau, lam, forces)

    # -- per-item evaluation -------------------------------------------------------------------
    @staticmethod
    def _x(r: _Rows, z: np.ndarray) -> np.ndarray:
        return z[r.cols].T  # (nx, K)

    def objective(self, z: np.ndarray) -> float:
        total = 0.0
        for r in self.costs:
            out = np.asarray(r.value.map(r.K)(self._x(r, z)))
            total += 0.5 * r.item.weight * float(np.sum(out**2))
        return total

    def objective_gradient(self, z: np.ndarray) -> np.ndarray:
        """``∇f(z)`` (CasADi's reverse mode on :meth:`symbolic_objective`)."""
        if not hasattr(self, "_grad_f"):
            zs = cs.MX.sym("z", self.n)
            self._grad_f = cs.Function(
                "grad_f", [zs], [cs.gradient(self.symbolic_objective(zs), zs)]
            )
        return np.asarray(self._grad_f(z)).ravel()

    def symbolic_objective(self, z: cs.MX) -> cs.MX:
        f = cs.MX(0)
        for r in self.costs:
            X = cs.reshape(z[r.cols.ravel().tolist()], r.cols.shape[1], r.K)
            f += 0.5 * r.item.weight * cs.sumsqr(r.value.map(r.K)(X))
        return f

    def constraints(self, z: np.ndarray) -> np.ndarray:
        q, v, tau = self.unpack(z)
        a = np.diff(v, axis=0) / self.dt
        if self.chart is None:
            kin = np.diff(q, axis=0) / self.dt - v[:-1]
        else:
            kin = self.chart.kinematics(q, v, self.dt)
        dyn = np.array([pin.rnea(self.model, self.data, q[k], v[k], a[k]) for k in range(self.N)])
        g = np.zeros(self.m)
        g[: 2 * self.N * self.nv] = np.concatenate(
            [kin.ravel(), (dyn + self.damping * v[1:] - tau).ravel()]
        )
        if self.chart is not None:
            g[2 * self.N * self.nv : (2 * self.nv + 1) * self.N] = self.chart.norm_rows(
                self._coordinates(z)[1:]
            )
        for r in self.rows:
            g[r.row0 : r.row0 + r.m * r.K] += np.asarray(r.value.map(r.K)(self._x(r, z))).T.ravel()
        for own in self.own:
            g[own.row0 : own.row0 + own.size] = own.values(q, v)
        return g

    def _jacobian_pattern(self) -> None:
        N, nv = self.N, self.nv
        steps, inner = np.arange(N), np.arange(1, N)
        kin = steps[:, None] * nv + np.arange(nv)
        dyn = kin + N * nv
        if self.chart is None:  # (q_{k+1} - q_k)/Δt: constant diagonals
            kin_q = [
                (kin.ravel(), self.iq(steps + 1).ravel()),
                (kin[inner].ravel(), self.iq(inner).ravel()),
            ]
        else:  # (q_{k+1} ⊖ q_k)/Δt: dense blocks in the coordinates
            kin_q = [block(kin, self.iq(steps + 1)), block(kin[inner], self.iq(inner))]
        triplets = [
            *kin_q,
            (kin[inner].ravel(), self.iv(inner).ravel()),
            block(dyn[inner], self.iq(inner)),
            block(dyn[inner], self.iv(inner)),
            block(dyn, self.iv(steps + 1)),
            (dyn.ravel(), self.itau(steps).ravel()),
        ]
        if self.chart is not None:  # |quat_k|² - 1, k = 1..N
            norm = 2 * N * nv + steps[:, None]
            triplets.append(block(norm, self.iq(steps + 1)[:, self.chart.quaternion]))
        for r in self.rows:
            lr, lc = (np.array(a, dtype=np.int64) for a in r.jac.sparsity_out(0).get_triplet())
            k = np.arange(r.K)[:, None]
            triplets.append(((r.row0 + k * r.m + lr).ravel(), r.cols[:, lc].ravel()))
        triplets += [(own.jac_rows, own.jac_cols) for own in self.own]
        rows = np.concatenate([r for r, _ in triplets])
        cols = np.concatenate([c for _, c in triplets])
        self.jac_pattern = SparsePattern((self.m, self.n), rows, cols, np.ones(rows.size, bool))
        steps = (np.full(N * nv, 1.0 / self.dt), np.full((N - 1) * nv, -1.0 / self.dt))
        self._jac_constant = np.concatenate(  # the kinematics rows' q parts: without a chart
            [*(steps if self.chart is None else ()), np.full((N - 1) * nv, -1.0)]
        )

    def jacobian_values(self, z: np.ndarray) -> np.ndarray:
        q, v, _ = self.unpack(z)
        a = np.diff(v, axis=0) / self.dt
        dq, dv, M = (np.empty((self.N, self.nv, self.nv)) for _ in range(3))
        for k in range(self.N):
            dq[k], dv[k], M[k] = pin.computeRNEADerivatives(self.model, self.data, q[k], v[k], a[k])
        kin = [self._jac_constant]
        if self.chart is not None:  # in the coordinates: C = ∂δ/∂q
            coords = self._coordinates(z)
            first, second = self.chart.kinematics_jacobians(coords, self.dt)
            dq = dq @ np.array([self.chart.tangent(qk) for qk in coords[:-1]])
            kin = [second.ravel(), first[1:].ravel(), self._jac_constant]
        parts = [
            *kin,
            dq[1:].ravel(),
            (dv[1:] - M[1:] / self.dt).ravel(),
            (M / self.dt + np.diag(self.damping)).ravel(),  # D v_{k+1}: linear, no Hessian term
            np.full(self.N * self.nv, -1.0),
        ]
        if self.chart is not None:
            parts.append(2.0 * self._coordinates(z)[1:, self.chart.quaternion].ravel())
        for r in self.rows:
            parts.append(np.asarray(r.jac.map(r.K)(self._x(r, z)).nonzeros()))
        parts += [own.jacobian_values(q, v) for own in self.own]
        return np.concatenate(parts)

    def jacobian(self, z: np.ndarray) -> sp.csc_matrix:
        return self.jac_pattern.csc(self.jacobian_values(z))

    def _hessian_pattern(self) -> None:
        N = self.N
        inner = np.arange(1, N)
        local = np.concatenate([self.iq(inner), self.iv(inner), self.iv(inner + 1)], axis=1)
        triplets = [block(local, local)]
        if self.chart is not None:  # the kinematics rows' bases (q_k, q_{k+1}); the norm rows'
            base = np.concatenate([self.iq(inner)[:, :7], self.iq(inner + 1)[:, :7]], axis=1)
            triplets += [block(self.iq([1])[:, :7], self.iq([1])[:, :7]), block(base, base)]
            quat = self.iq(np.arange(1, N + 1))[:, self.chart.quaternion]
            triplets.append((quat.ravel(), quat.ravel()))
        self._hess_sizes = []
        for r in (*self.rows, *self.costs):
            lr, lc = (np.array(a, dtype=np.int64) for a in r.hess.sparsity_out(0).get_triplet())
            triplets.append((r.cols[:, lr].ravel(), r.cols[:, lc].ravel()))
        triplets += [(own.hess_rows, own.hess_cols) for own in self.own]
        rows = np.concatenate([r for r, _ in triplets])
        cols = np.concatenate([c for _, c in triplets])
        self.hess_pattern = SparsePattern((self.n, self.n), rows, cols, rows <= cols)

    def hessian_values(self, z: np.ndarray, sigma: float, lam: np.ndarray) -> np.ndarray:
        N, nv, T = self.N, self.nv, self._a_of_x
        q, v, _ = self.unpack(z)
        a = np.diff(v, axis=0) / self.dt
        lam_dyn = lam[N * nv : 2 * N * nv].reshape(N, nv)
        coords = q if self.chart is None else self._coordinates(z)
        dyn = np.array(
            [
                T.T
                @ rnea_hessian(self.model, self.data, self.chart, coords[k], v[k], a[k], lam_dyn[k])
                @ T
                for k in range(1, N)
            ]
        )
        parts = [dyn.ravel()]
        if self.chart is not None:
            pairs = self.chart.kinematics_hessians(coords, lam[: N * nv].reshape(N, nv), self.dt)
            parts += [pairs[0, 7:, 7:].ravel(), pairs[1:].ravel()]
            parts.append(np.repeat(2.0 * lam[2 * N * nv : 2 * N * nv + N], 4))
        for r in self.rows:
            L = lam[r.row0 : r.row0 + r.m * r.K].reshape(r.K, r.m).T
            parts.append(np.asarray(r.hess.map(r.K)(self._x(r, z), L).nonzeros()))
        for r in self.costs:
            parts.append(sigma * np.asarray(r.hess.map(r.K)(self._x(r, z)).nonzeros()))
        parts += [block.hessian_values(q, v, lam) for block in self.own]
        return np.concatenate(parts)

    def lagrangian_hessian(self, z: np.ndarray, sigma: float, lam: np.ndarray) -> sp.csc_matrix:
        """Upper triangle of ``∇²(σ f + λᵀ g)``."""
        return self.hess_pattern.csc(self.hessian_values(z, sigma, lam))
