"""Maximal coordinates: an :class:`~mbplan.OCP` on SO(3)×R³ bodies with the LGVI, for the RIPM.

The multi-body LGVI of :mod:`mbplan.transcription.multibody` (with the robot's loop closures as
constraints between bodies, :mod:`mbplan.transcription.loops`) plus one group of terms per OCP
item, which its residual writes on the bodies' poses
(:meth:`mbplan.residuals.Residual.maximal_terms`, with this NLP as the context: the maximal
model ``mm``, the OCP, the joints' bodies and :meth:`MaximalNLP.joint_terms`).
"""

from __future__ import annotations

import time
from functools import lru_cache, partial

import numpy as np
import pinocchio as pin
import scipy.optimize
import scipy.sparse as sp

from mbplan.dynamics.friction import cone_edges
from mbplan.errors import InputError
from mbplan.formulations.maximal_joints import joint_terms
from mbplan.formulations.maximal_layout import JointEliminationPlans
from mbplan.formulations.maximal_turns import follow_turns
from mbplan.lie import SO3
from mbplan.multibody import MaximalModel, joint_positions, maximal_model
from mbplan.ocp.contacts import generalized_force
from mbplan.ocp.problem import OCP, Item
from mbplan.robots.configuration import difference, integrate
from mbplan.robots.free_body import rotations
from mbplan.robots.loops import Loop
from mbplan.simulation.closed_loop import closed_loop_actuation
from mbplan.simulation.reference import damped_aba, mass_matrix
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.transcription.contacts import contact_blocks, contact_forces, contact_terms
from mbplan.transcription.multibody import dynamics_rows, multibody_layout
from mbplan.transcription.terms import Term
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import Point, trajectory_variables
from mbplan.workspace import Workspace


# process-wide cache, result-neutral: maximal-coordinate data of the (unmodified) model and its
# loop closures alone
@lru_cache(maxsize=16)
def _maximal(model: pin.Model, loops: tuple[Loop, ...]) -> MaximalModel:
    return maximal_model(model, loops)


class MaximalNLP:
    """The TrajectoryProblem of ``ocp`` on SO(3)×R³ bodies (module docstring); ``workspace``:
    where its structures, elimination plans and warm start's dynamics rows are kept."""

    def __init__(self, ocp: OCP, jit: bool, workspace: Workspace | None = None):
        self.ocp, self.jit, self.workspace = ocp, jit, workspace
        robot = ocp.robot
        self.mm = mm = _maximal(robot.model, tuple(getattr(robot, "loops", ())))
        self.body_of_joint = {int(j): b for b, j in enumerate(mm.pin_joint)}
        self.passive = tuple(mm.joint_names.index(name) for name in getattr(robot, "passive", ()))
        layout = multibody_layout(mm, ocp.N, ocp.dt, jit=jit, workspace=workspace)
        terms = [*layout.terms, *contact_terms(mm, ocp.contacts, ocp.N, ocp.dt, jit)]
        for item in ocp.items:
            try:
                terms += item.residual.maximal_terms(self, item)
            except InputError as err:
                raise InputError(f"maximal formulation, {item.role} {item.name!r}: {err}") from None
        blocks = (*layout.blocks, *contact_blocks(ocp.contacts, ocp.N))
        variables = trajectory_variables(blocks, workspace)
        self.problem = TrajectoryProblem(variables, terms, workspace)
        # the RIPM's kkt_method="reduced" eliminates the joints through this plan, its pivots
        # picked on the reference values
        self.problem.elimination_plan = JointEliminationPlans(self.problem, workspace=workspace)
        self.problem.pick_reference = self.pick_reference
        if any("theta_ref" in t.parameters for t in terms):
            self.problem.accept = partial(follow_turns, self)

    def pick_reference(self, eq_jacobian: sp.spmatrix) -> np.ndarray | None:
        """The values of ``eq_jacobian``'s entries that the joint reduction picks its pivots on:
        the equality Jacobian with every knot at rest in the robot's neutral configuration
        (its loops closed nearby; inverse dynamics for the forces). The rows the pick reads (the
        LGVI's kinematics, dynamics and joint constraints) are a function of the robot model
        (with its loops), ``N`` and ``dt`` alone, so every problem of a family picks alike and shares one symbolic phase
        (``None``: another pattern than the problem's). Neutral rather than a generic
        configuration: its groups have full rank, its tied columns are broken alike in every
        process, and its pick stays well conditioned on tasks that move around it (a seeded
        generic configuration's did not on the 4-link chain's reach)."""
        q = self.ocp.robot.closed(pin.neutral(self.ocp.robot.model))
        point = self.initial_point(np.tile(q, (self.ocp.N + 1, 1)))
        ref = sp.csr_matrix(self.problem.evaluate(point, hessian=False).eq_jacobian)
        jac = sp.csr_matrix(eq_jacobian)
        same = np.array_equal(ref.indptr, jac.indptr) and np.array_equal(ref.indices, jac.indices)
        return ref.data.copy() if same else None

    # -- item translations ---------------------------------------------------------------------
    def bodies(self, item: Item) -> np.ndarray:
        """Bodies of the joints a joint residual selects (in the residual's order)."""
        idx = self.ocp.robot.joint_indices(getattr(item.residual, "joints", None))
        where = {int(v): b for b, v in enumerate(self.mm.idx_v)}
        return np.array([where[int(i)] for i in idx], dtype=np.int64)

    def about_axis(self, bodies: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """``R_rel0 exp(θ a)`` of revolute joints (identity for other joints' entries)."""
        mm = self.mm
        angles = np.where(mm.revolute[bodies], angles, 0.0)
        return mm.R_rel0[bodies] @ SO3.exp(angles[:, None] * mm.axis_child[bodies])

    def joint_terms(
        self,
        item: Item,
        kind: str,
        bodies: np.ndarray,
        revolute: dict,
        prismatic: dict,
        shared: dict | None = None,
    ) -> list[Term]:
        """Terms of a joint residual at ``item.knots × bodies`` (revolute / prismatic joints)."""
        per = {"revolute": revolute, "prismatic": prismatic}
        common = {"revolute": dict(shared or {}), "prismatic": dict(shared or {})}
        common["revolute"] |= {"dt": self.ocp.dt} if kind == "velocity_eq" else {}
        return joint_terms(self.mm, item, kind, self.jit, bodies, per, common, self.ocp.dt)

    # -- points and results --------------------------------------------------------------------
    def initial_point(self, q: np.ndarray) -> Point:
        """The LGVI point of a joint path ``q (N+1, nq)`` (inverse dynamics for λ, τ; the
        passive joints' torques zero). Its first step (knot 0's ``F, v``: data) is the robot's
        at rest over ``[t_0, t_1]``, held by its joints; a floating base cannot be held: its
        robot's first step is the free motion under zero joint torque
        (:func:`free_first_step`), or, held by a contact from the start, ``q_0 ⊕ Δt v_0`` (at
        rest: it stays, as a fixed-base robot does)."""
        ocp = self.ocp
        if self.mm.free.any():
            q = np.array(q, dtype=float)
            if any(c.first <= 1 for c in ocp.contacts):  # held from the start
                q[1] = integrate(self.mm.model, ocp.q0, ocp.dt * ocp.v0)
            else:
                q[1] = free_first_step(self.mm.model, ocp.q0, ocp.v0, ocp.dt)
        point = maximal_warm_start(
            self.mm, q, self.ocp.dt, jit=self.jit, workspace=self.workspace, passive=self.passive
        )
        if not self.ocp.contacts:
            return self.problem.check_point(point)
        for block in contact_blocks(self.ocp.contacts, self.ocp.N):
            point[block.name] = np.zeros(block.shape)
        return self._balance(self.problem.check_point(point))

    def _balance(self, point: Point) -> Point:
        """``point`` with the forces of every knot ``k`` (joint multipliers, the active joints'
        torques, the contact forces) corrected to balance step ``k-1``'s dynamics rows in least
        squares (minimum-norm change): the warm start's inverse dynamics, with the contacts
        carrying the base."""
        mm, N = self.mm, self.ocp.N
        ev = self.problem.evaluate(point, hessian=False)
        jac = ev.eq_jacobian.tocsr()
        index = self.problem.variables.tangent_index
        active = np.setdiff1d(np.arange(mm.nj), mm.joint_slot[list(self.passive)])
        per_knot = [
            index("lam").reshape(N + 1, -1),
            index("tau").reshape(N + 1, mm.nj)[:, active],
            *(index(b.name).reshape(N + 1, -1) for b in contact_blocks(self.ocp.contacts, N)),
        ]
        cols = np.concatenate(per_knot, axis=1)
        step = np.zeros(self.problem.n)
        for k in range(1, N + 1):
            rows = dynamics_rows(mm.nb, N, np.full(mm.nb, k - 1), np.arange(mm.nb)).ravel()
            c = cols[k][cols[k] >= 0]
            A = jac[rows][:, c].toarray()
            step[c] = np.linalg.lstsq(A, -ev.eq[rows], rcond=None)[0]
        return self.problem.retract(point, step)

    def trajectory(self, x: Point) -> dict:
        """PlanResult fields of a point: :meth:`joint_trajectory`, the bodies' ``R, p``."""
        bodies = {"R": x["R"], "p": x["p"], "body_names": self.mm.body_names}
        return bodies | self.joint_trajectory(x)

    def joint_trajectory(self, x: Point) -> dict[str, np.ndarray]:
        """Joint-space view of a maximal point: ``q (N+1, nq)``, ``v (N+1, nv)``, ``tau (N, nv)`` (interval
        means), ``tau_knots (N+1, nv)`` (first-order hold of the LGVI's knot torques, eq. 29).

        ``q_k`` from the relative poses and ``v_k`` their central differences (with ``q_{N+1}``
        from ``R_N F_N``; a floating base's local velocity, :func:`central_differences`; its
        torques are zero); with contacts (no loops), the velocity midway through each knot's
        impulse (:func:`impulse_midpoint_velocities`), a floating base's linear velocity the
        centre of mass's (:func:`momentum_consistent_base`). Knot 0's torque does not enter
        the LGVI, where the arm rests over the first step as in eq. (61): ``tau_knots[0]`` makes the mean over
        ``[t_0, t_1]`` the torque for which eq. (61)'s first step reaches the planned ``v_1``
        (with loop closures: the actuated joints' torques and closure forces that do, least
        squares; the passive joints' zero).
        """
        mm, N, dt = self.mm, self.ocp.N, self.ocp.dt
        Rk = np.concatenate([x["R"], (x["R"][-1] @ x["F"][-1])[None]])
        pk = np.concatenate([x["p"], (x["p"][-1] + x["v"][-1] * dt)[None]])
        q = joint_positions(mm, Rk, pk, q_ref=self.ocp.q0)
        v = np.zeros((N + 1, mm.nv))
        v[0] = self.ocp.v0
        v[1:] = central_differences(mm.model, q, dt)
        tau_knots = np.zeros((N + 1, mm.nv))
        tau_knots[:, mm.idx_v[mm.jointed]] = x["tau"][:, :, 0]
        if self.ocp.contacts:  # (contacts exclude loops)
            frames = [mm.model.getFrameId(c.frame) for c in self.ocp.contacts]
            forces = self._knot_forces(x)
            v[1:] = impulse_midpoint_velocities(mm.model, frames, q[1 : N + 1], v[1:],
                                                tau_knots[1:], forces[1:], dt)  # fmt: skip
            if mm.free.any():
                v[1:] = momentum_consistent_base(mm.model, q, v[1:], dt)
        a_0, external = (v[1] - v[0]) / dt, None
        contact = self._contact_trajectory(x, q[0], v[0], a_0)
        if contact:
            frames = [mm.model.getFrameId(f) for f in contact["contact_frames"]]
            external = generalized_force(mm.model, frames, q[0], contact["contact_forces"][0])
        tau_0 = first_step_torque(mm, q[0], v[0], a_0, external)
        tau_0 = tau_0 + np.asarray(mm.model.damping) * v[0]  # the LGVI's viscous damping
        tau_knots[0] = 2.0 * self._actuation(q[0], tau_0) - tau_knots[1]
        tau = 0.5 * (tau_knots[:-1] + tau_knots[1:])
        return {"q": q[: N + 1], "v": v, "tau": tau, "tau_knots": tau_knots} | contact

    def _contact_trajectory(
        self, x: Point, q0: np.ndarray, v0: np.ndarray, a0: np.ndarray
    ) -> dict[str, np.ndarray]:
        """``contact_forces_knots (N+1, nc, d)`` (the LGVI's knot forces, world frame; ``d`` 6
        with soles: their wrenches) and their interval means ``contact_forces``. Knot 0's
        force, which the LGVI does not use, is the one inside its cone for which the first
        interval's mean force of the contacts held from the start best balances the base's rows
        of the first step's inverse dynamics ``RNEA(q0, v0, a0)`` (non-negative least squares on
        the cones' edges; :meth:`joint_trajectory` then balances the rest with the torques)."""
        contacts, mm = self.ocp.contacts, self.mm
        if not contacts:
            return {}
        knots = self._knot_forces(x)
        start = [i for i, c in enumerate(contacts) if c.first <= 1]
        base = np.zeros(mm.nv, dtype=bool)
        for b in np.flatnonzero(mm.free):
            base[mm.idx_v[b] : mm.idx_v[b] + 6] = True
        if start and base.any():
            model = mm.model
            data = model.createData()
            demand = pin.rnea(model, data, q0, v0, a0)[base]
            columns = []
            for i in start:
                c = contacts[i]
                fid = model.getFrameId(c.frame)
                J = pin.computeFrameJacobian(model, data, q0, fid, pin.LOCAL_WORLD_ALIGNED)
                J = J[: c.dim, base].T
                demand -= 0.5 * J @ knots[1, i, : c.dim]
                columns.append(0.5 * J @ c.world(cone_edges(c.friction, c.sole)).T)
            beta = scipy.optimize.nnls(np.hstack(columns), demand)[0]
            edges = [cone_edges(contacts[i].friction, contacts[i].sole) for i in start]
            split = np.cumsum([len(e) for e in edges])[:-1]
            for i, b, e in zip(start, np.split(beta, split), edges, strict=True):
                knots[0, i, : contacts[i].dim] = b @ contacts[i].world(e)
        return {
            "contact_forces": 0.5 * (knots[:-1] + knots[1:]),
            "contact_forces_knots": knots,
            "contact_frames": self.ocp.contact_frames,
        }

    def _knot_forces(self, x: Point) -> np.ndarray:
        """The contacts' knot forces (and torques) ``(N+1, nc, d)`` of a point, world frame."""
        contacts = self.ocp.contacts
        knots = contact_forces(contacts, x, self.ocp.N + 1)
        for i, c in enumerate(contacts):
            knots[:, i, : c.dim] = c.world(knots[:, i, : c.dim])
        return knots

    def _actuation(self, q: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """The joint torques ``u`` (zero on passive joints) with ``u + Jᵀf = tau`` for some
        closure forces ``f`` (least squares; ``tau`` itself without loops)."""
        robot = self.ocp.robot
        if not robot.loops:
            return tau
        active = np.setdiff1d(np.arange(robot.nv), robot.joint_indices(robot.passive))
        return closed_loop_actuation(robot.model, robot.loops, active, q, tau)


def first_step_torque(
    mm: MaximalModel,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    external: np.ndarray | None = None,
) -> np.ndarray:
    """Inverse dynamics ``RNEA(q, v, a) - e`` of the first step under the generalized external
    force ``e`` (contact forces, :func:`~mbplan.ocp.contacts.generalized_force`; zero if None);
    with a floating base, whose rows take no torque, the joints' accelerations ``a`` and the
    base's that leave its rows balanced (``a_b = -M_bb⁻¹(h_b - e_b + M_bj a_j)``): the joint
    torques for which an Euler step reaches the joints' planned velocities, and zero on the
    base."""
    model, data = mm.model, mm.model.createData()
    base = np.zeros(mm.nv, dtype=bool)
    for b in np.flatnonzero(mm.free):
        base[mm.idx_v[b] : mm.idx_v[b] + 6] = True
    a = np.array(a, dtype=float)
    e = np.zeros(mm.nv) if external is None else np.asarray(external, dtype=float)
    if base.any():
        M = mass_matrix(model, data, q)
        h = pin.rnea(model, data, q, v, np.zeros(mm.nv)) - e
        a[base] = -np.linalg.solve(
            M[np.ix_(base, base)], h[base] + M[np.ix_(base, ~base)] @ a[~base]
        )
    tau = pin.rnea(model, data, q, v, a) - e
    tau[base] = 0.0
    return tau


def free_first_step(model: pin.Model, q0: np.ndarray, v0: np.ndarray, dt: float) -> np.ndarray:
    """``q_1 = q_0 ⊕ (Δt v_0 + ½Δt² a_0)``, ``a_0`` the forward dynamics (with the joints'
    damping) under zero torque: the first step of a robot released at ``(q_0, v_0)`` with zero
    joint torques (from rest: every body falls by
    ``½gΔt²``, the LGVI's own first step when no joint force acts at knot 0)."""
    a0 = damped_aba(model, model.createData(), q0, v0, np.zeros(model.nv))
    return integrate(model, q0, dt * np.asarray(v0) + 0.5 * dt**2 * a0)


MIDPOINT_ITERATIONS = 3  # fixed-point passes of impulse_midpoint_velocities (converged to ~1e-6)


def impulse_midpoint_velocities(
    model: pin.Model,
    frames: list[int],
    q: np.ndarray,
    v: np.ndarray,
    tau: np.ndarray,
    forces: np.ndarray,
    dt: float,
) -> np.ndarray:
    """The velocities ``(K, nv)`` at knots ``q (K, nq)`` midway through their impulses
    ``Δt (τ_k + Σ J_iᵀ f_{i,k})`` (knot torques ``tau (K, nv)``, contact forces
    ``forces (K, nc, 3)`` at ``frames``, or wrenches ``(K, nc, 6)``), from the central
    differences ``v (K, nv)``.

    The LGVI applies its knot forces as impulses with the unforced motion between
    (:mod:`mbplan.verification.multibody`). Along such a motion the secants ``w_{k-1}``,
    ``w_k`` of the intervals around knot ``k`` are ``v_k^∓ ∓ ½Δt a_k^∓ + O(Δt²)``, ``v_k^∓`` the
    velocities before and after the impulse and ``a_k^∓`` the unforced accelerations there
    (gravity, Coriolis, damping), so the velocity midway through the impulse,
    ``½(v_k^- + v_k^+)``, is

        ``v_k = ½(w_{k-1} + w_k) - ¼Δt (a_free(q_k, v_k^+) - a_free(q_k, v_k^-))``,
        ``v_k^± = v_k ± ½Δt M(q_k)⁻¹(τ_k + Σ J_iᵀ f_{i,k})``

    (fixed point, :data:`MIDPOINT_ITERATIONS` passes). The second term is ``O(Δt²)`` where
    the impulse is small, first order where it reverses a light leg: at a jump's take-off
    (solo12, Δt = 20 ms) the knee's velocity jumps by 13 rad/s within one knot and the central
    difference is 0.2 rad/s off the velocity of the continuous motion through the planned
    configurations (which an RK4 shooting from knot 2 finds within 0.02 rad/s of ``v_k``, and
    then through ``q_3 … q_9`` within 2e-5 rad)."""
    data = model.createData()
    zero = np.zeros(model.nv)
    out = np.array(v, dtype=float)
    for k in range(len(q)):
        load = tau[k] + generalized_force(model, frames, q[k], forces[k])
        kick = 0.5 * dt * np.linalg.solve(mass_matrix(model, data, q[k]), load)
        for _ in range(MIDPOINT_ITERATIONS):
            jump = damped_aba(model, data, q[k], out[k] + kick, zero) - damped_aba(
                model, data, q[k], out[k] - kick, zero
            )
            out[k] = v[k] - 0.25 * dt * jump
    return out


def momentum_consistent_base(
    model: pin.Model, q: np.ndarray, v: np.ndarray, dt: float
) -> np.ndarray:
    """The velocities ``v (K, nv)`` at knots ``1 … K`` of a path ``q (K+2, nq)`` with a free
    flyer's linear velocity set so that the robot's linear momentum is
    ``m (c_{k+1} - c_{k-1}) / (2Δt)``, ``c`` the centre of mass.

    Between the LGVI's impulses at the knots (:func:`impulse_midpoint_velocities`) only gravity
    acts on the centre of mass: it moves on a parabola, whose secant over an interval is its
    velocity at the interval's middle, and gravity's half-impulses on either side of a knot
    cancel, so the momentum midway through a knot's impulse is exactly the central difference
    of the centre of mass. The joints' velocities and the base's angular velocity are kept."""
    data = model.createData()
    mass = sum(inertia.mass for inertia in model.inertias)
    com = np.array([pin.centerOfMass(model, data, qk) for qk in q])
    out = np.array(v, dtype=float)
    for k in range(len(v)):
        target = mass * (com[k + 2] - com[k]) / (2.0 * dt)
        A = pin.computeCentroidalMap(model, data, q[k + 1])[:3]
        out[k, :3] += np.linalg.solve(A[:, :3], target - A @ out[k])
    return out


def central_differences(model: pin.Model, q: np.ndarray, dt: float) -> np.ndarray:
    """The velocities ``(K-2, nv)`` at knots ``k = 1 … K-2`` of a path ``q (K, nq)``, second
    order: ``(q_{k+1} - q_{k-1})/(2Δt)`` of the 1-dof joints; a floating base's local velocity
    ``R_kᵀ(p_{k+1} - p_{k-1})/(2Δt)`` and ``(log(R_kᵀR_{k+1}) - log(R_kᵀR_{k-1}))/(2Δt)``
    (a screw through ``k-1`` and ``k+1``, Pinocchio's ``difference``, would be off by
    ``O(Δt |ω| |v|)`` while the base turns and moves)."""
    v = difference(model, q[:-2], q[2:]) / (2 * dt)
    if model.nq == model.nv:
        return v
    R = rotations(q[:, 3:7])
    Rk = np.swapaxes(R[1:-1], -1, -2)
    v[:, :3] = np.einsum("kij,kj->ki", Rk, q[2:, :3] - q[:-2, :3]) / (2 * dt)
    v[:, 3:6] = (SO3.log(Rk @ R[2:]) - SO3.log(Rk @ R[:-2])) / (2 * dt)
    return v


def build(ocp: OCP, jit: bool, workspace: Workspace | None = None) -> tuple[MaximalNLP, float]:
    """:class:`MaximalNLP` of ``ocp`` (its structures kept in ``workspace``) and the build time
    (s)."""
    t0 = time.perf_counter()
    return MaximalNLP(ocp, jit, workspace), time.perf_counter() - t0
