"""Shooting: an :class:`~mbplan.OCP` as a Crocoddyl ``ShootingProblem`` (FDDP, mim-solvers CSQP).

State ``x = (q, v)``, control ``u = τ`` (fully actuated), forward dynamics by ABA
(``DifferentialActionModelFreeFwdDynamics``) and ``IntegratedActionModelEuler`` with the OCP's
Δt, which is *semi-implicit* (``v_{k+1} = v_k + Δt aba``, ``q_{k+1} = q_k + Δt v_{k+1}``), first
order like eq. (61). Crocoddyl ignores ``model.damping``: a robot with viscous joint damping
applies ``τ = u - D v_k`` through :class:`ActuationModelDamped`, explicit in ``v``, so damping
stiffer than :data:`MAX_DAMPING_STIFFNESS` (``λ(M⁻¹D) Δt`` at ``q0``) is refused. Node ``k < N``
carries the state items at knot ``k`` (``k ≥ 1``) and the
control items of interval ``k``; the terminal node the state items at knot ``N``. Crocoddyl
multiplies running costs by Δt, so their weights are divided by Δt.

Each residual translates itself (:meth:`mbplan.residuals.Residual.shooting`, with the
:class:`ShootingBuilder` as the context: Crocoddyl's state, the OCP, the residual models below):
Crocoddyl's state and control residuals for joint costs and limits,
:meth:`ShootingBuilder.symbolic` (the joint-space CasADi value and Jacobian as a Python residual)
for any other state residual, :class:`ResidualModelCylinderClearance` for eq. (62),
:class:`ResidualModelCoalDistance` for coal distances. Constraints that bound the torques
(:meth:`~mbplan.residuals.Residual.variable_bounds`) are also the nodes' control bounds
(box-FDDP).

Constraints: CSQP (``hard=True``) imposes every constraint (``ConstraintModelResidual``). FDDP
has none: inequality constraints become ``½ W max(violation, 0)²`` penalties
(``ActivationModelQuadraticBarrier``, :data:`OBSTACLE_WEIGHT` for obstacles,
:data:`LIMIT_WEIGHT` for limits) of the bounds tightened by :data:`PENALTY_MARGIN`, so that the
small violations a finite penalty leaves (up to 3e-3 rad/s on the iiwa's velocity limits at
``W = 1e3``) stay inside the true bounds; an equality constraint is not expressible (an
:class:`~mbplan.errors.InputError` naming it; make it a cost or use CSQP).

A robot with closed kinematic loops is refused (:func:`~mbplan.robots.loops.refuse_loops`):
Crocoddyl's free forward dynamics have no loop closures.

Importing needs the ``baselines`` extra (``crocoddyl==3.2.1``, ``mim-solvers==0.3.0``); the
first build checks that Crocoddyl's forward dynamics equal Pinocchio's ABA
(:func:`check_forward_dynamics`): a mismatched ``pin`` silently computes wrong dynamics.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import casadi as cs
import numpy as np
import pinocchio as pin

from mbplan.errors import InputError, MbplanError
from mbplan.formulations.joint_space import knot_function
from mbplan.multibody.collision import chain_kinematics, point_jacobians
from mbplan.ocp.problem import OCP, Item
from mbplan.residuals.base import ShootingResidual
from mbplan.robots.loops import refuse_loops
from mbplan.simulation.reference import damping_rate

try:
    import crocoddyl
    import mim_solvers  # noqa: F401  (the CSQP adapter's solver)
except ImportError as err:
    raise MbplanError(
        f"the Crocoddyl baselines cannot import {err.name or 'their libraries'} ({err}); "
        "install the baselines extra: pip install 'mbplan[baselines]' "
        "(crocoddyl==3.2.1, mim-solvers==0.3.0)"
    ) from None

OBSTACLE_WEIGHT = 1e4  # FDDP: ½ W (margin - r)² per knot; a 3 cm violation costs 4.5
LIMIT_WEIGHT = 1e3  # FDDP: the same on joint-position/velocity limits (rad, rad/s)
PENALTY_MARGIN = 5e-3  # FDDP: penalised bounds are tightened by this (rad, rad/s, m)
MAX_DAMPING_STIFFNESS = 1.0  # λ(M⁻¹D) Δt: explicit damping is stable below 2, accurate below ~1
FORWARD_DYNAMICS_TOL = 1e-8  # relative: |Δ ẍ| ≤ tol · max(1, |ẍ|)


def compare_forward_dynamics(xout: np.ndarray, reference: np.ndarray) -> None:
    """Raise :class:`MbplanError` if Crocoddyl's ``xout`` differs from Pinocchio's ABA
    ``reference`` by more than :data:`FORWARD_DYNAMICS_TOL` (relative, or if either is NaN)."""
    error = float(np.max(np.abs(np.asarray(xout) - reference)))
    if not error <= FORWARD_DYNAMICS_TOL * max(1.0, float(np.max(np.abs(reference)))):
        raise MbplanError(
            f"crocoddyl {crocoddyl.__version__} computes forward dynamics different from "
            f"pinocchio {pin.__version__} (max |Δq̈| = {error:.3g}): the wheels are built for "
            "different Pinocchio versions; install pin==4.0.0 with crocoddyl==3.2.1 "
            "(pip install 'mbplan[baselines]')"
        )


# process-wide cache, result-neutral: a check of the installed libraries, returns nothing
@cache
def check_forward_dynamics(seed: int = 0) -> None:
    """Compare Crocoddyl's free forward dynamics with ``pinocchio.aba`` at one random state of
    Pinocchio's sample manipulator; raise :class:`MbplanError` on a mismatch."""
    model = pin.buildSampleModelManipulator()
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.0, 1.0, model.nq)
    v, tau = rng.standard_normal(model.nv), rng.standard_normal(model.nv)
    try:
        state = crocoddyl.StateMultibody(model)
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(
            state, crocoddyl.ActuationModelFull(state), crocoddyl.CostModelSum(state, model.nv)
        )
        data = dam.createData()
        dam.calc(data, np.concatenate([q, v]), tau)
    except (TypeError, RuntimeError) as exc:  # Boost.Python rejects a foreign pinocchio.Model
        raise MbplanError(
            f"crocoddyl {crocoddyl.__version__} cannot use pinocchio {pin.__version__} "
            f"models ({exc}); install pin==4.0.0 with crocoddyl==3.2.1"
        ) from None
    compare_forward_dynamics(data.xout, pin.aba(model, model.createData(), q, v, tau))


class _Data(crocoddyl.ResidualDataAbstract):
    """Residual data with its own Pinocchio data."""

    def __init__(self, model: Any, collector: Any):
        crocoddyl.ResidualDataAbstract.__init__(self, model, collector)
        self.pinocchio = model.state.pinocchio.createData()


class ResidualModelJointSpace(crocoddyl.ResidualModelAbstract):
    """Any state residual of :mod:`mbplan.formulations.joint_space` (value and Jacobian by
    CasADi; Crocoddyl uses Gauss–Newton Hessians of residuals)."""

    def __init__(self, state: crocoddyl.StateMultibody, nu: int, fn: cs.Function):
        x = cs.SX.sym("x", fn.size1_in(0))
        out = fn(x)
        self._fn = cs.Function("rj", [x], [out, cs.jacobian(out, x)])
        crocoddyl.ResidualModelAbstract.__init__(self, state, out.numel(), nu, True, True, False)

    def calc(self, data: _Data, x: np.ndarray, u: np.ndarray | None = None) -> None:
        data.r[:] = np.asarray(self._fn(x)[0]).ravel()

    def calcDiff(self, data: _Data, x: np.ndarray, u: np.ndarray | None = None) -> None:
        Rx = data.Rx  # one row: a 1-D view
        Rx[...] = np.asarray(self._fn(x)[1]).reshape(Rx.shape)

    def createData(self, collector: Any) -> _Data:
        return _Data(self, collector)


class ResidualModelCylinderClearance(crocoddyl.ResidualModelAbstract):
    """``r_i = ‖(x_i, y_i) - c‖ - radius`` for the COM ``p_i`` of every link (eq. 62 without
    the margin), with ``∂r/∂q = n_iᵀ J_i[:2]`` (horizontal unit vector ``n_i`` from the axis)."""

    def __init__(self, state: crocoddyl.StateMultibody, nu: int, center: np.ndarray, radius: float):
        model = state.pinocchio
        self.links = np.arange(1, model.njoints)
        self.center, self.radius = np.asarray(center, float), float(radius)
        crocoddyl.ResidualModelAbstract.__init__(
            self, state, len(self.links), nu, True, False, False
        )
        self.levers = np.array([model.inertias[int(j)].lever for j in self.links])

    def _offsets(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        p = np.array(
            [data.oMi[int(j)].act(l) for j, l in zip(self.links, self.levers, strict=True)]
        )
        return p, p[:, :2] - self.center

    def calc(self, data: _Data, x: np.ndarray, u: np.ndarray | None = None) -> None:
        model = self.state.pinocchio
        pin.forwardKinematics(model, data.pinocchio, x[: model.nq])
        data.r[:] = np.linalg.norm(self._offsets(data.pinocchio)[1], axis=-1) - self.radius

    def calcDiff(self, data: _Data, x: np.ndarray, u: np.ndarray | None = None) -> None:
        model = self.state.pinocchio
        kin = chain_kinematics(model, data.pinocchio, x[None, : model.nq])
        p, d = self._offsets(data.pinocchio)
        n = d / np.linalg.norm(d, axis=-1, keepdims=True)
        J = point_jacobians(kin, self.links, p[None])[0]  # (nl, nv, 3)
        data.Rx[:, : model.nv] = np.einsum("ia,ija->ij", n, J[..., :2])

    def createData(self, collector: Any) -> _Data:
        return _Data(self, collector)


class ResidualModelCoalDistance(crocoddyl.ResidualModelAbstract):
    """``r_p = d_p(q)``: coal's signed distance of every (link geometry, object) pair of a
    :class:`~mbplan.residuals.Distance` from its rows ``margin - d``
    (:class:`~mbplan.residuals.distance.DistanceRows`), with the Jacobian ``-nᵀ J₁``."""

    def __init__(self, state: crocoddyl.StateMultibody, nu: int, ocp: OCP, residual: Any):
        self.rows = rows = residual.joint_space(ocp.robot, ocp.scene)
        crocoddyl.ResidualModelAbstract.__init__(self, state, rows.size, nu, True, False, False)

    def calc(self, data: _Data, x: np.ndarray, u: np.ndarray | None = None) -> None:
        data.r[:] = self.rows.margin - self.rows.values(x[None, : self.state.nq])[0]

    def calcDiff(self, data: _Data, x: np.ndarray, u: np.ndarray | None = None) -> None:
        data.Rx[:, : self.state.nv] = -self.rows.jacobian(x[None, : self.state.nq])[0]

    def createData(self, collector: Any) -> _Data:
        return _Data(self, collector)


class ActuationModelDamped(crocoddyl.ActuationModelAbstract):
    """Full actuation with viscous joint damping: ``τ = u - D v``, ``D = diag(model.damping)``."""

    def __init__(self, state: crocoddyl.StateMultibody):
        crocoddyl.ActuationModelAbstract.__init__(self, state, state.nv)
        self.damping = np.array(state.pinocchio.damping, dtype=float)

    def calc(self, data: Any, x: np.ndarray, u: np.ndarray) -> None:
        data.tau[:] = u - self.damping * x[self.state.nq :]

    def calcDiff(self, data: Any, x: np.ndarray, u: np.ndarray) -> None:
        nv = self.state.nv
        data.dtau_dx[:, nv:] = -np.diag(self.damping)
        data.dtau_du[:, :] = np.eye(nv)

    def commands(self, data: Any, x: np.ndarray, tau: np.ndarray) -> None:
        data.u[:] = tau + self.damping * x[self.state.nq :]

    def torqueTransform(self, data: Any, x: np.ndarray, u: np.ndarray) -> None:
        data.Mtau[:, :] = np.eye(self.state.nv)


class ShootingBuilder:
    """The shooting problem of ``ocp`` for FDDP (``hard=False``) or CSQP (``hard=True``); the
    context of the residuals' :meth:`~mbplan.residuals.Residual.shooting`."""

    crocoddyl = crocoddyl
    limit_weight = LIMIT_WEIGHT
    obstacle_weight = OBSTACLE_WEIGHT

    def __init__(self, ocp: OCP, hard: bool, method: str):
        refuse_loops(ocp.robot, method)
        check_forward_dynamics()
        self.ocp, self.hard, self.method = ocp, hard, method
        self.model = ocp.robot.model
        self.state = crocoddyl.StateMultibody(self.model)
        self.actuation = (
            ActuationModelDamped(self.state)
            if np.any(self.model.damping)
            else crocoddyl.ActuationModelFull(self.state)
        )
        self.nu = self.actuation.nu
        self.u_lb = np.full(self.nu, -np.inf)
        self.u_ub = np.full(self.nu, np.inf)
        for item in ocp.constraints:
            bounds = item.residual.variable_bounds(ocp.robot)
            if bounds is not None and bounds[0] == "tau":
                self.u_lb = np.maximum(self.u_lb, bounds[1])
                self.u_ub = np.minimum(self.u_ub, bounds[2])
            elif item.residual.sense == "eq" and not hard:
                kind = type(item.residual).__name__
                hint = "make it a cost or use csqp" if item.residual.cost else "use csqp"
                raise InputError(
                    f"{method} cannot express the equality constraint {item.name!r} ({kind}; "
                    f"FDDP has no constraints): {hint}"
                )
        self._nodes: dict[tuple, crocoddyl.IntegratedActionModelEuler] = {}
        stiffness = damping_rate(self.model, ocp.q0) * ocp.dt
        if stiffness > MAX_DAMPING_STIFFNESS:
            raise InputError(
                f"{method}: the joint damping of {ocp.robot.name!r} is too stiff for Crocoddyl's "
                f"Euler step (explicit in v): λ(M⁻¹D) Δt = {stiffness:.3g} > "
                f"{MAX_DAMPING_STIFFNESS:g} at q0; use a smaller dt, load the robot with "
                "damping=False, or plan with ipopt"
            )

    def symbolic(self, item: Item) -> ShootingResidual:
        """A state residual's joint-space CasADi rows as a Python residual (bounds ``r = 0`` or
        ``r ≤ 0``; FDDP: a penalty of weight :data:`OBSTACLE_WEIGHT`)."""
        r = item.residual
        fn = knot_function(self.ocp.robot, self.ocp.scene, r)
        res = ResidualModelJointSpace(self.state, self.nu, fn)
        lower = np.zeros(res.nr) if r.sense == "eq" else np.full(res.nr, -np.inf)
        return ShootingResidual(res, lower, np.zeros(res.nr), OBSTACLE_WEIGHT)

    def com_clearance(self, center: Any, radius: float) -> ResidualModelCylinderClearance:
        return ResidualModelCylinderClearance(self.state, self.nu, center, radius)

    def coal_distance(self, residual: Any) -> ResidualModelCoalDistance:
        return ResidualModelCoalDistance(self.state, self.nu, self.ocp, residual)

    def _node(self, k: int) -> crocoddyl.IntegratedActionModelEuler:
        ocp = self.ocp
        terminal = k == ocp.N
        active = tuple(i.name for i in ocp.items if k in i.knots)  # state 1..N, control 0..N-1
        if active in self._nodes:
            return self._nodes[active]
        state, nu = self.state, self.nu
        dt = 0.0 if terminal else ocp.dt
        scale = 1.0 / dt if dt else 1.0  # undo Crocoddyl's Δt factor on running costs
        costs = crocoddyl.CostModelSum(state, nu)
        constraints = crocoddyl.ConstraintModelManager(state, nu)
        for name in active:
            item = ocp[name]
            res = item.residual.shooting(self, item)
            if item.role == "cost":
                if res.activation is not None:
                    act = crocoddyl.ActivationModelWeightedQuad(res.activation)
                    cost = crocoddyl.CostModelResidual(state, act, res.model)
                else:
                    cost = crocoddyl.CostModelResidual(state, res.model)
                costs.addCost(name, cost, item.weight * scale)
            elif self.hard:
                constraint = crocoddyl.ConstraintModelResidual(
                    state, res.model, res.lower, res.upper
                )
                constraints.addConstraint(name, constraint)
            elif res.weight is not None:  # None: box-FDDP's control bounds
                bounds = crocoddyl.ActivationBounds(
                    res.lower + PENALTY_MARGIN, res.upper - PENALTY_MARGIN
                )
                barrier = crocoddyl.ActivationModelQuadraticBarrier(bounds)
                penalty = crocoddyl.CostModelResidual(state, barrier, res.model)
                costs.addCost(name, penalty, res.weight * scale)
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(
            state, self.actuation, costs, constraints
        )
        node = crocoddyl.IntegratedActionModelEuler(dam, dt)
        if np.all(np.isfinite(self.u_lb)) and np.all(np.isfinite(self.u_ub)):
            node.u_lb, node.u_ub = self.u_lb, self.u_ub
        self._nodes[active] = node
        return node

    def problem(self) -> crocoddyl.ShootingProblem:
        x0 = np.concatenate([self.ocp.q0, self.ocp.v0])
        running = [self._node(k) for k in range(self.ocp.N)]
        return crocoddyl.ShootingProblem(x0, running, self._node(self.ocp.N))

    def warm_start(self, q: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Quasi-static guess: ``xs = (q_k, 0)`` (knot 0: the OCP's ``v0``), ``us = g(q_k)``
        clipped to the torque limits."""
        data = self.model.createData()
        xs = [np.concatenate([qk, np.zeros(self.model.nv)]) for qk in q]
        xs[0] = np.concatenate([self.ocp.q0, self.ocp.v0])
        us = [
            np.clip(pin.computeGeneralizedGravity(self.model, data, qk), self.u_lb, self.u_ub)
            for qk in q[:-1]
        ]
        return xs, us
