"""Maximal coordinates: an :class:`~mbplan.OCP` on SO(3)×R³ bodies with the LGVI, for the RIPM.

The multi-body LGVI of :mod:`mbplan.transcription.multibody` plus one group of terms per OCP
item, each residual kind written once on the bodies' poses:

* joint positions, velocities and their limits of revolute and prismatic joints
  (:mod:`mbplan.formulations.maximal_joints`);
* torques (forces for prismatic joints) ``τ`` at the knots (interval ``k`` of the OCP is the LGVI's knot ``k+1``, eq. 29);
* frame translation and placement on the pose ``(R_b R_jf, p_b + R_b c)`` of the frame's body;
* eq. (62) on the body COMs, coal distances on the body poses (:mod:`.distance`).
"""

from __future__ import annotations

import time
from functools import cache, lru_cache

import casadi as cs
import numpy as np
import pinocchio as pin

from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.formulations.joint_space import distance_pairs, frame_error
from mbplan.formulations.maximal_joints import joint_terms
from mbplan.formulations.maximal_layout import JointEliminationPlans
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel, joint_positions, maximal_model
from mbplan.ocp.problem import OCP, Item
from mbplan.ocp.residuals import (
    ComOutsideCylinder,
    Distance,
    FramePlacement,
    FrameTranslation,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    JointVelocityLimits,
)
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.transcription.constraints import cylinder_clearance_function
from mbplan.transcription.distance import distance_constraint_function, pair_bodies
from mbplan.transcription.multibody import multibody_layout
from mbplan.transcription.terms import Term
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import Point, trajectory_variables
from mbplan.workspace import Workspace

_TORQUE = {
    "cost": (lambda tau, t, w: 0.5 * w * (tau - t) ** 2, [("t", 1), ("w", 1)]),
    "eq": (lambda tau, t: tau - t, [("t", 1)]),
    "limits": (lambda tau, lo, hi: cs.vertcat(tau - hi, lo - tau), [("lo", 1), ("hi", 1)]),
}


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _torque_function(kind: str, jit: bool) -> RiemannianFunction:
    fn, params = _TORQUE[kind]
    return RiemannianFunction(f"torque_{kind}", [("tau", R(1))], fn, params, jit=jit)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _frame_function(kind: str, cost: bool, jit: bool) -> RiemannianFunction:
    """Frame translation ``p_f - p_g`` or placement ``(p_f - p_g, log(R_gᵀ R_f))`` of the frame
    at ``(R_b R_jf, p_b + R_b c)`` on body ``(R_b, p_b)``; as a cost ``½ w ‖r‖²``."""
    goal = [("R_g", (3, 3)), ("p_g", 3)] if kind == "placement" else [("p_g", 3)]

    def fn(Rb, pb, R_jf, c, p_g, R_g=None, w=None):
        Rf, pf = cs.mtimes(Rb, R_jf), pb + cs.mtimes(Rb, c)
        r = frame_error(Rf, pf, p_g, R_g)
        return 0.5 * w * cs.sumsqr(r) if cost else r

    params = [("R_jf", (3, 3)), ("c", 3), *goal] + ([("w", 1)] if cost else [])
    name = f"frame_{kind}_{'cost' if cost else 'eq'}"
    return RiemannianFunction(name, [("Rb", SO3), ("pb", R(3))], fn, params, jit=jit)


# process-wide cache, result-neutral: maximal-coordinate data of the (unmodified) model alone
@lru_cache(maxsize=16)
def _maximal(model: pin.Model) -> MaximalModel:
    return maximal_model(model)


class MaximalNLP:
    """The TrajectoryProblem of ``ocp`` on SO(3)×R³ bodies (module docstring); ``workspace``:
    where its structures, elimination plans and warm start's dynamics rows are kept."""

    def __init__(self, ocp: OCP, jit: bool, workspace: Workspace | None = None):
        self.ocp, self.jit, self.workspace = ocp, jit, workspace
        self.mm = mm = _maximal(ocp.robot.model)
        self.body_of_joint = {int(j): b for b, j in enumerate(mm.pin_joint)}
        layout = multibody_layout(mm, ocp.N, ocp.dt, jit=jit, workspace=workspace)
        terms = list(layout.terms)
        for item in ocp.items:
            try:
                terms += self._terms(item)
            except InputError as err:
                raise InputError(f"maximal formulation, {item.role} {item.name!r}: {err}") from None
        variables = trajectory_variables(layout.blocks, workspace)
        self.problem = TrajectoryProblem(variables, terms, workspace)
        # the RIPM's kkt_method="reduced" eliminates the joints through this plan
        self.problem.elimination_plan = JointEliminationPlans(self.problem, workspace=workspace)

    # -- item translations ---------------------------------------------------------------------
    def _bodies(self, item: Item) -> np.ndarray:
        """Bodies of the joints a joint residual selects (in the residual's order)."""
        idx = self.ocp.robot.joint_indices(getattr(item.residual, "joints", None))
        where = {int(v): b for b, v in enumerate(self.mm.idx_v)}
        return np.array([where[int(i)] for i in idx], dtype=np.int64)

    def _about_axis(self, bodies: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """``R_rel0 exp(θ a)`` of revolute joints (identity for other joints' entries)."""
        mm = self.mm
        angles = np.where(mm.revolute[bodies], angles, 0.0)
        return mm.R_rel0[bodies] @ SO3.exp(angles[:, None] * mm.axis_child[bodies])

    def _joint_terms(
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

    def _terms(self, item: Item) -> list[Term]:
        r, mm, nb, ocp = item.residual, self.mm, self.mm.nb, self.ocp
        cost = item.role == "cost"
        rev = mm.revolute
        if isinstance(r, JointPosition):
            b = self._bodies(item)
            t = np.asarray(r.target, dtype=float)
            R_t = self._about_axis(b, t)
            if cost:
                w = {"w": item.weight}
                return self._joint_terms(item, "position_cost", b, {"R_t": R_t}, {"t": t}, w)
            per = {"R_t": R_t, "a": mm.axis_child[b]}
            return self._joint_terms(item, "position_eq", b, per, {"t": t})
        if isinstance(r, JointVelocity):
            b = self._bodies(item)
            target = np.asarray(r.target, dtype=float)
            if cost:
                if np.any(target != 0.0):
                    raise InputError("a velocity cost with a nonzero target is not expressible")
                w = {"w": item.weight / ocp.dt**2}
                return self._joint_terms(item, "velocity_cost", b, {}, {}, w)
            per = {"a": mm.axis_child[b], "target": target}
            return self._joint_terms(item, "velocity_eq", b, per, {"target": target})
        if isinstance(r, JointPositionLimits):
            lo, hi = np.asarray(r.lower)[mm.idx_v], np.asarray(r.upper)[mm.idx_v]
            # no rows for continuous joints, nor for a revolute range of 2π or more (it limits
            # no rotation: cos ≥ -1)
            limited = np.isin(mm.idx_v, r.indices(ocp.robot))
            b = np.flatnonzero(limited & (~rev | (hi - lo < 2 * np.pi)))
            if not b.size:
                return []
            lo, hi = lo[b], hi[b]
            half = np.minimum(0.5 * (hi - lo), np.pi)
            per = {"R_mid": self._about_axis(b, 0.5 * (lo + hi)), "cos_half": np.cos(half)}
            return self._joint_terms(item, "position_limits", b, per, {"lo": lo, "hi": hi})
        if isinstance(r, JointVelocityLimits):
            lo, hi = np.asarray(r.lower)[mm.idx_v], np.asarray(r.upper)[mm.idx_v]
            if not np.allclose(lo[rev], -hi[rev]):
                raise InputError(
                    "asymmetric velocity limits of revolute joints are not expressible"
                )
            per = {"cos_step": np.cos(np.minimum(hi * ocp.dt, np.pi))}
            b = np.arange(nb)
            return self._joint_terms(item, "velocity_limits", b, per, {"lo": lo, "hi": hi})
        if isinstance(r, (JointTorque, JointTorqueLimits)):
            if isinstance(r, JointTorque):
                b = self._bodies(item)
                per = {"t": np.asarray(r.target)}
                kind = "cost" if cost else "eq"
            else:
                b = np.arange(nb)
                per = {"lo": np.asarray(r.lower)[mm.idx_v], "hi": np.asarray(r.upper)[mm.idx_v]}
                kind = "limits"
            k, i = (
                a.ravel() for a in np.meshgrid(item.knots + 1, np.arange(len(b)), indexing="ij")
            )
            params = {n: v[i] for n, v in per.items()} | ({"w": item.weight} if cost else {})
            sense = "cost" if cost else r.sense
            fn = _torque_function(kind, self.jit)
            return [Term(item.name, sense, fn, {"tau": ("tau", k * nb + b[i])}, params)]
        if isinstance(r, (FramePlacement, FrameTranslation)):
            frame = ocp.robot.model.frames[ocp.robot.frame_id(r.frame)]
            b = self.body_of_joint[int(frame.parentJoint)]
            params = {
                "R_jf": frame.placement.rotation,
                "c": frame.placement.translation - mm.com_in_joint[b],
                "p_g": np.asarray(r.translation),
            }
            kind = "placement" if isinstance(r, FramePlacement) else "translation"
            if kind == "placement":
                params["R_g"] = r.rotation
            if cost:
                params["w"] = item.weight
            sites = item.knots * nb + b
            fn = _frame_function(kind, cost, self.jit)
            sense = "cost" if cost else r.sense
            return [Term(item.name, sense, fn, {"Rb": ("R", sites), "pb": ("p", sites)}, params)]
        if isinstance(r, ComOutsideCylinder):
            k, b = (a.ravel() for a in np.meshgrid(item.knots, np.arange(nb), indexing="ij"))
            fn = cylinder_clearance_function(self.jit)
            return [
                Term(item.name, "ineq", fn, {"p": ("p", k * nb + b)}, {"c": r.circle(ocp.scene)})
            ]
        if isinstance(r, Distance):
            pairs = distance_pairs(ocp.robot, ocp.scene, r.objects)
            k, i = (
                a.ravel() for a in np.meshgrid(item.knots, np.arange(pairs.size), indexing="ij")
            )
            sites = k * nb + pair_bodies(mm, pairs)[i]
            fn = distance_constraint_function(mm, pairs)
            bind = {"R": ("R", sites), "p": ("p", sites)}
            return [
                Term(item.name, "ineq", fn, bind, {"pair": i.astype(float), "margin": r.margin})
            ]
        raise InputError(f"{type(r).__name__} has no maximal-coordinate translation")

    # -- points and results --------------------------------------------------------------------
    def initial_point(self, q: np.ndarray) -> Point:
        """The LGVI point of a joint path ``q (N+1, nq)`` (inverse dynamics for λ, τ)."""
        point = maximal_warm_start(self.mm, q, self.ocp.dt, jit=self.jit, workspace=self.workspace)
        return self.problem.check_point(point)

    def trajectory(self, x: Point) -> dict:
        """PlanResult fields of a point: :meth:`joint_trajectory`, the bodies' ``R, p``."""
        bodies = {"R": x["R"], "p": x["p"], "body_names": self.mm.body_names}
        return bodies | self.joint_trajectory(x)

    def joint_trajectory(self, x: Point) -> dict[str, np.ndarray]:
        """Joint-space view of a maximal point: ``q, v (N+1, nq)``, ``tau (N, nv)`` (interval
        means), ``tau_knots (N+1, nv)`` (first-order hold of the LGVI's knot torques, eq. 29).

        ``q_k`` from the relative poses and ``v_k = (q_{k+1} - q_{k-1})/(2Δt)`` (with
        ``q_{N+1}`` from ``R_N F_N``). Knot 0's torque does not enter the LGVI, where the arm
        rests over the first step as in eq. (61): ``tau_knots[0]`` makes the mean over
        ``[t_0, t_1]`` the torque for which eq. (61)'s first step reaches the planned ``v_1``.
        """
        mm, N, dt = self.mm, self.ocp.N, self.ocp.dt
        Rk = np.concatenate([x["R"], (x["R"][-1] @ x["F"][-1])[None]])
        pk = np.concatenate([x["p"], (x["p"][-1] + x["v"][-1] * dt)[None]])
        q = joint_positions(mm, Rk, pk, q_ref=self.ocp.q0)
        v = np.zeros((N + 1, mm.nv))
        v[0] = self.ocp.v0
        v[1:] = (q[2:] - q[:-2]) / (2 * dt)
        tau_knots = np.array(x["tau"][:, :, 0])[:, np.argsort(mm.idx_v)]
        tau_0 = pin.rnea(mm.model, mm.model.createData(), q[0], v[0], (v[1] - v[0]) / dt)
        tau_0 = tau_0 + np.asarray(mm.model.damping) * v[0]  # the LGVI's viscous damping
        tau_knots[0] = 2.0 * tau_0 - tau_knots[1]
        tau = 0.5 * (tau_knots[:-1] + tau_knots[1:])
        return {"q": q[: N + 1], "v": v, "tau": tau, "tau_knots": tau_knots}


def build(ocp: OCP, jit: bool, workspace: Workspace | None = None) -> tuple[MaximalNLP, float]:
    """:class:`MaximalNLP` of ``ocp`` (its structures kept in ``workspace``) and the build time
    (s)."""
    t0 = time.perf_counter()
    return MaximalNLP(ocp, jit, workspace), time.perf_counter() - t0
