"""Crocoddyl baselines of the obstacle task: what users pick instead of an NLP solver.

* :func:`solve_fddp` — Crocoddyl's box-FDDP: torque limits as control bounds, the obstacle
  (eq. 62) and the joint-position/velocity limits as quadratic penalties;
* :func:`solve_csqp` — mim-solvers' constrained SQP (CSQP, an ADMM QP per iteration): the
  obstacle, torque, joint-position and velocity limits as hard inequality constraints.

Transcription (both). State ``x = (q, v)``, control ``u = τ`` (fully actuated), forward dynamics
by ABA (``DifferentialActionModelFreeFwdDynamics``) and ``IntegratedActionModelEuler`` with the
task's Δt. Crocoddyl's Euler step is *semi-implicit*::

    v_{k+1} = v_k + Δt aba(q_k, v_k, τ_k),   q_{k+1} = q_k + Δt v_{k+1},

where eq. (61) has ``q_{k+1} = q_k + Δt v_k``. Both are first order; their one-step errors in
``q`` are ``∓½Δt² q̈ + ⅙Δt³ q⃛ + …``, so where the two terms cancel for explicit Euler the
semi-implicit error is larger: :func:`mbplan.verification.verify`, whose per-knot threshold is
twice the explicit-Euler error, can reject an exact solution of this scheme (seen on 1 of 5
seeded cases, ratio 1.29 with defects < 1e-4).

Cost: the task cost exactly. Crocoddyl multiplies running costs by Δt, so running weights are
divided by Δt; the terminal node (``dt = 0``: no dynamics, no scaling) carries the state cost
times ``terminal_factor``. Node 0 (``x_0 = (q0, 0)`` fixed) carries only the control cost.

Obstacle: :class:`ResidualModelCylinderClearance` computes, for every link COM ``p_i`` and
cylinder ``c``, ``r_ic = ‖(x_i, y_i) - c‖ - radius_c`` (as :func:`~mbplan.tasks.obstacle.
com_clearances`) with its exact Jacobian; eq. (62) is ``r_ic ≥ margin`` at knots ``1..N``.
Crocoddyl has no distance-to-an-axis residual, and ``ResidualModelFrameTranslation`` with a box
barrier on ``(x, y)`` would model a square prism, not the cylinder, hence this Python residual.
With ``obstacle_constraint = "distance"``, :class:`ResidualModelCoalDistance` gives the coal
distance of every (link geometry, obstacle) pair instead (Crocoddyl's ``ResidualModelPairCollision``
returns the witness-point difference, not a signed distance), under the same ``≥ margin``.

* FDDP penalises ``½ W Σ max(margin - r_ic, 0)²`` per knot (``ActivationModelQuadraticBarrier``,
  ``W =`` :data:`OBSTACLE_WEIGHT`) and the URDF joint-position limits and the task's velocity
  limits with the same barrier (:data:`LIMIT_WEIGHT`). A penalty trades violation against the
  tracking cost: where the straight path is blocked, FDDP's optimum overshoots the velocity
  limits and moves a link across the cylinder within one interval, between knots that are in
  the margin or just inside the cylinder, which :func:`mbplan.verification.verify` rejects.
  Stiffer penalties (1e5-1e6) do not remove the crossing and stop FDDP converging within 500
  iterations; without the limit penalty it converges fastest but crosses at 2.6 times the
  velocity limit.
* CSQP imposes the same residuals as constraints (``ConstraintModelResidual``: ``r ≥ margin``,
  ``|τ| ≤ τ_max``, joint-position and velocity bounds); at node 0 only the torque bounds.

Warm start (both): ``q_k`` of :func:`~mbplan.tasks.obstacle.joint_interpolation` at rest
(``v_k = 0``) and gravity-compensation torques ``τ_k = g(q_k)`` (clipped to the limits): a
quasi-static, dynamically infeasible guess that both multiple-shooting solvers accept.

Importing this module needs the ``baselines`` extra (``crocoddyl==3.2.1``,
``mim-solvers==0.3.0``) and checks once that Crocoddyl's forward dynamics equal Pinocchio's ABA
(:func:`check_forward_dynamics`): Crocoddyl's wheels are built against one Pinocchio ABI, and a
mismatched ``pin`` (e.g. 4.1.0 with crocoddyl 3.2.1) silently computes wrong dynamics.
"""

from __future__ import annotations

import time
from typing import Any, Literal

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError, MbplanError
from mbplan.multibody.collision import (
    CollisionPairs,
    chain_kinematics,
    joint_space_contacts,
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
from mbplan.validation import as_int, as_real

try:
    import crocoddyl
    import mim_solvers
except ImportError as err:
    raise MbplanError(
        f"the Crocoddyl baselines cannot import {err.name or 'their libraries'} ({err}); "
        "install the baselines extra: pip install 'mbplan[baselines]' "
        "(crocoddyl==3.2.1, mim-solvers==0.3.0)"
    ) from None

OBSTACLE_WEIGHT = 1e4  # FDDP: ½ W (margin - r)² per knot; a 3 cm violation costs 4.5
LIMIT_WEIGHT = 1e3  # FDDP: the same on joint-position/velocity limits (rad, rad/s)
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


check_forward_dynamics()


class ResidualDataCylinderClearance(crocoddyl.ResidualDataAbstract):
    """Data of :class:`ResidualModelCylinderClearance`: its own Pinocchio data."""

    def __init__(self, model: ResidualModelCylinderClearance, collector: Any):
        crocoddyl.ResidualDataAbstract.__init__(self, model, collector)
        self.pinocchio = model.state.pinocchio.createData()


class ResidualModelCylinderClearance(crocoddyl.ResidualModelAbstract):
    """``r[i·nc + c] = ‖(x_i, y_i) - center_c‖ - radius_c`` for the COM ``p_i`` of every link
    ``i = 1..njoints-1`` and every vertical cylinder ``c`` (eq. 62 without the margin).

    Jacobian: ``∂r/∂q = n_icᵀ J_i[:2]`` with the horizontal unit vector ``n_ic`` from the axis
    to the COM and the COM Jacobian ``J_i = v_j + ω_j × p_i`` over the joints ``j`` moving link
    ``i`` (world-frame joint twists of ``computeJointJacobians``); undefined on the axis itself.
    """

    def __init__(
        self,
        state: crocoddyl.StateMultibody,
        nu: int,
        centers: np.ndarray,
        radii: np.ndarray,
    ):
        model = state.pinocchio
        self.links = range(1, model.njoints)
        self.centers = np.asarray(centers, dtype=float).reshape(-1, 2)
        self.radii = np.asarray(radii, dtype=float)
        crocoddyl.ResidualModelAbstract.__init__(
            self, state, len(self.links) * len(self.radii), nu, True, False, False
        )
        self.levers = [model.inertias[j].lever for j in self.links]

    def _offsets(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """COMs ``p (nl, 3)`` and horizontal offsets ``(x_i, y_i) - c`` ``(nl, nc, 2)``."""
        p = np.array(
            [data.oMi[j].act(lever) for j, lever in zip(self.links, self.levers, strict=True)]
        )
        return p, p[:, None, :2] - self.centers

    def calc(
        self, data: ResidualDataCylinderClearance, x: np.ndarray, u: np.ndarray | None = None
    ) -> None:
        model = self.state.pinocchio
        pin.forwardKinematics(model, data.pinocchio, x[: model.nq])
        _, d = self._offsets(data.pinocchio)
        data.r[:] = (np.linalg.norm(d, axis=-1) - self.radii).ravel()

    def calcDiff(
        self, data: ResidualDataCylinderClearance, x: np.ndarray, u: np.ndarray | None = None
    ) -> None:
        model = self.state.pinocchio
        kin = chain_kinematics(model, data.pinocchio, x[None, : model.nq])
        p, d = self._offsets(data.pinocchio)
        n = d / np.linalg.norm(d, axis=-1, keepdims=True)
        J = point_jacobians(kin, np.asarray(self.links), p[None])[0]  # (nl, nv, 3)
        data.Rx[:, : model.nv] = np.einsum("ica,ija->icj", n, J[..., :2]).reshape(-1, model.nv)

    def createData(self, collector: Any) -> ResidualDataCylinderClearance:
        return ResidualDataCylinderClearance(self, collector)


class ResidualDataCoalDistance(crocoddyl.ResidualDataAbstract):
    """Data of :class:`ResidualModelCoalDistance`: its own Pinocchio data."""

    def __init__(self, model: ResidualModelCoalDistance, collector: Any):
        crocoddyl.ResidualDataAbstract.__init__(self, model, collector)
        self.pinocchio = model.state.pinocchio.createData()


class ResidualModelCoalDistance(crocoddyl.ResidualModelAbstract):
    """``r[p] = d_p(q)``: coal's signed distance of every (link geometry, obstacle) pair, with
    the Jacobian ``-nᵀ J₁`` of :mod:`mbplan.multibody.collision` (Crocoddyl uses Gauss–Newton
    Hessians of residuals, so no second-order term)."""

    def __init__(self, state: crocoddyl.StateMultibody, nu: int, pairs: CollisionPairs):
        self.pairs = pairs
        crocoddyl.ResidualModelAbstract.__init__(self, state, pairs.size, nu, True, False, False)

    def _contacts(self, data: ResidualDataCoalDistance, x: np.ndarray):
        model = self.state.pinocchio
        kin = chain_kinematics(model, data.pinocchio, x[None, : model.nq])
        contacts, J = joint_space_contacts(self.pairs, kin)
        return contacts.distance[0], contacts.normal[0], J[0]

    def calc(
        self, data: ResidualDataCoalDistance, x: np.ndarray, u: np.ndarray | None = None
    ) -> None:
        data.r[:] = self._contacts(data, x)[0]

    def calcDiff(
        self, data: ResidualDataCoalDistance, x: np.ndarray, u: np.ndarray | None = None
    ) -> None:
        _, normal, J = self._contacts(data, x)
        data.Rx[:, : self.state.nv] = -np.einsum("pa,pja->pj", normal, J)

    def createData(self, collector: Any) -> ResidualDataCoalDistance:
        return ResidualDataCoalDistance(self, collector)


class _History(crocoddyl.CallbackAbstract):
    """Record ``(ffeas, stop)`` of Crocoddyl's solver at every iteration."""

    def __init__(self) -> None:
        crocoddyl.CallbackAbstract.__init__(self)
        self.rows: list[tuple[float, float]] = []

    def __call__(self, solver: crocoddyl.SolverAbstract) -> None:
        self.rows.append((solver.ffeas, solver.stop))


class _CsqpHistory(mim_solvers.CallbackAbstract):
    """Record ``(gap_norm + constraint_norm, KKT)`` of CSQP at every iteration."""

    def __init__(self) -> None:
        mim_solvers.CallbackAbstract.__init__(self)
        self.rows: list[tuple[float, float]] = []

    def __call__(self, solver: mim_solvers.SolverCSQP, solver_type: str = "CSQP") -> None:
        self.rows.append((solver.gap_norm + solver.constraint_norm, solver.KKT))


class _Builder:
    """The task's shooting problem and warm start for FDDP (``hard=False``) or CSQP."""

    def __init__(self, task: ObstacleTask, hard: bool):
        self.task, self.hard = task, hard
        self.model = robot_description(task.robot).model
        self.state = crocoddyl.StateMultibody(self.model)
        self.actuation = crocoddyl.ActuationModelFull(self.state)
        self.nu = self.actuation.nu
        m, w = self.model, task.weights
        self.x_lower = np.concatenate([m.lowerPositionLimit, -task.velocity_limit])
        self.x_upper = np.concatenate([m.upperPositionLimit, task.velocity_limit])
        self.x_weights = np.concatenate([np.full(m.nv, w.w_q), np.full(m.nv, w.w_v)])
        self.x_target = np.concatenate([task.q_target, np.zeros(m.nv)])

    def _clearance(self) -> ResidualModelCylinderClearance | ResidualModelCoalDistance | None:
        if self.task.obstacle_constraint == "distance" and self.task.obstacles:
            return ResidualModelCoalDistance(self.state, self.nu, task_collision_pairs(self.task))
        cylinders = self.task.cylinders
        if not cylinders:
            return None
        centers = np.array([c.center_xy for c in cylinders])
        radii = np.array([c.radius for c in cylinders])
        return ResidualModelCylinderClearance(self.state, self.nu, centers, radii)

    def _node(
        self, kind: Literal["first", "inner", "terminal"]
    ) -> crocoddyl.IntegratedActionModelEuler:
        """Action model of node 0 (``"first"``), nodes ``1..N-1`` (``"inner"``) or N."""
        task, state, nu = self.task, self.state, self.nu
        dt = 0.0 if kind == "terminal" else task.dt
        scale = 1.0 / dt if dt else 1.0  # undo Crocoddyl's Δt factor on running costs
        costs = crocoddyl.CostModelSum(state, nu)
        constraints = crocoddyl.ConstraintModelManager(state, nu)
        tau_max = task.torque_limit
        if kind != "terminal":
            control = crocoddyl.ResidualModelControl(state, nu)
            costs.addCost(
                "tau", crocoddyl.CostModelResidual(state, control), task.weights.w_tau * scale
            )
            if self.hard:
                constraints.addConstraint(
                    "tau", crocoddyl.ConstraintModelResidual(state, control, -tau_max, tau_max)
                )
        if kind != "first":
            factor = task.weights.terminal_factor if kind == "terminal" else scale
            tracking = crocoddyl.CostModelResidual(
                state,
                crocoddyl.ActivationModelWeightedQuad(self.x_weights),
                crocoddyl.ResidualModelState(state, self.x_target, nu),
            )
            costs.addCost("state", tracking, factor)
            limits = crocoddyl.ResidualModelState(state, np.zeros(state.nx), nu)
            clearance = self._clearance()
            bounds = [("limits", limits, self.x_lower, self.x_upper, LIMIT_WEIGHT)]
            if clearance is not None:
                margin = np.full(clearance.nr, task.margin)
                bounds.append(
                    ("obstacle", clearance, margin, np.full(clearance.nr, np.inf), OBSTACLE_WEIGHT)
                )
            for name, residual, lower, upper, weight in bounds:
                if self.hard:
                    constraints.addConstraint(
                        name, crocoddyl.ConstraintModelResidual(state, residual, lower, upper)
                    )
                else:
                    barrier = crocoddyl.ActivationModelQuadraticBarrier(
                        crocoddyl.ActivationBounds(lower, upper)
                    )
                    costs.addCost(
                        name, crocoddyl.CostModelResidual(state, barrier, residual), weight * scale
                    )
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(
            state, self.actuation, costs, constraints
        )
        node = crocoddyl.IntegratedActionModelEuler(dam, dt)
        node.u_lb, node.u_ub = -tau_max, tau_max
        return node

    def problem(self) -> crocoddyl.ShootingProblem:
        x0 = np.concatenate([self.task.q0, np.zeros(self.model.nv)])
        inner = self._node("inner")
        running = [self._node("first")] + [inner] * (self.task.N - 1)
        return crocoddyl.ShootingProblem(x0, running, self._node("terminal"))

    def warm_start(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Quasi-static guess: ``xs = (q_k, 0)``, ``us = g(q_k)`` clipped to the limits."""
        q = joint_interpolation(self.task)
        data = self.model.createData()
        xs = [np.concatenate([qk, np.zeros(self.model.nv)]) for qk in q]
        lim = self.task.torque_limit
        us = [
            np.clip(pin.computeGeneralizedGravity(self.model, data, qk), -lim, lim) for qk in q[:-1]
        ]
        return xs, us


def _result(
    task: ObstacleTask,
    method: str,
    converged: bool,
    solver: crocoddyl.SolverAbstract,
    iterations: int,
    max_iter: int,
    history: np.ndarray,
    solve_time: float,
    start: float,
    extra: dict[str, Any],
) -> PlanResult:
    xs, us = np.array(solver.xs), np.array(solver.us)
    nq = task.q0.size
    q, v, tau = xs[:, :nq], xs[:, nq:], us
    finite = all(np.all(np.isfinite(a)) for a in (q, v, tau))
    if converged:
        status, message = "converged", "converged"
    elif iterations >= max_iter:
        status, message = "max_iter", f"maximum number of iterations ({max_iter}) reached"
    else:
        status = "failed"
        message = (
            f"stopped after {iterations} iterations without converging (regularization at "
            "its maximum or no acceptable step)"
        )
    if not finite:
        message = f"{message}; the solution contains NaN or inf"
    return PlanResult(
        method=method,
        status=status,
        success=converged and finite,
        message=message,
        iterations=iterations,
        solve_time_s=solve_time,
        total_time_s=time.perf_counter() - start,
        time_per_iter_s=solve_time / max(iterations, 1),
        q=q,
        v=v,
        tau=tau,
        dt=task.dt,
        kkt_history=history.reshape(-1, 2),
        entered_restoration=None,
        extra={"objective": float(solver.cost), **extra},
    )


def _prepare(task: ObstacleTask, max_iter: object, tol: object) -> tuple[int, float]:
    """Checked ``max_iter`` and ``tol``; raise on a bad task or an infeasible request."""
    if not isinstance(task, ObstacleTask):
        raise InputError(f"task: expected ObstacleTask, got {type(task).__name__}")
    require_eq62(task, "the Crocoddyl baselines")
    max_iter = as_int(max_iter, "max_iter", minimum=0, what="iteration limit")
    tol = as_real(tol, "tol", positive=True)
    validate(task)
    return max_iter, tol


def _solve(
    solver, builder: _Builder, history, max_iter: int, start: float
) -> tuple[bool, float, float]:
    """Run a Crocoddyl-style solver from the builder's warm start with ``history`` as callback;
    ``(converged, build time since start, solve time)``."""
    solver.setCallbacks([history])
    xs, us = builder.warm_start()
    build_time = time.perf_counter() - start
    tic = time.perf_counter()
    converged = solver.solve(xs, us, max_iter, False)
    return converged, build_time, time.perf_counter() - tic


def solve_fddp(task: ObstacleTask, max_iter: int = 500, tol: float = 1e-9) -> PlanResult:
    """Solve ``task`` with Crocoddyl's ``SolverBoxFDDP`` (module docstring for the model).

    ``tol`` is Crocoddyl's ``th_stop`` on its stopping criterion, the expected cost decrease of
    a full step ``|d₁ + ½ d₂|``, checked once the iterate is dynamically feasible. ``success``
    means convergence with a finite solution. ``iterations`` counts the solver's steps;
    ``kkt_history[i] = (ffeas, stop)`` (∞-norm of the dynamics gaps, stopping criterion) at
    iterate ``i``, the last row evaluated after the solve. ``extra`` holds ``objective`` (the
    task cost plus the penalties), ``build_time_s`` and the penalty weights.
    """
    start = time.perf_counter()
    max_iter, tol = _prepare(task, max_iter, tol)
    builder = _Builder(task, hard=False)
    solver = crocoddyl.SolverBoxFDDP(builder.problem())
    solver.th_stop = tol
    history = _History()
    converged, build_time, solve_time = _solve(solver, builder, history, max_iter, start)
    iterations = len(history.rows)
    rows = [*history.rows, _fddp_final_row(solver)]
    return _result(
        task,
        "fddp",
        converged,
        solver,
        iterations,
        max_iter,
        np.array(rows),
        solve_time,
        start,
        {
            "build_time_s": build_time,
            "obstacle_weight": OBSTACLE_WEIGHT,
            "limit_weight": LIMIT_WEIGHT,
            "kkt_history_columns": ["ffeas", "stop"],
        },
    )


def _fddp_final_row(solver: crocoddyl.SolverBoxFDDP) -> tuple[float, float]:
    """``(ffeas, stop)`` at the final iterate: what the next iteration would test."""
    try:
        solver.computeDirection(True)
    except RuntimeError:  # backward pass failed: no stopping criterion there
        return solver.ffeas, float("nan")
    solver.updateExpectedImprovement()
    solver.expectedImprovement()
    return solver.ffeas, solver.stoppingCriteria()


def solve_csqp(task: ObstacleTask, max_iter: int = 500, tol: float = 1e-3) -> PlanResult:
    """Solve ``task`` with mim-solvers' ``SolverCSQP`` (module docstring for the model).

    ``tol`` is CSQP's ``termination_tolerance`` on its KKT residual (max of the ∞-norms of the
    Lagrangian gradient and of the dynamics gaps, and the ℓ1 constraint violation), default 1e-3
    as in mim-solvers' examples; the inner ADMM QP keeps mim-solvers' defaults
    (``eps_abs = eps_rel = 1e-4``, at most 1000 iterations). Where the obstacle is active the
    ADMM QP hits its iteration limit and the KKT residual levels off at 1.5e-3 to 3e-3 (more QP
    iterations or tighter ``eps`` do not lower it), so such cases end at ``max_iter``; the
    gaps and constraint violations are then ~1e-5. ``success`` means convergence with a finite
    solution. ``iterations`` counts SQP steps; ``kkt_history[i] = (gap_norm + constraint_norm,
    KKT)`` (ℓ1 norms of the dynamics gaps and constraint violations; KKT residual) at iterate
    ``i``: the last row comes from mim-solvers' ``extra_iteration_for_last_kkt``, whose QP is
    part of ``solve_time_s``. ``extra`` holds ``objective``, ``build_time_s`` and
    ``qp_iterations`` (of the last QP).
    """
    start = time.perf_counter()
    max_iter, tol = _prepare(task, max_iter, tol)
    builder = _Builder(task, hard=True)
    solver = mim_solvers.SolverCSQP(builder.problem())
    solver.termination_tolerance = tol
    solver.extra_iteration_for_last_kkt = True  # the KKT row of the last iterate
    history = _CsqpHistory()
    converged, build_time, solve_time = _solve(solver, builder, history, max_iter, start)
    iterations = int(solver.iter)
    return _result(
        task,
        "csqp",
        converged,
        solver,
        iterations,
        max_iter,
        np.array(history.rows[: iterations + 1]),
        solve_time,
        start,
        {
            "build_time_s": build_time,
            "qp_iterations": int(solver.qp_iters),
            "kkt_history_columns": ["gap_norm + constraint_norm", "KKT"],
        },
    )
